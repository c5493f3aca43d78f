use super::model::{raw_slice, raw_slice_mut};
use super::{Model, ModelLayout, ffi, guarded, init};
use crate::error::{Error, Result};
use mujoco_sys as sys;
use std::ffi::{c_char, c_int};
use std::ptr::NonNull;
use std::sync::Arc;

/// A shim stage on a model/data pair: `(m, d, err, err_sz)`, non-zero with a message in `err`
/// when MuJoCo raised.
type Stage = unsafe extern "C" fn(*const sys::mjModel, *mut sys::mjData, *mut c_char, c_int) -> c_int;

/// Simulation state of one [`Model`] (`mjData`). Owns an `Arc` of its model so it can't outlive
/// it; `Send` so each worker thread can own one.
pub struct Data {
    model: Arc<Model>,
    ptr: NonNull<sys::mjData>,
}

// SAFETY: an mjData is a heap block used by one thread at a time; Data hands out access only
// through &self/&mut self, so moving it to another thread is sound. The shared model is Sync.
unsafe impl Send for Data {}

impl Drop for Data {
    fn drop(&mut self) {
        // SAFETY: the pointer came from mj_makeData/mj_copyData and is owned by this Data.
        unsafe { sys::mj_deleteData(self.ptr.as_ptr()) }
    }
}

impl Clone for Data {
    /// Copies the whole simulation state (`mj_copyData`). Panics only if MuJoCo cannot allocate.
    fn clone(&self) -> Self {
        self.try_clone().expect("mj_copyData failed")
    }
}

impl std::fmt::Debug for Data {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Data").field("time", &self.time_secs()).field("model", &self.model).finish()
    }
}

/// MuJoCo's warning kinds (`mjtWarning`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Warning {
    /// Inertia too small or not positive definite.
    Inertia = sys::mjtWarning_mjWARN_INERTIA,
    /// Contact buffer full.
    ContactFull = sys::mjtWarning_mjWARN_CONTACTFULL,
    /// Constraint buffer full.
    ConstraintFull = sys::mjtWarning_mjWARN_CNSTRFULL,
    /// Bad number in qpos: the simulation diverged and MuJoCo reset it.
    BadQpos = sys::mjtWarning_mjWARN_BADQPOS,
    /// Bad number in qvel: diverged.
    BadQvel = sys::mjtWarning_mjWARN_BADQVEL,
    /// Bad number in qacc: diverged.
    BadQacc = sys::mjtWarning_mjWARN_BADQACC,
    /// Bad number in ctrl.
    BadCtrl = sys::mjtWarning_mjWARN_BADCTRL,
}

/// One contact's wrench from [`Data::contact_wrench_world`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactWrench {
    /// The two geoms (-1 for flex contacts).
    pub geoms: [i32; 2],
    /// Contact point, world frame, metres.
    pub position: [f64; 3],
    /// Force on the second geom, world frame, N (the first geom gets the opposite).
    pub force_n: [f64; 3],
    /// Torque on the second geom about `position`, world frame, N·m (zero without
    /// torsional/rolling friction).
    pub torque_nm: [f64; 3],
}

/// Which parts of the state [`Data::state`] copies (`mjtState` bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateSig(pub u32);

impl StateSig {
    /// Time, qpos, qvel, act, history: what integration needs (`mjSTATE_PHYSICS`).
    pub const PHYSICS: StateSig = StateSig(sys::mjtState_mjSTATE_PHYSICS);
    /// Physics plus time, plugin state (`mjSTATE_FULLPHYSICS`).
    pub const FULL_PHYSICS: StateSig = StateSig(sys::mjtState_mjSTATE_FULLPHYSICS);
    /// Everything a step depends on, user inputs included (`mjSTATE_INTEGRATION`).
    pub const INTEGRATION: StateSig = StateSig(sys::mjtState_mjSTATE_INTEGRATION);
}

