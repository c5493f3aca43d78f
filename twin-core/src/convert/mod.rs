//! URDF (+ Gazebo extensions, transmissions, `ros2_control`) → MuJoCo MJCF, with nothing
//! silently lost: what has no MuJoCo equivalent is listed in [`ConvertedModel::notes`].
//!
//! ```no_run
//! use twin_core::convert::{convert_urdf, ConvertOptions};
//! let out = convert_urdf("models/humanoid.urdf".as_ref(), &ConvertOptions::default())?;
//! println!("{} IMUs, topic {:?}", out.imus.len(), out.imus[0].topic);
//! let model = twin_core::mj::Model::from_xml_str(&out.mjcf)?;
//! # Ok::<(), twin_core::Error>(())
//! ```
//!
//! ## What the generated model contains
//! - One `body` per link, names kept (fixed-joint children stay bodies: `fusestatic="false"`),
//!   `inertial pos fullinertia` from the URDF inertial (rotated origin applied), no inertia from
//!   geometry (`inertiafromgeom="false"`).
//! - The root link gets a free joint named `floating_base` unless the URDF attaches it to a
//!   `world` link or [`ConvertOptions::fixed_base`] is set. The root is placed so that the lowest
//!   collision geom touches the floor (z = 0) at the zero joint pose, and keyframe `home` stores
//!   that pose (the nominal standing pose for controllers).
//! - Joints: revolute → hinge with range, continuous → unlimited hinge, prismatic → slide,
//!   spherical → ball, planar → two slides (`<joint>_tx`, `<joint>_ty`) + hinge, floating → free;
//!   `<dynamics damping friction>` → `damping` / `frictionloss`; effort → `actuatorfrcrange`;
//!   velocity limits are kept in [`JointMeta`]; `<mimic>` → `<equality joint polycoef>`.
//! - Actuators, one per joint named in a `SimpleTransmission` or `ros2_control` block, named
//!   after the joint: effort → `motor` (`forcerange` = `ctrlrange` = ±effort/gear), position →
//!   `position` (kp = [`ConvertOptions::position_kp_per_effort`] × effort), velocity →
//!   `velocity`; `mechanicalReduction` → `gear`, so `ctrl` is in actuator (motor-side) units.
//! - Sensors: every 1-DOF joint gets `<joint>_pos` (`jointpos`) and `<joint>_vel` (`jointvel`)
//!   when [`ConvertOptions::joint_sensors`]; Gazebo IMU → site + `<imu>_quat` (`framequat`),
//!   `<imu>_gyro`, `<imu>_accel` with the plugin's noise stored as `noise` (MuJoCo does not apply
//!   it); camera → `camera` (Gazebo +X view axis turned to MuJoCo's −Z); ray/lidar → replicated
//!   sites with `rangefinder` (`cutoff` = max range); force_torque on a joint → site in the child
//!   body + `<name>_force` / `<name>_torque`; contact → `touch` on a site covering the link's
//!   first collision geom.
//! - Contacts: robot collision geoms have `contype=2 conaffinity=1`, so they touch the floor and
//!   world objects (`1/1`) but not each other (Gazebo's default); `selfCollide` links and
//!   [`ConvertOptions::self_collision`] add bit 4. Gazebo `mu1`/`mu2` → `friction`; since MuJoCo
//!   takes the max of two geoms' friction and Gazebo the min, every geom gets a `priority` that
//!   ranks lower friction higher, which reproduces the min.
//! - `<option integrator="implicitfast">` (stable with stiff PD gains and joint damping),
//!   timestep [`ConvertOptions::timestep_secs`], no default armature (URDF has none; see
//!   [`ConvertOptions::armature`]).
//!
//! ## Limitations
//! Gazebo `kp`/`kd` contact stiffness, anisotropic friction (`mu1` ≠ `mu2` uses the smaller),
//! `safety_controller`, `calibration`, non-simple transmissions and Gazebo plugins other than
//! sensors and ros2_control are not converted; each is listed in the notes. Collada `up_axis`
//! and materials are ignored (geometry and `<unit>` are honoured).

mod ir;
mod mesh;
mod world;

pub use ir::Interface;

use crate::error::{Error, Result};
use crate::mj::{JointType, Model, ObjType};
use ir::{Ctx, GeomIr, JointIr, JointKind, LinkIr, Pose, RobotIr, SensorIr, Shape};
use nalgebra::{Matrix3, SymmetricEigen, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Options of the conversion. Every field documents its default.
#[derive(Debug, Clone)]
pub struct ConvertOptions {
    /// Weld the root link to the world instead of giving it a free joint (default: false).
    pub fixed_base: bool,
    /// Folders to search for `package://NAME/…` (a folder `NAME`, or one with a `package.xml`
    /// naming it, directly inside one of these); `ROS_PACKAGE_PATH` and the URDF's ancestor
    /// folders are searched after them (default: empty).
    pub package_paths: Vec<PathBuf>,
    /// Fix inertias that are not positive definite or violate the triangle inequality by the
    /// smallest change of principal moments, reported in the notes; otherwise they are errors
    /// (default: false).
    pub repair_inertia: bool,
    /// Where meshes converted to OBJ are written (default: `None`: a cache folder in the
    /// system temp dir, keyed by the source file).
    pub mesh_dir: Option<PathBuf>,
    /// Gazebo SDF world or MJCF file composed with the robot (default: `None`: a floor plane and
    /// a light, see [`ConvertOptions::floor`]).
    pub world: Option<PathBuf>,
    /// Add a floor plane and a light when no world is given (default: true).
    pub floor: bool,
    /// Let robot links collide with each other (default: false, as in Gazebo).
    pub self_collision: bool,
    /// Keep visual geoms (group 2, no contacts) (default: true).
    pub visuals: bool,
    /// Add `jointpos`/`jointvel` sensors for every 1-DOF joint (default: true).
    pub joint_sensors: bool,
    /// Simulation timestep, seconds (default: 0.002, Gazebo's `max_step_size`; a world file's
    /// own step wins).
    pub timestep_secs: f64,
    /// Armature (reflected rotor inertia) added to every joint, kg·m² or kg (default: 0).
    pub armature: f64,
    /// Armature of individual joints by URDF joint name, kg·m² or kg, replacing
    /// [`ConvertOptions::armature`] for those joints (e.g. identified by `twin sysid`; URDF has
    /// no place for it) (default: empty).
    pub joint_armature: std::collections::BTreeMap<String, f64>,
    /// Stiffness of `position` actuators per N·m of effort limit, 1/rad: kp = this × effort
    /// (default: 20, full effort at 0.05 rad error; 100 N·m/rad when no effort is given).
    pub position_kp_per_effort: f64,
    /// Damping of `position` actuators as a fraction of kp, seconds: kv = this × kp
    /// (default: 0.05).
    pub position_kv_per_kp: f64,
    /// Gain of `velocity` actuators per N·m of effort limit, s/rad (default: 1; 10 when no
    /// effort is given).
    pub velocity_kv_per_effort: f64,
    /// Actuator for movable joints that no transmission or ros2_control block names
    /// (default: `None`: they stay passive, listed in the notes).
    pub untransmitted: Option<Interface>,
    /// At most this many rangefinder rays per ray/lidar sensor; denser scans are subsampled
    /// evenly, said in the notes (default: 32).
    pub max_rays: usize,
}

impl Default for ConvertOptions {
    fn default() -> Self {
        ConvertOptions {
            fixed_base: false,
            package_paths: Vec::new(),
            repair_inertia: false,
            mesh_dir: None,
            world: None,
            floor: true,
            self_collision: false,
            visuals: true,
            joint_sensors: true,
            timestep_secs: 0.002,
            armature: 0.0,
            joint_armature: std::collections::BTreeMap::new(),
            position_kp_per_effort: 20.0,
            position_kv_per_kp: 0.05,
            velocity_kv_per_effort: 1.0,
            untransmitted: None,
            max_rays: 32,
        }
    }
}

/// An IMU of the robot, with what logging and noise models need.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuMeta {
    /// Gazebo sensor name; MuJoCo sensors are `<name>_quat`, `<name>_gyro`, `<name>_accel`.
    pub name: String,
    /// Link the IMU is mounted on.
    pub link: String,
    /// MuJoCo site at the IMU frame (named like the sensor).
    pub site: String,
    /// Publication rate, Hz, when the URDF gives one.
    pub update_rate_hz: Option<f64>,
    /// Gyroscope white-noise standard deviation, rad/s (0 when none).
    pub gyro_noise_std: f64,
    /// Accelerometer white-noise standard deviation, m/s² (0 when none).
    pub accel_noise_std: f64,
    /// ROS topic resolved from the plugin's namespace and remapping (e.g. `/humanoid/imu/data`).
    pub topic: Option<String>,
    /// `frame_id` of the messages (the plugin's `frame_name`, else the link).
    pub frame_id: String,
}

