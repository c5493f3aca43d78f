//! Controllers: what drives a twin during a rollout.
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
                    if model.actuator_ctrllimited()[u] != 0 {
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
                        _ if model.jnt_actfrclimited()[joint] != 0 => model.jnt_actfrcrange()[joint],
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
}

/// Options of [`PdHold`].
#[derive(Debug, Clone, PartialEq)]
pub struct PdHoldOptions {
    /// Joint angle error (radians; metres for slides) at which a joint's PD torque reaches its
    /// effort limit: `kp = effort / saturation_error`. Stiff enough for the shipped humanoid's
    /// ankles to hold its whole weight. (default: 0.25)
    pub saturation_error: f64,
    /// Damping ratio of each joint on its own effective inertia (`1 / dof_invweight0`):
    /// `kd = 2 · ratio · sqrt(kp · inertia)`. (default: 1.0)
    pub damping_ratio: f64,
    /// Effort (N·m or N) assumed for joints and actuators without a force limit.
    /// (default: 100.0)
    pub default_effort: f64,
}

impl Default for PdHoldOptions {
    fn default() -> Self {
        PdHoldOptions { saturation_error: 0.25, damping_ratio: 1.0, default_effort: 100.0 }
    }
}

/// One PD loop: a command entry driving one 1-DOF joint.
#[derive(Debug, Clone)]
pub struct PdLoop {
    /// Index in the command (`ctrl` or `qfrc_applied`).
    pub command: usize,
    /// The joint.
    pub joint: usize,
    /// Its `qpos` address.
    pub qpos_adr: usize,
    /// Its DOF.
    pub dof: usize,
    /// Stiffness, command units per rad (m).
    pub kp: f64,
    /// Damping, command units per rad/s (m/s).
    pub kd: f64,
    /// Joint torque (force) per command unit: the actuator gear, 1 for `qfrc_applied`.
    pub gear: f64,
    /// Target position, rad (m).
    pub target: f64,
    /// Command limits.
    pub limits: [f64; 2],
}

type Loop = PdLoop;

/// Holds the nominal pose ([`nominal_pose`]) with PD control on every actuated hinge/slide joint:
/// `τ = kp·(q_target − q) − kd·q̇`, clamped to the actuator's range / the joint's effort.
/// With actuators, each joint-transmission actuator drives its joint (torque / gear);
/// without, every hinge and slide joint gets `qfrc_applied`.
#[derive(Debug, Clone)]
pub struct PdHold {
    options: PdHoldOptions,
    loops: Vec<Loop>,
}

impl PdHold {
    /// A PD hold for `model`; the targets are set by [`Controller::reset`].
    pub fn new(model: &Model, options: PdHoldOptions) -> PdHold {
        let mut hold = PdHold { options, loops: Vec::new() };
        hold.build(model);
        hold
    }

    /// The loops, in command order (targets are set by [`Controller::reset`]).
    pub fn loops(&self) -> &[PdLoop] {
        &self.loops
    }

    /// The gains `(kp, kd)` of each loop, in command order.
    pub fn gains(&self) -> Vec<(f64, f64)> {
        self.loops.iter().map(|l| (l.kp, l.kd)).collect()
    }

