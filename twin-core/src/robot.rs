//! The robot, loaded once: the compiled [`Model`] plus what twin knows beyond MuJoCo (name,
//! floating base, feet and end-effectors, IMUs, cameras, joint limits, actuators and their
//! command interface). Every command (`twin sim`, `randomize`, `check`, `sysid`, `view`) starts
//! from a [`Robot`]; its ROS 2 topics come from [`crate::topics::TopicTable::new`].
//!
//! ```no_run
//! let robot = twin_core::robot::Robot::load("models/humanoid.urdf")?;
//! println!("{}: {} joints, feet {:?}", robot.name, robot.joints.len(), robot.body_names(&robot.feet));
//! # Ok::<(), twin_core::Error>(())
//! ```
//!
//! ## Where the metadata comes from
//! - URDF: twin's converter ([`crate::convert`]) gives IMU topics, rates and noise, joint
//!   velocity/effort limits and each actuator's command interface ([`RobotMeta`]).
//! - MJCF or scene: what the compiled model holds (IMUs as `<name>_gyro` + `<name>_accel`
//!   sensor pairs with their `noise`, published on `/<robot>/<name>`; effort limits from
//!   `actuatorfrcrange`; the interface from the actuator's gain/bias).
//!   [`crate::convert::robot_meta`] is the one place where metadata stored in an MJCF (by
//!   `twin convert`) is read.
//! - Feet and end-effectors come from the kinematic tree and the geometry, never from names.

use crate::convert::{ConvertOptions, ImuMeta, Interface, JointMeta, RobotMeta, SensorMeta};
use crate::error::Result;
use crate::mj::{BiasType, Data, FreeJoint, GeomType, JointType, Model, ObjType, SensorType, Transmission};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// An IMU bound to the compiled model: its description ([`ImuMeta`], the one IMU metadata
/// type, as the converter writes it) and where its values are.
#[derive(Debug, Clone, PartialEq)]
pub struct Imu {
    /// Name, site, rate, noise, topic (always set here) and `frame_id`.
    pub meta: ImuMeta,
    /// Body the IMU is mounted on.
    pub body: usize,
    /// IMU site pose in its body frame: position (m) and quaternion w x y z.
    pub body_from_imu: ([f64; 3], [f64; 4]),
    /// Address of the framequat values (w x y z) in `sensordata`, when the IMU has one.
    pub quat_adr: Option<usize>,
    /// Address of the gyroscope values (rad/s, IMU frame) in `sensordata`.
    pub gyro_adr: usize,
    /// Address of the accelerometer values (m/s², IMU frame) in `sensordata`.
    pub accel_adr: usize,
}

impl Imu {
    /// The ROS topic (resolved at load).
    pub fn topic(&self) -> &str {
        self.meta.topic.as_deref().unwrap_or(&self.meta.name)
    }
}

/// A camera of the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// MuJoCo camera id.
    pub id: usize,
    /// Name.
    pub name: String,
    /// Body it is attached to.
    pub body: usize,
}

/// A 1-DOF (hinge or slide) joint with its limits: what `/joint_states` carries.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// MuJoCo joint id.
    pub id: usize,
    /// Name.
    pub name: String,
    /// Hinge (radians) or slide (metres).
    pub kind: JointType,
    /// Address in `qpos`.
    pub qpos_adr: usize,
    /// Address in `qvel` (its DOF).
    pub dof: usize,
    /// Position range, rad or m, when limited.
    pub range: Option<[f64; 2]>,
    /// Velocity limit, rad/s or m/s, when the source gives one (URDF `<limit velocity>`).
    pub velocity_limit: Option<f64>,
    /// Effort limit, N·m or N (URDF `<limit effort>`, MJCF `actuatorfrcrange`).
    pub effort_limit: Option<f64>,
}