/// A non-IMU sensor (camera, rangefinder, force/torque, contact).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorMeta {
    /// Gazebo sensor name.
    pub name: String,
    /// Gazebo sensor type (`camera`, `ray`, `force_torque`, `contact`, …).
    pub kind: String,
    /// Link (or joint, for force/torque) it refers to.
    pub reference: String,
    /// Publication rate, Hz.
    pub update_rate_hz: Option<f64>,
    /// ROS topic, when a plugin names one.
    pub topic: Option<String>,
    /// Names of the MuJoCo sensors or cameras created for it.
    pub mujoco: Vec<String>,
}

/// A URDF joint as converted.
#[derive(Debug, Clone, PartialEq)]
pub struct JointMeta {
    /// URDF joint name (MuJoCo joint of the same name; planar joints add `_tx`, `_ty`).
    pub name: String,
    /// URDF type (`revolute`, `continuous`, `prismatic`, `fixed`, `floating`, `planar`, `spherical`).
    pub urdf_type: String,
    /// Effort limit, N·m or N (`None` when absent or 0).
    pub effort_limit: Option<f64>,
    /// Velocity limit, rad/s or m/s (`None` when absent or 0).
    pub velocity_limit: Option<f64>,
    /// Position range, when limited.
    pub range: Option<[f64; 2]>,
    /// Actuator driving it (named after the joint), and its command interface.
    pub actuator: Option<(String, Interface)>,
    /// Gear of that actuator (`mechanicalReduction`).
    pub gear: f64,
    /// Leader joint when this joint mimics another.
    pub mimic_of: Option<String>,
}

/// The result of a conversion.
#[derive(Debug, Clone)]
pub struct ConvertedModel {
    /// The MJCF document (mesh files referenced by absolute path).
    pub mjcf: String,
    /// Robot name (`<robot name>`).
    pub robot_name: String,
    /// Whether the root has a free joint.
    pub floating_base: bool,
    /// Height of the root link origin in the `home` pose, metres.
    pub base_height_m: f64,
    /// IMUs.
    pub imus: Vec<ImuMeta>,
    /// Other sensors.
    pub sensors: Vec<SensorMeta>,
    /// Joints in URDF order (fixed joints included).
    pub joints: Vec<JointMeta>,
    /// Everything that was approximated, repaired or dropped, one line each.
    pub notes: Vec<String>,
    /// Mesh files written by the conversion (ASCII STL / Collada → OBJ).
    pub converted_meshes: Vec<PathBuf>,
}

/// Converts the URDF file at `path`.
///
/// # Errors
/// [`Error::Io`] if it can't be read; [`Error::Xml`] for malformed XML; [`Error::Urdf`] naming
/// the file, line and element for invalid content (missing link, cycle, negative mass, bad
/// inertia, missing mesh …); [`Error::Load`] if MuJoCo rejects the result.
pub fn convert_urdf(path: &Path, opts: &ConvertOptions) -> Result<ConvertedModel> {
    let text = crate::fsio::read_to_string(path)?;
    convert_urdf_str(path, &text, opts)
}

/// Converts URDF `text`; `path` names it in errors and anchors relative mesh paths.
///
/// # Errors
/// As [`convert_urdf`].
pub fn convert_urdf_str(path: &Path, text: &str, opts: &ConvertOptions) -> Result<ConvertedModel> {
    crate::mj::init()?;
    let doc = crate::urdf::parse(path, text)?;
    let ctx = Ctx { path, doc: &doc };
    let robot = ir::parse_robot(&ctx)?;
    let tree = Tree::build(&robot)?;
    let mut conv = Converter::new(&robot, &tree, &doc, opts)?;
    conv.prepare()?;

    let world = match &opts.world {
        Some(w) => Some(world::load(w)?),
        None => None,
    };

    // Pass 1: robot alone, to find the lowest collision point at the zero pose.
    let base_height_m = if conv.placed {
        let probe = conv.emit(0.0, false, None, None)?;
        let model = conv.compile(&probe)?;
        let lowest = lowest_collision_z(&model)?;
        match lowest {
            Some(z) if conv.world_root => (-z).max(0.0),
            Some(z) => -z,
            None => 0.0,
        }
    } else {
        0.0
    };
    // Pass 2: the real model; its qpos0 is the home pose.
    let mjcf = conv.emit(base_height_m, true, world.as_ref(), None)?;
    let model = conv.compile(&mjcf)?;
    let mjcf = conv.emit(base_height_m, true, world.as_ref(), Some(&home_pose(&model)))?;
    let mut notes = robot.notes.clone();
    notes.append(&mut conv.notes);
    if let Some(w) = &world {
        notes.extend(w.notes.iter().cloned());
    }
    Ok(ConvertedModel {
        mjcf,
        robot_name: robot.name.clone(),
        floating_base: conv.floating,
        base_height_m,
        imus: conv.imus,
        sensors: conv.sensor_meta,
        joints: conv.joint_meta,
        notes,
        converted_meshes: conv.converted,
    })
}

/// `qpos0` with every limited hinge and slide clamped into its range (some URDFs put 0
/// outside the range, e.g. knees of quadrupeds): the nominal pose of keyframe `home`.
fn home_pose(model: &Model) -> Vec<f64> {
    let mut q = model.qpos0().to_vec();
    for j in 0..model.njnt() {
        if model.jnt_limited()[j] && matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
            let [lo, hi] = model.jnt_range()[j];
            let a = model.jnt_qposadr()[j] as usize;
            q[a] = q[a].clamp(lo, hi);
        }
    }
    q
}

/// Lowest world z of any collision geom of the robot at the model's `qpos0` (planes ignored).
fn lowest_collision_z(model: &Model) -> Result<Option<f64>> {
    let model = std::sync::Arc::new(model.try_clone()?);
    let mut data = crate::mj::Data::new(model.clone())?;
    let home = home_pose(&model);
    data.qpos_mut().copy_from_slice(&home);
    data.forward()?;
    let mut lowest: Option<f64> = None;
    let m = &model;
    for g in 0..m.ngeom() {
        if m.geom_contype()[g] == 0 && m.geom_conaffinity()[g] == 0 {
            continue;
        }
        let p = Vector3::from(data.geom_xpos()[g]);
        let r = Matrix3::from_row_slice(&data.geom_xmat()[g]);
        let s = m.geom_size()[g];
        // Row 2 of R: how each geom axis maps onto world z.
        let rz = Vector3::new(r[(2, 0)], r[(2, 1)], r[(2, 2)]);
        let z = match m.geom_type()[g] as u32 {
            mujoco_sys::mjtGeom_mjGEOM_PLANE => continue,
            mujoco_sys::mjtGeom_mjGEOM_SPHERE => p.z - s[0],
            mujoco_sys::mjtGeom_mjGEOM_CAPSULE => p.z - rz.z.abs() * s[1] - s[0],
            mujoco_sys::mjtGeom_mjGEOM_CYLINDER => p.z - rz.z.abs() * s[1] - s[0] * (1.0 - rz.z * rz.z).max(0.0).sqrt(),
            mujoco_sys::mjtGeom_mjGEOM_ELLIPSOID => {
                p.z - ((s[0] * rz.x).powi(2) + (s[1] * rz.y).powi(2) + (s[2] * rz.z).powi(2)).sqrt()
            }
            mujoco_sys::mjtGeom_mjGEOM_BOX => p.z - (s[0] * rz.x.abs() + s[1] * rz.y.abs() + s[2] * rz.z.abs()),
            mujoco_sys::mjtGeom_mjGEOM_MESH => {
                let id = m.geom_dataid()[g];
                if id < 0 {
                    continue;
                }
                let adr = m.mesh_vertadr()[id as usize] as usize;
                let n = m.mesh_vertnum()[id as usize] as usize;
                m.mesh_vert()[adr..adr + n]
                    .iter()
                    .map(|v| p.z + rz.dot(&Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)))
                    .fold(f64::INFINITY, f64::min)
            }
            _ => continue,
        };
        lowest = Some(lowest.map_or(z, |l: f64| l.min(z)));
    }
    Ok(lowest)
}

/// Kinematic tree of the URDF.
struct Tree {
    root: usize,
    /// Joint indices by parent link index, in URDF order.
    children: Vec<Vec<usize>>,
    link_index: HashMap<String, usize>,
}

