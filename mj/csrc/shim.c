// Catches MuJoCo's mju_user_error so that no MuJoCo error ends the process.
//
// MuJoCo reports fatal errors by calling mju_user_error, which by default prints and exit()s, and
// must not return. We install one handler for the whole process that longjmps to a setjmp placed
// in the wrapper below. The jump crosses only MuJoCo's C frames and this file's frames, never a
// Rust frame (a longjmp over Rust frames is undefined behaviour). The jump target and message are
// thread-local, so guarded calls on different threads do not interfere. This is what MuJoCo's own
// Python bindings do, with their setjmp in C++ right around each call.

#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

static _Thread_local jmp_buf* tls_jump = NULL;
static _Thread_local char tls_error[1024];
static _Thread_local unsigned long long tls_warning_count = 0;
static _Thread_local char tls_warning[1024];

static void copy_message(char* dst, size_t dst_sz, const char* msg) {
  if (!dst || dst_sz == 0) return;
  if (!msg) msg = "";
  size_t n = strlen(msg);
  if (n >= dst_sz) n = dst_sz - 1;
  memcpy(dst, msg, n);
  dst[n] = '\0';
}

static void twin_error_handler(const char* msg) {
  copy_message(tls_error, sizeof(tls_error), msg);
  if (tls_jump) {
    longjmp(*tls_jump, 1);
  }
  // Only reachable if twin calls a raising MuJoCo function without a guard: a bug in twin, not
  // bad input. MuJoCo must not continue after an error, so stop loudly rather than corrupt memory.
  fprintf(stderr, "twin: internal error: unguarded MuJoCo error: %s\n", tls_error);
  abort();
}

static void twin_warning_handler(const char* msg) {
  tls_warning_count++;
  copy_message(tls_warning, sizeof(tls_warning), msg);
}

void twin_install_handlers(void) {
  mju_user_error = twin_error_handler;
  mju_user_warning = twin_warning_handler;
}

unsigned long long twin_warning_count(void) { return tls_warning_count; }

const char* twin_last_warning(void) { return tls_warning; }

// After a longjmp out of a computation, mjData's arena stack still holds the frames that the
// interrupted functions had marked; drop them so the mjData stays usable.
static void reset_stack(mjData* d) {
  if (d) {
    d->pstack = 0;
    d->pbase = 0;
  }
}

// Runs STMT with a jump target installed; on a MuJoCo error, runs CLEANUP, copies the message to
// err and returns 1. Returns 0 on success. `prev` keeps nested guards correct.
#define TWIN_GUARD(STMT, CLEANUP)                   \
  jmp_buf env;                                      \
  jmp_buf* prev = tls_jump;                         \
  if (setjmp(env)) {                                \
    tls_jump = prev;                                \
    CLEANUP;                                        \
    copy_message(err, err_sz, tls_error);           \
    return 1;                                       \
  }                                                 \
  tls_jump = &env;                                  \
  STMT;                                             \
  tls_jump = prev;                                  \
  return 0;

// C++ frames under the guard of load and compile. mj_loadXML, mj_parseXMLString and mj_compile are
// C entry points into MuJoCo's C++ parser and compiler (src/xml/*.cc, src/user/user_model.cc).
// Frames that can be on the stack below this setjmp when MuJoCo raises:
//   twin_load_xml → mj_loadXML → mjXReader/mjXSchema (tinyxml2 document, std::string, std::vector)
//                 → mjCModel::Compile → mj_setConst / mj_makeData (C engine)
//   twin_parse_xml_string → mj_parseXMLString → the same parser frames
//   twin_compile → mj_compile → mjCModel::Compile → the same compile frames
// While compiling, MuJoCo installs its own thread-local error callback, which turns mju_error into
// a C++ exception (mjCError) caught inside mjCModel::Compile and the parser and returned as `err`;
// mju_error consults that callback before mju_user_error, so twin's handler — and its longjmp —
// does not run inside those C++ frames: the failure comes back as a NULL model and a message. The
// handler only fires for errors raised outside that window (e.g. by the C engine after the C++
// frames returned). If it ever fired inside them, the longjmp would skip their destructors
// (leaking the parser's and compiler's memory, never corrupting it: the Itanium C++ ABI unwinds
// nothing on longjmp and no MuJoCo lock is held across these calls); that is the residual risk,
// bounded by one leaked model per failed load.
int twin_load_xml(const char* filename, mjModel** out, char* err, int err_sz) {
  *out = NULL;
  TWIN_GUARD(*out = mj_loadXML(filename, NULL, err, err_sz), (void)0)
}