/// An actuator and its command interface.
#[derive(Debug, Clone, PartialEq)]
pub struct Actuator {
    /// MuJoCo actuator id (its index in `ctrl`).
    pub id: usize,
    /// Name.
    pub name: String,
    /// The 1-DOF joint it drives, when its transmission is a joint.
    pub joint: Option<usize>,
    /// Gear (joint torque = gear · actuator force).
    pub gear: f64,
    /// What a command means: torque, position or velocity.
    pub interface: Interface,
    /// Control range, when limited.
    pub ctrl_range: Option<[f64; 2]>,
}

impl Actuator {
    /// The torque (a force, on a slide joint) this actuator can apply to its joint,
    /// `[least, most]`, N·m or N: its actuator force (a motor's control range times its gain;
    /// any actuator's force range, where limited) times its gear, within the joint's
    /// actuator-force range; infinite where nothing limits it, `[0, 0]` with a zero gear. The
    /// one reading of an actuator's strength (the gain rule of pd-hold and `twin check`, the
    /// walker's torque budget).
    pub fn joint_effort_range(&self, model: &Model) -> [f64; 2] {
        if self.gear == 0.0 {
            return [0.0, 0.0];
        }
        let mut force = [f64::NEG_INFINITY, f64::INFINITY];
        if let (Interface::Effort, Some([lo, hi])) = (self.interface, self.ctrl_range) {
            // A `dcmotor` driven by torque feed-forward (a drive model's envelope) delivers its
            // command as force within the envelope: gain 1 (its `gainprm[0]` is a resistance).
            let gain = if model.actuator_dyn(self.id) == crate::mj::DynType::Dcmotor {
                1.0
            } else {
                model.actuator_gainprm()[self.id][0]
            };
            force = [(lo * gain).min(hi * gain), (lo * gain).max(hi * gain)];
        }
        if model.actuator_forcelimited()[self.id] {
            let [lo, hi] = model.actuator_forcerange()[self.id];
            force = [force[0].max(lo), force[1].min(hi)];
        }
        let (a, b) = (force[0] * self.gear, force[1] * self.gear);
        let mut torque = [a.min(b), a.max(b)];
        if let Some(joint) = self.joint.filter(|&j| model.jnt_actfrclimited()[j]) {
            let [lo, hi] = model.jnt_actfrcrange()[joint];
            torque = [torque[0].max(lo), torque[1].min(hi)];
        }
        torque
    }

    /// The torque this actuator can apply to its joint either way, N·m or N: the smaller
    /// magnitude of [`Actuator::joint_effort_range`] (infinite where unlimited).
    pub fn joint_effort(&self, model: &Model) -> f64 {
        let [lo, hi] = self.joint_effort_range(model);
        lo.abs().min(hi.abs())
    }
}

/// A compiled robot and what twin knows about it beyond the model.
#[derive(Debug, Clone)]
pub struct Robot {
    /// The model.
    pub model: Arc<Model>,
    /// Robot name: topic prefix (`/<name>/joint_commands`); ASCII letters, digits and `_`.
    pub name: String,
    /// The file it came from.
    pub path: PathBuf,
    /// The floating base (the free joint), if any.
    pub base: Option<FreeJoint>,
    /// Feet: bodies that carry the robot in its home pose (see [`find_feet`]), in body order.
    pub feet: Vec<usize>,
    /// End-effectors: leaf bodies of the kinematic tree that have geometry, in body order.
    pub end_effectors: Vec<usize>,
    /// IMUs.
    pub imus: Vec<Imu>,
    /// Cameras.
    pub cameras: Vec<Camera>,
    /// Non-IMU sensors the file describes (Gazebo cameras and LiDARs become
    /// [`crate::sense::RaySensor`]s).
    pub sensors: Vec<SensorMeta>,
    /// 1-DOF joints, in model order.
    pub joints: Vec<Joint>,
    /// Actuators, in `ctrl` order.
    pub actuators: Vec<Actuator>,
    /// Where commands go: `ctrl` (actuators) or `qfrc_applied` (no actuators).
    pub actuation: Actuation,
}