    fn build(&mut self, model: &Model) {
        let actuation = Actuation::of(model);
        let limits = actuation.limits(model);
        let o = &self.options;
        let gains = |effort: f64, dof: usize, gear: f64| {
            let effort = if effort.is_finite() && effort > 0.0 { effort } else { o.default_effort };
            let kp = effort / o.saturation_error;
            let inertia = 1.0 / model.dof_invweight0()[dof].max(1e-12);
            let kd = 2.0 * o.damping_ratio * (kp * inertia).sqrt();
            // Joint-space gains, expressed in command units (torque = gear · ctrl).
            (kp / gear, kd / gear)
        };
        self.loops.clear();
        match actuation {
            Actuation::Ctrl => {
                for (u, &[lo, hi]) in limits.iter().enumerate() {
                    // Only joint transmissions on 1-DOF joints are PD-able; others get 0.
                    if model.actuator_trntype()[u] as u32 != mujoco_sys::mjtTrn_mjTRN_JOINT {
                        continue;
                    }
                    let joint = model.actuator_trnid()[u][0] as usize;
                    if !matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide) {
                        continue;
                    }
                    let gear = model.actuator_gear()[u][0];
                    if gear == 0.0 {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[joint] as usize;
                    let mut effort = (hi.abs().min(lo.abs())) * gear.abs();
                    if model.actuator_forcelimited()[u] != 0 {
                        let [flo, fhi] = model.actuator_forcerange()[u];
                        effort = effort.min(flo.abs().min(fhi.abs()));
                    }
                    if model.jnt_actfrclimited()[joint] != 0 {
                        let [jlo, jhi] = model.jnt_actfrcrange()[joint];
                        effort = effort.min(jlo.abs().min(jhi.abs()));
                    }
                    let (kp, kd) = gains(effort, dof, gear);
                    self.loops.push(Loop {
                        command: u,
                        joint,
                        qpos_adr: model.jnt_qposadr()[joint] as usize,
                        dof,
                        kp,
                        kd,
                        gear,
                        target: 0.0,
                        limits: [lo, hi],
                    });
                }
            }
            Actuation::Qfrc => {
                for joint in 0..model.njnt() {
                    if !matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide) {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[joint] as usize;
                    let [lo, hi] = limits[dof];
                    let (kp, kd) = gains(hi.abs().min(lo.abs()), dof, 1.0);
                    self.loops.push(Loop {
                        command: dof,
                        joint,
                        qpos_adr: model.jnt_qposadr()[joint] as usize,
                        dof,
                        kp,
                        kd,
                        gear: 1.0,
                        target: 0.0,
                        limits: [lo, hi],
                    });
                }
            }
        }
    }
}

impl Controller for PdHold {
    fn name(&self) -> &'static str {
        "pd-hold"
    }

    fn reset(&mut self, model: &Model, _observation: &Observation<'_>) -> Result<()> {
        // Gains follow the episode's model (effort limits, gear and inertia may be randomized).
        self.build(model);
        let nominal = nominal_pose(model);
        for l in &mut self.loops {
            l.target = nominal[l.qpos_adr];
        }
        Ok(())
    }

    fn compute(&mut self, _model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        command.fill(0.0);
        for l in &self.loops {
            let error = l.target - observation.qpos[l.qpos_adr];
            let u = l.kp * error - l.kd * observation.qvel[l.dof];
            command[l.command] = u.clamp(l.limits[0], l.limits[1]);
        }
    }
}

/// Applies no command at all: the passive model (a baseline: how the robot does unpowered).
#[derive(Debug, Clone, Default)]
pub struct Passive;

impl Controller for Passive {
    fn name(&self) -> &'static str {
        "passive"
    }

    fn reset(&mut self, _model: &Model, _observation: &Observation<'_>) -> Result<()> {
        Ok(())
    }

    fn compute(&mut self, _model: &Model, _observation: &Observation<'_>, command: &mut [f64]) {
        command.fill(0.0);
    }
}

/// One joint of a [`JointTrajectory`]: samples sorted by time.
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectoryJoint {
    /// Joint name (matched to the model's joints by name).
    pub name: String,
    /// Sample times, seconds from the trajectory's start (sorted).
    pub time_secs: Vec<f64>,
    /// Positions, rad (or m).
    pub position: Vec<f64>,
    /// Velocities, rad/s (or m/s), when every sample has one: the feed-forward of [`Replay`].
    pub velocity: Option<Vec<f64>>,
}

impl TrajectoryJoint {
    /// Position and velocity at `t_secs`, linearly interpolated (held at the ends). The
    /// velocity is the logged one when present, else the slope of the segment.
    pub fn sample(&self, t_secs: f64) -> (f64, f64) {
        let t = &self.time_secs;
        let n = t.len();
        if n == 0 {
            return (0.0, 0.0);
        }
        if n == 1 || t_secs <= t[0] {
            return (self.position[0], self.velocity.as_ref().map_or(0.0, |v| v[0]));
        }
        if t_secs >= t[n - 1] {
            return (self.position[n - 1], self.velocity.as_ref().map_or(0.0, |v| v[n - 1]));
        }
        // First sample after t_secs (t[0] < t_secs < t[n-1], so 1 <= i <= n-1).
        let i = t.partition_point(|&x| x <= t_secs).clamp(1, n - 1);
        let (t0, t1) = (t[i - 1], t[i]);
        let span = t1 - t0;
        let a = if span > 0.0 { (t_secs - t0) / span } else { 1.0 };
        let (p0, p1) = (self.position[i - 1], self.position[i]);
        let velocity = match &self.velocity {
            Some(v) => v[i - 1] + a * (v[i] - v[i - 1]),
            None if span > 0.0 => (p1 - p0) / span,
            None => 0.0,
        };
        (p0 + a * (p1 - p0), velocity)
    }
}

