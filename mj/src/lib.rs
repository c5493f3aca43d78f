//! The safe MuJoCo wrapper, the lowest floor of twin above the raw bindings (`mujoco-sys`):
//! [`Model`] (immutable, `Send + Sync`), [`Data`] (`Send`, shares its model through an `Arc`),
//! [`ModelEdit`] for edits that need `mj_setConst`, and batched ray casting ([`RayScene`]) for
//! depth cameras and LiDARs. Everything above (the twin, its controllers, bridges and tools)
//! reaches MuJoCo through this crate: a model file or string goes in, `Model` and `Data` come
//! out, and each step, query or edit is a safe call whose failure is an [`Error`].
//!
//! Every MuJoCo call that can raise `mju_user_error` goes through the C shim in `csrc/shim.c`,
//! which turns the error into [`Error::MuJoCo`] instead of ending the process. twin's unsafe
//! code lives in this crate (and `mujoco-sys`) only, each block with a `// SAFETY:` comment.
//! [`Renderer`] draws camera images with MuJoCo's own renderer on an offscreen OpenGL context
//! ([`GlThread`]: a thread owning an EGL or OSMesa context, loaded at run time).

pub mod convert;
mod data;
mod edit;
pub mod error;
mod gl;
mod kinds;
mod model;
mod ray;
mod ray_shape;
mod render;

pub use data::{ContactWrench, Data, StateSig, Warning};
pub use edit::ModelEdit;
pub use error::{Error, Result};
pub use gl::{GlBackend, GlThread, gl_available};
pub use kinds::{BiasType, DynType, GeomType, Integrator, SensorType, Transmission};
pub use model::{FreeJoint, JointType, Model, ModelLayout, ObjType};
pub use ray::{RayFilter, RayHit, RayScene, RayStats};
pub use render::{Renderer, Segment, View};

use std::ffi::{CStr, c_char, c_int};
use std::mem::MaybeUninit;
use std::sync::OnceLock;

/// Declarations of the C shim (`csrc/shim.c`). Each guarded function returns 0 on success and
/// 1 when MuJoCo raised an error, with the message in `err`.
pub(crate) mod ffi {
    use mujoco_sys::{mjData, mjModel, mjSpec, mjtNum};
    use std::ffi::{c_char, c_int, c_long, c_ulonglong};