impl Robot {
    /// Loads a robot from a URDF (through twin's converter with default options), an MJCF or a
    /// scene.
    ///
    /// # Errors
    /// [`Error::File`](crate::Error::File) if the file can't be read; the converter's errors for a URDF;
    /// [`Error::Load`](crate::Error::Load) if MuJoCo refuses the model.
    pub fn load(path: impl AsRef<Path>) -> Result<Robot> {
        Robot::load_with(path, &ConvertOptions::default())
    }

    /// [`Robot::load`] with converter options (used for URDFs only).
    ///
    /// # Errors
    /// As [`Robot::load`].
    pub fn load_with(path: impl AsRef<Path>, options: &ConvertOptions) -> Result<Robot> {
        Robot::load_with_extra(path, options, "")
    }

    /// [`Robot::load_with`], with `extra_mjcf` (MJCF elements such as `<option>`) added inside
    /// the converted URDF's `<mujoco>` element (e.g. `twin sysid`'s timestep and flags).
    /// Ignored for MJCF files. The one path from a file is [`crate::convert::load`].
    ///
    /// # Errors
    /// As [`Robot::load`].
    pub fn load_with_extra(path: impl AsRef<Path>, options: &ConvertOptions, extra_mjcf: &str) -> Result<Robot> {
        let path = path.as_ref();
        Robot::from_loaded(path, crate::convert::load(path, options, extra_mjcf)?)
    }

    /// [`Robot::load_with_extra`] of a file whose text the caller has already read (`text`,
    /// the contents of `path`): [`crate::convert::load_str`].
    ///
    /// # Errors
    /// As [`Robot::load`].
    pub fn load_str_with_extra(path: &Path, text: &str, options: &ConvertOptions, extra_mjcf: &str) -> Result<Robot> {
        Robot::from_loaded(path, crate::convert::load_str(path, text, options, extra_mjcf)?)
    }

    /// The robot of a loaded file: the model with the metadata its file gives.
    fn from_loaded(path: &Path, loaded: crate::convert::Loaded) -> Result<Robot> {
        // A URDF's metadata from its conversion; an MJCF's from the `<custom>` texts that
        // `twin convert` writes (other MJCFs carry none beyond the model itself: sensor noise,
        // `actuatorfrcrange`, which `from_parts` reads).
        let meta = match loaded.converted {
            Some(converted) => Some(converted.meta),
            None => crate::convert::robot_meta(&loaded.model),
        };
        Robot::from_parts(Arc::new(loaded.model), path, meta)
    }

    /// A robot from a compiled model alone, named `name` (IMUs, limits and interfaces as the
    /// model holds them). [`Robot::from_parts`] with no metadata takes the model's own name.
    ///
    /// # Errors
    /// [`Error::MuJoCo`](crate::Error::MuJoCo) if MuJoCo fails while posing the model to find its feet.
    pub fn from_model(model: Arc<Model>, name: &str, path: &Path) -> Result<Robot> {
        let meta = RobotMeta { name: name.to_string(), ..RobotMeta::default() };
        Robot::from_parts(model, path, Some(meta))
    }