int twin_parse_xml_string(const char* xml, mjSpec** out, char* err, int err_sz) {
  *out = NULL;
  TWIN_GUARD(*out = mj_parseXMLString(xml, NULL, err, err_sz), (void)0)
}

int twin_compile(mjSpec* spec, mjModel** out, char* err, int err_sz) {
  *out = NULL;
  TWIN_GUARD(*out = mj_compile(spec, NULL), (void)0)
}

int twin_save_xml_string(const mjSpec* spec, char* xml, int xml_sz, int* status, char* err,
                         int err_sz) {
  TWIN_GUARD(*status = mj_saveXMLString(spec, xml, xml_sz, err, err_sz), (void)0)
}

int twin_copy_model(const mjModel* src, mjModel** out, char* err, int err_sz) {
  *out = NULL;
  TWIN_GUARD(*out = mj_copyModel(NULL, src), (void)0)
}

int twin_make_data(const mjModel* m, mjData** out, char* err, int err_sz) {
  *out = NULL;
  TWIN_GUARD(*out = mj_makeData(m), (void)0)
}

int twin_copy_data(mjData* dst, const mjModel* m, const mjData* src, char* err, int err_sz) {
  TWIN_GUARD(mj_copyData(dst, m, src), reset_stack(dst))
}

int twin_step(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_step(m, d), reset_stack(d))
}

int twin_step_n(const mjModel* m, mjData* d, long n, char* err, int err_sz) {
  TWIN_GUARD(for (long i = 0; i < n; i++) mj_step(m, d), reset_stack(d))
}

int twin_step1(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_step1(m, d), reset_stack(d))
}

int twin_step2(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_step2(m, d), reset_stack(d))
}

int twin_forward(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_forward(m, d), reset_stack(d))
}

int twin_inverse(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_inverse(m, d), reset_stack(d))
}

int twin_rne(const mjModel* m, mjData* d, int flg_acc, mjtNum* result, char* err, int err_sz) {
  TWIN_GUARD(mj_rne(m, d, flg_acc, result), reset_stack(d))
}

int twin_set_const(mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_setConst(m, d), reset_stack(d))
}

int twin_reset_data(const mjModel* m, mjData* d, int key, char* err, int err_sz) {
  TWIN_GUARD(if (key < 0) mj_resetData(m, d); else mj_resetDataKeyframe(m, d, key),
             reset_stack(d))
}

int twin_set_state(const mjModel* m, mjData* d, const mjtNum* state, int sig, char* err,
                   int err_sz) {
  TWIN_GUARD(mj_setState(m, d, state, sig), reset_stack(d))
}

// The reference loop for benchmarks: plain C, no guard, no Rust. Anything twin adds on top of
// this is twin's own overhead.
void twin_bench_c_step_loop(const mjModel* m, mjData* d, long n) {
  for (long i = 0; i < n; i++) {
    mj_step(m, d);
  }
}

// The reference for a controlled rollout: the same plain C loop replaying recorded commands.
// Step i copies `len` values from cmd + i * len into `dst` (d->ctrl or d->qfrc_applied), then
// calls mj_step; MuJoCo being deterministic, this reproduces the recorded rollout bit for bit.
void twin_bench_c_replay_loop(const mjModel* m, mjData* d, mjtNum* dst, const mjtNum* cmd, long len,
                              long n) {
  for (long i = 0; i < n; i++) {
    memcpy(dst, cmd + i * len, (size_t)len * sizeof(mjtNum));
    mj_step(m, d);
  }
}

// Kinematics and velocity-dependent quantities only (positions, com frame, cvel, cdof_dot):
// what Jacobians and their time derivatives need, without collision detection or dynamics.
int twin_kinematics_vel(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_kinematics(m, d); mj_comPos(m, d); mj_comVel(m, d), reset_stack(d))
}