impl Tree {
    fn build(robot: &RobotIr) -> Result<Tree> {
        let link_index: HashMap<String, usize> =
            robot.links.iter().enumerate().map(|(i, l)| (l.name.clone(), i)).collect();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children = vec![Vec::new(); robot.links.len()];
        let err = |j: &JointIr, message: String| Error::Urdf {
            path: robot.path.clone(),
            line: j.line,
            element: "joint".into(),
            name: Some(j.name.clone()),
            message,
        };
        for (ji, j) in robot.joints.iter().enumerate() {
            let c = link_index[&j.child];
            if let Some(prev) = parent_joint[c] {
                let p = &robot.joints[prev];
                return Err(err(
                    j,
                    format!(
                        "link \"{}\" is already the child of joint \"{}\" (line {}): a URDF must be a tree; \
                         remove one of the joints or use <mimic>/a closed-loop constraint instead",
                        j.child, p.name, p.line
                    ),
                ));
            }
            if j.parent == j.child {
                return Err(err(j, format!("joint connects link \"{}\" to itself: fix parent or child", j.child)));
            }
            parent_joint[c] = Some(ji);
            children[link_index[&j.parent]].push(ji);
        }
        let roots: Vec<usize> = (0..robot.links.len()).filter(|&i| parent_joint[i].is_none()).collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => {
                let j = &robot.joints[0];
                return Err(err(
                    j,
                    "the joints form a cycle: every link is some joint's child, so there is no root link; \
                     break the loop (a URDF must be a tree)"
                        .into(),
                ));
            }
            many => {
                let names: Vec<&str> = many.iter().map(|&i| robot.links[i].name.as_str()).collect();
                let l = &robot.links[many[1]];
                return Err(Error::Urdf {
                    path: robot.path.clone(),
                    line: l.line,
                    element: "link".into(),
                    name: Some(l.name.clone()),
                    message: format!(
                        "the robot has {} root links ({}): connect each to the tree with a joint",
                        many.len(),
                        names.join(", ")
                    ),
                });
            }
        };
        // Links not reachable from the root sit on a cycle.
        let mut reached = vec![false; robot.links.len()];
        let mut stack = vec![root];
        while let Some(l) = stack.pop() {
            reached[l] = true;
            for &j in &children[l] {
                let c = link_index[&robot.joints[j].child];
                if !reached[c] {
                    stack.push(c);
                }
            }
        }
        if let Some(l) = (0..robot.links.len()).find(|&l| !reached[l]) {
            let j = &robot.joints[parent_joint[l].expect("unreached links have a parent joint")];
            return Err(err(
                j,
                format!(
                    "link \"{}\" is on a cycle of joints (not reachable from the root \"{}\"): a URDF must be a tree; break the loop",
                    robot.links[l].name, robot.links[root].name
                ),
            ));
        }
        Ok(Tree { root, children, link_index })
    }
}

/// A collision or visual geom resolved for output.
struct MeshAsset {
    name: String,
    file: PathBuf,
    scale: [f64; 3],
}

/// Centre of mass (body frame), `fullinertia` (Ixx Iyy Izz Ixy Ixz Iyz, body frame), mass.
type BodyInertial = ([f64; 3], [f64; 6], f64);

struct Converter<'a> {
    robot: &'a RobotIr,
    tree: &'a Tree,
    doc: &'a roxmltree::Document<'a>,
    opts: &'a ConvertOptions,
    /// Root link is a `world` link: its children hang from the world body.
    world_root: bool,
    floating: bool,
    /// Whether the root is placed on the floor.
    placed: bool,
    /// Per link: inertial as `(pos, fullinertia [Ixx Iyy Izz Ixy Ixz Iyz], mass)`.
    inertials: Vec<Option<BodyInertial>>,
    /// Mesh asset index per (link, visual?, geom index).
    mesh_of: HashMap<(usize, bool, usize), usize>,
    meshes: Vec<MeshAsset>,
    /// Friction per link.
    mu: Vec<f64>,
    priority: BTreeMap<u64, i32>,
    imus: Vec<ImuMeta>,
    sensor_meta: Vec<SensorMeta>,
    joint_meta: Vec<JointMeta>,
    notes: Vec<String>,
    converted: Vec<PathBuf>,
    converted_from: HashMap<PathBuf, PathBuf>,
    sensor_names: std::collections::HashSet<String>,
    /// Per link: sites (XML lines) to put in its body.
    sites: Vec<Vec<String>>,
    /// Per link: cameras.
    cameras: Vec<Vec<String>>,
    sensor_xml: Vec<String>,
}

fn f(x: f64) -> String {
    if x == 0.0 { "0".into() } else { format!("{x}") }
}

fn fv(v: &[f64]) -> String {
    v.iter().map(|x| f(*x)).collect::<Vec<_>>().join(" ")
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;").replace('>', "&gt;")
}

fn quat_attr(q: &UnitQuaternion<f64>) -> String {
    if q.angle() == 0.0 { String::new() } else { format!(" quat=\"{}\"", fv(&[q.w, q.i, q.j, q.k])) }
}

fn pose_attrs(p: &Pose) -> String {
    let mut s = String::new();
    if p.xyz.norm() != 0.0 {
        s.push_str(&format!(" pos=\"{}\"", fv(p.xyz.as_slice())));
    }
    s.push_str(&quat_attr(&p.rot));
    s
}

/// Gazebo classic material colours (diffuse).
fn gazebo_rgba(name: &str) -> Option<[f64; 4]> {
    let n = name.trim().trim_start_matches("Gazebo/");
    let rgb = match n {
        "Black" | "FlatBlack" => [0.05, 0.05, 0.05],
        "White" => [1.0, 1.0, 1.0],
        "Grey" | "Gray" => [0.7, 0.7, 0.7],
        "DarkGrey" | "DarkGray" => [0.175, 0.175, 0.175],
        "LightGrey" | "LightGray" => [0.83, 0.83, 0.83],
        "Red" => [1.0, 0.0, 0.0],
        "Green" => [0.0, 1.0, 0.0],
        "Blue" => [0.0, 0.0, 1.0],
        "Yellow" => [1.0, 1.0, 0.0],
        "Orange" => [1.0, 0.5088, 0.0468],
        "Purple" => [1.0, 0.0, 1.0],
        "Turquoise" => [0.0, 1.0, 1.0],
        "Gold" => [0.8, 0.6, 0.2],
        "Indigo" => [0.33, 0.0, 0.5],
        "Wood" => [0.55, 0.35, 0.2],
        "SkyBlue" => [0.53, 0.81, 0.92],
        _ => return None,
    };
    Some([rgb[0], rgb[1], rgb[2], 1.0])
}

/// Repairs an inertia tensor by the smallest change of its principal moments: eigenvalues
/// raised to a small positive floor, then projected onto `a + b ≥ c`. Returns the new tensor
/// `[ixx, ixy, ixz, iyy, iyz, izz]` and a sentence saying what changed.
fn repair_inertia(v: [f64; 6]) -> ([f64; 6], String) {
    let [ixx, ixy, ixz, iyy, iyz, izz] = v;
    let t = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
    let eig = SymmetricEigen::new(t);
    let before: Vec<f64> = eig.eigenvalues.iter().copied().collect();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| before[a].total_cmp(&before[b]));
    let mut p = [before[order[0]], before[order[1]], before[order[2]]];
    let floor = (p[2].abs() * 1e-6).max(1e-12);
    for x in &mut p {
        *x = x.max(floor);
    }
    if p[0] + p[1] < p[2] {
        // Orthogonal projection onto the plane a + b = c (normal (1, 1, −1)), a hair inside.
        let d = (p[2] - p[0] - p[1]) / 3.0 * (1.0 + 1e-9);
        p[0] += d;
        p[1] += d;
        p[2] -= d;
    }
    let mut newp = before.clone();
    for (k, &i) in order.iter().enumerate() {
        newp[i] = p[k];
    }
    let q = eig.eigenvectors;
    let r = q * Matrix3::from_diagonal(&Vector3::new(newp[0], newp[1], newp[2])) * q.transpose();
    let mut sb = before.clone();
    sb.sort_by(f64::total_cmp);
    let msg = format!(
        "principal moments {:.6e}, {:.6e}, {:.6e} → {:.6e}, {:.6e}, {:.6e} kg·m² (smallest change that makes the tensor positive definite and satisfy the triangle inequality; principal axes kept)",
        sb[0], sb[1], sb[2], p[0], p[1], p[2]
    );
    ([r[(0, 0)], r[(0, 1)], r[(0, 2)], r[(1, 1)], r[(1, 2)], r[(2, 2)]], msg)
}

