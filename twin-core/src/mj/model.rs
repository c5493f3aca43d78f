use super::{buf_to_string, ffi, guarded, init};
use crate::error::{Error, Result};
use mujoco_sys as sys;
use std::ffi::{CStr, CString, c_char, c_int};
use std::path::Path;
use std::ptr::NonNull;

/// A compiled MuJoCo model (`mjModel`). Immutable once built, so it is `Send + Sync` and many
/// [`Data`](super::Data) can share it; edits go through [`Model::edit`].
pub struct Model {
    ptr: NonNull<sys::mjModel>,
}

// SAFETY: an mjModel is a plain heap block that MuJoCo only reads during simulation; twin never
// mutates a Model after construction except through ModelEdit, which owns it exclusively.
unsafe impl Send for Model {}
// SAFETY: see above; concurrent reads of an immutable mjModel are what MuJoCo's own
// multi-threaded rollouts do.
unsafe impl Sync for Model {}

impl Drop for Model {
    fn drop(&mut self) {
        // SAFETY: the pointer came from MuJoCo's allocator and is owned uniquely by this Model.
        unsafe { sys::mj_deleteModel(self.ptr.as_ptr()) }
    }
}

impl Clone for Model {
    /// Copies the model with `mj_copyModel`. Panics only if MuJoCo cannot allocate the copy.
    fn clone(&self) -> Self {
        self.try_clone().expect("mj_copyModel failed")
    }
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Model")
            .field("nq", &self.nq())
            .field("nv", &self.nv())
            .field("nu", &self.nu())
            .field("nbody", &self.nbody())
            .finish()
    }
}

/// MuJoCo object kinds used for name lookups (`mjtObj`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum ObjType {
    /// `mjOBJ_BODY`
    Body,
    /// `mjOBJ_JOINT`
    Joint,
    /// `mjOBJ_GEOM`
    Geom,
    /// `mjOBJ_SITE`
    Site,
    /// `mjOBJ_CAMERA`
    Camera,
    /// `mjOBJ_ACTUATOR`
    Actuator,
    /// `mjOBJ_SENSOR`
    Sensor,
    /// `mjOBJ_KEY`
    Key,
    /// `mjOBJ_EQUALITY`
    Equality,
    /// `mjOBJ_MESH`
    Mesh,
}

impl ObjType {
    fn raw(self) -> sys::mjtObj {
        match self {
            ObjType::Body => sys::mjtObj_mjOBJ_BODY,
            ObjType::Joint => sys::mjtObj_mjOBJ_JOINT,
            ObjType::Geom => sys::mjtObj_mjOBJ_GEOM,
            ObjType::Site => sys::mjtObj_mjOBJ_SITE,
            ObjType::Camera => sys::mjtObj_mjOBJ_CAMERA,
            ObjType::Actuator => sys::mjtObj_mjOBJ_ACTUATOR,
            ObjType::Sensor => sys::mjtObj_mjOBJ_SENSOR,
            ObjType::Key => sys::mjtObj_mjOBJ_KEY,
            ObjType::Equality => sys::mjtObj_mjOBJ_EQUALITY,
            ObjType::Mesh => sys::mjtObj_mjOBJ_MESH,
        }
    }

    /// Lower-case name for messages.
    pub fn label(self) -> &'static str {
        match self {
            ObjType::Body => "body",
            ObjType::Joint => "joint",
            ObjType::Geom => "geom",
            ObjType::Site => "site",
            ObjType::Camera => "camera",
            ObjType::Actuator => "actuator",
            ObjType::Sensor => "sensor",
            ObjType::Key => "keyframe",
            ObjType::Equality => "equality",
            ObjType::Mesh => "mesh",
        }
    }

    fn count(self, m: &sys::mjModel) -> i64 {
        match self {
            ObjType::Body => m.nbody,
            ObjType::Joint => m.njnt,
            ObjType::Geom => m.ngeom,
            ObjType::Site => m.nsite,
            ObjType::Camera => m.ncam,
            ObjType::Actuator => m.nu,
            ObjType::Sensor => m.nsensor,
            ObjType::Key => m.nkey,
            ObjType::Equality => m.neq,
            ObjType::Mesh => m.nmesh,
        }
    }
}

