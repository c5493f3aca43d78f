//! The robot as the identification sees it: MuJoCo's compile of the URDF (the twin's own
//! kinematics), the identified joints (1-DOF joints matched to the log by name), the moving
//! links, and their CAD parameters in the standard (Pinocchio) order.

use crate::error::{Error, Result};
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use twin_core::mj::{JointType, Model, ObjType};

/// Number of standard inertial parameters per link.
pub const LINK_PARAMS: usize = 10;

/// Names of the standard parameters of a link, in Pinocchio's order: mass, first moment
/// `h = m·c`, inertia about the link frame origin.
pub const LINK_PARAM_NAMES: [&str; LINK_PARAMS] = ["m", "hx", "hy", "hz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"];

/// Standard parameters of one link: `[m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]` (kg, kg·m,
/// kg·m²), the inertia `Ī` about the link frame's origin, in the link frame.
pub type LinkParams = [f64; LINK_PARAMS];

/// Mass, centre of mass (link frame, m) and inertia about the centre of mass (link frame axes,
/// kg·m²): the form URDF stores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the link frame, metres.
    pub com_link: Vector3<f64>,
    /// Inertia about the centre of mass, link frame axes, kg·m².
    pub inertia_com: Matrix3<f64>,
}

impl MassProperties {
    /// Standard parameters (parallel-axis theorem to the frame origin).
    pub fn to_params(&self) -> LinkParams {
        let m = self.mass_kg;
        let c = self.com_link;
        let i = self.inertia_com + m * (c.norm_squared() * Matrix3::identity() - c * c.transpose());
        let h = m * c;
        [m, h.x, h.y, h.z, i[(0, 0)], i[(0, 1)], i[(1, 1)], i[(0, 2)], i[(1, 2)], i[(2, 2)]]
    }

    /// From standard parameters; `None` for a non-positive mass.
    pub fn from_params(p: &LinkParams) -> Option<MassProperties> {
        let m = p[0];
        if m.is_nan() || m <= 0.0 {
            return None;
        }
        let c = Vector3::new(p[1], p[2], p[3]) / m;
        let ibar = inertia_matrix(p);
        let i = ibar - m * (c.norm_squared() * Matrix3::identity() - c * c.transpose());
        Some(MassProperties { mass_kg: m, com_link: c, inertia_com: i })
    }
}

/// The 3×3 inertia `Ī` of standard parameters.
pub fn inertia_matrix(p: &LinkParams) -> Matrix3<f64> {
    Matrix3::new(p[4], p[5], p[7], p[5], p[6], p[8], p[7], p[8], p[9])
}

/// Pseudo-inertia `J = [[Σ, h], [hᵀ, m]]`, `Σ = ½ tr(Ī)·1 − Ī`: positive definite exactly when
/// the link is physically realisable (Wensing, Kim, Slotine 2017).
pub fn pseudo_inertia(p: &LinkParams) -> nalgebra::Matrix4<f64> {
    let ibar = inertia_matrix(p);
    let sigma = 0.5 * ibar.trace() * Matrix3::identity() - ibar;
    let mut j = nalgebra::Matrix4::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&sigma);
    j[(0, 3)] = p[1];
    j[(1, 3)] = p[2];
    j[(2, 3)] = p[3];
    j[(3, 0)] = p[1];
    j[(3, 1)] = p[2];
    j[(3, 2)] = p[3];
    j[(3, 3)] = p[0];
    j
}

/// Standard parameters of a pseudo-inertia.
pub fn params_from_pseudo_inertia(j: &nalgebra::Matrix4<f64>) -> LinkParams {
    let sigma = j.fixed_view::<3, 3>(0, 0).into_owned();
    let ibar = sigma.trace() * Matrix3::identity() - sigma;
    [
        j[(3, 3)],
        j[(0, 3)],
        j[(1, 3)],
        j[(2, 3)],
        ibar[(0, 0)],
        ibar[(0, 1)],
        ibar[(1, 1)],
        ibar[(0, 2)],
        ibar[(1, 2)],
        ibar[(2, 2)],
    ]
}

/// Whether a link's parameters are physically valid (pseudo-inertia positive definite, i.e.
/// mass > 0, inertia about the CoM positive definite, triangle inequalities hold).
pub fn physically_valid(p: &LinkParams) -> bool {
    pseudo_inertia(p).cholesky().is_some()
}