impl<'a> Converter<'a> {
    fn new(
        robot: &'a RobotIr,
        tree: &'a Tree,
        doc: &'a roxmltree::Document<'a>,
        opts: &'a ConvertOptions,
    ) -> Result<Converter<'a>> {
        let root = &robot.links[tree.root];
        let world_root = root.name == "world";
        if world_root && (root.inertial.is_some() || !root.collisions.is_empty()) {
            return Err(Error::Urdf {
                path: robot.path.clone(),
                line: root.line,
                element: "link".into(),
                name: Some("world".into()),
                message: "the \"world\" link must have no inertial or collision: it stands for the fixed world".into(),
            });
        }
        let floating = !world_root && !opts.fixed_base;
        let n = robot.links.len();
        Ok(Converter {
            robot,
            tree,
            doc,
            opts,
            world_root,
            floating,
            placed: true,
            inertials: vec![None; n],
            mesh_of: HashMap::new(),
            meshes: Vec::new(),
            mu: vec![1.0; n],
            priority: BTreeMap::new(),
            imus: Vec::new(),
            sensor_meta: Vec::new(),
            joint_meta: Vec::new(),
            notes: Vec::new(),
            converted: Vec::new(),
            converted_from: HashMap::new(),
            sensor_names: std::collections::HashSet::new(),
            sites: vec![Vec::new(); n],
            cameras: vec![Vec::new(); n],
            sensor_xml: Vec::new(),
        })
    }

    fn urdf_err(&self, line: u32, element: &str, name: &str, message: String) -> Error {
        Error::Urdf { path: self.robot.path.clone(), line, element: element.into(), name: Some(name.into()), message }
    }

    /// Everything that does not depend on the placement: inertias, meshes, friction, sensors,
    /// joint metadata.
    fn prepare(&mut self) -> Result<()> {
        let robot = self.robot;
        // Inertials.
        for (li, link) in robot.links.iter().enumerate() {
            let Some(inertial) = &link.inertial else {
                continue;
            };
            if inertial.mass == 0.0 {
                continue;
            }
            let mut v = inertial.inertia;
            if let Err(problem) = crate::urdf::check_inertia(v) {
                if self.opts.repair_inertia {
                    let (fixed, how) = repair_inertia(v);
                    self.notes.push(format!(
                        "link \"{}\" (line {}): inertia repaired: {how}",
                        link.name, inertial.inertia_line
                    ));
                    v = fixed;
                } else {
                    return Err(self.urdf_err(
                        inertial.inertia_line,
                        "inertia",
                        &link.name,
                        format!("{problem}; or convert with --repair-inertia to apply the smallest fix"),
                    ));
                }
            }
            let [ixx, ixy, ixz, iyy, iyz, izz] = v;
            let t = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
            let r = inertial.pose.rot.to_rotation_matrix();
            let b = r.matrix() * t * r.matrix().transpose();
            self.inertials[li] = Some((
                [inertial.pose.xyz.x, inertial.pose.xyz.y, inertial.pose.xyz.z],
                [b[(0, 0)], b[(1, 1)], b[(2, 2)], b[(0, 1)], b[(0, 2)], b[(1, 2)]],
                inertial.mass,
            ));
        }
        // Movable bodies need mass (MuJoCo refuses them otherwise).
        for (ji, j) in robot.joints.iter().enumerate() {
            if j.kind == JointKind::Fixed {
                continue;
            }
            let c = self.tree.link_index[&j.child];
            if self.subtree_mass(c) <= 0.0 {
                let link = &robot.links[c];
                if self.opts.repair_inertia {
                    self.inertials[c] = Some(([0.0; 3], [1e-6, 1e-6, 1e-6, 0.0, 0.0, 0.0], 1e-3));
                    self.notes.push(format!(
                        "link \"{}\" (line {}) moves (joint \"{}\") but has no mass: given 1 g and 1e-6 kg·m² (repair)",
                        link.name, link.line, j.name
                    ));
                } else {
                    return Err(self.urdf_err(
                        link.line,
                        "link",
                        &link.name,
                        format!(
                            "link moves (joint \"{}\", line {}) but it and its fixed children have no mass: add an <inertial> with the real mass, or convert with --repair-inertia",
                            j.name, robot.joints[ji].line
                        ),
                    ));
                }
            }
        }
        // Meshes.
        let mut search = self.opts.package_paths.clone();
        if let Some(env) = std::env::var_os("ROS_PACKAGE_PATH") {
            search.extend(std::env::split_paths(&env).filter(|p| !p.as_os_str().is_empty()));
        }
        let urdf_dir = robot.path.parent().map(Path::to_path_buf).unwrap_or_default();
        let urdf_dir = if urdf_dir.as_os_str().is_empty() { PathBuf::from(".") } else { urdf_dir };
        let abs_dir = std::path::absolute(&urdf_dir).unwrap_or(urdf_dir.clone());
        // A vendored description package usually holds the URDF in PKG/urdf/: its ancestors.
        search.extend(abs_dir.ancestors().skip(1).take(4).map(Path::to_path_buf));
        search.push(abs_dir.clone());
        let mut by_key: HashMap<(PathBuf, [u64; 3]), usize> = HashMap::new();
        let mut used_names: HashMap<String, usize> = HashMap::new();
        for (li, link) in robot.links.iter().enumerate() {
            let visuals = if self.opts.visuals { &link.visuals[..] } else { &[] };
            for (visual, geoms) in [(false, &link.collisions[..]), (true, visuals)] {
                for (gi, g) in geoms.iter().enumerate() {
                    let Shape::Mesh { filename, scale, line } = &g.shape else {
                        continue;
                    };
                    let file = mesh::resolve(filename, &abs_dir, &search)
                        .map_err(|m| self.urdf_err(*line, "mesh", &link.name, m))?;
                    let file = std::path::absolute(&file).unwrap_or(file);
                    let key = (file.clone(), scale.map(f64::to_bits));
                    let idx = match by_key.get(&key) {
                        Some(&i) => i,
                        None => {
                            let file =
                                self.native_mesh(&file).map_err(|m| self.urdf_err(*line, "mesh", &link.name, m))?;
                            let stem: String = key
                                .0
                                .file_stem()
                                .and_then(|s| s.to_str())
                                .unwrap_or("mesh")
                                .chars()
                                .map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' })
                                .collect();
                            let count = used_names.entry(stem.clone()).or_insert(0);
                            *count += 1;
                            let name = if *count == 1 { stem } else { format!("{stem}_{count}") };
                            self.meshes.push(MeshAsset { name, file, scale: *scale });
                            by_key.insert(key, self.meshes.len() - 1);
                            self.meshes.len() - 1
                        }
                    };
                    self.mesh_of.insert((li, visual, gi), idx);
                }
            }
        }
        // Friction from <gazebo reference> (links only).
        for (li, link) in robot.links.iter().enumerate() {
            if let Some(g) = robot.gazebo.get(&link.name) {
                let mu = match (g.mu1, g.mu2) {
                    (Some(a), Some(b)) => {
                        if a != b {
                            self.notes.push(format!(
                                "link \"{}\": mu1 {a} ≠ mu2 {b}: MuJoCo friction is isotropic, the smaller ({}) is used",
                                link.name,
                                a.min(b)
                            ));
                        }
                        Some(a.min(b))
                    }
                    (Some(a), None) | (None, Some(a)) => Some(a),
                    (None, None) => None,
                };
                if let Some(mu) = mu {
                    if mu < 0.0 {
                        return Err(self.urdf_err(
                            g.line,
                            "gazebo",
                            &link.name,
                            format!("friction mu {mu} must be ≥ 0"),
                        ));
                    }
                    self.mu[li] = mu;
                }
                if g.kp.is_some() || g.kd.is_some() {
                    self.notes.push(format!(
                        "link \"{}\" (line {}): Gazebo contact kp/kd not converted (MuJoCo's default soft contact is used)",
                        link.name, g.line
                    ));
                }
            }
        }
        // Joint metadata and actuator notes.
        let mut passive = Vec::new();
        for j in &robot.joints {
            let movable = !matches!(j.kind, JointKind::Fixed);
            let drive = robot.drives.get(&j.name);
            let mut actuator = None;
            let mut gear = 1.0;
            if let Some(d) = drive {
                if !movable {
                    self.notes.push(format!("transmission on fixed joint \"{}\": ignored", j.name));
                } else if j.mimic.is_some() {
                    self.notes.push(format!(
                        "joint \"{}\" mimics another joint: its transmission is not converted (the equality drives it)",
                        j.name
                    ));
                } else if matches!(j.kind, JointKind::Floating | JointKind::Planar | JointKind::Spherical) {
                    self.notes.push(format!("transmission on multi-DOF joint \"{}\": not converted", j.name));
                } else {
                    actuator = Some((j.name.clone(), d.interface));
                    gear = d.gear;
                }
            } else if movable
                && j.mimic.is_none()
                && matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic)
            {
                match self.opts.untransmitted {
                    Some(i) => actuator = Some((j.name.clone(), i)),
                    None => passive.push(j.name.clone()),
                }
            }
            let nz = |x: f64| if x > 0.0 { Some(x) } else { None };
            self.joint_meta.push(JointMeta {
                name: j.name.clone(),
                urdf_type: format!("{:?}", j.kind).to_lowercase(),
                effort_limit: j.limit.as_ref().and_then(|l| nz(l.effort)),
                velocity_limit: j.limit.as_ref().and_then(|l| nz(l.velocity)),
                range: match (j.kind, &j.limit) {
                    (JointKind::Revolute | JointKind::Prismatic, Some(l)) => Some([l.lower, l.upper]),
                    _ => None,
                },
                actuator,
                gear,
                mimic_of: j.mimic.as_ref().map(|m| m.joint.clone()),
            });
        }
        for j in &robot.joints {
            if let Some(m) = &j.mimic {
                let movable = |n: &str| {
                    robot.joints.iter().any(|k| {
                        k.name == n
                            && matches!(k.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic)
                    })
                };
                if !movable(&j.name) || !movable(&m.joint) {
                    self.notes.push(format!(
                        "mimic of joint \"{}\" (line {}) on \"{}\": one of them is not a 1-DOF joint; no equality added",
                        j.name, m.line, m.joint
                    ));
                }
            }
        }
        if !passive.is_empty() {
            self.notes.push(format!(
                "{} movable joint(s) have no transmission or ros2_control entry and stay passive (no actuator): {}",
                passive.len(),
                passive.join(", ")
            ));
        }
        if robot.joints.iter().any(|j| j.limit.as_ref().is_some_and(|l| l.velocity > 0.0)) {
            self.notes.push(
                "joint velocity limits have no MuJoCo equivalent: kept as metadata for controllers and checks".into(),
            );
        }
        self.sensors()?;
        Ok(())
    }

    fn subtree_mass(&self, link: usize) -> f64 {
        let own = self.inertials[link].map_or(0.0, |i| i.2);
        own + self.tree.children[link]
            .iter()
            .map(|&j| self.subtree_mass(self.tree.link_index[&self.robot.joints[j].child]))
            .sum::<f64>()
    }

    /// Path of a mesh MuJoCo can read: the file itself, or a converted OBJ.
    fn native_mesh(&mut self, file: &Path) -> std::result::Result<PathBuf, String> {
        let kind = mesh::classify(file)?;
        if kind == mesh::MeshKind::Native {
            return Ok(file.to_path_buf());
        }
        if let Some(done) = self.converted_from.get(file) {
            return Ok(done.clone());
        }
        let bytes = std::fs::read(file).map_err(|e| format!("{}: {e}", file.display()))?;
        let mut key = file.as_os_str().as_encoded_bytes().to_vec();
        key.extend_from_slice(&bytes);
        let hash = mesh::fnv1a(&key);
        let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh");
        let dir = match &self.opts.mesh_dir {
            Some(d) => d.clone(),
            None => std::env::temp_dir().join("twin-meshes"),
        };
        let out = dir.join(format!("{stem}-{hash:016x}.obj"));
        if self.opts.mesh_dir.is_none() && out.is_file() {
            return Ok(out);
        }
        let tris = match kind {
            mesh::MeshKind::AsciiStl => mesh::read_ascii_stl(file)?,
            _ => mesh::read_collada(file)?,
        };
        std::fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
        // Atomic: parallel conversions of the same mesh never see a half-written file.
        crate::fsio::write_atomic(&out, &mesh::obj(&tris), crate::fsio::Backup::None).map_err(|e| {
            match std::error::Error::source(&e) {
                Some(source) => format!("writing converted mesh {e}: {source}"),
                None => format!("writing converted mesh: {e}"),
            }
        })?;
        self.notes.push(format!(
            "mesh {} ({}) converted to OBJ {} ({} triangles)",
            file.display(),
            if kind == mesh::MeshKind::AsciiStl { "ASCII STL" } else { "Collada" },
            out.display(),
            tris.len()
        ));
        self.converted.push(out.clone());
        self.converted_from.insert(file.to_path_buf(), out.clone());
        Ok(out)
    }

    fn sensor_node(&self, s: &SensorIr) -> roxmltree::Node<'a, 'a> {
        self.doc.descendants().find(|n| n.range() == s.node_range).expect("sensor node recorded from this document")
    }

    /// Link that a `<gazebo reference>` of a sensor resolves to, and the pose of the reference
    /// frame in that link.
    fn sensor_link(&self, s: &SensorIr) -> (usize, Pose) {
        if let Some(&l) = self.tree.link_index.get(&s.reference) {
            return (l, Pose::IDENTITY);
        }
        let j = self.robot.joints.iter().find(|j| j.name == s.reference).expect("reference checked at parse time");
        (self.tree.link_index[&j.child], Pose::IDENTITY)
    }

    fn unique_sensor_name(&mut self, base: &str) -> String {
        let mut name = base.to_string();
        let mut k = 1;
        while !self.sensor_names.insert(name.clone()) {
            k += 1;
            name = format!("{base}_{k}");
        }
        name
    }

    fn sensors(&mut self) -> Result<()> {
        let robot = self.robot;
        for s in &robot.sensors {
            let node = self.sensor_node(s);
            let (link, frame) = self.sensor_link(s);
            let pose = frame.then(&s.pose);
            let link_name = robot.links[link].name.clone();
            let unique = self.unique_sensor_name(&s.name);
            if unique != s.name {
                self.notes.push(format!(
                    "sensor \"{}\" (line {}) repeats an earlier sensor's name: converted as \"{unique}\"",
                    s.name, s.line
                ));
            }
            let name = esc(&unique);
            let topic = resolve_topic(node);
            match s.kind.as_str() {
                "imu" => {
                    let (gyro, accel) = imu_noise(node);
                    self.sites[link]
                        .push(format!("<site name=\"{name}\"{} size=\"0.005\" group=\"4\"/>", pose_attrs(&pose)));
                    let noise = |x: f64| {
                        if x > 0.0 { format!(" noise=\"{}\"", f(x)) } else { String::new() }
                    };
                    self.sensor_xml
                        .push(format!("<framequat name=\"{name}_quat\" objtype=\"site\" objname=\"{name}\"/>"));
                    self.sensor_xml.push(format!("<gyro name=\"{name}_gyro\" site=\"{name}\"{}/>", noise(gyro)));
                    self.sensor_xml
                        .push(format!("<accelerometer name=\"{name}_accel\" site=\"{name}\"{}/>", noise(accel)));
                    let frame_id = ir::child(node, "plugin")
                        .and_then(|p| ir::child_text(p, "frame_name").or_else(|| ir::child_text(p, "frameName")))
                        .map(str::to_string)
                        .unwrap_or_else(|| link_name.clone());
                    self.imus.push(ImuMeta {
                        name: s.name.clone(),
                        link: link_name,
                        site: s.name.clone(),
                        update_rate_hz: s.update_rate_hz,
                        gyro_noise_std: gyro,
                        accel_noise_std: accel,
                        topic,
                        frame_id,
                    });
                }
                "camera" | "depth" | "depth_camera" | "rgbd_camera" | "wideanglecamera" | "multicamera" => {
                    let cams: Vec<roxmltree::Node<'_, '_>> = ir::children(node, "camera").collect();
                    let mut made = Vec::new();
                    for (k, cam) in cams.iter().enumerate() {
                        let hfov = ir::child_text(*cam, "horizontal_fov").and_then(ir::parse_num).unwrap_or(1.047);
                        let img = ir::child(*cam, "image");
                        let w = img.and_then(|i| ir::child_text(i, "width")).and_then(ir::parse_num).unwrap_or(320.0);
                        let h = img.and_then(|i| ir::child_text(i, "height")).and_then(ir::parse_num).unwrap_or(240.0);
                        let fovy = 2.0 * ((hfov / 2.0).tan() * h / w).atan();
                        let cam_pose = match ir::child_text(*cam, "pose").and_then(ir::parse_vec::<6>) {
                            Some(v) => Pose::from_xyz_rpy([v[0], v[1], v[2]], [v[3], v[4], v[5]]),
                            None => Pose::IDENTITY,
                        };
                        // Gazebo: view along +X, up +Z. MuJoCo: view along −Z, up +Y.
                        let gz_from_mj =
                            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(
                                Matrix3::new(0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
                            ));
                        let p = pose.then(&cam_pose).then(&Pose { xyz: Vector3::zeros(), rot: gz_from_mj });
                        let cname = if cams.len() == 1 { name.clone() } else { format!("{name}_{k}") };
                        self.cameras[link].push(format!(
                            "<camera name=\"{cname}\"{} fovy=\"{}\" resolution=\"{} {}\"/>",
                            pose_attrs(&p),
                            f(fovy.to_degrees()),
                            w as i64,
                            h as i64
                        ));
                        made.push(cname);
                    }
                    self.sensor_meta.push(SensorMeta {
                        name: s.name.clone(),
                        kind: s.kind.clone(),
                        reference: s.reference.clone(),
                        update_rate_hz: s.update_rate_hz,
                        topic,
                        mujoco: made,
                    });
                }
                "ray" | "gpu_ray" | "lidar" | "gpu_lidar" => {
                    let ray = ir::child(node, "ray").or_else(|| ir::child(node, "lidar"));
                    let scan = ray.and_then(|r| ir::child(r, "scan"));
                    let axis = |tag: &str| -> (usize, f64, f64) {
                        let a = scan.and_then(|s| ir::child(s, tag));
                        let samples = a
                            .and_then(|a| ir::child_text(a, "samples"))
                            .and_then(ir::parse_num)
                            .unwrap_or(1.0)
                            .max(1.0) as usize;
                        let lo = a.and_then(|a| ir::child_text(a, "min_angle")).and_then(ir::parse_num).unwrap_or(0.0);
                        let hi = a.and_then(|a| ir::child_text(a, "max_angle")).and_then(ir::parse_num).unwrap_or(0.0);
                        (samples, lo, hi)
                    };
                    let (hn, hlo, hhi) = axis("horizontal");
                    let (vn, vlo, vhi) = axis("vertical");
                    let range = ray.and_then(|r| ir::child(r, "range"));
                    let max_range =
                        range.and_then(|r| ir::child_text(r, "max")).and_then(ir::parse_num).unwrap_or(10.0);
                    let total = hn * vn;
                    let keep = total.min(self.opts.max_rays.max(1));
                    if keep < total {
                        self.notes.push(format!(
                            "ray sensor \"{}\": {total} rays subsampled to {keep} rangefinders (ConvertOptions::max_rays)",
                            s.name
                        ));
                    }
                    let mut made = Vec::new();
                    for k in 0..keep {
                        let idx = if keep == 1 { 0 } else { k * (total - 1) / (keep - 1) };
                        let (hi_i, vi_i) = (idx % hn, idx / hn);
                        let lerp = |n: usize, lo: f64, hi: f64, i: usize| {
                            if n <= 1 { lo } else { lo + (hi - lo) * i as f64 / (n - 1) as f64 }
                        };
                        let yaw = lerp(hn, hlo, hhi, hi_i);
                        let pitch = lerp(vn, vlo, vhi, vi_i);
                        // Ray direction in the sensor frame; rangefinders look along site +Z.
                        let dir = Vector3::new(yaw.cos() * pitch.cos(), yaw.sin() * pitch.cos(), -pitch.sin());
                        let rot = UnitQuaternion::rotation_between(&Vector3::z(), &dir).unwrap_or_else(|| {
                            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
                        });
                        let p = pose.then(&Pose { xyz: Vector3::zeros(), rot });
                        let site = format!("{name}_ray{k}");
                        self.sites[link]
                            .push(format!("<site name=\"{site}\"{} size=\"0.003\" group=\"4\"/>", pose_attrs(&p)));
                        self.sensor_xml.push(format!(
                            "<rangefinder name=\"{site}\" site=\"{site}\" cutoff=\"{}\"/>",
                            f(max_range)
                        ));
                        made.push(site);
                    }
                    self.sensor_meta.push(SensorMeta {
                        name: s.name.clone(),
                        kind: s.kind.clone(),
                        reference: s.reference.clone(),
                        update_rate_hz: s.update_rate_hz,
                        topic,
                        mujoco: made,
                    });
                }
                "force_torque" => {
                    let site = format!("{name}_site");
                    self.sites[link]
                        .push(format!("<site name=\"{site}\"{} size=\"0.005\" group=\"4\"/>", pose_attrs(&pose)));
                    self.sensor_xml.push(format!("<force name=\"{name}_force\" site=\"{site}\"/>"));
                    self.sensor_xml.push(format!("<torque name=\"{name}_torque\" site=\"{site}\"/>"));
                    self.sensor_meta.push(SensorMeta {
                        name: s.name.clone(),
                        kind: s.kind.clone(),
                        reference: s.reference.clone(),
                        update_rate_hz: s.update_rate_hz,
                        topic,
                        mujoco: vec![format!("{}_force", s.name), format!("{}_torque", s.name)],
                    });
                }
                "contact" => {
                    let l = &robot.links[link];
                    let Some(g) = l.collisions.first() else {
                        self.notes.push(format!(
                            "contact sensor \"{}\": link \"{}\" has no collision geom; not converted",
                            s.name, l.name
                        ));
                        continue;
                    };
                    // The touch sensor counts contacts inside the site: cover the geom, 5 % larger.
                    let (ty, size) = match &g.shape {
                        Shape::Box(sz) => ("box", vec![sz[0] * 0.525, sz[1] * 0.525, sz[2] * 0.525]),
                        Shape::Sphere(r) => ("sphere", vec![r * 1.05]),
                        Shape::Cylinder { radius, length } => ("cylinder", vec![radius * 1.05, length * 0.525]),
                        Shape::Capsule { radius, length } => ("capsule", vec![radius * 1.05, length * 0.525]),
                        Shape::Mesh { .. } => {
                            self.notes.push(format!(
                                "contact sensor \"{}\": mesh collision (line {}) approximated by a 10 cm sphere site",
                                s.name, g.line
                            ));
                            ("sphere", vec![0.1])
                        }
                    };
                    let site = format!("{name}_site");
                    self.sites[link].push(format!(
                        "<site name=\"{site}\" type=\"{ty}\" size=\"{}\"{} group=\"4\" rgba=\"1 0 0 0.2\"/>",
                        fv(&size),
                        pose_attrs(&g.pose)
                    ));
                    self.sensor_xml.push(format!("<touch name=\"{name}\" site=\"{site}\"/>"));
                    self.sensor_meta.push(SensorMeta {
                        name: s.name.clone(),
                        kind: s.kind.clone(),
                        reference: s.reference.clone(),
                        update_rate_hz: s.update_rate_hz,
                        topic,
                        mujoco: vec![s.name.clone()],
                    });
                }
                other => {
                    self.notes.push(format!(
                        "sensor \"{}\" of type {other} (line {}) has no MuJoCo equivalent here: not converted",
                        s.name, s.line
                    ));
                }
            }
        }
        Ok(())
    }

    fn compile(&self, mjcf: &str) -> Result<Model> {
        Model::from_xml_str(mjcf).map_err(|e| match e {
            Error::Load { message, .. } => {
                // MuJoCo names the element ("Element name 'X'"): point at the URDF line.
                let named = message.split("name '").nth(1).and_then(|r| r.split('\'').next()).map(str::to_string);
                let hit = named.as_deref().and_then(|n| {
                    self.robot
                        .links
                        .iter()
                        .find(|l| l.name == n)
                        .map(|l| (l.line, "link"))
                        .or_else(|| self.robot.joints.iter().find(|j| j.name == n).map(|j| (j.line, "joint")))
                });
                match (hit, named) {
                    (Some((line, element)), Some(n)) => Error::Urdf {
                        path: self.robot.path.clone(),
                        line,
                        element: element.into(),
                        name: Some(n),
                        message: format!("MuJoCo rejected the converted {element}: {message}"),
                    },
                    _ => Error::Load {
                        path: Some(self.robot.path.clone()),
                        message: format!("MuJoCo rejected the converted model: {message}"),
                    },
                }
            }
            other => other,
        })
    }

    fn contype(&self, link: &LinkIr) -> (i32, i32) {
        let selfc =
            self.opts.self_collision || self.robot.gazebo.get(&link.name).and_then(|g| g.self_collide).unwrap_or(false);
        if selfc { (6, 5) } else { (2, 1) }
    }

    fn priority_of(&self, mu: f64) -> i32 {
        self.priority.get(&mu.to_bits()).copied().unwrap_or(0)
    }

    /// Writes the MJCF. `base_z`: height of the root; `home`: qpos of keyframe `home`.
    fn emit(&mut self, base_z: f64, scene: bool, world: Option<&world::World>, home: Option<&[f64]>) -> Result<String> {
        // Friction priorities: lower mu ranks higher, so pairs take the min as Gazebo does.
        let mut mus: Vec<f64> = self.mu.clone();
        mus.push(1.0);
        if let Some(w) = world {
            mus.extend(w.mus.iter().copied());
        }
        mus.sort_by(|a, b| b.total_cmp(a));
        mus.dedup();
        self.priority = mus.iter().enumerate().map(|(i, m)| (m.to_bits(), i as i32)).collect();

        let robot = self.robot;
        let mut x = String::with_capacity(64 * 1024);
        let _ = writeln!(x, "<mujoco model=\"{}\">", esc(&robot.name));
        let _ = writeln!(
            x,
            "  <!-- converted by twin {} from {} -->",
            env!("CARGO_PKG_VERSION"),
            esc(&robot.path.display().to_string()).replace("--", "- -")
        );
        let _ = writeln!(
            x,
            "  <compiler angle=\"radian\" autolimits=\"true\" inertiafromgeom=\"false\" fusestatic=\"false\" discardvisual=\"false\"/>"
        );
        let timestep = world.and_then(|w| w.timestep_secs).unwrap_or(self.opts.timestep_secs);
        let gravity = world.and_then(|w| w.gravity).unwrap_or([0.0, 0.0, -9.81]);
        let _ = writeln!(
            x,
            "  <option timestep=\"{}\" gravity=\"{}\" integrator=\"implicitfast\"/>",
            f(timestep),
            fv(&gravity)
        );
        let _ = writeln!(x, "  <asset>");
        for m in &self.meshes {
            let scale = if m.scale == [1.0; 3] { String::new() } else { format!(" scale=\"{}\"", fv(&m.scale)) };
            let _ = writeln!(
                x,
                "    <mesh name=\"{}\" file=\"{}\"{scale}/>",
                esc(&m.name),
                esc(&m.file.display().to_string())
            );
        }
        if let (true, Some(w)) = (scene, world) {
            x.push_str(&w.assets);
        } else if scene && self.opts.floor {
            let _ = writeln!(
                x,
                "    <texture name=\"twin_grid\" type=\"2d\" builtin=\"checker\" width=\"512\" height=\"512\" rgb1=\"0.2 0.3 0.4\" rgb2=\"0.1 0.2 0.3\"/>"
            );
            let _ = writeln!(
                x,
                "    <material name=\"twin_grid\" texture=\"twin_grid\" texrepeat=\"1 1\" texuniform=\"true\" reflectance=\"0.2\"/>"
            );
        }
        let _ = writeln!(x, "  </asset>");
        let _ = writeln!(x, "  <worldbody>");
        let root = self.tree.root;
        if self.world_root {
            // Children of the world link hang from the world body.
            for &j in &self.tree.children[root] {
                self.emit_body(&mut x, j, 2, base_z)?;
            }
        } else {
            self.emit_root(&mut x, root, base_z)?;
        }
        if scene {
            if let Some(w) = world {
                let mut body = w.worldbody.clone();
                for mu in &w.mus {
                    body = body.replace(&world::prio_tag(*mu), &self.priority_of(*mu).to_string());
                }
                x.push_str(&body);
            } else if self.opts.floor {
                let _ = writeln!(
                    x,
                    "    <light name=\"twin_sun\" directional=\"true\" pos=\"0 0 5\" dir=\"0 0 -1\" diffuse=\"0.8 0.8 0.8\"/>"
                );
                let _ = writeln!(
                    x,
                    "    <geom name=\"floor\" type=\"plane\" size=\"0 0 0.05\" material=\"twin_grid\" contype=\"1\" conaffinity=\"1\" friction=\"1 0.005 0.0001\" priority=\"{}\"/>",
                    self.priority_of(1.0)
                );
            }
        }
        let _ = writeln!(x, "  </worldbody>");

        let one_dof = |name: &str| {
            robot.joints.iter().any(|j| {
                j.name == name && matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic)
            })
        };
        let mimics: Vec<&JointIr> = robot
            .joints
            .iter()
            .filter(|j| j.mimic.as_ref().is_some_and(|m| one_dof(&j.name) && one_dof(&m.joint)))
            .collect();
        if !mimics.is_empty() {
            let _ = writeln!(x, "  <equality>");
            for j in mimics {
                let m = j.mimic.as_ref().expect("filtered");
                let _ = writeln!(
                    x,
                    "    <joint name=\"{}_mimic\" joint1=\"{}\" joint2=\"{}\" polycoef=\"{} {} 0 0 0\"/>",
                    esc(&j.name),
                    esc(&j.name),
                    esc(&m.joint),
                    f(m.offset),
                    f(m.multiplier)
                );
            }
            let _ = writeln!(x, "  </equality>");
        }

        let mut act = String::new();
        for (meta, j) in self.joint_meta.iter().zip(&robot.joints) {
            let Some((name, iface)) = &meta.actuator else {
                continue;
            };
            let g = meta.gear;
            let effort = meta.effort_limit;
            let drive = robot.drives.get(&j.name);
            let fr =
                effort.map(|e| format!(" forcerange=\"{} {}\"", f(-e / g.abs()), f(e / g.abs()))).unwrap_or_default();
            let gear = if g == 1.0 { String::new() } else { format!(" gear=\"{}\"", f(g)) };
            let line = match iface {
                Interface::Effort => {
                    let range = drive
                        .and_then(|d| d.cmd_range)
                        .map(|r| [r[0] / g.abs(), r[1] / g.abs()])
                        .or(effort.map(|e| [-e / g.abs(), e / g.abs()]));
                    let cr = range.map(|r| format!(" ctrlrange=\"{}\"", fv(&r))).unwrap_or_default();
                    format!("<motor name=\"{}\" joint=\"{}\"{gear}{cr}{fr}/>", esc(name), esc(&j.name))
                }
                Interface::Position => {
                    let kp = effort.map_or(100.0, |e| self.opts.position_kp_per_effort * e);
                    let kv = kp * self.opts.position_kv_per_kp;
                    let cr = meta
                        .range
                        .map(|r| format!(" ctrlrange=\"{} {}\"", f(r[0] * g), f(r[1] * g)))
                        .unwrap_or_default();
                    format!(
                        "<position name=\"{}\" joint=\"{}\"{gear} kp=\"{}\" kv=\"{}\"{cr}{fr}/>",
                        esc(name),
                        esc(&j.name),
                        f(kp),
                        f(kv)
                    )
                }
                Interface::Velocity => {
                    let kv = effort.map_or(10.0, |e| self.opts.velocity_kv_per_effort * e);
                    let cr = meta
                        .velocity_limit
                        .map(|v| format!(" ctrlrange=\"{} {}\"", f(-v * g.abs()), f(v * g.abs())))
                        .unwrap_or_default();
                    format!(
                        "<velocity name=\"{}\" joint=\"{}\"{gear} kv=\"{}\"{cr}{fr}/>",
                        esc(name),
                        esc(&j.name),
                        f(kv)
                    )
                }
            };
            let _ = writeln!(act, "    {line}");
        }
        if !act.is_empty() {
            let _ = writeln!(x, "  <actuator>\n{act}  </actuator>");
        }

        let mut sens = String::new();
        if self.opts.joint_sensors {
            for j in &robot.joints {
                if matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic) {
                    let n = esc(&j.name);
                    let _ = writeln!(sens, "    <jointpos name=\"{n}_pos\" joint=\"{n}\"/>");
                    let _ = writeln!(sens, "    <jointvel name=\"{n}_vel\" joint=\"{n}\"/>");
                }
            }
        }
        for s in &self.sensor_xml {
            let _ = writeln!(sens, "    {s}");
        }
        if !sens.is_empty() {
            let _ = writeln!(x, "  <sensor>\n{sens}  </sensor>");
        }
        if let Some(q) = home {
            let _ = writeln!(x, "  <keyframe>\n    <key name=\"home\" qpos=\"{}\"/>\n  </keyframe>", fv(q));
        }
        let _ = writeln!(x, "</mujoco>");
        Ok(x)
    }

    fn emit_root(&self, x: &mut String, link: usize, base_z: f64) -> Result<()> {
        let name = esc(&self.robot.links[link].name);
        let pos = if base_z != 0.0 { format!(" pos=\"0 0 {}\"", f(base_z)) } else { String::new() };
        let _ = writeln!(x, "    <body name=\"{name}\"{pos}>");
        if self.floating {
            let _ = writeln!(x, "      <freejoint name=\"floating_base\"/>");
        }
        self.emit_link_content(x, link, 3)?;
        let _ = writeln!(x, "    </body>");
        Ok(())
    }

    fn emit_body(&self, x: &mut String, joint: usize, depth: usize, lift_z: f64) -> Result<()> {
        let j = &self.robot.joints[joint];
        let link = self.tree.link_index[&j.child];
        let ind = "  ".repeat(depth);
        let mut origin = j.origin;
        origin.xyz.z += lift_z;
        let _ = writeln!(x, "{ind}<body name=\"{}\"{}>", esc(&j.child), pose_attrs(&origin));
        let ji = format!("{ind}  ");
        let n = esc(&j.name);
        let axis = fv(j.axis.as_slice());
        let mut dyn_attrs = String::new();
        if j.damping > 0.0 {
            let _ = write!(dyn_attrs, " damping=\"{}\"", f(j.damping));
        }
        if j.friction > 0.0 {
            let _ = write!(dyn_attrs, " frictionloss=\"{}\"", f(j.friction));
        }
        let armature = self.opts.joint_armature.get(&j.name).copied().unwrap_or(self.opts.armature);
        if armature > 0.0 {
            let _ = write!(dyn_attrs, " armature=\"{}\"", f(armature));
        }
        if let Some(l) = &j.limit
            && l.effort > 0.0
        {
            let _ = write!(dyn_attrs, " actuatorfrcrange=\"{} {}\"", f(-l.effort), f(l.effort));
        }
        match j.kind {
            JointKind::Fixed => {}
            JointKind::Revolute | JointKind::Prismatic => {
                let ty = if j.kind == JointKind::Revolute { "hinge" } else { "slide" };
                let range =
                    j.limit.as_ref().map(|l| format!(" range=\"{} {}\"", f(l.lower), f(l.upper))).unwrap_or_default();
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"{ty}\" axis=\"{axis}\"{range}{dyn_attrs}/>");
            }
            JointKind::Continuous => {
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"hinge\" axis=\"{axis}\"{dyn_attrs}/>");
            }
            JointKind::Spherical => {
                let range = j
                    .limit
                    .as_ref()
                    .filter(|l| l.upper > 0.0)
                    .map(|l| format!(" range=\"0 {}\"", f(l.upper)))
                    .unwrap_or_default();
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"ball\"{range}{dyn_attrs}/>");
            }
            JointKind::Planar => {
                let normal = j.axis;
                let u = if normal.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
                let u = (u - normal * normal.dot(&u)).normalize();
                let v = normal.cross(&u);
                let _ =
                    writeln!(x, "{ji}<joint name=\"{n}_tx\" type=\"slide\" axis=\"{}\"{dyn_attrs}/>", fv(u.as_slice()));
                let _ =
                    writeln!(x, "{ji}<joint name=\"{n}_ty\" type=\"slide\" axis=\"{}\"{dyn_attrs}/>", fv(v.as_slice()));
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"hinge\" axis=\"{axis}\"{dyn_attrs}/>");
            }
            JointKind::Floating => {
                let parent = self.tree.link_index[&j.parent];
                if !(self.world_root && parent == self.tree.root) {
                    return Err(self.urdf_err(
                        j.line,
                        "joint",
                        &j.name,
                        "a floating joint is only supported between the world link and the robot's base (MuJoCo free joints belong to top-level bodies)".into(),
                    ));
                }
                let _ = writeln!(x, "{ji}<freejoint name=\"{n}\"/>");
            }
        }
        self.emit_link_content(x, link, depth + 1)?;
        let _ = writeln!(x, "{ind}</body>");
        Ok(())
    }

    fn emit_link_content(&self, x: &mut String, li: usize, depth: usize) -> Result<()> {
        let ind = "  ".repeat(depth);
        let link = &self.robot.links[li];
        if let Some((pos, fi, mass)) = &self.inertials[li] {
            let p = format!(" pos=\"{}\"", fv(pos));
            let _ = writeln!(x, "{ind}<inertial{p} mass=\"{}\" fullinertia=\"{}\"/>", f(*mass), fv(fi));
        }
        let gz_rgba = self.robot.gazebo.get(&link.name).and_then(|g| g.material.as_deref()).and_then(gazebo_rgba);
        let (ct, ca) = self.contype(link);
        let mu = self.mu[li];
        let prio = self.priority_of(mu);
        let prio = if prio != 0 { format!(" priority=\"{prio}\"") } else { String::new() };
        let rgba_c = link.visuals.first().and_then(|v| v.rgba).or(gz_rgba);
        // Zero friction: frictionless contacts (a zero-width friction cone is degenerate).
        let condim = if mu <= 0.0 { " condim=\"1\"" } else { "" };
        for (gi, g) in link.collisions.iter().enumerate() {
            let rgba = rgba_c.map(|c| format!(" rgba=\"{}\"", fv(&c))).unwrap_or_default();
            let _ = writeln!(
                x,
                "{ind}<geom name=\"{}_collision_{gi}\"{} contype=\"{ct}\" conaffinity=\"{ca}\" group=\"3\" friction=\"{} 0.005 0.0001\"{condim}{prio}{rgba}/>",
                esc(&link.name),
                self.geom_attrs(li, false, gi, g),
                f(mu)
            );
        }
        if self.opts.visuals {
            for (gi, g) in link.visuals.iter().enumerate() {
                let rgba = g.rgba.or(gz_rgba).map(|c| format!(" rgba=\"{}\"", fv(&c))).unwrap_or_default();
                let _ = writeln!(
                    x,
                    "{ind}<geom name=\"{}_visual_{gi}\"{} contype=\"0\" conaffinity=\"0\" group=\"2\"{rgba}/>",
                    esc(&link.name),
                    self.geom_attrs(li, true, gi, g)
                );
            }
        }
        for s in &self.sites[li] {
            let _ = writeln!(x, "{ind}{s}");
        }
        for c in &self.cameras[li] {
            let _ = writeln!(x, "{ind}{c}");
        }
        for &j in &self.tree.children[li] {
            self.emit_body(x, j, depth, 0.0)?;
        }
        Ok(())
    }

    fn geom_attrs(&self, li: usize, visual: bool, gi: usize, g: &GeomIr) -> String {
        let shape = match &g.shape {
            Shape::Box(s) => format!(" type=\"box\" size=\"{}\"", fv(&[s[0] / 2.0, s[1] / 2.0, s[2] / 2.0])),
            Shape::Cylinder { radius, length } => {
                format!(" type=\"cylinder\" size=\"{} {}\"", f(*radius), f(length / 2.0))
            }
            Shape::Capsule { radius, length } => {
                format!(" type=\"capsule\" size=\"{} {}\"", f(*radius), f(length / 2.0))
            }
            Shape::Sphere(r) => format!(" type=\"sphere\" size=\"{}\"", f(*r)),
            Shape::Mesh { .. } => {
                let m = &self.meshes[self.mesh_of[&(li, visual, gi)]];
                format!(" type=\"mesh\" mesh=\"{}\"", esc(&m.name))
            }
        };
        format!("{shape}{}", pose_attrs(&g.pose))
    }
}