/// A joint-space trajectory to replay, from a ROS 2 log's `JointState` topic or a CSV file.
#[derive(Debug, Clone, PartialEq)]
pub struct JointTrajectory {
    /// Where it came from (for messages).
    pub source: std::path::PathBuf,
    /// Absolute time of the trajectory's time 0, ns (the earliest log stamp; 0 for CSV).
    pub start_nanos: i64,
    /// The joints, in file order.
    pub joints: Vec<TrajectoryJoint>,
}

impl JointTrajectory {
    /// Duration, seconds (last sample of any joint).
    pub fn duration_secs(&self) -> f64 {
        self.joints.iter().filter_map(|j| j.time_secs.last().copied()).fold(0.0, f64::max)
    }

    /// Reads a trajectory: a `.csv` file (see [`JointTrajectory::from_csv`]) or else a ROS 2 log
    /// (`.mcap` or rosbag2 folder) whose `topic` is read with [`crate::log::Log::joint_states`].
    ///
    /// # Errors
    /// [`Error::Trajectory`] for a malformed file; log errors as [`crate::log::Log`].
    pub fn load(path: &std::path::Path, topic: &str) -> Result<JointTrajectory> {
        if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv")) {
            JointTrajectory::from_csv(path)
        } else {
            JointTrajectory::from_log(path, topic)
        }
    }

    /// From a `sensor_msgs/msg/JointState` topic: every joint logged, times from the header
    /// stamps (log time where zero) relative to the earliest sample; velocities kept when each
    /// of a joint's samples has one.
    ///
    /// # Errors
    /// As [`crate::log::Log::joint_states`]; [`Error::Trajectory`] when the topic has no samples.
    pub fn from_log(path: &std::path::Path, topic: &str) -> Result<JointTrajectory> {
        let log = crate::log::Log::open(path, crate::log::ReadOptions::default())?;
        let series = log.joint_states(topic)?;
        let t0 = series.joints.iter().filter_map(|j| j.time_nanos.first().copied()).min().ok_or_else(|| {
            Error::Trajectory {
                path: path.to_path_buf(),
                line: None,
                message: format!("topic {topic} has no joint samples"),
            }
        })?;
        let joints = series
            .joints
            .into_iter()
            .map(|j| TrajectoryJoint {
                time_secs: j.time_nanos.iter().map(|&t| (t - t0) as f64 * 1e-9).collect(),
                velocity: (!j.velocity.is_empty() && j.velocity.iter().all(|v| v.is_finite())).then_some(j.velocity),
                position: j.position,
                name: j.name,
            })
            .collect();
        Ok(JointTrajectory { source: path.to_path_buf(), start_nanos: t0, joints })
    }

    /// From a CSV file: a header `time_sec,<joint>,<joint>,…` (a column `<joint>_vel` next to a
    /// column `<joint>` gives its velocity), then one row per sample, times in seconds,
    /// increasing.
    ///
    /// # Errors
    /// [`Error::Io`]; [`Error::Trajectory`] naming the line for a bad header, a non-number, a
    /// short row or a time that does not increase.
    pub fn from_csv(path: &std::path::Path) -> Result<JointTrajectory> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let bad =
            |line: usize, message: String| Error::Trajectory { path: path.to_path_buf(), line: Some(line), message };
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let Some((_, header)) = lines.next() else {
            return Err(bad(1, "empty file; expected a header `time_sec,<joint>,…`".into()));
        };
        let columns: Vec<&str> = header.split(',').map(str::trim).collect();
        if columns.first().is_none_or(|c| !matches!(*c, "time_sec" | "time_secs" | "time" | "t")) || columns.len() < 2 {
            return Err(bad(1, format!("header must be `time_sec,<joint>,…` (got `{header}`)")));
        }
        let mut rows: Vec<Vec<f64>> = vec![Vec::new(); columns.len()];
        for (i, line) in lines {
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            if cells.len() != columns.len() {
                return Err(bad(i + 1, format!("{} values, the header has {} columns", cells.len(), columns.len())));
            }
            for (k, cell) in cells.iter().enumerate() {
                let v: f64 = cell
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or_else(|| bad(i + 1, format!("column {}: `{cell}` is not a finite number", columns[k])))?;
                rows[k].push(v);
            }
            let t = &rows[0];
            if t.len() > 1 && t[t.len() - 1] <= t[t.len() - 2] {
                return Err(bad(i + 1, format!("time {} does not increase", t[t.len() - 1])));
            }
        }
        let time = &rows[0];
        if time.is_empty() {
            return Err(bad(2, "no samples after the header".into()));
        }
        let t0 = time[0];
        let time_secs: Vec<f64> = time.iter().map(|t| t - t0).collect();
        let mut joints = Vec::new();
        for (k, name) in columns.iter().enumerate().skip(1) {
            if let Some(base) = name.strip_suffix("_vel")
                && columns.contains(&base)
            {
                continue;
            }
            let velocity = columns.iter().position(|c| c.strip_suffix("_vel") == Some(name)).map(|kv| rows[kv].clone());
            joints.push(TrajectoryJoint {
                name: name.to_string(),
                time_secs: time_secs.clone(),
                position: rows[k].clone(),
                velocity,
            });
        }
        Ok(JointTrajectory { source: path.to_path_buf(), start_nanos: 0, joints })
    }
}