/// One identified joint: a 1-DOF joint of the model, matched to the log by name.
#[derive(Debug, Clone)]
pub struct JointInfo {
    /// Joint name (URDF and log).
    pub name: String,
    /// MuJoCo DOF index.
    pub dof: usize,
    /// MuJoCo qpos address.
    pub qpos_adr: usize,
    /// URDF `<dynamics damping>` as compiled (N·m·s/rad).
    pub damping: f64,
    /// URDF `<dynamics friction>` as compiled (MuJoCo `frictionloss`, N·m).
    pub friction: f64,
    /// Armature of the model (URDF has none: 0).
    pub armature: f64,
}

/// One moving link: a body moved by at least one identified joint.
#[derive(Debug, Clone)]
pub struct LinkInfo {
    /// Link (body) name.
    pub name: String,
    /// MuJoCo body id.
    pub body: usize,
    /// Identified joints (indices into [`RobotModel::joints`]) that move this link.
    pub ancestor_joints: Vec<usize>,
    /// CAD parameters of the body as the twin runs it (from the URDF): the link's own inertial
    /// plus those of the fixed-joint links the converter lumps into it.
    pub cad: LinkParams,
    /// The part of [`LinkInfo::cad`] that belongs to fixed-joint links lumped into this body
    /// (standard parameters in this body's frame; zero when none): the URDF keeps them on their
    /// own links, so the write-back subtracts them (see [`LinkInfo::own_params`]).
    pub welded: LinkParams,
    /// Moved by the floating base (in the free joint's subtree): its wrench shows in the base
    /// rows. Always `false` for a fixed base.
    pub floating: bool,
}

impl LinkInfo {
    /// The URDF link's own share of body parameters `body` (identified or CAD): `body` less
    /// the fixed-joint links lumped into it, which keep their URDF values.
    pub fn own_params(&self, body: &LinkParams) -> LinkParams {
        std::array::from_fn(|i| body[i] - self.welded[i])
    }
}

/// The free joint of a floating-base robot (MuJoCo's convention: `qpos` = position (m, world)
/// then orientation quaternion `w x y z` (world_from_base); `qvel` = linear velocity of the base
/// origin (world frame, m/s) then angular velocity (base frame, rad/s)).
#[derive(Debug, Clone)]
pub struct FloatingBase {
    /// The base link (root link of the URDF).
    pub name: String,
    /// MuJoCo body id of the base link.
    pub body: usize,
    /// First of the free joint's 6 DOFs.
    pub dof: usize,
    /// First of the free joint's 7 qpos entries.
    pub qpos_adr: usize,
}

/// Name of the free joint twin adds to the root link for floating-base identification.
pub const FLOATING_JOINT: &str = "twin_floating_base";

/// The robot model used for identification.
#[derive(Debug, Clone)]
pub struct RobotModel {
    /// The URDF file.
    pub urdf_path: PathBuf,
    /// The twin's compile of the URDF.
    pub model: Arc<Model>,
    /// 1-DOF joints, in MuJoCo DOF order.
    pub joints: Vec<JointInfo>,
    /// Moving links, in MuJoCo body order.
    pub links: Vec<LinkInfo>,
    /// The free joint when the base is floating (`None`: fixed base).
    pub floating: Option<FloatingBase>,
}

/// The root link of a URDF: the one link that is no joint's child.
fn root_link(path: &Path, text: &str) -> Result<String> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: e.to_string() })?;
    let root = doc.root_element();
    let children: Vec<&str> = root
        .children()
        .filter(|n| n.has_tag_name("joint"))
        .filter_map(|j| j.children().find(|c| c.has_tag_name("child")).and_then(|c| c.attribute("link")))
        .collect();
    let roots: Vec<&str> = root
        .children()
        .filter(|n| n.has_tag_name("link"))
        .filter_map(|l| l.attribute("name"))
        .filter(|name| !children.contains(name))
        .collect();
    match roots.as_slice() {
        [one] if *one == "world" => Err(Error::Urdf {
            path: path.to_path_buf(),
            message: "the URDF attaches its root to a link named \"world\": the base is fixed there, so \
                      --base floating does not apply; identify it with --base fixed"
                .into(),
        }),
        [one] => Ok(one.to_string()),
        _ => Err(Error::Urdf {
            path: path.to_path_buf(),
            message: format!("expected exactly one root link (a link that is no joint's child), found {}", roots.len()),
        }),
    }
}