// Positions and contacts only (mj_kinematics, mj_collision): self-collision checks along a
// planned path without the dynamics and the constraint solver of a forward pass.
int twin_kinematics_collision(const mjModel* m, mjData* d, char* err, int err_sz) {
  TWIN_GUARD(mj_kinematics(m, d); mj_collision(m, d), reset_stack(d))
}

// Jacobian of a body frame's origin and its time derivative (each 3 x nv, row-major).
int twin_jac_body_dot(const mjModel* m, mjData* d, int body, mjtNum* jacp, mjtNum* jacr,
                      mjtNum* jacp_dot, mjtNum* jacr_dot, char* err, int err_sz) {
  TWIN_GUARD(mj_jacBody(m, d, jacp, jacr, body);
             mj_jacDot(m, d, jacp_dot, jacr_dot, d->xpos + 3 * body, body), reset_stack(d))
}


// Rays from one point (mj_multiRay); it takes its scratch from d's stack, which can run out.
int twin_multi_ray(const mjModel* m, mjData* d, const mjtNum* pnt, const mjtNum* vec,
                   const mjtByte* geomgroup, mjtByte flg_static, int bodyexclude, int* geomid,
                   mjtNum* dist, int nray, mjtNum cutoff, char* err, int err_sz) {
  TWIN_GUARD(mj_multiRay(m, d, pnt, vec, geomgroup, flg_static, bodyexclude, geomid, dist, NULL,
                         nray, cutoff),
             reset_stack(d))
}

// Offscreen rendering (twin-core/src/mj/render.rs), with an OpenGL context current on the calling
// thread. mjr_makeContext raises when OpenGL lacks what MuJoCo needs; the offscreen buffer is
// grown to width x height when the model's <visual><global offwidth offheight> is smaller. With
// samples >= 0 the offscreen buffer has that many multisamples instead of the model's
// <visual><quality offsamples> (mjr_makeContext reads them from the model: a copy carries them).
int twin_render_make_context(const mjModel* m, mjrContext* con, int width, int height, int samples, char* err,
                             int err_sz) {
  mjModel* volatile copy = NULL;
  mjr_defaultContext(con);
  TWIN_GUARD(
      {
        const mjModel* use = m;
        if (samples >= 0 && samples != m->vis.quality.offsamples) {
          copy = mj_copyModel(NULL, m);
          copy->vis.quality.offsamples = samples;
          use = copy;
        }
        mjr_makeContext(use, con, mjFONTSCALE_100);
        if (copy) {
          mj_deleteModel(copy);
          copy = NULL;
        }
        mjr_setBuffer(mjFB_OFFSCREEN, con);
        if (con->currentBuffer != mjFB_OFFSCREEN) {
          mju_error("the OpenGL context has no offscreen framebuffer");
        }
        if (width > con->offWidth || height > con->offHeight) {
          mjr_resizeOffscreen(width > con->offWidth ? width : con->offWidth,
                              height > con->offHeight ? height : con->offHeight, con);
          mjr_setBuffer(mjFB_OFFSCREEN, con);
        }
        con->readDepthMap = mjDEPTH_ZEROFAR;
      },
      if (copy) mj_deleteModel(copy))
}

int twin_render_make_scene(const mjModel* m, mjvScene* scn, int maxgeom, char* err, int err_sz) {
  mjv_defaultScene(scn);
  TWIN_GUARD(mjv_makeScene(m, scn, maxgeom), (void)0)
}

int twin_render_update_scene(const mjModel* m, mjData* d, const mjvOption* opt, mjvCamera* cam, mjvScene* scn,
                             char* err, int err_sz) {
  TWIN_GUARD(mjv_updateScene(m, d, opt, NULL, cam, mjCAT_ALL, scn), reset_stack(d))
}

int twin_render_read(int width, int height, mjvScene* scn, const mjrContext* con, unsigned char* rgb, float* depth,
                     char* err, int err_sz) {
  mjrRect viewport = {0, 0, width, height};
  TWIN_GUARD(
      {
        mjr_render(viewport, scn, con);
        mjr_readPixels(rgb, depth, viewport, con);
      },
      (void)0)
}