/// Typed views of `mjData` arrays: `name: element type = row count field of mjModel`.
macro_rules! data_arrays {
    ($( $(#[$doc:meta])* $name:ident, $name_mut:ident : $ty:ty = $count:ident; )*) => {
        impl Data {
            $(
                $(#[$doc])*
                pub fn $name(&self) -> &[$ty] {
                    let n = self.model.raw().$count as usize;
                    // SAFETY: mj_makeData allocates this array with `$count` rows of the row
                    // type's size; it is only read while self is borrowed.
                    unsafe { raw_slice(self.raw().$name as *const $ty, n) }
                }

                #[doc = concat!("Mutable [`Data::", stringify!($name), "`].")]
                pub fn $name_mut(&mut self) -> &mut [$ty] {
                    let n = self.model.raw().$count as usize;
                    // SAFETY: as above, and `&mut self` makes the borrow exclusive.
                    unsafe { raw_slice_mut(self.ptr.as_ref().$name as *mut $ty, n) }
                }
            )*
        }
    };
}

data_arrays! {
    /// Joint positions (len `nq`): metres, radians, unit quaternions (w x y z) for free/ball.
    qpos, qpos_mut: f64 = nq;
    /// Joint velocities (len `nv`); free joints: linear in world frame, angular in body frame.
    qvel, qvel_mut: f64 = nv;
    /// Joint accelerations (len `nv`); input of `inverse`, output of `forward`.
    qacc, qacc_mut: f64 = nv;
    /// Actuator controls (len `nu`).
    ctrl, ctrl_mut: f64 = nu;
    /// Actuator activations (len `na`).
    act, act_mut: f64 = na;
    /// Generalised forces applied by the user (len `nv`).
    qfrc_applied, qfrc_applied_mut: f64 = nv;
    /// Cartesian wrench applied at each body's centre of mass, world frame: force (N) then
    /// torque (N·m) (len `nbody`).
    xfrc_applied, xfrc_applied_mut: [f64; 6] = nbody;
    /// Sensor readings (len `nsensordata`).
    sensordata, sensordata_mut: f64 = nsensordata;
    /// Body frame positions, world frame, metres (len `nbody`).
    xpos, xpos_mut: [f64; 3] = nbody;
    /// Body frame orientations, world frame, quaternion w x y z (len `nbody`).
    xquat, xquat_mut: [f64; 4] = nbody;
    /// Body frame orientations as row-major 3×3 matrices (len `nbody`).
    xmat, xmat_mut: [f64; 9] = nbody;
    /// Body centres of mass, world frame (len `nbody`).
    xipos, xipos_mut: [f64; 3] = nbody;
    /// Centre of mass of each body's subtree, world frame (len `nbody`).
    subtree_com, subtree_com_mut: [f64; 3] = nbody;
    /// Geom positions, world frame (len `ngeom`).
    geom_xpos, geom_xpos_mut: [f64; 3] = ngeom;
    /// Geom orientations as row-major 3×3 matrices, world frame (len `ngeom`).
    geom_xmat, geom_xmat_mut: [f64; 9] = ngeom;
    /// Site positions, world frame (len `nsite`).
    site_xpos, site_xpos_mut: [f64; 3] = nsite;
    /// Site orientations as row-major 3×3 matrices (len `nsite`).
    site_xmat, site_xmat_mut: [f64; 9] = nsite;
    /// Generalised forces from `inverse` (len `nv`).
    qfrc_inverse, qfrc_inverse_mut: f64 = nv;
    /// Coriolis, centrifugal and gravity forces C(q, q̇) (len `nv`).
    qfrc_bias, qfrc_bias_mut: f64 = nv;
    /// Generalised actuator forces (len `nv`).
    qfrc_actuator, qfrc_actuator_mut: f64 = nv;
    /// Scalar force of each actuator (len `nu`).
    actuator_force, actuator_force_mut: f64 = nu;
}

impl Data {
    /// Allocates simulation state for `model` at its default pose (`mj_makeData`).
    ///
    /// # Errors
    /// [`Error::MuJoCo`] if MuJoCo can't allocate (e.g. the model's `<size memory>` is too big).
    pub fn new(model: Arc<Model>) -> Result<Data> {
        init()?;
        let mut out = std::ptr::null_mut();
        guarded("mj_makeData", |e, n| {
            // SAFETY: model is live; out receives a new mjData.
            unsafe { ffi::twin_make_data(model.as_ptr(), &mut out, e, n) }
        })?;
        let ptr = NonNull::new(out).ok_or(Error::MuJoCo { call: "mj_makeData", message: "returned no data".into() })?;
        Ok(Data { model, ptr })
    }

    /// Copies the state (`mj_copyData`).
    ///
    /// # Errors
    /// [`Error::MuJoCo`] if MuJoCo can't allocate.
    pub fn try_clone(&self) -> Result<Data> {
        let copy = Data::new(self.model.clone())?;
        guarded("mj_copyData", |e, n| {
            // SAFETY: both are live and made for the same model.
            unsafe { ffi::twin_copy_data(copy.ptr.as_ptr(), self.model.as_ptr(), self.ptr.as_ptr(), e, n) }
        })?;
        Ok(copy)
    }

    /// Moves this state over to `model`, an edited copy of its current model (same sizes, as
    /// [`Model::edit`] makes), and resets it there (`mj_resetData`). Saves allocating a new
    /// `mjData` per randomized episode.
    ///
    /// # Errors
    /// [`Error::Size`] naming the first size field (of all `nq` … `nbuffer`) in which `model`
    /// differs from the current model; [`Error::MuJoCo`] as
    /// [`Data::reset`].
    pub fn set_model(&mut self, model: Arc<Model>) -> Result<()> {
        // Every size must match: the mjData buffer's layout depends on all of them.
        ModelLayout::of(&self.model).require_same(&ModelLayout::of(&model))?;
        self.model = model;
        self.reset()
    }

    /// Geom ids of each active contact (`contact[i].geom`), after the last forward pass; -1
    /// for flex contacts.
    pub fn contact_geoms(&self) -> impl Iterator<Item = [i32; 2]> + '_ {
        let d = self.raw();
        // SAFETY: d.contact holds d.ncon initialised contacts after a forward pass; the borrow
        // of self keeps them unmodified.
        let contacts = unsafe { raw_slice(d.contact as *const sys::mjContact, self.ncon()) };
        contacts.iter().map(|c| c.geom)
    }

    /// Geom ids and world position (metres) of each active contact, after the last forward pass:
    /// [`Data::contact_geoms`] with `contact[i].pos`, for observers that need where contacts are
    /// but not their forces (no `mj_contactForce`, no allocation).
    pub fn contact_points(&self) -> impl Iterator<Item = ([i32; 2], [f64; 3])> + '_ {
        let d = self.raw();
        // SAFETY: as in contact_geoms().
        let contacts = unsafe { raw_slice(d.contact as *const sys::mjContact, self.ncon()) };
        contacts.iter().map(|c| (c.geom, c.pos))
    }

    /// The model this state belongs to.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// The raw `mjData`, read-only.
    pub fn raw(&self) -> &sys::mjData {
        // SAFETY: live for self's lifetime; only read through this reference.
        unsafe { self.ptr.as_ref() }
    }

    /// Raw pointers for FFI calls not wrapped here. The caller must not let MuJoCo raise an
    /// error through them (use only calls that cannot raise, or the guarded methods).
    pub fn raw_parts(&mut self) -> (*const sys::mjModel, *mut sys::mjData) {
        (self.model.as_ptr(), self.ptr.as_ptr())
    }

    /// Simulation time, seconds.
    pub fn time_secs(&self) -> f64 {
        self.raw().time
    }

    /// Sets the simulation time, seconds.
    pub fn set_time_secs(&mut self, t: f64) {
        // SAFETY: exclusive access through &mut self; `time` is a plain field.
        unsafe { self.ptr.as_mut().time = t }
    }

    /// Number of active contacts after the last forward pass.
    pub fn ncon(&self) -> usize {
        self.raw().ncon.max(0) as usize
    }

    /// Signed distance of each active contact, metres (negative: penetration), with the two
    /// geom ids.
    pub fn contacts(&self) -> Vec<(f64, [i32; 2])> {
        let n = self.ncon();
        // SAFETY: d->contact holds at least ncon initialised contacts after a forward pass.
        let c = unsafe { raw_slice(self.raw().contact as *const sys::mjContact, n) };
        c.iter().map(|c| (c.dist, c.geom)).collect()
    }

    /// World position of each active contact, metres.
    pub fn contact_positions(&self) -> Vec<[f64; 3]> {
        let n = self.ncon();
        // SAFETY: d->contact holds at least ncon initialised contacts after a forward pass.
        let c = unsafe { raw_slice(self.raw().contact as *const sys::mjContact, n) };
        c.iter().map(|c| c.pos).collect()
    }

    /// The joint-space inertia matrix `M` (`nv × nv`, row-major, dense) of the last forward
    /// pass (`mj_fullM`).
    pub fn full_mass_matrix(&self) -> Vec<f64> {
        let mut m = Vec::new();
        self.full_mass_matrix_into(&mut m);
        m
    }

    /// [`Data::full_mass_matrix`] into `m` (resized to `nv × nv`), for a loop that asks every
    /// step without allocating.
    pub fn full_mass_matrix_into(&self, m: &mut Vec<f64>) {
        let nv = self.model.nv();
        m.resize(nv * nv, 0.0);
        // SAFETY: `m` has the nv·nv entries mj_fullM writes; it reads d->qM, which the forward
        // pass filled (mj_makeData zero-fills it before); model and data are a live pair, only
        // read; mj_fullM never raises.
        unsafe { sys::mj_fullM(self.model.as_ptr(), self.ptr.as_ptr(), m.as_mut_ptr()) };
    }

    /// Force and torque of active contact `i` (`mj_contactForce`), in the world frame, acting on
    /// the contact's second geom (its first geom gets the opposite), with the contact position
    /// (world, metres) the torque is taken about: `(geoms, position, force_n, torque_nm)`.
    /// `None` when `i >= ncon`.
    pub fn contact_wrench_world(&self, i: usize) -> Option<ContactWrench> {
        if i >= self.ncon() {
            return None;
        }
        let mut local = [0.0f64; 6];
        // SAFETY: i < ncon, so the id is valid (mj_contactForce never raises for valid ids);
        // `local` has the 6 entries it writes; model and data are a live pair, only read.
        unsafe { sys::mj_contactForce(self.model.as_ptr(), self.ptr.as_ptr(), i as c_int, local.as_mut_ptr()) };
        // SAFETY: as in contacts(): d->contact holds ncon initialised contacts.
        let c = unsafe { &raw_slice(self.raw().contact as *const sys::mjContact, self.ncon())[i] };
        // The contact frame's rows are its axes in world coordinates (normal first, from geom1 to
        // geom2): world = frameᵀ · local.
        let to_world = |v: &[f64]| {
            let f = &c.frame;
            [
                f[0] * v[0] + f[3] * v[1] + f[6] * v[2],
                f[1] * v[0] + f[4] * v[1] + f[7] * v[2],
                f[2] * v[0] + f[5] * v[1] + f[8] * v[2],
            ]
        };
        Some(ContactWrench {
            geoms: c.geom,
            position: c.pos,
            force_n: to_world(&local[..3]),
            torque_nm: to_world(&local[3..]),
        })
    }

    /// Potential and kinetic energy, joules (when the model enables the energy flag).
    pub fn energy(&self) -> [f64; 2] {
        self.raw().energy
    }

    /// How often MuJoCo raised warning `w` on this data since the last reset.
    pub fn warning_count(&self, w: Warning) -> u32 {
        self.raw().warning[w as usize].number.max(0) as u32
    }

    /// Whether the simulation diverged (bad qpos/qvel/qacc: MuJoCo reset the state to recover).
    /// A diverged run must not count as a success.
    pub fn diverged(&self) -> bool {
        [Warning::BadQpos, Warning::BadQvel, Warning::BadQacc].iter().any(|&w| self.warning_count(w) > 0)
    }

    /// Advances the simulation by one timestep (`mj_step`).
    ///
    /// # Errors
    /// [`Error::MuJoCo`] if MuJoCo raises (e.g. its arena is too small for the contacts); the
    /// state is then inconsistent and should be reset.
    #[inline]
    pub fn step(&mut self) -> Result<()> {
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        // SAFETY: live model/data pair made for each other; exclusive through &mut self.
        guarded("mj_step", |e, n| unsafe { ffi::twin_step(m, d, e, n) })
    }

    /// Runs one of the shim's guarded stages that take only the model/data pair
    /// (`twin_step1`, `twin_forward`, …), `call` naming it in an error.
    #[inline]
    fn stage(&mut self, call: &'static str, stage: Stage) -> Result<()> {
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        // SAFETY: live model/data pair made for each other; exclusive through &mut self; every
        // `Stage` is a shim function reading `m`, writing `d` and at most `n` bytes of `e`.
        guarded(call, |e, n| unsafe { stage(m, d, e, n) })
    }

    /// Advances `n` timesteps in one guarded C loop (no per-step work in Rust).
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn step_n(&mut self, n: u64) -> Result<()> {
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        // SAFETY: as in step.
        guarded("mj_step", |e, len| unsafe { ffi::twin_step_n(m, d, n as std::ffi::c_long, e, len) })
    }

    /// First half of a step, up to the control-dependent stage (`mj_step1`): set `ctrl` from
    /// the fresh sensors, then call [`Data::step2`].
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn step1(&mut self) -> Result<()> {
        self.stage("mj_step1", ffi::twin_step1)
    }

    /// Second half of a step (`mj_step2`).
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn step2(&mut self) -> Result<()> {
        self.stage("mj_step2", ffi::twin_step2)
    }

    /// Forward dynamics without integration (`mj_forward`): positions, sensors, accelerations.
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn forward(&mut self) -> Result<()> {
        self.stage("mj_forward", ffi::twin_forward)
    }

    /// Inverse dynamics (`mj_inverse`): from qpos, qvel, qacc to [`Data::qfrc_inverse`].
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn inverse(&mut self) -> Result<()> {
        self.stage("mj_inverse", ffi::twin_inverse)
    }

    /// Recursive Newton–Euler (`mj_rne`): M(q)·q̈ + C(q, q̇) with `with_acceleration`, else
    /// C(q, q̇) only. Needs positions and velocities computed (after `forward`). Len `nv`.
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn rne(&mut self, with_acceleration: bool) -> Result<Vec<f64>> {
        let mut out = vec![0.0; self.model.nv()];
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        let res = out.as_mut_ptr();
        // SAFETY: `out` has nv entries as mj_rne requires; pair is live and exclusive.
        guarded("mj_rne", |e, n| unsafe { ffi::twin_rne(m, d, with_acceleration as c_int, res, e, n) })?;
        Ok(out)
    }

    /// Position and velocity kinematics only (`mj_kinematics`, `mj_comPos`, `mj_comVel`): body
    /// poses, `cdof`, `cvel` and `cdof_dot`, as [`Data::body_jacobian_dot`] needs, without
    /// collision detection or dynamics.
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn kinematics_with_velocity(&mut self) -> Result<()> {
        self.stage("mj_kinematics", ffi::twin_kinematics_vel)
    }

    /// Body poses and contacts only (`mj_kinematics`, `mj_collision`): [`Data::contacts`] at
    /// the current `qpos` without the dynamics and constraint solver of [`Data::forward`].
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn kinematics_collision(&mut self) -> Result<()> {
        self.stage("mj_collision", ffi::twin_kinematics_collision)
    }

    /// Jacobian of body `body`'s frame origin and its time derivative (`mj_jacBody`,
    /// `mj_jacDot`), world frame, each row-major 3 × nv: translational `jacp`, rotational
    /// `jacr`, then their derivatives. Needs [`Data::kinematics_with_velocity`] (or a forward
    /// pass) at the current `qpos`/`qvel`.
    ///
    /// # Errors
    /// [`Error::Size`] for a bad body id or output lengths other than `3 * nv`.
    pub fn body_jacobian_dot(
        &mut self,
        body: usize,
        jacp: &mut [f64],
        jacr: &mut [f64],
        jacp_dot: &mut [f64],
        jacr_dot: &mut [f64],
    ) -> Result<()> {
        let nbody = self.model.nbody();
        if body >= nbody {
            return Err(Error::Size { what: "body id", expected: nbody, got: body });
        }
        let len = 3 * self.model.nv();
        for out in [&*jacp, &*jacr, &*jacp_dot, &*jacr_dot] {
            if out.len() != len {
                return Err(Error::Size { what: "Jacobian buffer length (3 * nv)", expected: len, got: out.len() });
            }
        }
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        let (p, r) = (jacp.as_mut_ptr(), jacr.as_mut_ptr());
        let (pd, rd) = (jacp_dot.as_mut_ptr(), jacr_dot.as_mut_ptr());
        // SAFETY: body checked in range; each buffer has 3 * nv entries as both functions write;
        // the pair is live and exclusive through &mut self.
        guarded("mj_jacDot", |e, n| unsafe { ffi::twin_jac_body_dot(m, d, body as c_int, p, r, pd, rd, e, n) })
    }

    /// Jacobian of the world point `point_world` attached to body `body` (`mj_jac`), world
    /// frame, each row-major 3 × nv: translational `jacp` (m per unit of each DOF) and
    /// rotational `jacr`. Needs body poses and `cdof` of the current `qpos` (a forward pass, or
    /// [`Data::kinematics_with_velocity`]).
    ///
    /// # Errors
    /// [`Error::Size`] for a bad body id or output lengths other than `3 * nv`.
    pub fn point_jacobian(&self, body: usize, point_world: [f64; 3], jacp: &mut [f64], jacr: &mut [f64]) -> Result<()> {
        let nbody = self.model.nbody();
        if body >= nbody {
            return Err(Error::Size { what: "body id", expected: nbody, got: body });
        }
        let len = 3 * self.model.nv();
        for out in [&*jacp, &*jacr] {
            if out.len() != len {
                return Err(Error::Size { what: "Jacobian buffer length (3 * nv)", expected: len, got: out.len() });
            }
        }
        // SAFETY: body checked in range and each buffer has 3 * nv entries, as mj_jac writes;
        // mj_jac only reads the model and data (it raises no error for valid ids).
        unsafe {
            sys::mj_jac(
                self.model.as_ptr(),
                self.ptr.as_ptr(),
                jacp.as_mut_ptr(),
                jacr.as_mut_ptr(),
                point_world.as_ptr(),
                body as c_int,
            );
        }
        Ok(())
    }

    /// Signed distance between geoms `geom1` and `geom2` (`mj_geomDistance`), metres (negative:
    /// penetration), capped at `distmax`: a pair farther apart than `distmax` reads `distmax`.
    /// Needs geom poses of the current `qpos`. Planes, height fields and SDFs are refused
    /// (MuJoCo's distance is defined for convex geoms).
    ///
    /// # Errors
    /// [`Error::Size`] for a bad geom id; [`Error::Options`] for a non-convex geom type.
    pub fn geom_distance(&mut self, geom1: usize, geom2: usize, distmax: f64) -> Result<f64> {
        let ngeom = self.model.ngeom();
        for g in [geom1, geom2] {
            if g >= ngeom {
                return Err(Error::Size { what: "geom id", expected: ngeom, got: g });
            }
            let t = self.model.geom_type()[g] as u32;
            if matches!(t, sys::mjtGeom_mjGEOM_PLANE | sys::mjtGeom_mjGEOM_HFIELD | sys::mjtGeom_mjGEOM_SDF) {
                return Err(Error::Options(format!(
                    "geom {g} (\"{}\"): mj_geomDistance needs convex geoms, not planes, height fields or SDFs",
                    self.model.name(super::ObjType::Geom, g)
                )));
            }
        }
        // SAFETY: both ids are valid convex geoms (checked above), for which MuJoCo's collision
        // table has a distance function that raises no error; `fromto` may be NULL; the pair is
        // live and exclusive through &mut self (mj_geomDistance uses the data's stack).
        let d = unsafe {
            sys::mj_geomDistance(
                self.model.as_ptr(),
                self.ptr.as_ptr(),
                geom1 as c_int,
                geom2 as c_int,
                distmax,
                std::ptr::null_mut(),
            )
        };
        Ok(d)
    }

    /// Resets to the model's default state (`mj_resetData`), warnings included.
    ///
    /// # Errors
    /// As [`Data::step`].
    pub fn reset(&mut self) -> Result<()> {
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        // SAFETY: as in step.
        guarded("mj_resetData", |e, n| unsafe { ffi::twin_reset_data(m, d, -1, e, n) })
    }

    /// Resets to keyframe `key` (`mj_resetDataKeyframe`).
    ///
    /// # Errors
    /// [`Error::Size`] if the model has no such keyframe.
    pub fn reset_to_keyframe(&mut self, key: usize) -> Result<()> {
        let nkey = self.model.nkey();
        if key >= nkey {
            return Err(Error::Size { what: "keyframe index", expected: nkey, got: key });
        }
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        // SAFETY: key checked above; pair live and exclusive.
        guarded("mj_resetDataKeyframe", |e, n| unsafe { ffi::twin_reset_data(m, d, key as c_int, e, n) })
    }

    /// Copies the parts of the state named by `sig` (`mj_getState`).
    ///
    /// # Errors
    /// [`Error::MuJoCo`] for a signature MuJoCo rejects.
    pub fn state(&self, sig: StateSig) -> Result<Vec<f64>> {
        // Checked here because mj_stateSize/mj_getState raise on bad signatures and they are not
        // wrapped by the shim.
        if sig.0 >= (1 << sys::mjtState_mjNSTATE) {
            return Err(Error::MuJoCo {
                call: "mj_getState",
                message: format!("invalid state signature {:#x}", sig.0),
            });
        }
        // SAFETY: valid signature checked above; model live.
        let size = unsafe { sys::mj_stateSize(self.model.as_ptr(), sig.0 as c_int) };
        let mut out = vec![0.0; size.max(0) as usize];
        // SAFETY: `out` has mj_stateSize entries for this signature.
        unsafe { sys::mj_getState(self.model.as_ptr(), self.ptr.as_ptr(), out.as_mut_ptr(), sig.0 as c_int) };
        Ok(out)
    }

    /// Restores a state saved with [`Data::state`] and the same signature (`mj_setState`).
    ///
    /// # Errors
    /// [`Error::Size`] for a wrong length, [`Error::MuJoCo`] for a signature MuJoCo rejects.
    pub fn set_state(&mut self, state: &[f64], sig: StateSig) -> Result<()> {
        let (m, d) = (self.model.as_ptr(), self.ptr.as_ptr());
        if sig.0 < (1 << sys::mjtState_mjNSTATE) {
            // SAFETY: valid signature; model live.
            let size = unsafe { sys::mj_stateSize(m, sig.0 as c_int) }.max(0) as usize;
            if state.len() != size {
                return Err(Error::Size { what: "state vector length", expected: size, got: state.len() });
            }
        }
        // SAFETY: length checked for valid signatures; an invalid one makes MuJoCo raise before
        // reading `state`, which the shim catches.
        guarded("mj_setState", |e, n| unsafe { ffi::twin_set_state(m, d, state.as_ptr(), sig.0 as c_int, e, n) })
    }
}