/// Standard parameters of body `b` as the model holds them.
fn cad_params_of_body(model: &Model, b: usize) -> LinkParams {
    let q = model.body_iquat()[b];
    let rot =
        UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3])).to_rotation_matrix().into_inner();
    let d = model.body_inertia()[b];
    let inertia_com = rot * Matrix3::from_diagonal(&Vector3::new(d[0], d[1], d[2])) * rot.transpose();
    let ipos = model.body_ipos()[b];
    MassProperties { mass_kg: model.body_mass()[b], com_link: Vector3::new(ipos[0], ipos[1], ipos[2]), inertia_com }
        .to_params()
}

/// Whether body `b` holds inertia of its own in the model the twin runs: it moves by a joint
/// of its own, or carries mass. A massless body welded to its parent (a fixed-joint link whose
/// URDF mass the converter lumped into the body that moves it, or a massless frame such as the
/// UR5's `ee_link` and `tool0`) has no parameters: its regressor columns would copy its
/// parent's, and its zero pseudo-inertia would sit on the boundary of physical validity.
fn carries_inertia(model: &Model, b: usize) -> bool {
    model.body_dofnum()[b] > 0 || model.body_mass()[b] > 0.0
}

/// The links' own inertials ([`urdf_own_params`]) of the file at `path` when it is a readable
/// URDF; a model compiled from something else (an MJCF given to [`RobotModel::from_model`]) has
/// no URDF links to split its bodies into: empty.
///
/// # Errors
/// [`Error::Urdf`] for a URDF that is not well-formed XML.
fn file_own_params(path: &Path) -> Result<OwnParams> {
    match twin_core::fsio::read_to_string(path) {
        Ok(text) => urdf_own_params(path, &text),
        Err(_) => Ok(OwnParams::new()),
    }
}

/// Each link's own `<inertial>` in URDF `text` (of `path`), as standard parameters in its link
/// frame (links without one, or with no mass, are absent); empty when `text` is not a URDF.
///
/// # Errors
/// [`Error::Urdf`] for a URDF that is not well-formed XML.
fn urdf_own_params(path: &Path, text: &str) -> Result<OwnParams> {
    let mut own = OwnParams::new();
    if !twin_core::urdf::is_urdf(text) {
        return Ok(own);
    }
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: e.to_string() })?;
    let triplet = |s: Option<&str>| -> [f64; 3] {
        let mut out = [0.0; 3];
        for (o, v) in out.iter_mut().zip(s.unwrap_or("").split_whitespace()) {
            *o = v.parse().unwrap_or(0.0);
        }
        out
    };
    let num = |n: Option<roxmltree::Node<'_, '_>>, attr: &str| -> f64 {
        n.and_then(|n| n.attribute(attr)).and_then(|v| v.trim().parse().ok()).unwrap_or(0.0)
    };
    for link in doc.root_element().children().filter(|n| n.has_tag_name("link")) {
        let (Some(name), Some(inertial)) =
            (link.attribute("name"), link.children().find(|c| c.has_tag_name("inertial")))
        else {
            continue;
        };
        let child = |tag: &str| inertial.children().find(|c| c.has_tag_name(tag));
        let mass_kg = num(child("mass"), "value");
        if mass_kg.is_nan() || mass_kg <= 0.0 {
            continue;
        }
        let origin = child("origin");
        let xyz = triplet(origin.and_then(|o| o.attribute("xyz")));
        let rpy = triplet(origin.and_then(|o| o.attribute("rpy")));
        let i = child("inertia");
        let (ixx, ixy, ixz, iyy, iyz, izz) =
            (num(i, "ixx"), num(i, "ixy"), num(i, "ixz"), num(i, "iyy"), num(i, "iyz"), num(i, "izz"));
        let inertial_axes = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
        // URDF rpy: fixed-axis roll about x, pitch about y, yaw about z.
        let link_from_inertial = nalgebra::Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        let inertia_com = link_from_inertial.matrix() * inertial_axes * link_from_inertial.matrix().transpose();
        let mp = MassProperties { mass_kg, com_link: Vector3::new(xyz[0], xyz[1], xyz[2]), inertia_com };
        own.insert(name.to_string(), mp.to_params());
    }
    Ok(own)
}