/// Gyro and accelerometer noise standard deviations of a Gazebo `<sensor type="imu">`.
fn imu_noise(sensor: roxmltree::Node<'_, '_>) -> (f64, f64) {
    let Some(imu) = ir::child(sensor, "imu") else {
        return (0.0, 0.0);
    };
    let stddev_under = |n: Option<roxmltree::Node<'_, '_>>| -> f64 {
        n.map(|n| {
            n.descendants()
                .filter(|d| d.has_tag_name("stddev"))
                .filter_map(|d| d.text().and_then(ir::parse_num))
                .fold(0.0, f64::max)
        })
        .unwrap_or(0.0)
    };
    let mut gyro = stddev_under(ir::child(imu, "angular_velocity"));
    let mut accel = stddev_under(ir::child(imu, "linear_acceleration"));
    // Gazebo classic's older form: <imu><noise><rate><stddev>, <accel><stddev>.
    if let Some(n) = ir::child(imu, "noise") {
        gyro = gyro.max(stddev_under(ir::child(n, "rate")));
        accel = accel.max(stddev_under(ir::child(n, "accel")));
    }
    (gyro, accel)
}

/// ROS topic of a Gazebo sensor from its plugin: ROS 2 `<ros><namespace>` + `<remapping>`
/// (`~/out:=imu/data`), ROS 1 `<robotNamespace>` + `<topicName>`, or the sensor's `<topic>`.
fn resolve_topic(sensor: roxmltree::Node<'_, '_>) -> Option<String> {
    let join = |ns: &str, rel: &str| -> String {
        if rel.starts_with('/') {
            rel.to_string()
        } else {
            let ns = ns.trim_end_matches('/');
            let ns = if ns.starts_with('/') || ns.is_empty() { ns.to_string() } else { format!("/{ns}") };
            format!("{ns}/{rel}")
        }
    };
    if let Some(p) = ir::child(sensor, "plugin") {
        let plugin_name = p.attribute("name").unwrap_or("plugin");
        if let Some(ros) = ir::child(p, "ros") {
            let ns = ir::child_text(ros, "namespace").unwrap_or("");
            let mut out = None;
            for r in ir::children(ros, "remapping") {
                let t = r.text().unwrap_or("").trim();
                if let Some((from, to)) = t.split_once(":=")
                    && (from == "~/out" || from == "out")
                {
                    out = Some(to.to_string());
                }
            }
            let topic = match out {
                Some(to) if to.starts_with("~/") => join(ns, &format!("{plugin_name}/{}", &to[2..])),
                Some(to) => join(ns, &to),
                None => join(ns, &format!("{plugin_name}/out")),
            };
            return Some(topic);
        }
        if let Some(t) = ir::child_text(p, "topicName").or_else(|| ir::child_text(p, "topic_name")) {
            let ns = ir::child_text(p, "robotNamespace").unwrap_or("");
            return Some(join(ns, t));
        }
    }
    ir::child_text(sensor, "topic").map(|t| join("", t))
}