/// Options of [`Replay`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReplayOptions {
    /// Gains, as for [`PdHold`] (default: [`PdHoldOptions::default`]; stiffer gains did not
    /// track the shipped humanoid's legs better: with both feet planted their error comes from
    /// the closed chain, not the gains).
    pub gains: PdHoldOptions,
}

/// Tracks a [`JointTrajectory`]: `τ = kp·(q_ref(t) − q) + kd·(q̇_ref(t) − q̇)` on every joint the
/// trajectory names (position interpolated in time, velocity feed-forward from the log or the
/// interpolation slope); the model's other actuated joints hold the nominal pose. Time 0 of the
/// trajectory is the time of [`Controller::reset`].
#[derive(Debug, Clone)]
pub struct Replay {
    trajectory: JointTrajectory,
    hold: PdHold,
    /// Trajectory joint index per PD loop (None: hold nominal).
    tracks: Vec<Option<usize>>,
    start_secs: f64,
}

impl Replay {
    /// A replay of `trajectory` on `model`.
    ///
    /// # Errors
    /// [`Error::Trajectory`] when the trajectory names a joint the model lacks or that no
    /// actuator drives, listing the model's actuated joints.
    pub fn new(model: &Model, trajectory: JointTrajectory, options: ReplayOptions) -> Result<Replay> {
        let hold = PdHold::new(model, options.gains);
        let mut replay = Replay { trajectory, hold, tracks: Vec::new(), start_secs: 0.0 };
        replay.bind(model)?;
        Ok(replay)
    }

    /// The trajectory replayed.
    pub fn trajectory(&self) -> &JointTrajectory {
        &self.trajectory
    }

    fn bind(&mut self, model: &Model) -> Result<()> {
        let loop_joint: Vec<usize> = self.hold.loops.iter().map(|l| model.dof_jntid()[l.dof] as usize).collect();
        let driven: Vec<&str> = loop_joint.iter().map(|&j| model.name(ObjType::Joint, j)).collect();
        for tj in &self.trajectory.joints {
            if !driven.contains(&tj.name.as_str()) {
                let what = if model.id(ObjType::Joint, &tj.name).is_some() {
                    "is a joint of the model but no actuator drives it"
                } else {
                    "is not a joint of the model"
                };
                return Err(Error::Trajectory {
                    path: self.trajectory.source.clone(),
                    line: None,
                    message: format!("trajectory joint \"{}\" {what}; actuated joints: {}", tj.name, driven.join(", ")),
                });
            }
        }
        self.tracks = driven.iter().map(|name| self.trajectory.joints.iter().position(|t| t.name == *name)).collect();
        Ok(())
    }

    /// The reference `(position, velocity)` of every trajectory joint at controller time
    /// `t_secs` (seconds since reset), in trajectory order.
    pub fn reference(&self, t_secs: f64) -> Vec<(f64, f64)> {
        self.trajectory.joints.iter().map(|j| j.sample(t_secs)).collect()
    }
}