/// The share of body `name`'s parameters `cad` that the converter lumped in from fixed-joint
/// links: `cad` less the link's own URDF inertial. Zero when the masses agree (nothing was
/// lumped; the difference is then the MJCF's rounding or a converter repair, which belongs to
/// the link).
fn welded_params(own: &OwnParams, name: &str, cad: &LinkParams) -> LinkParams {
    let own = own.get(name).copied().unwrap_or([0.0; LINK_PARAMS]);
    if (cad[0] - own[0]).abs() <= 1e-9 * cad[0].abs().max(1e-12) {
        return [0.0; LINK_PARAMS];
    }
    std::array::from_fn(|i| cad[i] - own[i])
}

/// Each URDF link's own inertial parameters, by link name ([`urdf_own_params`]).
type OwnParams = std::collections::HashMap<String, LinkParams>;

/// A URDF as sysid reads it: its path and its text, read once. The model twin runs is
/// converted from this text ([`twin_core::robot::Robot::load_str_with_extra`], the one path
/// from a robot file to a robot), and the checks sysid makes of the file (its root link, no
/// `<mujoco>` block of its own) and the links' own inertials ([`RobotModel::of_urdf`]) read the
/// same text.
#[derive(Debug, Clone)]
pub struct UrdfSource {
    /// The file.
    pub path: PathBuf,
    /// Its text.
    pub text: String,
}

impl UrdfSource {
    /// Reads the URDF at `path`.
    ///
    /// # Errors
    /// [`Error::Core`] when the file can't be read.
    pub fn read(path: &Path) -> Result<UrdfSource> {
        Ok(UrdfSource { path: path.to_path_buf(), text: twin_core::fsio::read_to_string(path)? })
    }

    /// The model as [`load_urdf_in_mujoco`] (`floating` false) or
    /// [`load_urdf_in_mujoco_floating`] (true) compile it.
    ///
    /// # Errors
    /// As those.
    pub fn model(&self, extra_mujoco: &str, floating: bool) -> Result<Model> {
        let robot = self.robot(extra_mujoco, floating, false)?;
        Ok(Arc::try_unwrap(robot.model).unwrap_or_else(|shared| (*shared).clone()))
    }

    /// Converts the text and compiles it with `extra_mujoco` appended inside `<mujoco>`, fixed
    /// base unless `floating` (then the root link must not be `world`), with self-collision
    /// when `self_collision`; twin's [`twin_core::robot::Robot`] view of it.
    ///
    /// # Errors
    /// [`Error::Urdf`] for malformed XML, a `<mujoco>` block of the URDF's own, or (floating) a
    /// root link named `world`; the converter's and MuJoCo's errors.
    pub fn robot(&self, extra_mujoco: &str, floating: bool, self_collision: bool) -> Result<twin_core::robot::Robot> {
        let path = self.path.as_path();
        let doc = roxmltree::Document::parse(&self.text)
            .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: e.to_string() })?;
        if doc.root_element().children().any(|n| n.has_tag_name("mujoco")) {
            return Err(Error::Urdf {
                path: path.to_path_buf(),
                message: "the URDF has its own <mujoco> block; remove it for `twin sysid` (it may fuse links and hide their inertias)".into(),
            });
        }
        if floating {
            root_link(path, &self.text)?;
        }
        let options = twin_core::convert::ConvertOptions {
            fixed_base: !floating,
            floor: false,
            visuals: false,
            joint_sensors: false,
            self_collision,
            ..twin_core::convert::ConvertOptions::default()
        };
        Ok(twin_core::robot::Robot::load_str_with_extra(path, &self.text, &options, extra_mujoco)?)
    }
}

/// As [`load_urdf_in_mujoco`], with a free joint between the world and the URDF's root link
/// (the converter's `floating_base`), which then moves with the logged base motion.
///
/// # Errors
/// As [`load_urdf_in_mujoco`]; [`Error::Urdf`] when the root link is `world`.
pub fn load_urdf_in_mujoco_floating(path: &Path, extra_mujoco: &str) -> Result<Model> {
    UrdfSource::read(path)?.model(extra_mujoco, true)
}