    /// A robot from a compiled model of `path` and the metadata its file gives.
    ///
    /// # Errors
    /// [`Error::MuJoCo`](crate::Error::MuJoCo) if MuJoCo fails while posing the model to find its feet.
    pub fn from_parts(model: Arc<Model>, path: &Path, meta: Option<RobotMeta>) -> Result<Robot> {
        let meta = meta.unwrap_or_default();
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("robot");
        // The file's robot name, else the model's own name, else the file name.
        let raw_name = Some(meta.name.as_str())
            .filter(|n| !n.is_empty())
            .or(Some(model.model_name()).filter(|n| !n.is_empty() && *n != "MuJoCo Model"))
            .unwrap_or(stem);
        let name: String =
            raw_name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
        let imus = find_imus(&model, &name, &meta.imus);
        let joints = (0..model.njnt())
            .filter(|&j| matches!(model.joint_type(j), JointType::Hinge | JointType::Slide))
            .map(|j| {
                let jname = model.name(ObjType::Joint, j).to_string();
                let from_file = meta.joints.iter().find(|m| m.name == jname);
                let effort_from_model = model.jnt_actfrclimited()[j].then(|| {
                    let [lo, hi] = model.jnt_actfrcrange()[j];
                    lo.abs().min(hi.abs())
                });
                Joint {
                    id: j,
                    kind: model.joint_type(j),
                    qpos_adr: model.jnt_qposadr()[j] as usize,
                    dof: model.jnt_dofadr()[j] as usize,
                    range: model.jnt_limited()[j].then(|| model.jnt_range()[j]),
                    velocity_limit: from_file.and_then(|m| m.velocity_limit),
                    effort_limit: from_file.and_then(|m| m.effort_limit).or(effort_from_model),
                    name: jname,
                }
            })
            .collect();
        let actuators = actuators_of(&model, &meta.joints);
        let cameras = (0..model.ncam())
            .map(|c| Camera {
                id: c,
                name: model.name(ObjType::Camera, c).to_string(),
                body: model.cam_bodyid()[c] as usize,
            })
            .collect();
        let base = model.free_joint();
        let feet = match base {
            Some(_) => find_feet(&model)?,
            None => Vec::new(),
        };
        let end_effectors = end_effectors(&model);
        Ok(Robot {
            actuation: Actuation::of(&model),
            model,
            name,
            path: path.to_path_buf(),
            base,
            feet,
            end_effectors,
            imus,
            cameras,
            sensors: meta.sensors.clone(),
            joints,
            actuators,
        })
    }

    /// The floating base body, if any.
    pub fn base_body(&self) -> Option<usize> {
        self.base.map(|b| b.body)
    }

    /// Names of bodies (e.g. of [`Robot::feet`]).
    pub fn body_names(&self, bodies: &[usize]) -> Vec<String> {
        bodies.iter().map(|&b| self.model.name(ObjType::Body, b).to_string()).collect()
    }

    /// The same robot on another model of the same layout (e.g. one randomized episode's):
    /// every id and address stays valid.
    ///
    /// # Errors
    /// [`Error::Size`](crate::Error::Size) when `model` does not have this robot's layout.
    pub fn with_model(&self, model: Arc<Model>) -> Result<Robot> {
        crate::mj::ModelLayout::of(&self.model).require_same(&crate::mj::ModelLayout::of(&model))?;
        Ok(Robot { model, ..self.clone() })
    }
}

/// The command interface of actuator `a` from its gain and bias: a position servo has bias
/// `−kp·q`, a velocity servo `−kv·q̇`; anything else commands force.
/// The actuators of `model`, in `ctrl` order: each with the hinge or slide joint it drives (a
/// joint transmission), its gear, its control range and its command interface (what
/// `meta_joints`, the file's metadata, says; else what the actuator is in MuJoCo: a position
/// or velocity servo, else effort). [`Robot::actuators`] and every controller read them here.
pub fn actuators_of(model: &Model, meta_joints: &[JointMeta]) -> Vec<Actuator> {
    (0..model.nu())
        .map(|a| {
            let joint = (model.actuator_transmission(a) == Transmission::Joint)
                .then(|| model.actuator_trnid()[a][0])
                .filter(|&j| j >= 0)
                .map(|j| j as usize)
                .filter(|&j| matches!(model.joint_type(j), JointType::Hinge | JointType::Slide));
            let from_file = joint.and_then(|j| {
                let jname = model.name(ObjType::Joint, j);
                meta_joints.iter().find(|m| m.name == jname).and_then(|m| m.actuator.as_ref()).map(|(_, i)| *i)
            });
            Actuator {
                id: a,
                name: model.name(ObjType::Actuator, a).to_string(),
                joint,
                gear: model.actuator_gear()[a][0],
                interface: from_file.unwrap_or_else(|| interface_of(model, a)),
                ctrl_range: model.actuator_ctrllimited()[a].then(|| model.actuator_ctrlrange()[a]),
            }
        })
        .collect()
}

fn interface_of(model: &Model, a: usize) -> Interface {
    let affine = model.actuator_bias(a) == BiasType::Affine;
    let bias = model.actuator_biasprm()[a];
    if affine && bias[1] != 0.0 {
        Interface::Position
    } else if affine && bias[2] != 0.0 {
        Interface::Velocity
    } else {
        Interface::Effort
    }
}