    unsafe extern "C" {
        pub fn twin_install_handlers();
        pub fn twin_warning_count() -> c_ulonglong;
        pub fn twin_last_warning() -> *const c_char;
        pub fn twin_load_xml(filename: *const c_char, out: *mut *mut mjModel, err: *mut c_char, err_sz: c_int)
        -> c_int;
        pub fn twin_parse_xml_string(
            xml: *const c_char,
            out: *mut *mut mjSpec,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_compile(spec: *mut mjSpec, out: *mut *mut mjModel, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_copy_model(src: *const mjModel, out: *mut *mut mjModel, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_make_data(m: *const mjModel, out: *mut *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_copy_data(
            dst: *mut mjData,
            m: *const mjModel,
            src: *const mjData,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_step(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_step_n(m: *const mjModel, d: *mut mjData, n: c_long, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_step1(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_step2(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_forward(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_inverse(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_rne(
            m: *const mjModel,
            d: *mut mjData,
            flg_acc: c_int,
            result: *mut mjtNum,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_set_const(m: *mut mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_reset_data(m: *const mjModel, d: *mut mjData, key: c_int, err: *mut c_char, err_sz: c_int)
        -> c_int;
        pub fn twin_set_state(
            m: *const mjModel,
            d: *mut mjData,
            state: *const mjtNum,
            sig: c_int,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_kinematics_vel(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_kinematics_collision(m: *const mjModel, d: *mut mjData, err: *mut c_char, err_sz: c_int) -> c_int;
        pub fn twin_jac_body_dot(
            m: *const mjModel,
            d: *mut mjData,
            body: c_int,
            jacp: *mut mjtNum,
            jacr: *mut mjtNum,
            jacp_dot: *mut mjtNum,
            jacr_dot: *mut mjtNum,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_bench_c_step_loop(m: *const mjModel, d: *mut mjData, n: c_long);
        pub fn twin_bench_c_replay_loop(
            m: *const mjModel,
            d: *mut mjData,
            dst: *mut mjtNum,
            cmd: *const mjtNum,
            len: c_long,
            n: c_long,
        );
        pub fn twin_multi_ray(
            m: *const mjModel,
            d: *mut mjData,
            pnt: *const mjtNum,
            vec: *const mjtNum,
            geomgroup: *const u8,
            flg_static: u8,
            bodyexclude: c_int,
            geomid: *mut c_int,
            dist: *mut mjtNum,
            nray: c_int,
            cutoff: mjtNum,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_render_make_context(
            m: *const mjModel,
            con: *mut mujoco_sys::mjrContext,
            width: c_int,
            height: c_int,
            samples: c_int,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_render_make_scene(
            m: *const mjModel,
            scn: *mut mujoco_sys::mjvScene,
            maxgeom: c_int,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_render_update_scene(
            m: *const mjModel,
            d: *mut mjData,
            opt: *const mujoco_sys::mjvOption,
            cam: *mut mujoco_sys::mjvCamera,
            scn: *mut mujoco_sys::mjvScene,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
        pub fn twin_render_read(
            width: c_int,
            height: c_int,
            scn: *mut mujoco_sys::mjvScene,
            con: *const mujoco_sys::mjrContext,
            rgb: *mut u8,
            depth: *mut f32,
            err: *mut c_char,
            err_sz: c_int,
        ) -> c_int;
    }
}

const ERR_LEN: usize = 1024;

/// Installs the error handlers once per process and checks the library version.
pub(crate) fn init() -> Result<()> {
    static INIT: OnceLock<std::result::Result<(), (i32, i32)>> = OnceLock::new();
    let checked = INIT.get_or_init(|| {
        // SAFETY: sets two global function pointers to handlers defined in the shim; done once,
        // before any other MuJoCo call of twin.
        unsafe { ffi::twin_install_handlers() };
        // SAFETY: mj_version has no preconditions.
        let library = unsafe { mujoco_sys::mj_version() };
        let header = mujoco_sys::mjVERSION_HEADER as i32;
        if library == header { Ok(()) } else { Err((library, header)) }
    });
    checked.map_err(|(library, header)| Error::Version { library, header })
}

/// Runs one guarded shim call: hands it an error buffer and turns a raised error into `Err`.
#[inline]
pub(crate) fn guarded(call: &'static str, f: impl FnOnce(*mut c_char, c_int) -> c_int) -> Result<()> {
    // Uninitialised on purpose: the shim writes a NUL-terminated message only on error, and we
    // read it only then. Zeroing 1 KiB per step would show in the step loop.
    let mut buf = MaybeUninit::<[c_char; ERR_LEN]>::uninit();
    let ptr = buf.as_mut_ptr().cast::<c_char>();
    if f(ptr, ERR_LEN as c_int) == 0 {
        return Ok(());
    }
    // SAFETY: on a non-zero return the shim has written a NUL-terminated string into the buffer.
    let message = unsafe { CStr::from_ptr(ptr) }.to_string_lossy().trim().to_string();
    Err(Error::MuJoCo { call, message })
}

/// Reads a NUL-terminated buffer written by MuJoCo.
pub(crate) fn buf_to_string(buf: &[c_char]) -> String {
    let bytes: Vec<u8> = buf.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).trim().to_string()
}

/// The version of the MuJoCo headers the bindings were generated from (`mjVERSION_HEADER`),
/// e.g. `"4.0.1"`; [`init`] refuses a library of another version.
pub fn header_version() -> String {
    let v = mujoco_sys::mjVERSION_HEADER;
    format!("{}.{}.{}", v / 1_000_000, v / 1_000 % 1_000, v % 1_000)
}

/// The MuJoCo library's version string, e.g. `"4.0.1"`.
pub fn version() -> String {
    // SAFETY: returns a pointer to a static NUL-terminated string.
    unsafe { CStr::from_ptr(mujoco_sys::mj_versionString()) }.to_string_lossy().into_owned()
}

/// MuJoCo warnings raised on the calling thread so far (each `mju_warning`, e.g. "Nan, Inf or
/// huge value in QACC"), and the text of the last one. Per-`Data` counts are in
/// [`Data::warning_count`].
pub fn thread_warnings() -> (u64, String) {
    // SAFETY: both read thread-local state of the shim; the string is NUL-terminated.
    unsafe {
        let n = ffi::twin_warning_count();
        let text = CStr::from_ptr(ffi::twin_last_warning()).to_string_lossy().into_owned();
        (n, text)
    }
}

/// Steps `data` `n` times with a plain C loop of `mj_step` and no error guard: the reference
/// that benchmarks compare twin's own stepping against. Not for general use: a MuJoCo error in
/// this loop is not caught.
#[doc(hidden)]
pub fn bench_c_step_loop(data: &mut Data, n: u64) {
    let (m, d) = data.raw_parts();
    // SAFETY: pointers from a live Model/Data pair; mj_step on a valid pair has no other
    // preconditions (errors are the documented exception of this function).
    unsafe { ffi::twin_bench_c_step_loop(m, d, n as std::ffi::c_long) }
}

/// Replays `commands` with a plain C loop of `mj_step` and no error guard: per step, the next
/// `nu` values into `ctrl` (or `nv` values into `qfrc_applied` with `into_qfrc_applied`), then
/// `mj_step`. The reference for a controlled rollout: the same physics as the rollout that
/// recorded the commands, without its controller, observers or wrappers. Returns the steps run
/// (`commands.len()` / the command length). Not for general use: a MuJoCo error in this loop is
/// not caught.
///
/// # Errors
/// [`Error::Size`] when `commands` is not a whole number of commands (or the model has no
/// command entries).
#[doc(hidden)]
pub fn bench_c_replay_loop(data: &mut Data, into_qfrc_applied: bool, commands: &[f64]) -> Result<u64> {
    let len = if into_qfrc_applied { data.model().nv() } else { data.model().nu() };
    if len == 0 || !commands.len().is_multiple_of(len) {
        return Err(Error::Size {
            what: "replayed commands (a multiple of the command length)",
            expected: len,
            got: commands.len(),
        });
    }
    let n = commands.len() / len;
    let dst = if into_qfrc_applied { data.qfrc_applied_mut().as_mut_ptr() } else { data.ctrl_mut().as_mut_ptr() };
    let (m, d) = data.raw_parts();
    // SAFETY: pointers from a live Model/Data pair; `dst` has `len` entries and `commands` `n * len`
    // (checked above); mj_step on a valid pair has no other preconditions (errors are the documented
    // exception of this function).
    unsafe {
        ffi::twin_bench_c_replay_loop(m, d, dst, commands.as_ptr(), len as std::ffi::c_long, n as std::ffi::c_long)
    };
    Ok(n as u64)
}
