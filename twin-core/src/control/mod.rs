//! Controllers: what drives a twin during a rollout ([`pd_hold`], [`passive`], [`replay`]; one
//! file each), the registry of their names ([`by_name`]), and the home pose.
//!
//! A [`Controller`] reads an [`Observation`] (time, joint positions and velocities, sensor
//! values: possibly noisy or delayed copies of the simulation's own) and writes a command. The
//! command's meaning depends on the model, through [`Actuation`]:
//!
//! - a model with actuators (`nu > 0`, e.g. the converter's humanoid with one `motor` per joint)
//!   gets `ctrl` (len `nu`);
//! - a model without actuators (e.g. MuJoCo's own URDF import) gets generalised forces written
//!   to `qfrc_applied` (len `nv`): N·m for hinges, N for slides, zero on the free joint.
//!
//! Controllers are written against [`Actuation`] so the same controller drives both kinds;
//! [`Actuation::apply`] writes a command into [`Data`], clamped to the actuators' control range
//! or the joints' effort limits.
//!
//! ```no_run
//! use std::sync::Arc;
//! use twin_core::control::{Actuation, Controller, Observation, PdHold, PdHoldOptions};
//! use twin_core::mj::{Data, Model};
//!
//! let model = Arc::new(Model::from_file("models/humanoid.xml")?);
//! let mut data = Data::new(model.clone())?;
//! twin_core::control::reset_to_home(&mut data)?;
//! let actuation = Actuation::of(&model);
//! let mut controller = PdHold::new(&model, PdHoldOptions::default());
//! controller.reset(&model, &Observation::of(&data))?;
//! let mut command = vec![0.0; actuation.len(&model)];
//! for _ in 0..1000 {
//!     controller.compute(&model, &Observation::of(&data), &mut command);
//!     actuation.apply(&mut data, &command);
//!     data.step()?;
//! }
//! # Ok::<(), twin_core::Error>(())
//! ```

mod passive;
mod pd_hold;
mod replay;

pub use passive::Passive;
pub use pd_hold::{PdHold, PdHoldOptions, PdLoop, pd_gains};
pub use replay::{JointTrajectory, Replay, ReplayOptions, TrajectoryJoint};

use crate::error::{Error, Result};
use crate::mj::{Data, JointType, Model, ObjType};

/// What a controller reads each step. Slices have the model's lengths (`nq`, `nv`,
/// `nsensordata`).
#[derive(Debug, Clone, Copy)]
pub struct Observation<'a> {
    /// Simulation time, seconds.
    pub time_secs: f64,
    /// Joint positions (len `nq`).
    pub qpos: &'a [f64],
    /// Joint velocities (len `nv`).
    pub qvel: &'a [f64],
    /// Sensor values (len `nsensordata`).
    pub sensordata: &'a [f64],
}

impl<'a> Observation<'a> {
    /// The simulation's exact state, without noise or delay.
    pub fn of(data: &'a Data) -> Observation<'a> {
        Observation { time_secs: data.time_secs(), qpos: data.qpos(), qvel: data.qvel(), sensordata: data.sensordata() }
    }
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

/// A closed-loop controller. One instance drives one simulation at a time; `reset` starts a new
/// episode (it may use the model, which can differ per episode after randomization).
pub trait Controller: Send {
    /// Short name, as selected on the command line (e.g. `pd-hold`).
    fn name(&self) -> &'static str;

    /// Prepares for a new episode on `model`, starting from `observation`.
    ///
    /// # Errors
    /// When the controller can't drive this model (e.g. a joint it needs is missing).
    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()>;

    /// Computes the command for the current step into `command` (len
    /// `Actuation::of(model).len(model)`, see [`Actuation`]).
    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]);

    /// Adjusts the initial joint positions `qpos` (len `nq`, the home pose) before an episode,
    /// e.g. to start a replay where its trajectory starts. Default: leaves them.
    fn initial_qpos(&self, _model: &Model, _qpos: &mut [f64]) {}

