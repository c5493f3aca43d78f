//! What a conversion can be asked to do differently; every field documents its default.

use super::Interface;
use std::path::PathBuf;

/// Actuators of movable 1-DOF joints (`twin convert --actuators`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ActuatorMode {
    /// Transmissions / `ros2_control` where declared; a `motor` within ±effort for every other
    /// movable joint with an effort limit (default).
    #[default]
    Auto,
    /// Only joints named by a transmission or `ros2_control` entry get an actuator.
    Transmissions,
    /// A `motor` on every movable joint (declared interfaces ignored; gear kept).
    Motor,
    /// A `position` servo on every movable joint (gains from
    /// [`ConvertOptions::position_kp_per_effort`] and [`ConvertOptions::position_kv_per_kp`]).
    Position,
    /// No actuators at all (a passive model, e.g. for identification).
    None,
}

impl ActuatorMode {
    /// The interface forced on every joint, if the mode forces one.
    pub(crate) fn forced(self) -> Option<Interface> {
        match self {
            ActuatorMode::Motor => Some(Interface::Effort),
            ActuatorMode::Position => Some(Interface::Position),
            _ => None,
        }
    }
}

impl std::str::FromStr for ActuatorMode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Ok(match s {
            "auto" => ActuatorMode::Auto,
            "transmissions" => ActuatorMode::Transmissions,
            "motor" => ActuatorMode::Motor,
            "position" => ActuatorMode::Position,
            "none" => ActuatorMode::None,
            other => {
                return Err(format!(
                    "unknown actuator mode \"{other}\": use auto, transmissions, motor, position or none"
                ));
            }
        })
    }
}

/// Options of the conversion. Every field documents its default.
#[derive(Debug, Clone, smart_default::SmartDefault)]
pub struct ConvertOptions {
    /// Weld the root link to the world instead of giving it a free joint (default: false).
    pub fixed_base: bool,
    /// Folders to search for `package://NAME/…` (a folder `NAME`, or one with a `package.xml`
    /// naming it, directly inside one of these); `ROS_PACKAGE_PATH` and the URDF's ancestor
    /// folders are searched after them (default: empty).
    pub package_paths: Vec<PathBuf>,
    /// Refuse inertias that violate the triangle inequality or are not positive definite
    /// (beyond floating-point noise) instead of repairing them by the smallest change of
    /// principal moments, which is listed in the notes (default: false: repair).
    pub strict_inertia: bool,
    /// Where meshes converted to OBJ are written (default: `None`: a cache folder in the
    /// system temp dir, keyed by the source file).
    pub mesh_dir: Option<PathBuf>,
    /// Gazebo SDF world or MJCF file composed with the robot (default: `None`: a floor plane and
    /// a light, see [`ConvertOptions::floor`]).
    pub world: Option<PathBuf>,
    /// Add a floor plane and a light when no world is given (default: true).
    #[default(true)]
    pub floor: bool,
    /// Let robot links collide with each other (default: false, as in Gazebo).
    pub self_collision: bool,
    /// Keep visual geoms (group 2, no contacts) (default: true).
    #[default(true)]
    pub visuals: bool,
    /// Add `jointpos`/`jointvel` sensors for every 1-DOF joint (default: true).
    #[default(true)]
    pub joint_sensors: bool,
    /// Simulation timestep, seconds (default: 0.002, Gazebo's `max_step_size`; a world file's
    /// own step wins).
    #[default(0.002)]
    pub timestep_secs: f64,
    /// Armature (reflected rotor inertia) added to every joint, kg·m² or kg (default: 0).
    pub armature: f64,
    /// Armature of individual joints by URDF joint name, kg·m² or kg, replacing
    /// [`ConvertOptions::armature`] for those joints (e.g. identified by `twin sysid`; URDF has
    /// no place for it) (default: empty).
    pub joint_armature: std::collections::BTreeMap<String, f64>,
    /// Drive model (command delay, position-loop gains, torque–speed envelope) of individual
    /// joints by URDF joint name (see [`crate::actuator`]); the URDF's `<twin_actuator>` block
    /// fills the joints the caller left out (default: empty: ideal drives).
    pub joint_drive: std::collections::BTreeMap<String, crate::actuator::DriveModel>,
    /// Give every actuator a command-history buffer spanning at least this delay, seconds,
    /// so that a delay can be set (randomized) on the compiled model up to it
    /// (default: 0: buffers only for the drive models' own delays).
    pub delay_buffer_secs: f64,
    /// Which joints get actuators, and of which kind (default: [`ActuatorMode::Auto`]).
    #[default(ActuatorMode::Auto)]
    pub actuators: ActuatorMode,
    /// Stiffness of `position` actuators per N·m of effort limit, 1/rad: kp = this × effort
    /// (default: 20, full effort at 0.05 rad error; 100 N·m/rad when no effort is given).
    #[default(20.0)]
    pub position_kp_per_effort: f64,
    /// Damping of `position` actuators as a fraction of kp, seconds: kv = this × kp
    /// (default: 0.05).
    #[default(0.05)]
    pub position_kv_per_kp: f64,
    /// Gain of `velocity` actuators per N·m of effort limit, s/rad (default: 1; 10 when no
    /// effort is given).
    #[default(1.0)]
    pub velocity_kv_per_effort: f64,
    /// Links given a contact sensor as if the URDF declared one on each
    /// (`<gazebo reference="LINK"><sensor type="contact">`), covering every collision geom of
    /// the link: a MuJoCo `touch` sensor over each, named `LINK_contact`, `LINK_contact_2`, …
    /// (a declared Gazebo sensor covers the first alone), e.g. the feet of a robot whose real
    /// feet sense load but whose URDF does not say so (default: empty). A link that already has
    /// a contact sensor keeps its own; a name that is no link is an error.
    pub contact_sensors: Vec<String>,
    /// SRDF file whose named pose (`<group_state>`) is the home pose (default: `None`: an SRDF
    /// beside the URDF, in `srdf/` beside it or in `srdf/` one folder up, that names this
    /// robot's joints; see [`crate::srdf`]).
    pub srdf: Option<PathBuf>,
    /// Name of the SRDF pose taken as home (`--pose`) (default: `None`: "standing", "home",
    /// "default" or "neutral", else one whose name says "stand" or "home"; with no such pose,
    /// the zero pose clamped into every joint's range; see [`crate::srdf`]).
    pub pose: Option<String>,
}