/// Metadata of a compiled model for callers that only have a [`Model`]: the joints with an
/// actuator, with the actuator id (first actuator acting on each joint).
pub fn actuated_joints(model: &Model) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for a in 0..model.nu() {
        if model.actuator_trntype()[a] as u32 != mujoco_sys::mjtTrn_mjTRN_JOINT {
            continue;
        }
        let j = model.actuator_trnid()[a][0];
        if j >= 0 && !out.iter().any(|&(jj, _)| jj == j as usize) {
            let j = j as usize;
            if matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
                out.push((j, a));
            }
        }
    }
    let _ = ObjType::Joint;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repair_makes_valid_inertia_with_small_change() {
        let bad = [1.0, 0.0, 0.0, 1.0, 0.0, 3.0];
        assert!(crate::urdf::check_inertia(bad).is_err());
        let (fixed, msg) = repair_inertia(bad);
        assert!(crate::urdf::check_inertia(fixed).is_ok(), "{fixed:?}");
        // Projection onto a + b = c: each moment moves by (3 − 2)/3.
        assert!((fixed[0] - (1.0 + 1.0 / 3.0)).abs() < 1e-6, "{fixed:?}");
        assert!((fixed[5] - (3.0 - 1.0 / 3.0)).abs() < 1e-6, "{fixed:?}");
        assert!(msg.contains("triangle"));
        let not_pd = [1.0, 2.0, 0.0, 1.0, 0.0, 1.0];
        let (fixed, _) = repair_inertia(not_pd);
        assert!(crate::urdf::check_inertia(fixed).is_ok(), "{fixed:?}");
    }

    #[test]
    fn topics_resolve_like_gazebo_ros() {
        let doc = roxmltree::Document::parse(
            "<sensor><plugin name=\"imu_plugin\"><ros><namespace>/humanoid</namespace><remapping>~/out:=imu/data</remapping></ros></plugin></sensor>",
        )
        .unwrap();
        assert_eq!(resolve_topic(doc.root_element()).as_deref(), Some("/humanoid/imu/data"));
        let doc = roxmltree::Document::parse(
            "<sensor><plugin name=\"p\"><ros><namespace>robot</namespace></ros></plugin></sensor>",
        )
        .unwrap();
        assert_eq!(resolve_topic(doc.root_element()).as_deref(), Some("/robot/p/out"));
        let doc = roxmltree::Document::parse(
            "<sensor><plugin name=\"p\"><robotNamespace>r1</robotNamespace><topicName>imu</topicName></plugin></sensor>",
        )
        .unwrap();
        assert_eq!(resolve_topic(doc.root_element()).as_deref(), Some("/r1/imu"));
    }
}