/// Compiles a URDF the way the twin runs it: through twin's converter
/// (`twin_core::robot::Robot::load_with`, which resolves `package://` meshes and converts
/// Collada/ASCII STL), fixed base, no floor, no visuals, fixed-joint links' inertia lumped
/// into the body that moves them (as every command runs the robot), with
/// `extra_mujoco` (MJCF elements such as `<option>`) added to the model.
///
/// # Errors
/// [`Error::Core`]; the converter's errors (naming the file, line and element); MuJoCo's load
/// error.
pub fn load_urdf_in_mujoco(path: &Path, extra_mujoco: &str) -> Result<Model> {
    UrdfSource::read(path)?.model(extra_mujoco, false)
}

/// As [`load_urdf_in_mujoco`] (fixed base), with the robot's links colliding with each other
/// when `self_collision`, and twin's [`twin_core::robot::Robot`] view of it (joint limits,
/// actuators) kept: for designing trajectories that respect the limits and avoid
/// self-collision (`twin excite`).
///
/// # Errors
/// As [`load_urdf_in_mujoco`].
pub fn load_urdf_robot(path: &Path, self_collision: bool) -> Result<twin_core::robot::Robot> {
    UrdfSource::read(path)?.robot("", false, self_collision)
}

impl RobotModel {
    /// Loads `urdf` for identification.
    ///
    /// # Errors
    /// As [`load_urdf_in_mujoco`]; [`Error::Urdf`] if the robot has no 1-DOF joint.
    pub fn from_urdf(urdf: impl AsRef<Path>) -> Result<RobotModel> {
        let source = UrdfSource::read(urdf.as_ref())?;
        let model = source.model("", false)?;
        RobotModel::of_urdf(&source, Arc::new(model), false)
    }

    /// Loads `urdf` with a floating base: a free joint ([`FLOATING_JOINT`]) between the world
    /// and the URDF's root link, which then moves with the logged base motion and whose inertia
    /// is identified too.
    ///
    /// # Errors
    /// As [`RobotModel::from_urdf`]; [`Error::Urdf`] when the root link is `world` (fixed).
    pub fn from_urdf_floating(urdf: impl AsRef<Path>) -> Result<RobotModel> {
        let source = UrdfSource::read(urdf.as_ref())?;
        let model = source.model("", true)?;
        RobotModel::of_urdf(&source, Arc::new(model), true)
    }

    /// Wraps a model compiled from `source` (as [`UrdfSource::model`] compiles it, possibly
    /// edited), the links' own inertials read from the same text; `floating` as
    /// [`RobotModel::from_model_floating`].
    ///
    /// # Errors
    /// As [`RobotModel::from_model`] and [`RobotModel::from_model_floating`].
    pub fn of_urdf(source: &UrdfSource, model: Arc<Model>, floating: bool) -> Result<RobotModel> {
        let own = urdf_own_params(&source.path, &source.text)?;
        RobotModel::with_own_params(&source.path, model, &own, floating)
    }

    /// Wraps a compiled model whose base link hangs from the world by a free joint: the free
    /// joint's subtree is identified as a floating base.
    ///
    /// # Errors
    /// [`Error::Urdf`] if the model has no free joint or no 1-DOF joint.
    pub fn from_model_floating(urdf_path: &Path, model: Arc<Model>) -> Result<RobotModel> {
        RobotModel::with_own_params(urdf_path, model, &file_own_params(urdf_path)?, true)
    }

    /// [`RobotModel::fixed`] of `model`, and with `floating` the free joint's subtree as a
    /// floating base; `own`: the links' own URDF inertials.
    fn with_own_params(urdf_path: &Path, model: Arc<Model>, own: &OwnParams, floating: bool) -> Result<RobotModel> {
        let mut robot = RobotModel::fixed(urdf_path, model.clone(), own)?;
        if !floating {
            return Ok(robot);
        }
        let free = model.free_joint().ok_or_else(|| Error::Urdf {
            path: urdf_path.to_path_buf(),
            message: "the model has no free joint for a floating base".into(),
        })?;
        let body = free.body;
        let mut links = Vec::new();
        let mut existing = std::mem::take(&mut robot.links).into_iter().peekable();
        for b in 1..model.nbody() {
            let known = existing.next_if(|l| l.body == b);
            let floating = model.in_subtree(body, b);
            match known {
                Some(mut l) => {
                    l.floating = floating;
                    links.push(l);
                }
                None if floating && carries_inertia(&model, b) => {
                    let name = model.name(ObjType::Body, b).to_string();
                    let cad = cad_params_of_body(&model, b);
                    let welded = welded_params(own, &name, &cad);
                    links.push(LinkInfo { name, body: b, ancestor_joints: Vec::new(), cad, welded, floating: true });
                }
                None => {}
            }
        }
        robot.links = links;
        robot.floating = Some(FloatingBase {
            name: model.name(ObjType::Body, body).to_string(),
            body,
            dof: free.dof,
            qpos_adr: free.qpos_adr,
        });
        Ok(robot)
    }