impl Controller for Replay {
    fn name(&self) -> &'static str {
        "replay"
    }

    fn initial_qpos(&self, model: &Model, qpos: &mut [f64]) {
        for tj in &self.trajectory.joints {
            if let Some(j) = model.id(ObjType::Joint, &tj.name) {
                qpos[model.jnt_qposadr()[j] as usize] = tj.sample(0.0).0;
            }
        }
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        self.hold.reset(model, observation)?;
        self.bind(model)?;
        self.start_secs = observation.time_secs;
        Ok(())
    }

    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        self.hold.compute(model, observation, command);
        let t = observation.time_secs - self.start_secs;
        for (l, track) in self.hold.loops.iter().zip(&self.tracks) {
            let Some(k) = *track else { continue };
            let (q_ref, v_ref) = self.trajectory.joints[k].sample(t);
            let u = l.kp * (q_ref - observation.qpos[l.qpos_adr]) + l.kd * (v_ref - observation.qvel[l.dof]);
            command[l.command] = u.clamp(l.limits[0], l.limits[1]);
        }
    }
}

/// Names accepted by [`by_name`].
pub const CONTROLLERS: &[&str] = &["pd-hold", "passive"];

/// The controller called `name` (one of [`CONTROLLERS`]) with default options, for `model`.
///
/// # Errors
/// [`Error::NotFound`] (kind `controller`) for an unknown name.
pub fn by_name(name: &str, model: &Model) -> Result<Box<dyn Controller>> {
    match name {
        "pd-hold" => Ok(Box::new(PdHold::new(model, PdHoldOptions::default()))),
        "passive" => Ok(Box::new(Passive)),
        _ => Err(Error::NotFound { kind: "controller (available: pd-hold, passive)", name: name.to_string() }),
    }
}

/// The pose a robot is meant to hold: keyframe `home` if the model has one, else `qpos0`
/// (len `nq`).
pub fn nominal_pose(model: &Model) -> Vec<f64> {
    model.id(ObjType::Key, "home").and_then(|k| model.key_qpos(k)).unwrap_or_else(|| model.qpos0()).to_vec()
}

/// The body of the model's free joint (the floating base, e.g. `pelvis`), if it has one.
pub fn base_body(model: &Model) -> Option<usize> {
    (0..model.njnt()).find(|&j| model.joint_type(j) == JointType::Free).map(|j| model.jnt_bodyid()[j] as usize)
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
    let Some(base) = base_body(&model) else {
        return Ok(());
    };
    let lowest = lowest_robot_point_z(&model, data);
    if lowest.is_finite() {
        let joint = (0..model.njnt())
            .find(|&j| model.joint_type(j) == JointType::Free && model.jnt_bodyid()[j] as usize == base)
            .expect("base_body found a free joint");
        let adr = model.jnt_qposadr()[joint] as usize;
        data.qpos_mut()[adr + 2] -= lowest;
        data.forward()?;
    }
    Ok(())
}

/// Lowest z (world frame, metres) of any geom not attached to the world body, from the geoms'
/// current poses; +inf when there is none.
pub fn lowest_robot_point_z(model: &Model, data: &Data) -> f64 {
    let mut lowest = f64::INFINITY;
    for g in 0..model.ngeom() {
        if model.geom_bodyid()[g] == 0 {
            continue;
        }
        let z = data.geom_xpos()[g][2];
        let size = model.geom_size()[g];
        let r = geom_xmat_row_z(data, g);
        let extent = match model.geom_type()[g] as u32 {
            mujoco_sys::mjtGeom_mjGEOM_SPHERE => size[0],
            mujoco_sys::mjtGeom_mjGEOM_CAPSULE => size[0] + size[1] * r[2].abs(),
            mujoco_sys::mjtGeom_mjGEOM_CYLINDER => size[0] * (1.0 - r[2] * r[2]).max(0.0).sqrt() + size[1] * r[2].abs(),
            mujoco_sys::mjtGeom_mjGEOM_BOX => (0..3).map(|k| size[k] * r[k].abs()).sum(),
            mujoco_sys::mjtGeom_mjGEOM_ELLIPSOID => (0..3).map(|k| (size[k] * r[k]).powi(2)).sum::<f64>().sqrt(),
            mujoco_sys::mjtGeom_mjGEOM_PLANE => continue,
            // Meshes and others: their bounding sphere (conservative: may leave a small gap).
            _ => model.geom_rbound()[g],
        };
        lowest = lowest.min(z - extent);
    }
    lowest
}

/// Row z of geom `g`'s world rotation: the world z component of each of its local axes.
fn geom_xmat_row_z(data: &Data, g: usize) -> [f64; 3] {
    let m = data.geom_xmat()[g];
    [m[6], m[7], m[8]]
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
        assert_eq!(base_body(&model), model.id(ObjType::Body, "base"));
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