/// The IMUs of a compiled `model` as [`Robot::imus`] finds them, without the file's metadata
/// (topics `/robot/<name>`, noise from the sensors): for controllers, which see only the model.
pub fn imus_of(model: &Model) -> Vec<Imu> {
    find_imus(model, "robot", &[])
}

/// IMUs: `<name>_gyro` (a gyro) + `<name>_accel` sensor pairs on one site, with `<name>_quat`
/// when present. `meta` (from the file) gives topics, rates and noise; otherwise the topic is
/// `/<robot>/<name>`, the `frame_id` the body, the noise the sensors' `noise`.
fn find_imus(model: &Model, robot_name: &str, meta: &[ImuMeta]) -> Vec<Imu> {
    let mut imus = Vec::new();
    let sensor = |n: &str| model.id(ObjType::Sensor, n);
    for s in 0..model.nsensor() {
        let sname = model.name(ObjType::Sensor, s);
        let Some(base) = sname.strip_suffix("_gyro") else { continue };
        if model.sensor_kind(s) != SensorType::Gyro {
            continue;
        }
        let Some(accel) = sensor(&format!("{base}_accel")) else { continue };
        let quat = sensor(&format!("{base}_quat"));
        let site = model.sensor_objid()[s] as usize;
        let body = model.site_bodyid()[site] as usize;
        let mut m = meta.iter().find(|m| m.name == base).cloned().unwrap_or_else(|| ImuMeta {
            name: base.to_string(),
            link: model.name(ObjType::Body, body).to_string(),
            site: model.name(ObjType::Site, site).to_string(),
            update_rate_hz: None,
            gyro_noise_std: model.sensor_noise()[s],
            accel_noise_std: model.sensor_noise()[accel],
            gyro_bias: Default::default(),
            accel_bias: Default::default(),
            topic: None,
            frame_id: model.name(ObjType::Body, body).to_string(),
        });
        m.update_rate_hz = m.update_rate_hz.filter(|r| *r > 0.0);
        if m.topic.is_none() {
            m.topic = Some(format!("/{robot_name}/{base}"));
        }
        imus.push(Imu {
            meta: m,
            body,
            body_from_imu: (model.site_pos()[site], model.site_quat()[site]),
            quat_adr: quat.map(|q| model.sensor_adr()[q] as usize),
            gyro_adr: model.sensor_adr()[s] as usize,
            accel_adr: model.sensor_adr()[accel] as usize,
        });
    }
    imus
}

/// Height tolerance for a body to count as touching the ground at home, metres.
const FOOT_TOLERANCE_M: f64 = 0.01;

/// The feet of a floating-base robot, from the kinematic tree and the geometry: in the home
/// pose ([`reset_to_home`]), the bodies with a collision geom within 1 cm of
/// the robot's lowest collision geom, keeping of each touching chain only its body nearest the
/// base (a toe body under a touching foot belongs to that foot). Sorted by body id.
///
/// # Errors
/// [`Error::MuJoCo`](crate::Error::MuJoCo) if MuJoCo fails while posing the model.
pub fn find_feet(model: &Model) -> Result<Vec<usize>> {
    let mut data = Data::new(Arc::new(model.try_clone()?))?;
    reset_to_home(&mut data)?;
    // The lowest collision geom: a visual mesh below the collision geometry (the G1's feet
    // touch the ground with four small spheres above the sole's mesh) touches nothing.
    let collision_lowest: Vec<(usize, f64)> = (0..model.ngeom())
        .filter(|&g| model.geom_bodyid()[g] != 0 && (model.geom_contype()[g] != 0 || model.geom_conaffinity()[g] != 0))
        .filter_map(|g| geom_lowest_z(model, &data, g).map(|z| (model.geom_bodyid()[g] as usize, z)))
        .collect();
    let lowest = collision_lowest.iter().map(|&(_, z)| z).fold(f64::INFINITY, f64::min);
    if !lowest.is_finite() {
        return Ok(Vec::new());
    }
    let mut touching = vec![false; model.nbody()];
    for &(body, z) in &collision_lowest {
        if z <= lowest + FOOT_TOLERANCE_M {
            touching[body] = true;
        }
    }
    let parent = model.body_parentid();
    let has_touching_ancestor = |mut b: usize| {
        while b != 0 {
            b = parent[b] as usize;
            if touching[b] {
                return true;
            }
        }
        false
    };
    Ok((1..model.nbody()).filter(|&b| touching[b] && !has_touching_ancestor(b)).collect())
}