/// Joint kinds (`mjtJoint`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointType {
    /// 6-DOF free joint (7 qpos: position + unit quaternion w x y z).
    Free,
    /// 3-DOF ball joint (4 qpos: unit quaternion).
    Ball,
    /// 1-DOF prismatic joint (metres).
    Slide,
    /// 1-DOF revolute joint (radians).
    Hinge,
}

impl JointType {
    /// Number of position coordinates.
    pub fn nq(self) -> usize {
        match self {
            JointType::Free => 7,
            JointType::Ball => 4,
            JointType::Slide | JointType::Hinge => 1,
        }
    }

    /// Number of velocity coordinates (degrees of freedom).
    pub fn nv(self) -> usize {
        match self {
            JointType::Free => 6,
            JointType::Ball => 3,
            JointType::Slide | JointType::Hinge => 1,
        }
    }

    /// MJCF name of the type.
    pub fn label(self) -> &'static str {
        match self {
            JointType::Free => "free",
            JointType::Ball => "ball",
            JointType::Slide => "slide",
            JointType::Hinge => "hinge",
        }
    }
}

/// Borrows `len` elements of type `T` starting at `ptr`, or an empty slice for a null pointer
/// (MuJoCo leaves arrays of zero-sized groups null).
///
/// # Safety
/// `ptr` must be null or point to `len` initialised `T`s that live and stay unmodified for `'a`.
pub(super) unsafe fn raw_slice<'a, T>(ptr: *const T, len: usize) -> &'a [T] {
    if ptr.is_null() || len == 0 {
        &[]
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts(ptr, len) }
    }
}

/// Mutable counterpart of [`raw_slice`].
///
/// # Safety
/// `ptr` must be null or point to `len` initialised `T`s exclusively borrowed for `'a`.
pub(super) unsafe fn raw_slice_mut<'a, T>(ptr: *mut T, len: usize) -> &'a mut [T] {
    if ptr.is_null() || len == 0 {
        &mut []
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts_mut(ptr, len) }
    }
}