    /// Wraps an already compiled model of `urdf_path` (for callers that compile it themselves).
    ///
    /// # Errors
    /// [`Error::Urdf`] if the robot has no 1-DOF joint.
    pub fn from_model(urdf_path: &Path, model: Arc<Model>) -> Result<RobotModel> {
        RobotModel::with_own_params(urdf_path, model, &file_own_params(urdf_path)?, false)
    }

    /// The fixed-base view of `model`: its 1-DOF joints and the links they move; `own`: the
    /// links' own URDF inertials.
    fn fixed(urdf_path: &Path, model: Arc<Model>, own: &OwnParams) -> Result<RobotModel> {
        let mut joints = Vec::new();
        let mut joint_of_dof = vec![None; model.nv()];
        for j in 0..model.njnt() {
            if matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
                let dof = model.jnt_dofadr()[j] as usize;
                joint_of_dof[dof] = Some(joints.len());
                joints.push(JointInfo {
                    name: model.name(ObjType::Joint, j).to_string(),
                    dof,
                    qpos_adr: model.jnt_qposadr()[j] as usize,
                    damping: model.dof_damping()[dof],
                    friction: model.dof_frictionloss()[dof],
                    armature: model.dof_armature()[dof],
                });
            }
        }
        if joints.is_empty() {
            return Err(Error::Urdf {
                path: urdf_path.to_path_buf(),
                message: "the robot has no revolute or prismatic joint to identify".into(),
            });
        }
        let mut links = Vec::new();
        let parent = model.body_parentid();
        for b in 1..model.nbody() {
            let mut ancestor_joints = Vec::new();
            let mut k = b;
            while k != 0 {
                let (adr, num) = (model.body_dofadr()[k], model.body_dofnum()[k]);
                for d in 0..num.max(0) {
                    if let Some(j) = joint_of_dof[(adr + d) as usize] {
                        ancestor_joints.push(j);
                    }
                }
                k = parent[k] as usize;
            }
            if ancestor_joints.is_empty() || !carries_inertia(&model, b) {
                continue;
            }
            ancestor_joints.sort_unstable();
            let name = model.name(ObjType::Body, b).to_string();
            let cad = cad_params_of_body(&model, b);
            let welded = welded_params(own, &name, &cad);
            links.push(LinkInfo { name, body: b, ancestor_joints, cad, welded, floating: false });
        }
        Ok(RobotModel { urdf_path: urdf_path.to_path_buf(), model, joints, links, floating: None })
    }

    /// Index of joint `name` among [`RobotModel::joints`].
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_round_trip_through_mass_properties_and_pseudo_inertia() {
        let mp = MassProperties {
            mass_kg: 2.5,
            com_link: Vector3::new(0.1, -0.02, 0.3),
            inertia_com: Matrix3::new(0.02, 0.001, -0.002, 0.001, 0.03, 0.0005, -0.002, 0.0005, 0.015),
        };
        let p = mp.to_params();
        // Pinocchio order: Ixy is entry 5, Iyy entry 6, Ixz entry 7.
        let ibar = inertia_matrix(&p);
        let c = mp.com_link;
        let expected = mp.inertia_com + 2.5 * (c.norm_squared() * Matrix3::identity() - c * c.transpose());
        assert!((ibar - expected).norm() < 1e-15);
        assert_eq!(p[5], ibar[(0, 1)]);
        assert_eq!(p[7], ibar[(0, 2)]);
        let back = MassProperties::from_params(&p).unwrap();
        assert!((back.com_link - mp.com_link).norm() < 1e-15);
        assert!((back.inertia_com - mp.inertia_com).norm() < 1e-15);
        let p2 = params_from_pseudo_inertia(&pseudo_inertia(&p));
        for (a, b) in p.iter().zip(p2) {
            assert!((a - b).abs() < 1e-15);
        }
        assert!(physically_valid(&p));
        // A point mass far out with too little inertia about the origin is not realisable.
        let mut bad = p;
        bad[4] = 0.0;
        assert!(!physically_valid(&bad));
    }
}