    /// Called after each step's command is applied: `Ok(false)` ends the run early (a live
    /// bridge asked to stop), an error aborts it (a lockstep controller that stopped
    /// answering). Default: go on.
    ///
    /// # Errors
    /// Whatever made the controller unable to go on.
    fn proceed(&mut self) -> Result<bool> {
        Ok(true)
    }

    /// Lines saying what the controller decided during the run (e.g. a grasp refused before
    /// moving), printed by `twin sim`. Default: none.
    fn report(&self) -> Vec<String> {
        Vec::new()
    }

    /// The controller's own topics, besides the robot's [`crate::topics::TopicTable`]: its
    /// diagnostics (a walking controller's planned footsteps, reference and measured CoM, ZMP,
    /// DCM), recorded into every sink (MCAP, rerun, live ROS 2) like the table's topics. Give each
    /// [`TopicKind::Controller`](crate::topics::TopicKind::Controller)`(k)`, k its index here.
    /// Asked once per run, before the first message; a topic appears in the sinks with its first
    /// message. Default: none.
    fn topics(&self) -> Vec<crate::topics::TopicInfo> {
        Vec::new()
    }

    /// Emits this step's messages on [`Controller::topics`]: `emit(k, log_time_nanos, message)`
    /// for topic `k`, stamped in simulation time (usually the time of the observation they were
    /// computed from), each topic in time order. A recording calls it once per step, after the
    /// step, so a controller emits what its last `compute` produced (e.g. on the steps that
    /// start a control period, at the rate it declared). Messages borrow the controller's own
    /// buffers, so nothing is allocated per call. Default: nothing.
    fn diagnostics(&self, _emit: &mut dyn FnMut(usize, u64, crate::topics::TypedMessage<'_>)) {}

    /// The joint positions the last `compute` steers to, for the tracking metrics
    /// ([`crate::tracking`]): `emit(qpos address, target)`, rad (m) — a PD hold's or a position
    /// servo's targets. Default: none (torque or velocity commands without a position target).
    fn position_targets(&self, _emit: &mut dyn FnMut(usize, f64)) {}
}

/// Names accepted by [`by_name`]: the one controller registry of twin (`twin sim`,
/// `twin randomize`).
pub const CONTROLLERS: &[&str] = &["pd-hold", "passive", "replay", "walk", "grasp"];

/// What [`by_name`] may need beyond the model.
#[derive(Debug, Clone, Default)]
pub struct ControllerOptions {
    /// Gains of `pd-hold` and `replay`. (default: [`PdHoldOptions::default`])
    pub gains: PdHoldOptions,
    /// The trajectory `replay` tracks (required for it). (default: none)
    pub trajectory: Option<JointTrajectory>,
    /// Parameters of `walk` (velocity command, gait, gains). (default: [`crate::walk::WalkOptions::default`])
    pub walk: crate::walk::WalkOptions,
    /// Parameters of `grasp` (its legs balance with `walk`). (default: [`crate::grasp::GraspOptions::default`])
    pub grasp: crate::grasp::GraspOptions,
}

/// The controller called `name` for `model`: `pd-hold` (alias `hold`) holds the nominal pose,
/// `passive` applies nothing, `replay` tracks `options.trajectory`, `walk` walks (or stands and
/// balances) with `options.walk` ([`crate::walk::Walker`]).
///
/// # Errors
/// [`Error::NotFound`] (kind `controller`) for an unknown name; [`Error::Options`] for
/// `replay` without a trajectory, or a trajectory given to another controller; as
/// [`Replay::new`] and [`crate::walk::Walker::new`].
pub fn by_name_with(name: &str, model: &Model, options: &ControllerOptions) -> Result<Box<dyn Controller>> {
    let canonical = if name == "hold" { "pd-hold" } else { name };
    if canonical != "replay" && options.trajectory.is_some() {
        return Err(Error::Options(format!("a trajectory is for the replay controller, not {name}")));
    }
    match canonical {
        "pd-hold" => Ok(Box::new(PdHold::new(model, options.gains.clone()))),
        "passive" => Ok(Box::new(Passive)),
        "replay" => {
            let Some(trajectory) = options.trajectory.clone() else {
                return Err(Error::Options(
                    "the replay controller needs a trajectory: a ROS 2 log or a CSV time_sec,<joint>,…".into(),
                ));
            };
            let replay_options = ReplayOptions { gains: options.gains.clone() };
            Ok(Box::new(Replay::new(model, trajectory, replay_options)?))
        }
        "walk" => Ok(Box::new(crate::walk::Walker::new(model, options.walk.clone())?)),
        "grasp" => Ok(Box::new(crate::grasp::Grasper::new(model, options.grasp.clone(), options.walk.clone())?)),
        _ => Err(Error::NotFound {
            kind: "controller (available: pd-hold, passive, replay, walk, grasp)",
            name: name.to_string(),
        }),
    }
}

/// [`by_name_with`] with default options (no trajectory).
///
/// # Errors
/// As [`by_name_with`].
pub fn by_name(name: &str, model: &Model) -> Result<Box<dyn Controller>> {
    by_name_with(name, model, &ControllerOptions::default())
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
        return data.forward();
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
    let extent = match model.geom_type()[g] as u32 {
        mujoco_sys::mjtGeom_mjGEOM_SPHERE => size[0],
        mujoco_sys::mjtGeom_mjGEOM_CAPSULE => size[0] + size[1] * r[2].abs(),
        mujoco_sys::mjtGeom_mjGEOM_CYLINDER => size[0] * (1.0 - r[2] * r[2]).max(0.0).sqrt() + size[1] * r[2].abs(),
        mujoco_sys::mjtGeom_mjGEOM_BOX => (0..3).map(|k| size[k] * r[k].abs()).sum(),
        mujoco_sys::mjtGeom_mjGEOM_ELLIPSOID => (0..3).map(|k| (size[k] * r[k]).powi(2)).sum::<f64>().sqrt(),
        mujoco_sys::mjtGeom_mjGEOM_PLANE => return None,
        _ => model.geom_rbound()[g],
    };
    Some(z - extent)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    const BOX: &str = r#"<mujoco><worldbody><geom type="plane" size="1 1 0.1"/>
        <body name="base" pos="0 0 0.5"><freejoint/>
          <geom type="box" size="0.1 0.2 0.05" euler="0 0.3 0"/>
          <body name="leg" pos="0 0 -0.2"><joint name="hip" axis="0 1 0" range="-1 1"
              actuatorfrcrange="-20 20"/><geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.04"/>
          </body></body></worldbody></mujoco>"#;

    #[test]
    fn home_without_keyframe_puts_the_lowest_geom_on_the_floor() {
        let model = Arc::new(Model::from_xml_str(BOX).unwrap());
        assert_eq!(model.free_joint().map(|f| f.body), model.id(ObjType::Body, "base"));
        let mut data = Data::new(model.clone()).unwrap();
        reset_to_home(&mut data).unwrap();
        // Capsule bottom: 0.2 + 0.3 + 0.04 below the base origin.
        assert!((data.qpos()[2] - 0.54).abs() < 1e-9, "{}", data.qpos()[2]);
        assert!(lowest_robot_point_z(&model, &data).abs() < 1e-9);
    }

    #[test]
    fn pd_hold_without_actuators_clamps_to_joint_effort() {
        let model = Arc::new(Model::from_xml_str(BOX).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        reset_to_home(&mut data).unwrap();
        let actuation = Actuation::of(&model);
        assert_eq!(actuation, Actuation::Qfrc);
        assert_eq!(actuation.limits(&model)[6], [-20.0, 20.0]);
        let mut pd = PdHold::new(&model, PdHoldOptions::default());
        pd.reset(&model, &Observation::of(&data)).unwrap();
        // kp = effort / saturation error.
        assert!((pd.gains()[0].0 - 20.0 / 0.25).abs() < 1e-12);
        data.qpos_mut()[7] = 0.1;
        let mut command = vec![0.0; actuation.len(&model)];
        pd.compute(&model, &Observation::of(&data), &mut command);
        assert!((command[6] + 8.0).abs() < 1e-9, "{command:?}");
        assert!(command[..6].iter().all(|&c| c == 0.0), "no force on the free joint");
        data.qpos_mut()[7] = 0.9;
        pd.compute(&model, &Observation::of(&data), &mut command);
        assert_eq!(command[6], -20.0);
        assert!(by_name("dance", &model).is_err());
    }

    #[test]
    fn trajectory_interpolates_and_csv_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        std::fs::write(&path, "time_sec,hip,hip_vel\n1.0,0.0,0.5\n1.5,0.5,1.5\n").unwrap();
        let t = JointTrajectory::from_csv(&path).unwrap();
        assert_eq!(t.joints.len(), 1, "the _vel column is the hip's velocity");
        let hip = &t.joints[0];
        assert_eq!(hip.time_secs, [0.0, 0.5]);
        assert_eq!(hip.sample(0.25), (0.25, 1.0));
        assert_eq!(hip.sample(-1.0), (0.0, 0.5));
        assert_eq!(hip.sample(9.0), (0.5, 1.5));
        std::fs::write(&path, "time_sec,hip\n0,0\n0,1\n").unwrap();
        let e = JointTrajectory::from_csv(&path).unwrap_err().to_string();
        assert!(e.contains("t.csv:3") && e.contains("does not increase"), "{e}");
        std::fs::write(&path, "when,hip\n0,0\n").unwrap();
        let e = JointTrajectory::from_csv(&path).unwrap_err().to_string();
        assert!(e.contains("t.csv:1") && e.contains("time_sec"), "{e}");

        // Replay drives the named joint toward the interpolated target with feed-forward.
        let model = Arc::new(Model::from_xml_str(BOX).unwrap());
        std::fs::write(&path, "time_sec,hip\n0,0.0\n1,0.5\n").unwrap();
        let mut replay =
            Replay::new(&model, JointTrajectory::from_csv(&path).unwrap(), ReplayOptions::default()).unwrap();
        let mut data = Data::new(model.clone()).unwrap();
        reset_to_home(&mut data).unwrap();
        replay.reset(&model, &Observation::of(&data)).unwrap();
        data.set_time_secs(0.5);
        data.qpos_mut()[7] = 0.24;
        let mut command = vec![0.0; model.nv()];
        replay.compute(&model, &Observation::of(&data), &mut command);
        let (kp, kd) = replay.hold.gains()[0];
        assert!((command[6] - (kp * 0.01 + kd * 0.5)).abs() < 1e-9, "{command:?}");
        std::fs::write(&path, "time_sec,knee\n0,0\n").unwrap();
        let e = Replay::new(&model, JointTrajectory::from_csv(&path).unwrap(), ReplayOptions::default()).unwrap_err();
        assert!(e.to_string().contains("\"knee\" is not a joint of the model; actuated joints: hip"), "{e}");
    }

    #[test]
    fn set_model_refuses_another_model() {
        let model = Arc::new(Model::from_xml_str(BOX).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        let edited = Arc::new(model.edit().unwrap().finish().unwrap());
        data.set_model(edited).unwrap();
        let other = Arc::new(
            Model::from_xml_str("<mujoco><worldbody><body><freejoint/><geom size=\"1\"/></body></worldbody></mujoco>")
                .unwrap(),
        );
        assert!(matches!(data.set_model(other), Err(Error::Size { .. })));
    }
}
