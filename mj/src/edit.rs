use super::model::raw_slice_mut;
use super::{GeomType, Integrator, Model, ffi, guarded};
use crate::error::{Error, Result};
use std::ptr::NonNull;

/// An edit of a copy of a [`Model`]: change masses, inertias, friction, damping, armature, then
/// [`ModelEdit::finish`] runs `mj_setConst` so that derived quantities (subtree masses,
/// `dof_invweight0`, `actuator_acc0`, …) match. The only way to get the edited model is through
/// `finish`, so no caller can forget `mj_setConst`.
pub struct ModelEdit {
    model: Model,
}

/// `body`, `geom` or `dof` index out of range.
fn check(what: &'static str, index: usize, count: usize) -> Result<()> {
    if index < count { Ok(()) } else { Err(Error::Size { what, expected: count, got: index }) }
}

fn finite(what: &str, values: &[f64]) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(Error::InvalidEdit(format!("{what} must be finite, got {values:?}")))
    }
}

impl ModelEdit {
    pub(super) fn new(model: Model) -> ModelEdit {
        ModelEdit { model }
    }

    /// The model as edited so far (derived quantities not yet updated).
    pub fn model(&self) -> &Model {
        &self.model
    }

    fn raw_mut(&mut self) -> &mut mujoco_sys::mjModel {
        // SAFETY: ModelEdit owns its Model exclusively; no Data refers to it until finish().
        unsafe { &mut *self.model.as_mut_ptr() }
    }

    /// Writes `value` into row `id` of the model array `pick` returns (`rows` rows of `T`):
    /// the one write of every single-array setter below. Panics if `id ≥ rows` (the setters
    /// check ids first, with an error).
    ///
    /// # Safety
    /// `pick` must return one of the model's arrays, null or with at least `rows` rows of `T`.
    unsafe fn set_row<T>(
        &mut self,
        rows: usize,
        id: usize,
        value: T,
        pick: impl FnOnce(&mujoco_sys::mjModel) -> *mut T,
    ) {
        let ptr = pick(self.raw_mut());
        // SAFETY: guaranteed by the caller; exclusive access through &mut self.
        let all = unsafe { raw_slice_mut(ptr, rows) };
        all[id] = value;
    }

    /// Sets body `body`'s mass in kg, keeping its inertia tensor as is.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for a non-positive or non-finite mass; [`Error::Size`] for a bad id.
    pub fn set_body_mass(&mut self, body: usize, mass_kg: f64) -> Result<&mut Self> {
        check("body id", body, self.model.nbody())?;
        if body == 0 || !(mass_kg > 0.0 && mass_kg.is_finite()) {
            return Err(Error::InvalidEdit(format!(
                "body {body} (\"{}\"): mass must be positive and finite, got {mass_kg} kg",
                self.model.name(super::ObjType::Body, body)
            )));
        }
        // SAFETY: body_mass has nbody entries.
        unsafe { self.set_row(self.model.nbody(), body, mass_kg, |m| m.body_mass) };
        Ok(self)
    }

    /// Scales body `body`'s mass and its inertia by `factor` (a uniformly denser or lighter
    /// link), the physically consistent way to randomise a mass.
    ///
    /// # Errors
    /// As [`ModelEdit::set_body_mass`].
    pub fn scale_body_mass(&mut self, body: usize, factor: f64) -> Result<&mut Self> {
        check("body id", body, self.model.nbody())?;
        let mass = self.model.body_mass()[body] * factor;
        let inertia = self.model.body_inertia()[body].map(|i| i * factor);
        self.set_body_mass(body, mass)?;
        self.set_body_inertia(body, inertia)
    }

    /// Sets body `body`'s principal inertia (kg·m², in its inertial frame).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] unless all are positive and satisfy the triangle inequality.
    pub fn set_body_inertia(&mut self, body: usize, inertia: [f64; 3]) -> Result<&mut Self> {
        check("body id", body, self.model.nbody())?;
        finite("inertia", &inertia)?;
        let [a, b, c] = inertia;
        let triangle = a + b >= c * (1.0 - 1e-12) && a + c >= b * (1.0 - 1e-12) && b + c >= a * (1.0 - 1e-12);
        if body == 0 || a <= 0.0 || b <= 0.0 || c <= 0.0 || !triangle {
            return Err(Error::InvalidEdit(format!(
                "body {body} (\"{}\"): principal inertia {inertia:?} must be positive and satisfy \
                 the triangle inequality (each entry at most the sum of the other two)",
                self.model.name(super::ObjType::Body, body)
            )));
        }
        // SAFETY: body_inertia has nbody rows of 3.
        unsafe { self.set_row(self.model.nbody(), body, inertia, |m| m.body_inertia.cast()) };
        Ok(self)
    }