/// Leaf bodies of the kinematic tree (no child body) that have at least one geom.
pub fn end_effectors(model: &Model) -> Vec<usize> {
    let parent = model.body_parentid();
    let mut has_child = vec![false; model.nbody()];
    for b in 1..model.nbody() {
        has_child[parent[b] as usize] = true;
    }
    let mut has_geom = vec![false; model.nbody()];
    for &b in model.geom_bodyid() {
        has_geom[b as usize] = true;
    }
    (1..model.nbody()).filter(|&b| !has_child[b] && has_geom[b]).collect()
}

/// Where a command goes: `ctrl` when the model has actuators, else `qfrc_applied`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Actuation {
    /// Command = `ctrl` (len `nu`), clamped to each actuator's `ctrlrange` when limited.
    Ctrl,
    /// Command = `qfrc_applied` (len `nv`), clamped to each joint's effort (`actuatorfrcrange`)
    /// when limited; free and ball joints get none.
    Qfrc,
}

impl Actuation {
    /// [`Actuation::Ctrl`] for models with actuators, else [`Actuation::Qfrc`].
    pub fn of(model: &Model) -> Actuation {
        if model.nu() > 0 { Actuation::Ctrl } else { Actuation::Qfrc }
    }

    /// Length of a command: `nu` or `nv`.
    pub fn len(self, model: &Model) -> usize {
        match self {
            Actuation::Ctrl => model.nu(),
            Actuation::Qfrc => model.nv(),
        }
    }

    /// Whether a command is empty (a model without actuators and DOFs).
    pub fn is_empty(self, model: &Model) -> bool {
        self.len(model) == 0
    }

    /// Limits of each command entry, `[low, high]` (infinite where unlimited; zero for the
    /// DOFs of free and ball joints under [`Actuation::Qfrc`], which no motor drives).
    pub fn limits(self, model: &Model) -> Vec<[f64; 2]> {
        match self {
            Actuation::Ctrl => (0..model.nu())
                .map(|u| {
                    if model.actuator_ctrllimited()[u] {
                        model.actuator_ctrlrange()[u]
                    } else {
                        [f64::NEG_INFINITY, f64::INFINITY]
                    }
                })
                .collect(),
            Actuation::Qfrc => (0..model.nv())
                .map(|dof| {
                    let joint = model.dof_jntid()[dof] as usize;
                    match model.joint_type(joint) {
                        JointType::Free | JointType::Ball => [0.0, 0.0],
                        _ if model.jnt_actfrclimited()[joint] => model.jnt_actfrcrange()[joint],
                        _ => [f64::NEG_INFINITY, f64::INFINITY],
                    }
                })
                .collect(),
        }
    }

    /// Writes `command` into `data` (`ctrl` or `qfrc_applied`). MuJoCo clamps `ctrl` to limited
    /// control ranges itself; controllers clamp `qfrc_applied` commands (see [`Actuation::limits`]).
    ///
    /// # Panics
    /// If `command` does not have [`Actuation::len`] entries.
    pub fn apply(self, data: &mut Data, command: &[f64]) {
        match self {
            Actuation::Ctrl => data.ctrl_mut().copy_from_slice(command),
            Actuation::Qfrc => data.qfrc_applied_mut().copy_from_slice(command),
        }
    }
}

