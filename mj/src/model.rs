use super::{BiasType, DynType, GeomType, Integrator, SensorType, Transmission, buf_to_string, ffi, guarded, init};
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
    const ALL: [ObjType; 10] = [
        ObjType::Body,
        ObjType::Joint,
        ObjType::Geom,
        ObjType::Site,
        ObjType::Camera,
        ObjType::Actuator,
        ObjType::Sensor,
        ObjType::Key,
        ObjType::Equality,
        ObjType::Mesh,
    ];

    /// The kind of MuJoCo's integer `raw` (`mjtObj`), when this wrapper names it.
    pub fn from_raw(raw: i32) -> Option<ObjType> {
        ObjType::ALL.into_iter().find(|o| o.raw() as i32 == raw)
    }

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

/// Read-only typed views of `mjModel` arrays. Each row states the C element type, the row width
/// and the count field: `name: elem x width = count;` views `count` rows of `[elem; width]`
/// (`name: elem = count;` rows of one `elem`). The element type is checked against the C field
/// at compile time (a pointer of another type does not coerce); the width is MuJoCo's documented
/// one (`mjmodel.h`, e.g. `nbody x 3`).
macro_rules! model_arrays {
    (@one $(#[$doc:meta])* $name:ident, $elem:ident, $row:ty, $count:ident) => {
        $(#[$doc])*
        pub fn $name(&self) -> &[$row] {
            let m = self.raw();
            let ptr: *mut $elem = m.$name;
            // SAFETY: MuJoCo allocates this array with `$count` rows of `$row` (the element type
            // is checked above; the width is the one mjmodel.h documents), aligned for `$elem`;
            // the model is immutable while `self` is borrowed.
            unsafe { raw_slice(ptr as *const $row, m.$count as usize) }
        }
    };
    ($( $(#[$doc:meta])* $name:ident : $elem:ident $(x $width:literal)? = $count:ident; )*) => {
        impl Model {
            $(
                model_arrays!(@one $(#[$doc])* $name, $elem, model_arrays!(@row $elem $(, $width)?), $count);
            )*
        }
    };
    (@row $elem:ident) => { $elem };
    (@row $elem:ident, $width:literal) => { [$elem; $width] };
}

model_arrays! {
    /// Contact `solref` of each geom: time constant and damping ratio, or (negative) direct
    /// stiffness and damping (len `ngeom`).
    geom_solref: f64 x 2 = ngeom;
    /// Default joint positions (len `nq`).
    qpos0: f64 = nq;
    /// Parent body id of each body (len `nbody`; the world's parent is itself).
    body_parentid: i32 = nbody;
    /// Mass of each body in kg (len `nbody`).
    body_mass: f64 = nbody;
    /// Principal inertia of each body in kg·m², in its inertial frame (len `nbody`).
    body_inertia: f64 x 3 = nbody;
    /// Centre of mass in the body frame, metres (len `nbody`).
    body_ipos: f64 x 3 = nbody;
    /// Orientation of the inertial frame in the body frame, quaternion w x y z (len `nbody`).
    body_iquat: f64 x 4 = nbody;
    /// Position of each body's frame in its parent's frame, metres (len `nbody`).
    body_pos: f64 x 3 = nbody;
    /// Orientation of each body's frame in its parent's frame, quaternion w x y z (len `nbody`).
    body_quat: f64 x 4 = nbody;
    /// Anchor of each joint in its body's frame, metres (len `njnt`).
    jnt_pos: f64 x 3 = njnt;
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
    jnt_axis: f64 x 3 = njnt;
    /// Whether each joint's range is enforced (len `njnt`).
    jnt_limited: bool = njnt;
    /// Joint range, radians or metres (len `njnt`).
    jnt_range: f64 x 2 = njnt;
    /// Joint each DOF belongs to (len `nv`).
    dof_jntid: i32 = nv;
    /// Viscous damping per DOF, N·m·s/rad or N·s/m (len `nv`).
    dof_damping: f64 = nv;
    /// Diagonal of the inverse inertia at `qpos0` per DOF (len `nv`; derived, set by
    /// `mj_setConst`): 1 / effective inertia, 1/(kg·m²) or 1/kg.
    dof_invweight0: f64 = nv;
    /// Inverse effective mass (translation, 1/kg) and inertia (rotation) of each body at
    /// `qpos0`, as the constraint solver sees it (len `nbody`).
    body_invweight0: f64 x 2 = nbody;
    /// Whether each joint's total actuator force is limited (len `njnt`).
    jnt_actfrclimited: bool = njnt;
    /// Range of each joint's total actuator force, N·m or N (URDF `effort`) (len `njnt`).
    jnt_actfrcrange: f64 x 2 = njnt;
    /// Dry friction loss per DOF, N·m or N (len `nv`).
    dof_frictionloss: f64 = nv;
    /// Armature (reflected rotor inertia) per DOF, kg·m² or kg (len `nv`).
    dof_armature: f64 = nv;
    /// Body each geom belongs to (len `ngeom`).
    geom_bodyid: i32 = ngeom;
    /// Sliding, torsional and rolling friction of each geom (len `ngeom`).
    geom_friction: f64 x 3 = ngeom;
    /// Geometric type of each geom (`mjtGeom`) (len `ngeom`).
    geom_type: i32 = ngeom;
    /// Type-specific size parameters of each geom, metres (len `ngeom`).
    geom_size: f64 x 3 = ngeom;
    /// Radius of each geom's bounding sphere, metres (len `ngeom`).
    geom_rbound: f64 = ngeom;
    /// Each geom's bounding box in its own frame: centre then half-sizes, metres (len `ngeom`).
    geom_aabb: f64 x 6 = ngeom;
    /// Transmission type of each actuator (`mjtTrn`) (len `nu`).
    actuator_trntype: i32 = nu;
    /// Transmission target ids of each actuator (len `nu`).
    actuator_trnid: i32 x 2 = nu;
    /// Gear of each actuator (len `nu`).
    actuator_gear: f64 x 6 = nu;
    /// Whether each actuator's control is clamped to its range (len `nu`).
    actuator_ctrllimited: bool = nu;
    /// Control range of each actuator (len `nu`).
    actuator_ctrlrange: f64 x 2 = nu;
    /// Whether each actuator's force is clamped to its force range (len `nu`).
    actuator_forcelimited: bool = nu;
    /// Force range of each actuator, N·m or N (len `nu`).
    actuator_forcerange: f64 x 2 = nu;
    /// Gain parameters of each actuator (`kp` of position actuators is entry 0) (len `nu`).
    actuator_gainprm: f64 x 10 = nu;
    /// Bias parameters of each actuator (len `nu`).
    actuator_biasprm: f64 x 10 = nu;
    /// Command delay of each actuator, seconds (0: none), read from its history buffer (len `nu`).
    actuator_delay: f64 = nu;
    /// History buffer of each actuator: number of samples and interpolation (0 zero-order hold,
    /// 1 linear) (len `nu`).
    actuator_history: i32 x 2 = nu;
    /// Armature of each actuator's transmission, kg·m² or kg (len `nu`).
    actuator_armature: f64 = nu;
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
    geom_pos: f64 x 3 = ngeom;
    /// Orientation of each geom in its body frame, quaternion w x y z (len `ngeom`).
    geom_quat: f64 x 4 = ngeom;
    /// Colour of each geom when it has no material (len `ngeom`).
    geom_rgba: f32 x 4 = ngeom;
    /// Colour of each material (len `nmat`).
    mat_rgba: f32 x 4 = nmat;
    /// First vertex of each mesh in [`Model::mesh_vert`] (len `nmesh`).
    mesh_vertadr: i32 = nmesh;
    /// Vertex count of each mesh (len `nmesh`).
    mesh_vertnum: i32 = nmesh;
    /// First face of each mesh in [`Model::mesh_face`] (len `nmesh`).
    mesh_faceadr: i32 = nmesh;
    /// Face count of each mesh (len `nmesh`).
    mesh_facenum: i32 = nmesh;
    /// Vertices of all meshes, in their geom's frame, metres (len `nmeshvert`).
    mesh_vert: f32 x 3 = nmeshvert;
    /// Triangles of all meshes as vertex indices relative to the mesh's first vertex (len `nmeshface`).
    mesh_face: i32 x 3 = nmeshface;
    /// Contact priority of each geom (len `ngeom`).
    geom_priority: i32 = ngeom;
    /// Body each site belongs to (len `nsite`).
    site_bodyid: i32 = nsite;
    /// Position of each site in its body frame, metres (len `nsite`).
    site_pos: f64 x 3 = nsite;
    /// Orientation of each site in its body frame, quaternion w x y z (len `nsite`).
    site_quat: f64 x 4 = nsite;
    /// Id of the body each body is welded to (itself when it has joints) (len `nbody`).
    body_weldid: i32 = nbody;
    /// Gain type of each actuator (`mjtGain`) (len `nu`).
    actuator_gaintype: i32 = nu;
    /// Bias type of each actuator (`mjtBias`) (len `nu`).
    actuator_biastype: i32 = nu;
    /// Activation dynamics type of each actuator (`mjtDyn`; 0 = none: the force follows `ctrl`
    /// within the step) (len `nu`).
    actuator_dyntype: i32 = nu;
    /// Body each camera is attached to (len `ncam`).
    cam_bodyid: i32 = ncam;
    /// Position of each camera in its body's frame, metres (len `ncam`).
    cam_pos: f64 x 3 = ncam;
    /// Orientation of each camera in its body's frame, quaternion w x y z (len `ncam`).
    cam_quat: f64 x 4 = ncam;
}

/// The free joint of a floating-base model: which body it moves and where its state is.
/// `qpos[qpos_adr..+7]` = base position (world, m) then orientation `w x y z`
/// (world_from_base); `qvel[dof..+6]` = linear velocity (world, m/s) then angular velocity
/// (base frame, rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FreeJoint {
    /// Joint id.
    pub joint: usize,
    /// The body it moves (the floating base).
    pub body: usize,
    /// Address of its 7 entries in `qpos`.
    pub qpos_adr: usize,
    /// Address of its 6 DOFs in `qvel`.
    pub dof: usize,
}

/// Every size of a model (`nq` … `nbuffer`, the `mjModel` fields that fix the memory layout of
/// its `mjData`): two models with equal layouts can share one `mjData`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelLayout {
    sizes: [i64; MODEL_SIZE_FIELDS.len()],
}

/// Names of the `mjModel` size fields, in struct order (`nq` first, `nbuffer` last).
const MODEL_SIZE_FIELDS: [&str; 98] = [
    "nq",
    "nv",
    "nu",
    "nactuator",
    "nout",
    "na",
    "nbody",
    "nbvh",
    "nbvhstatic",
    "nbvhdynamic",
    "noct",
    "njnt",
    "ntree",
    "nM",
    "nB",
    "nC",
    "nD",
    "ngeom",
    "nsite",
    "ncam",
    "nlight",
    "nflex",
    "nflexnode",
    "nflexvert",
    "nflexedge",
    "nflexelem",
    "nflexelemdata",
    "nflexstiffness",
    "nflexbending",
    "nefm0dof",
    "nefm0L",
    "nefmCvert",
    "nflexelemedge",
    "nflexshelldata",
    "nflextexcoord",
    "nJfe",
    "nmesh",
    "nmeshvert",
    "nmeshnormal",
    "nmeshtexcoord",
    "nmeshface",
    "nmeshgraph",
    "nmeshpoly",
    "nmeshpolyvert",
    "nmeshpolymap",
    "nskin",
    "nskinvert",
    "nskintexvert",
    "nskinface",
    "nskinbone",
    "nskinbonevert",
    "nhfield",
    "nhfielddata",
    "ntex",
    "ntexdata",
    "nmat",
    "npair",
    "nexclude",
    "neq",
    "ntendon",
    "nJten",
    "nwrap",
    "nsensor",
    "nnumeric",
    "nnumericdata",
    "ntext",
    "ntextdata",
    "ntuple",
    "ntupledata",
    "nkey",
    "nmocap",
    "nplugin",
    "npluginattr",
    "nuser_body",
    "nuser_jnt",
    "nuser_geom",
    "nuser_site",
    "nuser_cam",
    "nuser_tendon",
    "nuser_actuator",
    "nuser_sensor",
    "nnames",
    "npaths",
    "nplastic",
    "nnames_map",
    "nJmom",
    "ngravcomp",
    "nemax",
    "njmax",
    "nconmax",
    "npolygonmax",
    "nmeshdegmax",
    "nuserdata",
    "nsensordata",
    "npluginstate",
    "nhistory",
    "narena",
    "nbuffer",
];

impl ModelLayout {
    /// The layout of `model`.
    pub fn of(model: &Model) -> ModelLayout {
        let m = model.raw();
        let sizes = [
            m.nq,
            m.nv,
            m.nu,
            m.nactuator,
            m.nout,
            m.na,
            m.nbody,
            m.nbvh,
            m.nbvhstatic,
            m.nbvhdynamic,
            m.noct,
            m.njnt,
            m.ntree,
            m.nM,
            m.nB,
            m.nC,
            m.nD,
            m.ngeom,
            m.nsite,
            m.ncam,
            m.nlight,
            m.nflex,
            m.nflexnode,
            m.nflexvert,
            m.nflexedge,
            m.nflexelem,
            m.nflexelemdata,
            m.nflexstiffness,
            m.nflexbending,
            m.nefm0dof,
            m.nefm0L,
            m.nefmCvert,
            m.nflexelemedge,
            m.nflexshelldata,
            m.nflextexcoord,
            m.nJfe,
            m.nmesh,
            m.nmeshvert,
            m.nmeshnormal,
            m.nmeshtexcoord,
            m.nmeshface,
            m.nmeshgraph,
            m.nmeshpoly,
            m.nmeshpolyvert,
            m.nmeshpolymap,
            m.nskin,
            m.nskinvert,
            m.nskintexvert,
            m.nskinface,
            m.nskinbone,
            m.nskinbonevert,
            m.nhfield,
            m.nhfielddata,
            m.ntex,
            m.ntexdata,
            m.nmat,
            m.npair,
            m.nexclude,
            m.neq,
            m.ntendon,
            m.nJten,
            m.nwrap,
            m.nsensor,
            m.nnumeric,
            m.nnumericdata,
            m.ntext,
            m.ntextdata,
            m.ntuple,
            m.ntupledata,
            m.nkey,
            m.nmocap,
            m.nplugin,
            m.npluginattr,
            m.nuser_body,
            m.nuser_jnt,
            m.nuser_geom,
            m.nuser_site,
            m.nuser_cam,
            m.nuser_tendon,
            m.nuser_actuator,
            m.nuser_sensor,
            m.nnames,
            m.npaths,
            m.nplastic,
            m.nnames_map,
            m.nJmom,
            m.ngravcomp,
            m.nemax,
            m.njmax,
            m.nconmax,
            m.npolygonmax,
            m.nmeshdegmax,
            m.nuserdata,
            m.nsensordata,
            m.npluginstate,
            m.nhistory,
            m.narena,
            m.nbuffer,
        ];
        ModelLayout { sizes }
    }

    /// `Ok` when `other` has this layout, else [`Error::Size`] naming the first size field
    /// that differs (e.g. `njnt: expected 2, got 1`).
    ///
    /// # Errors
    /// [`Error::Size`].
    pub fn require_same(&self, other: &ModelLayout) -> Result<()> {
        match self.sizes.iter().zip(&other.sizes).position(|(a, b)| a != b) {
            None => Ok(()),
            Some(k) => Err(Error::Size {
                what: MODEL_SIZE_FIELDS[k],
                expected: self.sizes[k] as usize,
                got: other.sizes[k] as usize,
            }),
        }
    }
}

/// Attributes that hold names or file paths, never numbers.
const NAME_ATTRIBUTES: [&str; 24] = [
    "name",
    "class",
    "childclass",
    "joint",
    "joint1",
    "joint2",
    "body",
    "body1",
    "body2",
    "site",
    "geom",
    "geom1",
    "geom2",
    "tendon",
    "actuator",
    "objname",
    "target",
    "mesh",
    "material",
    "texture",
    "hfield",
    "file",
    "model",
    "prefix",
];

/// MuJoCo's parser takes `nan` and `inf` as numbers and then quietly replaces some (a `mass="nan"`
/// becomes the density-based mass): refuse them with the element and line.
fn check_finite_attributes(path: Option<&Path>, text: &str) -> Result<()> {
    // A document roxmltree cannot read is left to MuJoCo, whose message names the problem.
    let Ok(doc) = roxmltree::Document::parse(text) else { return Ok(()) };
    for node in doc.descendants().filter(|n| n.is_element()) {
        for attr in node.attributes() {
            if NAME_ATTRIBUTES.contains(&attr.name()) {
                continue;
            }
            let bad = attr.value().split_whitespace().find(|t| {
                let t = t.trim_start_matches(['+', '-']).to_ascii_lowercase();
                t == "nan" || t == "inf" || t == "infinity"
            });
            if let Some(token) = bad {
                let line = doc.text_pos_at(node.range().start).row;
                let file = path.map_or_else(|| "the model".to_string(), |p| p.display().to_string());
                return Err(Error::OutOfRange {
                    what: format!("{file}:{line}: <{} {}>", node.tag_name().name(), attr.name()),
                    message: format!(
                        "`{}` is not a finite number; give a finite value",
                        twin_fsio::excerpt(token, twin_fsio::EXCERPT_CHARS)
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Timesteps a model may have, seconds: below, a run never ends; above, nothing is simulated
/// faithfully (and a 10 s step "simulates" seconds in zero steps).
pub const TIMESTEP_RANGE_SECS: (f64, f64) = (1e-6, 0.1);

impl Model {
    /// Loads a file with MuJoCo's own parser (`mj_loadXML`): MJCF, or a URDF through MuJoCo's
    /// URDF importer (no actuators, no sensors, welded root). Used to compare twin's converter
    /// against MuJoCo's import.
    ///
    /// # Errors
    /// [`Error::Load`] with MuJoCo's message.
    pub fn from_mujoco_file(path: impl AsRef<Path>) -> Result<Model> {
        init()?;
        let path = path.as_ref();
        // MuJoCo opens the file itself: a FIFO would block it forever.
        let text = twin_fsio::read(path)?;
        check_finite_attributes(Some(path), &String::from_utf8_lossy(&text))?;
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

    /// Loads an MJCF (or URDF) document from a string. Relative file references (meshes)
    /// resolve against the current directory.
    ///
    /// # Errors
    /// [`Error::Load`] with MuJoCo's message if MuJoCo refuses the document.
    pub fn from_xml_str(xml: &str) -> Result<Model> {
        init()?;
        check_finite_attributes(None, xml)?;
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
            Some(ptr) => {
                let model = Model { ptr };
                model.check_numbers(path.as_deref())?;
                Ok(model)
            }
            None => {
                let message = buf_to_string(err);
                let message = if message.is_empty() { "unknown error".to_string() } else { message };
                Err(Error::Load { path, message })
            }
        }
    }

    /// Refuses numbers MuJoCo compiles but that make every later answer wrong or a run endless:
    /// a timestep outside [`TIMESTEP_RANGE_SECS`] or not finite, a mass or inertia that is not
    /// finite.
    fn check_numbers(&self, path: Option<&Path>) -> Result<()> {
        let what = || path.map_or_else(|| "the model".to_string(), |p| p.display().to_string());
        let dt = self.timestep_secs();
        let (lo, hi) = TIMESTEP_RANGE_SECS;
        if !(dt.is_finite() && (lo..=hi).contains(&dt)) {
            return Err(Error::OutOfRange {
                what: format!("{}: <option timestep>", what()),
                message: format!(
                    "timestep {dt} s is outside {lo} … {hi} s; MuJoCo models use about 0.001 … 0.01 s \
                     (default 0.002)"
                ),
            });
        }
        for (b, (m, inertia)) in self.body_mass().iter().zip(self.body_inertia()).enumerate() {
            if !m.is_finite() || *m < 0.0 || !inertia.iter().all(|i| i.is_finite()) {
                let name = self.name(ObjType::Body, b);
                return Err(Error::OutOfRange {
                    what: format!("{}: body \"{name}\"", what()),
                    message: format!(
                        "mass {m} kg, inertia {inertia:?} kg·m²: masses and inertias must be finite numbers ≥ 0"
                    ),
                });
            }
        }
        Ok(())
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

    /// User numbers of camera `cam` (len `nuser_cam`; empty for a bad index). twin keeps a depth
    /// camera's noise standard deviation (m) in entry 0 when the model has one
    /// (the grasping controller's).
    pub fn cam_user(&self, cam: usize) -> &[f64] {
        let n = self.raw().nuser_cam.max(0) as usize;
        if cam >= self.ncam() || n == 0 {
            return &[];
        }
        // SAFETY: cam_user has ncam rows of nuser_cam entries; cam checked above; model
        // immutable while self is borrowed.
        let all = unsafe { raw_slice(self.raw().cam_user as *const f64, self.ncam() * n) };
        &all[cam * n..(cam + 1) * n]
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

    /// Whether body `body` is `root` or inside its kinematic subtree (the one walk up the tree).
    pub fn in_subtree(&self, root: usize, mut body: usize) -> bool {
        let parent = self.body_parentid();
        loop {
            if body == root {
                return true;
            }
            if body == 0 {
                return false;
            }
            body = parent[body] as usize;
        }
    }

    /// The bodies of the kinematic subtree rooted at `root` (itself included), in body order:
    /// e.g. a whole robot from its root body, or a gripper from its hand.
    pub fn subtree(&self, root: usize) -> Vec<usize> {
        (0..self.nbody()).filter(|&b| self.in_subtree(root, b)).collect()
    }

    /// The free joint (the floating base), if the model has one: the first in joint order.
    pub fn free_joint(&self) -> Option<FreeJoint> {
        (0..self.njnt()).find(|&j| self.joint_type(j) == JointType::Free).map(|j| FreeJoint {
            joint: j,
            body: self.jnt_bodyid()[j] as usize,
            qpos_adr: self.jnt_qposadr()[j] as usize,
            dof: self.jnt_dofadr()[j] as usize,
        })
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
        matches!(self.sensor_kind(id), SensorType::Gyro | SensorType::Accelerometer)
    }

    /// Geometric type of geom `id`.
    pub fn geom_kind(&self, id: usize) -> GeomType {
        GeomType::from_raw(self.geom_type()[id])
    }

    /// What sensor `id` measures.
    pub fn sensor_kind(&self, id: usize) -> SensorType {
        SensorType::from_raw(self.sensor_type()[id])
    }

    /// The kind of object sensor `id` is attached to, when it is one [`ObjType`] names.
    pub fn sensor_object(&self, id: usize) -> Option<ObjType> {
        ObjType::from_raw(self.sensor_objtype()[id])
    }

    /// How actuator `id` transmits its force.
    pub fn actuator_transmission(&self, id: usize) -> Transmission {
        Transmission::from_raw(self.actuator_trntype()[id])
    }

    /// Actuator `id`'s bias force type.
    pub fn actuator_bias(&self, id: usize) -> BiasType {
        BiasType::from_raw(self.actuator_biastype()[id])
    }

    /// Actuator `id`'s activation dynamics type (`Dcmotor` for a `dcmotor`).
    pub fn actuator_dyn(&self, id: usize) -> DynType {
        DynType::from_raw(self.actuator_dyntype()[id])
    }

    /// Actuator `id`'s torque–speed envelope `(stall force, no-load speed)` in actuator space
    /// (N·m or N, rad/s or m/s per unit gear) when it is a `dcmotor` whose driver clamps its
    /// voltage (`controller` Vmax): `τ_s = K·Vmax/R`, `ω₀ = Vmax/K`.
    pub fn actuator_envelope(&self, id: usize) -> Option<(f64, f64)> {
        if self.actuator_dyn(id) != DynType::Dcmotor {
            return None;
        }
        let p = self.actuator_gainprm()[id];
        let (r, k, vmax) = (p[0], p[1], p[7]);
        (r > 0.0 && k > 0.0 && vmax > 0.0).then(|| (k * vmax / r, vmax / k))
    }

    /// The numerical integrator.
    pub fn integrator(&self) -> Integrator {
        Integrator::from_raw(self.raw().opt.integrator)
    }

    /// Custom text elements (`<custom><text name="…" data="…"/>`), `(name, data)` in model
    /// order; an element whose bytes are not UTF-8 reads as empty.
    pub fn custom_texts(&self) -> Vec<(&str, &str)> {
        let m = self.raw();
        let n = m.ntext as usize;
        // SAFETY: MuJoCo allocates text_adr and text_size with ntext ints each, and text_data
        // with ntextdata bytes; the model is immutable while self is borrowed.
        let (adr, size, data) = unsafe {
            (
                raw_slice(m.text_adr as *const c_int, n),
                raw_slice(m.text_size as *const c_int, n),
                raw_slice(m.text_data as *const u8, m.ntextdata as usize),
            )
        };
        (0..n)
            .map(|i| {
                let (a, len) = (adr[i].max(0) as usize, size[i].max(0) as usize);
                let bytes = data.get(a..(a + len).min(data.len())).unwrap_or(&[]);
                // text_size counts the terminating NUL.
                let bytes = bytes.split(|&b| b == 0).next().unwrap_or(&[]);
                (self.raw_name(sys::mjtObj_mjOBJ_TEXT, i), std::str::from_utf8(bytes).unwrap_or(""))
            })
            .collect()
    }

    /// Custom numeric elements (`<custom><numeric name="…" data="…"/>`), `(name, values)` in
    /// model order.
    pub fn custom_numerics(&self) -> Vec<(&str, &[f64])> {
        let m = self.raw();
        let n = m.nnumeric as usize;
        // SAFETY: MuJoCo allocates numeric_adr and numeric_size with nnumeric ints each and
        // numeric_data with nnumericdata values; the model is immutable while self is borrowed.
        let (adr, size, data) = unsafe {
            (
                raw_slice(m.numeric_adr as *const c_int, n),
                raw_slice(m.numeric_size as *const c_int, n),
                raw_slice(m.numeric_data as *const f64, m.nnumericdata as usize),
            )
        };
        (0..n)
            .map(|i| {
                let (a, len) = (adr[i].max(0) as usize, size[i].max(0) as usize);
                (self.raw_name(sys::mjtObj_mjOBJ_NUMERIC, i), data.get(a..(a + len).min(data.len())).unwrap_or(&[]))
            })
            .collect()
    }

    /// Name of object `id` of raw kind `obj` (caller keeps `id` in range).
    fn raw_name(&self, obj: sys::mjtObj, id: usize) -> &str {
        // SAFETY: id is in range (callers iterate the object's count); the pointer is into the
        // model's name buffer, which lives as long as self.
        let p = unsafe { sys::mj_id2name(self.as_ptr(), obj as c_int, id as c_int) };
        if p.is_null() {
            return "";
        }
        // SAFETY: MuJoCo names are NUL-terminated; the buffer outlives the borrow of self.
        unsafe { CStr::from_ptr(p) }.to_str().unwrap_or("")
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

    /// The model's own name (`<mujoco model="…">`, the URDF's `<robot name>`); empty when
    /// unnamed.
    pub fn model_name(&self) -> &str {
        // The model's name is the first string of the name buffer (mjModel.names).
        let p = self.raw().names;
        if p.is_null() || self.raw().nnames == 0 {
            return "";
        }
        // SAFETY: MuJoCo names are NUL-terminated; the buffer outlives the borrow of self.
        unsafe { CStr::from_ptr(p) }.to_str().unwrap_or("")
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