    /// Sets body `body`'s centre of mass in its body frame, metres.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for non-finite values; [`Error::Size`] for a bad id.
    pub fn set_body_com(&mut self, body: usize, com_body: [f64; 3]) -> Result<&mut Self> {
        check("body id", body, self.model.nbody())?;
        finite("centre of mass", &com_body)?;
        // SAFETY: body_ipos has nbody rows of 3.
        unsafe { self.set_row(self.model.nbody(), body, com_body, |m| m.body_ipos.cast()) };
        Ok(self)
    }

    /// Sets geom `geom`'s friction (sliding, torsional, rolling).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for negative or non-finite values.
    pub fn set_geom_friction(&mut self, geom: usize, friction: [f64; 3]) -> Result<&mut Self> {
        check("geom id", geom, self.model.ngeom())?;
        finite("friction", &friction)?;
        if friction.iter().any(|&f| f < 0.0) {
            return Err(Error::InvalidEdit(format!("geom {geom}: friction {friction:?} must not be negative")));
        }
        // SAFETY: geom_friction has ngeom rows of 3.
        unsafe { self.set_row(self.model.ngeom(), geom, friction, |m| m.geom_friction.cast()) };
        Ok(self)
    }

    /// Sets geom `geom`'s contact priority (of two geoms in contact, the one with the higher
    /// priority gives the contact its friction and solver parameters).
    ///
    /// # Errors
    /// [`Error::Size`] for a bad id.
    pub fn set_geom_priority(&mut self, geom: usize, priority: i32) -> Result<&mut Self> {
        check("geom id", geom, self.model.ngeom())?;
        // SAFETY: geom_priority has ngeom entries.
        unsafe { self.set_row(self.model.ngeom(), geom, priority, |m| m.geom_priority) };
        Ok(self)
    }