/// The pose a robot is meant to hold: keyframe `home` if the model has one, else `qpos0`
/// (len `nq`).
pub fn nominal_pose(model: &Model) -> Vec<f64> {
    model.id(ObjType::Key, "home").and_then(|k| model.key_qpos(k)).unwrap_or_else(|| model.qpos0()).to_vec()
}

/// Puts `data` in the model's standing pose: keyframe `home` if the model has one; otherwise
/// `qpos0` with the floating base raised or lowered so that the lowest robot geom touches
/// z = 0. Runs `forward` so positions and sensors are current.
///
/// # Errors
/// As [`Data::forward`].
pub fn reset_to_home(data: &mut Data) -> Result<()> {
    let model = data.model().clone();
    if let Some(key) = model.id(ObjType::Key, "home") {
        data.reset_to_keyframe(key)?;
        return Ok(data.forward()?);
    }
    data.reset()?;
    data.forward()?;
    let Some(base) = model.free_joint() else {
        return Ok(());
    };
    let lowest = lowest_robot_point_z(&model, data);
    if lowest.is_finite() {
        data.qpos_mut()[base.qpos_adr + 2] -= lowest;
        data.forward()?;
    }
    Ok(())
}

/// Lowest z (world frame, metres) of any geom not attached to the world body, from the geoms'
/// current poses; +inf when there is none.
pub fn lowest_robot_point_z(model: &Model, data: &Data) -> f64 {
    (0..model.ngeom())
        .filter(|&g| model.geom_bodyid()[g] != 0)
        .filter_map(|g| geom_lowest_z(model, data, g))
        .fold(f64::INFINITY, f64::min)
}