/// Read-only typed views of `mjModel` arrays: `name: element type = row count field`.
/// Arrays with several columns are viewed as fixed-size rows (`[f64; 3]` for `nbody x 3`).
macro_rules! model_arrays {
    ($( $(#[$doc:meta])* $name:ident : $ty:ty = $count:ident; )*) => {
        impl Model {
            $(
                $(#[$doc])*
                pub fn $name(&self) -> &[$ty] {
                    let m = self.raw();
                    // SAFETY: MuJoCo allocates this array with `$count` rows of exactly the row
                    // type's size and alignment; the model is immutable while `self` is borrowed.
                    unsafe { raw_slice(m.$name as *const $ty, m.$count as usize) }
                }
            )*
        }
    };
}

model_arrays! {
    /// Default joint positions (len `nq`).
    qpos0: f64 = nq;
    /// Parent body id of each body (len `nbody`; the world's parent is itself).
    body_parentid: i32 = nbody;
    /// Mass of each body in kg (len `nbody`).
    body_mass: f64 = nbody;
    /// Principal inertia of each body in kg·m², in its inertial frame (len `nbody`).
    body_inertia: [f64; 3] = nbody;
    /// Centre of mass in the body frame, metres (len `nbody`).
    body_ipos: [f64; 3] = nbody;
    /// Orientation of the inertial frame in the body frame, quaternion w x y z (len `nbody`).
    body_iquat: [f64; 4] = nbody;
    /// Position of each body's frame in its parent's frame, metres (len `nbody`).
    body_pos: [f64; 3] = nbody;
    /// Orientation of each body's frame in its parent's frame, quaternion w x y z (len `nbody`).
    body_quat: [f64; 4] = nbody;
    /// Anchor of each joint in its body's frame, metres (len `njnt`).
    jnt_pos: [f64; 3] = njnt;
    /// Mass of each body's subtree, kg (len `nbody`; derived, set by `mj_setConst`).
    body_subtreemass: f64 = nbody;
    /// First joint of each body, -1 if none (len `nbody`).
    body_jntadr: i32 = nbody;
    /// Number of degrees of freedom of each body (len `nbody`).
    body_dofnum: i32 = nbody;
    /// Address of each body's first DOF, −1 when it has none (len `nbody`).
    body_dofadr: i32 = nbody;
    /// Parent DOF of each DOF, −1 at the root of a chain (len `nv`).
    dof_parentid: i32 = nv;
    /// Body each DOF moves (len `nv`).
    dof_bodyid: i32 = nv;
    /// Number of joints of each body (len `nbody`).
    body_jntnum: i32 = nbody;
    /// Type of each joint (`mjtJoint`) (len `njnt`).
    jnt_type: i32 = njnt;
    /// Body each joint belongs to (len `njnt`).
    jnt_bodyid: i32 = njnt;
    /// Address of each joint's first position in `qpos` (len `njnt`).
    jnt_qposadr: i32 = njnt;
    /// Address of each joint's first DOF in `qvel` (len `njnt`).
    jnt_dofadr: i32 = njnt;
    /// Joint axis in the body frame (len `njnt`).
    jnt_axis: [f64; 3] = njnt;
    /// Whether each joint's range is enforced (len `njnt`).
    jnt_limited: u8 = njnt;
    /// Joint range, radians or metres (len `njnt`).
    jnt_range: [f64; 2] = njnt;
    /// Joint each DOF belongs to (len `nv`).
    dof_jntid: i32 = nv;
    /// Viscous damping per DOF, N·m·s/rad or N·s/m (len `nv`).
    dof_damping: f64 = nv;
    /// Diagonal of the inverse inertia at `qpos0` per DOF (len `nv`; derived, set by
    /// `mj_setConst`): 1 / effective inertia, 1/(kg·m²) or 1/kg.
    dof_invweight0: f64 = nv;
    /// Whether each joint's total actuator force is limited (len `njnt`).
    jnt_actfrclimited: u8 = njnt;
    /// Range of each joint's total actuator force, N·m or N (URDF `effort`) (len `njnt`).
    jnt_actfrcrange: [f64; 2] = njnt;
    /// Dry friction loss per DOF, N·m or N (len `nv`).
    dof_frictionloss: f64 = nv;
    /// Armature (reflected rotor inertia) per DOF, kg·m² or kg (len `nv`).
    dof_armature: f64 = nv;
    /// Body each geom belongs to (len `ngeom`).
    geom_bodyid: i32 = ngeom;
    /// Sliding, torsional and rolling friction of each geom (len `ngeom`).
    geom_friction: [f64; 3] = ngeom;
    /// Geometric type of each geom (`mjtGeom`) (len `ngeom`).
    geom_type: i32 = ngeom;
    /// Type-specific size parameters of each geom, metres (len `ngeom`).
    geom_size: [f64; 3] = ngeom;
    /// Radius of each geom's bounding sphere, metres (len `ngeom`).
    geom_rbound: f64 = ngeom;
    /// Transmission type of each actuator (`mjtTrn`) (len `nu`).
    actuator_trntype: i32 = nu;
    /// Transmission target ids of each actuator (len `nu`).
    actuator_trnid: [i32; 2] = nu;
    /// Gear of each actuator (len `nu`).
    actuator_gear: [f64; 6] = nu;
    /// Whether each actuator's control is clamped to its range (len `nu`).
    actuator_ctrllimited: u8 = nu;
    /// Control range of each actuator (len `nu`).
    actuator_ctrlrange: [f64; 2] = nu;
    /// Whether each actuator's force is clamped to its force range (len `nu`).
    actuator_forcelimited: u8 = nu;
    /// Force range of each actuator, N·m or N (len `nu`).
    actuator_forcerange: [f64; 2] = nu;
    /// Gain parameters of each actuator (`kp` of position actuators is entry 0) (len `nu`).
    actuator_gainprm: [f64; 10] = nu;
    /// Bias parameters of each actuator (len `nu`).
    actuator_biasprm: [f64; 10] = nu;
    /// Type of each sensor (`mjtSensor`) (len `nsensor`).
    sensor_type: i32 = nsensor;
    /// Number of values each sensor writes (len `nsensor`).
    sensor_dim: i32 = nsensor;
    /// Address of each sensor's values in `sensordata` (len `nsensor`).
    sensor_adr: i32 = nsensor;
    /// Object type each sensor is attached to (len `nsensor`).
    sensor_objtype: i32 = nsensor;
    /// Object id each sensor is attached to (len `nsensor`).
    sensor_objid: i32 = nsensor;
    /// Noise standard deviation stored with each sensor (MuJoCo does not apply it) (len `nsensor`).
    sensor_noise: f64 = nsensor;
    /// Contact type bits of each geom (len `ngeom`).
    geom_contype: i32 = ngeom;
    /// Contact affinity bits of each geom (len `ngeom`).
    geom_conaffinity: i32 = ngeom;
    /// Mesh (or height field) id of each geom, -1 for none (len `ngeom`).
    geom_dataid: i32 = ngeom;
    /// Material id of each geom, -1 for none (len `ngeom`).
    geom_matid: i32 = ngeom;
    /// Visibility group of each geom (len `ngeom`).
    geom_group: i32 = ngeom;
    /// Position of each geom in its body frame, metres (len `ngeom`).
    geom_pos: [f64; 3] = ngeom;
    /// Orientation of each geom in its body frame, quaternion w x y z (len `ngeom`).
    geom_quat: [f64; 4] = ngeom;
    /// Colour of each geom when it has no material (len `ngeom`).
    geom_rgba: [f32; 4] = ngeom;
    /// Colour of each material (len `nmat`).
    mat_rgba: [f32; 4] = nmat;
    /// First vertex of each mesh in [`Model::mesh_vert`] (len `nmesh`).
    mesh_vertadr: i32 = nmesh;
    /// Vertex count of each mesh (len `nmesh`).
    mesh_vertnum: i32 = nmesh;
    /// First face of each mesh in [`Model::mesh_face`] (len `nmesh`).
    mesh_faceadr: i32 = nmesh;
    /// Face count of each mesh (len `nmesh`).
    mesh_facenum: i32 = nmesh;
    /// Vertices of all meshes, in their geom's frame, metres (len `nmeshvert`).
    mesh_vert: [f32; 3] = nmeshvert;
    /// Triangles of all meshes as vertex indices relative to the mesh's first vertex (len `nmeshface`).
    mesh_face: [i32; 3] = nmeshface;
    /// Contact priority of each geom (len `ngeom`).
    geom_priority: i32 = ngeom;
    /// Body each site belongs to (len `nsite`).
    site_bodyid: i32 = nsite;
    /// Position of each site in its body frame, metres (len `nsite`).
    site_pos: [f64; 3] = nsite;
    /// Orientation of each site in its body frame, quaternion w x y z (len `nsite`).
    site_quat: [f64; 4] = nsite;
    /// Id of the body each body is welded to (itself when it has joints) (len `nbody`).
    body_weldid: i32 = nbody;
    /// Gain type of each actuator (`mjtGain`) (len `nu`).
    actuator_gaintype: i32 = nu;
    /// Bias type of each actuator (`mjtBias`) (len `nu`).
    actuator_biastype: i32 = nu;
}

impl Model {
    /// Loads an MJCF or URDF file. A URDF (root `<robot>`) goes through twin's converter
    /// ([`crate::convert`]) with default options: free-floating base placed on a floor, one
    /// actuator per transmission, IMU and joint sensors, keyframe `home`.
    ///
    /// # Errors
    /// [`Error::Io`] if the file can't be read, [`Error::Urdf`]/[`Error::Xml`] for an invalid
    /// URDF, [`Error::Load`] with MuJoCo's message (element and line) if MuJoCo refuses it.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Model> {
        init()?;
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        if crate::urdf::is_urdf(&text) {
            let converted = crate::convert::convert_urdf_str(path, &text, &crate::convert::ConvertOptions::default())?;
            return Model::from_xml_str(&converted.mjcf).map_err(|e| match e {
                Error::Load { message, .. } => Error::Load { path: Some(path.to_path_buf()), message },
                other => other,
            });
        }
        Self::from_mujoco_file(path)
    }

    /// Loads a file with MuJoCo's own parser (`mj_loadXML`): MJCF, or a URDF through MuJoCo's
    /// URDF importer (no actuators, no sensors, welded root). Used to compare twin's converter
    /// against MuJoCo's import.
    ///
    /// # Errors
    /// [`Error::Load`] with MuJoCo's message.
    pub fn from_mujoco_file(path: impl AsRef<Path>) -> Result<Model> {
        init()?;
        let path = path.as_ref();
        let c_path = CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| Error::Load {
            path: Some(path.to_path_buf()),
            message: "the path contains a NUL byte".into(),
        })?;
        let mut out = std::ptr::null_mut();
        let mut err = [0 as c_char; 1024];
        // mj_loadXML reports model errors in `err` itself; a raised error lands there too.
        // SAFETY: c_path is NUL-terminated; `out` and `err` outlive the call; the shim writes at
        // most `err.len()` bytes.
        let rc = unsafe { ffi::twin_load_xml(c_path.as_ptr(), &mut out, err.as_mut_ptr(), err.len() as c_int) };
        let raised =
            if rc == 0 { Ok(()) } else { Err(Error::MuJoCo { call: "mj_loadXML", message: buf_to_string(&err) }) };
        Self::finish_load(out, raised, &err, Some(path))
    }

    /// Converts the URDF at `path` with `opts` ([`crate::convert::convert_urdf`]) and compiles it.
    ///
    /// # Errors
    /// As [`crate::convert::convert_urdf`].
    pub fn from_urdf(path: impl AsRef<Path>, opts: &crate::convert::ConvertOptions) -> Result<Model> {
        let path = path.as_ref();
        let converted = crate::convert::convert_urdf(path, opts)?;
        Model::from_xml_str(&converted.mjcf).map_err(|e| match e {
            Error::Load { message, .. } => Error::Load { path: Some(path.to_path_buf()), message },
            other => other,
        })
    }

    /// Loads an MJCF (or URDF) document from a string. Relative file references (meshes)
    /// resolve against the current directory.
    ///
    /// # Errors
    /// [`Error::Load`] with MuJoCo's message if MuJoCo refuses the document.
    pub fn from_xml_str(xml: &str) -> Result<Model> {
        init()?;
        let c_xml = CString::new(xml)
            .map_err(|_| Error::Load { path: None, message: "the document contains a NUL byte".into() })?;
        let mut spec = std::ptr::null_mut();
        let mut err = [0 as c_char; 1024];
        // SAFETY: c_xml is NUL-terminated; `spec` and `err` outlive the call.
        let rc = unsafe { ffi::twin_parse_xml_string(c_xml.as_ptr(), &mut spec, err.as_mut_ptr(), err.len() as c_int) };
        let raised = if rc == 0 {
            Ok(())
        } else {
            Err(Error::MuJoCo { call: "mj_parseXMLString", message: buf_to_string(&err) })
        };
        if spec.is_null() {
            return Self::finish_load(std::ptr::null_mut(), raised, &err, None);
        }
        let mut out = std::ptr::null_mut();
        let raised = guarded("mj_compile", |e, n| {
            // SAFETY: spec is a live mjSpec from mj_parseXMLString.
            unsafe { ffi::twin_compile(spec, &mut out, e, n) }
        });
        if out.is_null() && raised.is_ok() {
            // SAFETY: spec is live; mjs_getError returns a NUL-terminated string owned by it.
            let msg = unsafe { CStr::from_ptr(sys::mjs_getError(spec)) }.to_string_lossy().into_owned();
            let n = msg.len().min(err.len() - 1);
            for (dst, src) in err.iter_mut().zip(msg.bytes().take(n)) {
                *dst = src as c_char;
            }
            err[n] = 0;
        }
        // SAFETY: the compiled model does not refer to the spec; the spec is deleted once.
        unsafe { sys::mj_deleteSpec(spec) };
        Self::finish_load(out, raised, &err, None)
    }

    fn finish_load(out: *mut sys::mjModel, raised: Result<()>, err: &[c_char], path: Option<&Path>) -> Result<Model> {
        let path = path.map(Path::to_path_buf);
        if let Err(Error::MuJoCo { message, .. }) = raised {
            if !out.is_null() {
                // SAFETY: a model returned despite an error is still ours to free.
                unsafe { sys::mj_deleteModel(out) };
            }
            return Err(Error::Load { path, message });
        }
        match NonNull::new(out) {
            Some(ptr) => Ok(Model { ptr }),
            None => {
                let message = buf_to_string(err);
                let message = if message.is_empty() { "unknown error".to_string() } else { message };
                Err(Error::Load { path, message })
            }
        }
    }

    /// Copies this model (`mj_copyModel`).
    ///
    /// # Errors
    /// [`Error::MuJoCo`] if MuJoCo cannot allocate the copy.
    pub fn try_clone(&self) -> Result<Model> {
        let mut out = std::ptr::null_mut();
        guarded("mj_copyModel", |e, n| {
            // SAFETY: self.ptr is a live model; out receives a new one.
            unsafe { ffi::twin_copy_model(self.ptr.as_ptr(), &mut out, e, n) }
        })?;
        NonNull::new(out)
            .map(|ptr| Model { ptr })
            .ok_or(Error::MuJoCo { call: "mj_copyModel", message: "returned no model".into() })
    }

    /// Starts an edit of a copy of this model; see [`ModelEdit`].
    ///
    /// # Errors
    /// As [`Model::try_clone`].
    pub fn edit(&self) -> Result<super::ModelEdit> {
        Ok(super::ModelEdit::new(self.try_clone()?))
    }

    /// The raw `mjModel`, read-only: sizes and options (`raw().opt.timestep`) are plain fields.
    pub fn raw(&self) -> &sys::mjModel {
        // SAFETY: the pointer is live for self's lifetime and only read through this reference.
        unsafe { self.ptr.as_ref() }
    }

    /// Raw pointer for FFI calls that take `const mjModel*`.
    pub fn as_ptr(&self) -> *const sys::mjModel {
        self.ptr.as_ptr()
    }

    /// Mutable raw pointer, for [`ModelEdit`] only.
    pub(super) fn as_mut_ptr(&mut self) -> *mut sys::mjModel {
        self.ptr.as_ptr()
    }

    /// Number of position coordinates.
    pub fn nq(&self) -> usize {
        self.raw().nq as usize
    }
    /// Number of degrees of freedom (velocity coordinates).
    pub fn nv(&self) -> usize {
        self.raw().nv as usize
    }
    /// Number of actuators (controls).
    pub fn nu(&self) -> usize {
        self.raw().nu as usize
    }
    /// Number of bodies, the world body included.
    pub fn nbody(&self) -> usize {
        self.raw().nbody as usize
    }
    /// Number of joints.
    pub fn njnt(&self) -> usize {
        self.raw().njnt as usize
    }
    /// Number of geoms.
    pub fn ngeom(&self) -> usize {
        self.raw().ngeom as usize
    }
    /// Number of sites.
    pub fn nsite(&self) -> usize {
        self.raw().nsite as usize
    }
    /// Number of sensors.
    pub fn nsensor(&self) -> usize {
        self.raw().nsensor as usize
    }
    /// Number of sensor values (length of `sensordata`).
    pub fn nsensordata(&self) -> usize {
        self.raw().nsensordata as usize
    }
    /// Number of keyframes.
    pub fn nkey(&self) -> usize {
        self.raw().nkey as usize
    }
    /// Number of meshes.
    pub fn nmesh(&self) -> usize {
        self.raw().nmesh as usize
    }
    /// Number of equality constraints.
    pub fn neq(&self) -> usize {
        self.raw().neq as usize
    }
    /// Number of cameras.
    pub fn ncam(&self) -> usize {
        self.raw().ncam as usize
    }

    /// Diagonal of the joint-space inertia at `qpos0`, kg·m² or kg (`dof_M0`, len `nv`).
    pub fn dof_m0(&self) -> &[f64] {
        // SAFETY: dof_M0 has nv entries; model immutable while self is borrowed.
        unsafe { raw_slice(self.raw().dof_M0 as *const f64, self.nv()) }
    }

    /// Joint positions of keyframe `key` (len `nq`), `None` for a bad index.
    pub fn key_qpos(&self, key: usize) -> Option<&[f64]> {
        if key >= self.nkey() {
            return None;
        }
        let nq = self.nq();
        // SAFETY: key_qpos has nkey rows of nq entries; key checked above; model immutable
        // while self is borrowed.
        let all = unsafe { raw_slice(self.raw().key_qpos as *const f64, self.nkey() * nq) };
        Some(&all[key * nq..(key + 1) * nq])
    }

    /// Simulation timestep in seconds.
    pub fn timestep_secs(&self) -> f64 {
        self.raw().opt.timestep
    }
    /// Gravity in the world frame, m/s².
    pub fn gravity(&self) -> [f64; 3] {
        self.raw().opt.gravity
    }

    /// Number of bytes of the model's buffer (all its arrays): equal for a model and its edited
    /// copies.
    pub fn nbuffer(&self) -> usize {
        self.raw().nbuffer as usize
    }
    /// Number of bytes of each `mjData` arena made for this model.
    pub fn narena(&self) -> usize {
        self.raw().narena as usize
    }

    /// Total mass of all bodies, kg (the world body has none).
    pub fn total_mass_kg(&self) -> f64 {
        self.body_mass().iter().sum()
    }

    /// Type of joint `id`.
    pub fn joint_type(&self, id: usize) -> JointType {
        match self.jnt_type()[id] as u32 {
            sys::mjtJoint_mjJNT_FREE => JointType::Free,
            sys::mjtJoint_mjJNT_BALL => JointType::Ball,
            sys::mjtJoint_mjJNT_SLIDE => JointType::Slide,
            _ => JointType::Hinge,
        }
    }

    /// Whether sensor `id` is an inertial one of an IMU (gyro or accelerometer).
    pub fn sensor_is_imu(&self, id: usize) -> bool {
        let ty = self.sensor_type()[id] as u32;
        ty == sys::mjtSensor_mjSENS_GYRO || ty == sys::mjtSensor_mjSENS_ACCELEROMETER
    }

    /// Id of the object of kind `obj` named `name`, if any.
    pub fn id(&self, obj: ObjType, name: &str) -> Option<usize> {
        let c_name = CString::new(name).ok()?;
        // SAFETY: live model, NUL-terminated name; mj_name2id only reads.
        let id = unsafe { sys::mj_name2id(self.as_ptr(), obj.raw() as c_int, c_name.as_ptr()) };
        usize::try_from(id).ok()
    }

    /// Like [`Model::id`], but an error naming what was not found.
    ///
    /// # Errors
    /// [`Error::NotFound`].
    pub fn require_id(&self, obj: ObjType, name: &str) -> Result<usize> {
        self.id(obj, name).ok_or_else(|| Error::NotFound { kind: obj.label(), name: name.to_string() })
    }

    /// Name of object `id` of kind `obj`; empty for unnamed objects or out-of-range ids.
    pub fn name(&self, obj: ObjType, id: usize) -> &str {
        if id as i64 >= obj.count(self.raw()) {
            return "";
        }
        // SAFETY: id is in range; the returned pointer is into the model's name buffer, which
        // lives as long as self.
        let p = unsafe { sys::mj_id2name(self.as_ptr(), obj.raw() as c_int, id as c_int) };
        if p.is_null() {
            return "";
        }
        // SAFETY: MuJoCo names are NUL-terminated; the buffer outlives the borrow of self.
        unsafe { CStr::from_ptr(p) }.to_str().unwrap_or("")
    }
}