    /// Places box geom `geom`: its position and orientation (quaternion w x y z) in its body's
    /// frame and its half sizes (m); its bounding sphere and box follow.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for a geom that is not a box, non-positive or non-finite sizes, a
    /// non-finite pose; [`Error::Size`] for a bad id.
    pub fn set_geom_box(&mut self, geom: usize, pos: [f64; 3], quat: [f64; 4], half: [f64; 3]) -> Result<&mut Self> {
        check("geom id", geom, self.model.ngeom())?;
        finite("geom pose", &[pos[0], pos[1], pos[2], quat[0], quat[1], quat[2], quat[3]])?;
        if self.model.geom_kind(geom) != GeomType::Box {
            return Err(Error::InvalidEdit(format!("geom {geom} is not a box")));
        }
        if !half.iter().all(|h| *h > 0.0 && h.is_finite()) {
            return Err(Error::InvalidEdit(format!("geom {geom}: half sizes {half:?} must be positive")));
        }
        let n = self.model.ngeom();
        let m = self.raw_mut();
        // SAFETY: geom_pos/size have ngeom rows of 3, geom_quat of 4, geom_aabb of 6, geom_rbound
        // ngeom entries; id checked; exclusive access.
        unsafe {
            raw_slice_mut(m.geom_pos.cast::<[f64; 3]>(), n)[geom] = pos;
            raw_slice_mut(m.geom_quat.cast::<[f64; 4]>(), n)[geom] = quat;
            raw_slice_mut(m.geom_size.cast::<[f64; 3]>(), n)[geom] = half;
            raw_slice_mut(m.geom_aabb.cast::<[f64; 6]>(), n)[geom] = [0.0, 0.0, 0.0, half[0], half[1], half[2]];
            raw_slice_mut(m.geom_rbound, n)[geom] = (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt();
        }
        Ok(self)
    }

    /// Sets geom `geom`'s position in its body's frame, m.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for a non-finite position; [`Error::Size`] for a bad id.
    pub fn set_geom_pos(&mut self, geom: usize, pos: [f64; 3]) -> Result<&mut Self> {
        check("geom id", geom, self.model.ngeom())?;
        finite("geom position", &pos)?;
        // SAFETY: geom_pos has ngeom rows of 3.
        unsafe { self.set_row(self.model.ngeom(), geom, pos, |m| m.geom_pos.cast()) };
        Ok(self)
    }

    /// Replaces heightfield `hfield`'s elevations: `data` (row-major, `nrow × ncol`, each in
    /// [0, 1]) scaled by `elevation_m`, the height of 1 (the asset's `size[2]`).
    ///
    /// # Errors
    /// [`Error::Size`] for a bad id or a data length other than `nrow × ncol`;
    /// [`Error::InvalidEdit`] for values outside [0, 1] or a non-positive elevation.
    pub fn set_hfield(&mut self, hfield: usize, elevation_m: f64, data: &[f32]) -> Result<&mut Self> {
        let count = self.model.raw().nhfield.max(0) as usize;
        check("heightfield id", hfield, count)?;
        if !(elevation_m > 0.0 && elevation_m.is_finite() && data.iter().all(|v| (0.0..=1.0).contains(v))) {
            return Err(Error::InvalidEdit(format!(
                "heightfield {hfield}: elevation must be positive ({elevation_m}) and data within [0, 1]"
            )));
        }
        let total = self.model.raw().nhfielddata.max(0) as usize;
        let m = self.raw_mut();
        // SAFETY: hfield_nrow/ncol/adr have nhfield entries, hfield_size nhfield rows of 4,
        // hfield_data nhfielddata entries; id and length checked; exclusive access.
        unsafe {
            let rows = raw_slice_mut(m.hfield_nrow, count)[hfield] as usize;
            let cols = raw_slice_mut(m.hfield_ncol, count)[hfield] as usize;
            let adr = raw_slice_mut(m.hfield_adr, count)[hfield] as usize;
            if data.len() != rows * cols || adr + data.len() > total {
                return Err(Error::Size { what: "heightfield data", expected: rows * cols, got: data.len() });
            }
            raw_slice_mut(m.hfield_data, total)[adr..adr + data.len()].copy_from_slice(data);
            raw_slice_mut(m.hfield_size.cast::<[f64; 4]>(), count)[hfield][2] = elevation_m;
        }
        Ok(self)
    }

    fn set_dof(
        &mut self,
        what: &'static str,
        dof: usize,
        value: f64,
        pick: fn(&mujoco_sys::mjModel) -> *mut f64,
    ) -> Result<&mut Self> {
        check("dof id", dof, self.model.nv())?;
        if !(value >= 0.0 && value.is_finite()) {
            return Err(Error::InvalidEdit(format!("dof {dof}: {what} must be finite and ≥ 0, got {value}")));
        }
        // SAFETY: every dof_* array picked here has nv entries.
        unsafe { self.set_row(self.model.nv(), dof, value, pick) };
        Ok(self)
    }

    /// Sets DOF `dof`'s viscous damping (N·m·s/rad or N·s/m).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for negative values.
    pub fn set_dof_damping(&mut self, dof: usize, damping: f64) -> Result<&mut Self> {
        self.set_dof("damping", dof, damping, |m| m.dof_damping)
    }

    /// Sets DOF `dof`'s dry friction loss (N·m or N).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for negative values.
    pub fn set_dof_frictionloss(&mut self, dof: usize, frictionloss: f64) -> Result<&mut Self> {
        self.set_dof("friction loss", dof, frictionloss, |m| m.dof_frictionloss)
    }

    /// Sets DOF `dof`'s armature (kg·m² or kg).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for negative values.
    pub fn set_dof_armature(&mut self, dof: usize, armature: f64) -> Result<&mut Self> {
        self.set_dof("armature", dof, armature, |m| m.dof_armature)
    }

    /// Turns actuator `act` into a joint-space PD servo: force = kp·(ctrl − q) − kv·q̇, the
    /// form of MuJoCo's `position` actuator (its velocity term is integrated implicitly by the
    /// `implicitfast` integrator). The force range and gear are kept.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for negative or non-finite gains; [`Error::Size`] for a bad id.
    pub fn set_actuator_servo(&mut self, act: usize, kp: f64, kv: f64) -> Result<&mut Self> {
        check("actuator id", act, self.model.nu())?;
        finite("servo gains", &[kp, kv])?;
        if kp < 0.0 || kv < 0.0 {
            return Err(Error::InvalidEdit(format!("actuator {act}: servo gains must be ≥ 0, got kp {kp}, kv {kv}")));
        }
        let n = self.model.nu();
        let m = self.raw_mut();
        // SAFETY: each actuator_* array below has nu rows of the row size used; exclusive access.
        unsafe {
            raw_slice_mut(m.actuator_gaintype, n)[act] = mujoco_sys::mjtGain_mjGAIN_FIXED as i32;
            raw_slice_mut(m.actuator_biastype, n)[act] = mujoco_sys::mjtBias_mjBIAS_AFFINE as i32;
            let gain = &mut raw_slice_mut(m.actuator_gainprm.cast::<[f64; 10]>(), n)[act];
            *gain = [0.0; 10];
            gain[0] = kp;
            let bias = &mut raw_slice_mut(m.actuator_biasprm.cast::<[f64; 10]>(), n)[act];
            *bias = [0.0; 10];
            bias[1] = -kp;
            bias[2] = -kv;
            // The servo's control is a position target: leave it unclamped (the force range
            // still limits the effort).
            raw_slice_mut(m.actuator_ctrllimited, n)[act] = false;
        }
        Ok(self)
    }

    /// Sets actuator `act`'s command delay (MuJoCo's `actuator_delay`), seconds; its history
    /// buffer (`nsample`, fixed when the model was compiled) must span it at the timestep.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for a negative or non-finite delay, or one longer than the buffer
    /// holds (saying how long it may be); [`Error::Size`] for a bad id.
    pub fn set_actuator_delay(&mut self, act: usize, delay_secs: f64) -> Result<&mut Self> {
        check("actuator id", act, self.model.nu())?;
        finite("actuator delay", &[delay_secs])?;
        let nsample = self.model.actuator_history()[act][0];
        let longest = f64::from((nsample - 1).max(0)) * self.model.timestep_secs();
        if delay_secs < 0.0 || delay_secs > longest + 1e-12 {
            return Err(Error::InvalidEdit(format!(
                "actuator {act}: delay {delay_secs} s outside [0, {longest}] s, what its {nsample}-sample history \
                 buffer holds at the {} s timestep (convert the robot with a longer delay buffer, \
                 ConvertOptions::delay_buffer_secs)",
                self.model.timestep_secs()
            )));
        }
        let n = self.model.nu();
        // SAFETY: actuator_delay has nu rows; id checked above.
        unsafe { self.set_row(n, act, delay_secs, |m| m.actuator_delay) };
        Ok(self)
    }

    /// Sets the integrator.
    pub fn set_integrator(&mut self, integrator: Integrator) -> &mut Self {
        self.raw_mut().opt.integrator = integrator.raw();
        self
    }

    /// Sets actuator `actuator`'s transmission gear (entry 0 scales a joint motor's torque).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for non-finite values; [`Error::Size`] for a bad id.
    pub fn set_actuator_gear(&mut self, actuator: usize, gear: [f64; 6]) -> Result<&mut Self> {
        check("actuator id", actuator, self.model.nu())?;
        finite("gear", &gear)?;
        // SAFETY: actuator_gear has nu rows of 6.
        unsafe { self.set_row(self.model.nu(), actuator, gear, |m| m.actuator_gear.cast()) };
        Ok(self)
    }

    /// Sets the gravity vector, world frame, m/s².
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for non-finite values.
    pub fn set_gravity(&mut self, gravity: [f64; 3]) -> Result<&mut Self> {
        finite("gravity", &gravity)?;
        self.raw_mut().opt.gravity = gravity;
        Ok(self)
    }

    /// Sets how stiff DOF `dof`'s friction-loss constraint is: `solref` (time constant in
    /// seconds, damping ratio) and `solimp` (5 impedance numbers), as MJCF `solreffriction` /
    /// `solimpfriction`. A stiffer constraint makes friction loss closer to ideal Coulomb
    /// friction.
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for non-finite values or impedances outside (0, 1).
    pub fn set_dof_friction_solver(&mut self, dof: usize, solref: [f64; 2], solimp: [f64; 5]) -> Result<&mut Self> {
        check("dof id", dof, self.model.nv())?;
        finite("solref", &solref)?;
        finite("solimp", &solimp)?;
        if !(solimp[0] > 0.0 && solimp[0] < 1.0 && solimp[1] > 0.0 && solimp[1] < 1.0) {
            return Err(Error::InvalidEdit(format!(
                "dof {dof}: solimp {solimp:?} must have its first two entries in (0, 1)"
            )));
        }
        let n = self.model.nv();
        let m = self.raw_mut();
        // SAFETY: dof_solref has nv rows of mjNREF (2) and dof_solimp nv rows of mjNIMP (5);
        // exclusive access.
        let (refs, imps) = unsafe {
            (raw_slice_mut(m.dof_solref.cast::<[f64; 2]>(), n), raw_slice_mut(m.dof_solimp.cast::<[f64; 5]>(), n))
        };
        refs[dof] = solref;
        imps[dof] = solimp;
        Ok(self)
    }

    /// Sets entries `adr..adr + values.len()` of keyframe `key`'s `qpos` (e.g. where a scene
    /// object starts).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for non-finite values; [`Error::Size`] for a bad key or a range
    /// beyond `nq`.
    pub fn set_key_qpos(&mut self, key: usize, adr: usize, values: &[f64]) -> Result<&mut Self> {
        check("keyframe id", key, self.model.nkey())?;
        let nq = self.model.nq();
        check("qpos address", adr + values.len().max(1) - 1, nq)?;
        finite("keyframe qpos", values)?;
        let nkey = self.model.nkey();
        let m = self.raw_mut();
        // SAFETY: key_qpos has nkey rows of nq entries; key and range checked; exclusive access.
        let all = unsafe { raw_slice_mut(m.key_qpos, nkey * nq) };
        all[key * nq + adr..key * nq + adr + values.len()].copy_from_slice(values);
        Ok(self)
    }

    /// Sets user number `index` of camera `cam` (e.g. a depth camera's noise σ, see
    /// [`Model::cam_user`]).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for a non-finite value; [`Error::Size`] for a bad camera or index.
    pub fn set_cam_user(&mut self, cam: usize, index: usize, value: f64) -> Result<&mut Self> {
        check("camera id", cam, self.model.ncam())?;
        let n = self.model.raw().nuser_cam.max(0) as usize;
        check("camera user index (nuser_cam)", index, n)?;
        finite("camera user value", &[value])?;
        let ncam = self.model.ncam();
        let m = self.raw_mut();
        // SAFETY: cam_user has ncam rows of nuser_cam entries; both checked; exclusive access.
        let all = unsafe { raw_slice_mut(m.cam_user, ncam * n) };
        all[cam * n + index] = value;
        Ok(self)
    }

    /// Sets the friction cone to elliptic (`cone="elliptic"`) with `impratio`, the ratio of
    /// frictional to normal constraint impedance (MuJoCo's remedy for slip of held objects).
    ///
    /// # Errors
    /// [`Error::InvalidEdit`] for an impratio that is not positive and finite.
    pub fn set_elliptic_cone(&mut self, impratio: f64) -> Result<&mut Self> {
        if !(impratio > 0.0 && impratio.is_finite()) {
            return Err(Error::InvalidEdit(format!("impratio must be positive and finite, got {impratio}")));
        }
        let opt = &mut self.raw_mut().opt;
        opt.cone = mujoco_sys::mjtCone_mjCONE_ELLIPTIC as i32;
        opt.impratio = impratio;
        Ok(self)
    }

    /// Recomputes derived quantities with `mj_setConst` and returns the edited model.
    ///
    /// # Errors
    /// [`Error::MuJoCo`] if MuJoCo rejects the edited model.
    pub fn finish(mut self) -> Result<Model> {
        let mut data = std::ptr::null_mut();
        guarded("mj_makeData", |e, n| {
            // SAFETY: the model is live; data receives a scratch mjData.
            unsafe { ffi::twin_make_data(self.model.as_ptr(), &mut data, e, n) }
        })?;
        let data =
            NonNull::new(data).ok_or(Error::MuJoCo { call: "mj_makeData", message: "returned no data".into() })?;
        let m = self.model.as_mut_ptr();
        // SAFETY: exclusive model, scratch data made for it.
        let res = guarded("mj_setConst", |e, n| unsafe { ffi::twin_set_const(m, data.as_ptr(), e, n) });
        // SAFETY: scratch data is ours and no longer used.
        unsafe { mujoco_sys::mj_deleteData(data.as_ptr()) };
        res.map(|()| self.model)
    }
}
