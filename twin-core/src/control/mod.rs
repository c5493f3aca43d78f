//! Controllers: what drives a twin during a rollout ([`PdHold`], [`Passive`], [`Replay`]; one
//! file each; their registry by name is `twin_controllers::registry`, above every controller).
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

/// Where a command goes and the pose a robot holds are the robot's ([`crate::robot`]);
/// re-exported here for controllers.
pub use crate::robot::{Actuation, nominal_pose, reset_to_home};
pub use passive::Passive;
pub use pd_hold::{PdHold, PdHoldOptions, PdLoop, pd_gains, stance_stiffness};
pub use replay::{JointTrajectory, Replay, ReplayOptions, TrajectoryJoint};

use crate::error::Result;
use crate::mj::{Data, Model};

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

/// A closed-loop controller. One instance drives one simulation at a time; `reset` starts a new
/// episode (it may use the model, which can differ per episode after randomization).
pub trait Controller: Send {
    /// Short name, as selected on the command line (e.g. `pd-hold`).
    fn name(&self) -> &'static str;

    /// Prepares for a new episode on `model`, starting from `observation`. Default: nothing to
    /// prepare (a controller that keeps no state between steps and drives any model).
    ///
    /// # Errors
    /// When the controller can't drive this model (e.g. a joint it needs is missing).
    fn reset(&mut self, _model: &Model, _observation: &Observation<'_>) -> Result<()> {
        Ok(())
    }

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mj::ObjType;
    use crate::robot::lowest_robot_point_z;
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
        assert!(matches!(data.set_model(other), Err(twin_mj::Error::Size { .. })));
    }
}