/// Lowest z (world frame, metres) of geom `g` in its current pose: exact for spheres,
/// capsules, cylinders, boxes and ellipsoids; the bounding sphere for meshes and others
/// (conservative: may leave a small gap); `None` for planes.
pub fn geom_lowest_z(model: &Model, data: &Data, g: usize) -> Option<f64> {
    let z = data.geom_xpos()[g][2];
    let size = model.geom_size()[g];
    let m = data.geom_xmat()[g];
    // Row z of the geom's world rotation: the world z component of each of its local axes.
    let r = [m[6], m[7], m[8]];
    let extent = match model.geom_kind(g) {
        GeomType::Sphere => size[0],
        GeomType::Capsule => size[0] + size[1] * r[2].abs(),
        GeomType::Cylinder => size[0] * (1.0 - r[2] * r[2]).max(0.0).sqrt() + size[1] * r[2].abs(),
        GeomType::Box => (0..3).map(|k| size[k] * r[k].abs()).sum(),
        GeomType::Ellipsoid => (0..3).map(|k| (size[k] * r[k]).powi(2)).sum::<f64>().sqrt(),
        GeomType::Plane => return None,
        _ => model.geom_rbound()[g],
    };
    Some(z - extent)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One reading of an actuator's strength: a motor's command range × gain × gear, within its
    /// force range (× gear) and the joint's actuator-force range; a servo's force range × gear.
    #[test]
    fn joint_effort_is_force_times_gear_within_the_joints_range() {
        let xml = r#"<mujoco><worldbody><body><joint name="a" axis="0 1 0"/><geom size="0.1"/>
            <body><joint name="b" axis="0 1 0" actuatorfrcrange="-12 12"/><geom size="0.1"/>
            <body><joint name="c" axis="0 1 0"/><geom size="0.1"/>
            <body><joint name="d" axis="0 1 0"/><geom size="0.1"/></body></body></body></body></worldbody>
            <actuator>
              <motor joint="a" gear="2" ctrlrange="-10 10" forcerange="-8 9" forcelimited="true"/>
              <motor joint="b" gear="2" ctrlrange="-10 10"/>
              <position joint="c" gear="3" kp="100" forcerange="-5 6" forcelimited="true"/>
              <position joint="d" kp="100"/>
            </actuator></mujoco>"#;
        let model = Model::from_xml_str(xml).unwrap();
        let acts = actuators_of(&model, &[]);
        let ranges: Vec<[f64; 2]> = acts.iter().map(|a| a.joint_effort_range(&model)).collect();
        // a: force within ±10 and [−8, 9] → [−8, 9], × 2; b: ±10 × 2 = ±20 within the joint's ±12;
        // c: [−5, 6] × 3; d: nothing limits it.
        assert_eq!(ranges[0], [-16.0, 18.0]);
        assert_eq!(ranges[1], [-12.0, 12.0]);
        assert_eq!(ranges[2], [-15.0, 18.0]);
        assert_eq!(ranges[3], [f64::NEG_INFINITY, f64::INFINITY]);
        assert_eq!(acts[2].joint_effort(&model), 15.0);
        assert!(acts[3].joint_effort(&model).is_infinite());
    }

    /// Feet named neither `foot` nor `ankle`, with a toe body under one of them, and arms whose
    /// hands hang lower than the pelvis but above the ground.
    const ROBOT: &str = r#"<mujoco><worldbody><geom type="plane" size="5 5 0.1"/>
        <body name="pelvis" pos="0 0 1"><freejoint/><geom type="box" size="0.1 0.15 0.05"/>
          <body name="l_arm" pos="0 0.2 0"><joint name="l_sh" axis="0 1 0"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.03"/>
            <body name="l_hand" pos="0 0 -0.55"><geom type="sphere" size="0.04"/></body></body>
          <body name="thigh_a" pos="0 0.1 -0.05"><joint name="hip_a" axis="0 1 0" actuatorfrcrange="-30 30"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.8" size="0.04"/>
            <body name="sole_a" pos="0 0 -0.85"><joint name="ank_a" axis="0 1 0"/>
              <geom type="box" size="0.1 0.05 0.02" pos="0.02 0 -0.07"/>
              <body name="toe_a" pos="0.12 0 -0.07"><joint name="toe_j" axis="0 1 0"/>
                <geom type="box" size="0.03 0.05 0.02"/></body></body></body>
          <body name="thigh_b" pos="0 -0.1 -0.05"><joint name="hip_b" axis="0 1 0"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.8" size="0.04"/>
            <body name="sole_b" pos="0 0 -0.85"><joint name="ank_b" axis="0 1 0"/>
              <geom type="box" size="0.1 0.05 0.02" pos="0.02 0 -0.07"/></body></body>
        </body></worldbody>
        <sensor><gyro name="imu_gyro" site="imu"/><accelerometer name="imu_accel" site="imu"/></sensor>
        </mujoco>"#;

    #[test]
    fn feet_and_end_effectors_come_from_tree_and_geometry() {
        let xml = ROBOT.replace(
            r#"<geom type="box" size="0.1 0.15 0.05"/>"#,
            r#"<geom type="box" size="0.1 0.15 0.05"/><site name="imu" pos="0 0 0.05"/>"#,
        );
        let model = Arc::new(Model::from_xml_str(&xml).unwrap());
        let robot = Robot::from_model(model.clone(), "biped bot", Path::new("biped.xml")).unwrap();
        assert_eq!(robot.name, "biped_bot");
        assert_eq!(robot.body_names(&robot.feet), ["sole_a", "sole_b"], "the toe belongs to its foot");
        assert_eq!(robot.body_names(&robot.end_effectors), ["l_hand", "toe_a", "sole_b"]);
        let base = robot.base.unwrap();
        assert_eq!((base.body, base.qpos_adr, base.dof), (1, 0, 0));
        assert_eq!(robot.imus.len(), 1);
        assert_eq!(robot.imus[0].topic(), "/biped_bot/imu");
        assert_eq!(robot.joints.len(), 6);
        assert_eq!(robot.joints[1].effort_limit, Some(30.0));
        assert_eq!(robot.actuation, Actuation::Qfrc);
        // Fixed base: nothing stands, so no feet.
        let fixed = Model::from_xml_str(&xml.replace("<freejoint/>", "")).unwrap();
        let robot = Robot::from_model(Arc::new(fixed), "arm", Path::new("arm.xml")).unwrap();
        assert!(robot.base.is_none() && robot.feet.is_empty());
    }
}
