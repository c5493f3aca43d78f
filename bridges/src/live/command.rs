//! Turning the commands a controller publishes into actuator commands: `Float64MultiArray` on
//! `/<robot>/joint_commands` (one value per commanded joint, in `/joint_states` order),
//! `JointTrajectory` on `/<robot>/joint_trajectory`, and `JointState` on
//! `/<robot>/joint_command` (joints by name, the `topic_based_ros2_control` convention).
//!
//! The commanded joints are the actuated 1-DOF joints in `/joint_states` order (model order).
//! Each joint is driven through the loop [`PdHold`] builds for it: the gains are the ones
//! twin's own controllers get (the one gain rule, [`twin_core::control::pd_gains`], or the
//! gains a URDF's `ros2_control` block declares), and the law is PdHold's:
//! - position (rad, m): `u = kp·(q* − q) + kd·(q̇* − q̇)`, `q̇* = 0` unless a `JointState`
//!   command gives a velocity too;
//! - velocity (rad/s, m/s): `u = kd·(q̇* − q̇)`;
//! - effort (N·m, N): `u = τ*`, added to the above when a `JointState` command gives both;
//!
//! in command units (`u / gear`), clamped to the actuator's control range (the joint's effort
//! limit without actuators). A joint on a position or velocity servo actuator gets its target
//! (`gear · q*`, `gear · q̇*`) and closes its own loop. Holding the first `/joint_states` pose
//! is therefore `--controller pd-hold` with other targets.

use twin_core::control::{PdHold, PdHoldOptions, PdLoop, nominal_pose};
use twin_core::convert::Interface;
use twin_core::log::{Float64MultiArray, JointState, JointTrajectory};
use twin_core::mj::{Model, ObjType};

/// What the numbers of a `Float64MultiArray` command are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandInterface {
    /// Joint positions, rad (m): a PD servo per joint.
    Position,
    /// Joint velocities, rad/s (m/s): a damping servo per joint.
    Velocity,
    /// Joint efforts, N·m (N).
    Effort,
}

impl CommandInterface {
    /// Lower-case name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            CommandInterface::Position => "position",
            CommandInterface::Velocity => "velocity",
            CommandInterface::Effort => "effort",
        }
    }
}

/// One joint's setpoint: a position, a velocity and an effort feed-forward, each optional.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Setpoint {
    /// Target position, rad (m).
    position: Option<f64>,
    /// Target velocity, rad/s (m/s).
    velocity: Option<f64>,
    /// Effort added to the servo's, N·m (N).
    effort: f64,
}

impl Setpoint {
    fn hold(position: f64) -> Setpoint {
        Setpoint { position: Some(position), ..Setpoint::default() }
    }
}

/// What the joints are told to do now.
#[derive(Debug, Clone, PartialEq)]
enum Mode {
    /// Hold these positions (home pose at start, the current pose after a silent controller).
    Hold(Vec<f64>),
    /// The last good command: one setpoint per commanded joint.
    Direct(Vec<Setpoint>),
    /// A trajectory started at `start_secs` (sim time): positions interpolated linearly.
    Trajectory { start_secs: f64, times_secs: Vec<f64>, positions: Vec<Vec<f64>> },
}

/// Interprets commands for one robot.
#[derive(Debug, Clone)]
pub struct Commander {
    loops: Vec<PdLoop>,
    names: Vec<String>,
    interface: CommandInterface,
    mode: Mode,
}

impl Commander {
    /// The commanded joints of `model` (actuated hinge/slide joints, model order), holding the
    /// home pose until a command arrives. The loops and gains are [`PdHold`]'s for `model`.
    pub fn new(model: &Model, interface: CommandInterface) -> Commander {
        let hold = PdHold::new(model, PdHoldOptions::default());
        let mut loops = hold.loops().to_vec();
        loops.sort_by_key(|l| l.joint);
        let names = loops.iter().map(|l| model.name(ObjType::Joint, l.joint).to_string()).collect();
        let home = nominal_pose(model);
        let targets = loops.iter().map(|l| home[l.qpos_adr]).collect();
        Commander { loops, names, interface, mode: Mode::Hold(targets) }
    }

    /// The commanded joints, in command order.
    pub fn joint_names(&self) -> &[String] {
        &self.names
    }

    /// The gains `(kp, kd)` of each commanded joint, in command order, command units.
    pub fn gains(&self) -> Vec<(f64, f64)> {
        self.loops.iter().map(|l| (l.kp, l.kd)).collect()
    }

    /// The interface of `Float64MultiArray` commands.
    pub fn interface(&self) -> CommandInterface {
        self.interface
    }

    /// Whether the current command is a hold (no command yet, or after a silent controller).
    pub fn holding(&self) -> bool {
        matches!(self.mode, Mode::Hold(_))
    }

    /// Checks a `Float64MultiArray` command: one finite value per commanded joint.
    ///
    /// # Errors
    /// A sentence saying what is wrong with it.
    pub fn check(&self, m: &Float64MultiArray) -> Result<(), String> {
        if m.data.len() != self.loops.len() {
            return Err(format!(
                "{} values, expected {} ({} for {}, in this order: {})",
                m.data.len(),
                self.loops.len(),
                self.interface.name(),
                if self.loops.len() == 1 { "the commanded joint" } else { "the commanded joints" },
                self.names.join(", ")
            ));
        }
        if let Some(i) = m.data.iter().position(|x| !x.is_finite()) {
            return Err(format!("value {i} ({}) is {}", self.names[i], m.data[i]));
        }
        Ok(())
    }

    /// Applies a checked command (see [`Commander::check`]).
    pub fn set_direct(&mut self, m: &Float64MultiArray) {
        let of = |v: f64| match self.interface {
            CommandInterface::Position => Setpoint::hold(v),
            CommandInterface::Velocity => Setpoint { velocity: Some(v), ..Setpoint::default() },
            CommandInterface::Effort => Setpoint { effort: v, ..Setpoint::default() },
        };
        self.mode = Mode::Direct(m.data.iter().map(|&v| of(v)).collect());
    }

    /// Checks and applies a `JointState` command (`topic_based_ros2_control`'s convention):
    /// joints by name (a subset is fine: the others keep their setpoint), each of `position`,
    /// `velocity`, `effort` empty or one finite value per name, at least one given. A joint
    /// with a position is servoed to it (with the velocity as the target rate, the effort as
    /// feed-forward); with a velocity only, damped to it; with an effort only, driven by it.
    /// `qpos` (the current positions) is where the joints without a setpoint yet are held.
    ///
    /// # Errors
    /// A sentence saying what is wrong with it; nothing is applied then.
    pub fn set_by_name(&mut self, m: &JointState, qpos: &[f64]) -> Result<(), String> {
        let n = m.name.len();
        let fields = [("position", &m.position), ("velocity", &m.velocity), ("effort", &m.effort)];
        for (field, values) in fields {
            if !values.is_empty() && values.len() != n {
                return Err(format!("{} {field} values for {n} names (give none or one per name)", values.len()));
            }
            if let Some(i) = values.iter().position(|x| !x.is_finite()) {
                return Err(format!("{field} of {} is {}", m.name[i], values[i]));
            }
        }
        if n == 0 || fields.iter().all(|(_, v)| v.is_empty()) {
            return Err("no joint with a position, velocity or effort".into());
        }
        let mut columns = Vec::with_capacity(n);
        for name in &m.name {
            match self.names.iter().position(|x| x == name) {
                Some(i) => columns.push(i),
                None => return Err(format!("joint `{name}` is not a commanded joint ({})", self.names.join(", "))),
            }
        }
        let mut setpoints = self.setpoints(qpos);
        for (k, &i) in columns.iter().enumerate() {
            setpoints[i] = Setpoint {
                position: m.position.get(k).copied(),
                velocity: m.velocity.get(k).copied(),
                effort: m.effort.get(k).copied().unwrap_or(0.0),
            };
        }
        self.mode = Mode::Direct(setpoints);
        Ok(())
    }

    /// The current command as setpoints (a trajectory: holding where the joints are).
    fn setpoints(&self, qpos: &[f64]) -> Vec<Setpoint> {
        match &self.mode {
            Mode::Hold(targets) => targets.iter().map(|&q| Setpoint::hold(q)).collect(),
            Mode::Direct(s) => s.clone(),
            Mode::Trajectory { .. } => self.loops.iter().map(|l| Setpoint::hold(qpos[l.qpos_adr])).collect(),
        }
    }

    /// Checks a trajectory and starts it at `now_secs`: joints by name (a subset is fine; the
    /// others hold where they are), positions for every point, times increasing.
    ///
    /// # Errors
    /// A sentence saying what is wrong with it.
    pub fn set_trajectory(&mut self, t: &JointTrajectory, now_secs: f64, qpos: &[f64]) -> Result<(), String> {
        let mut columns = Vec::with_capacity(t.joint_names.len());
        for n in &t.joint_names {
            match self.names.iter().position(|m| m == n) {
                Some(i) => columns.push(i),
                None => return Err(format!("joint `{n}` is not a commanded joint ({})", self.names.join(", "))),
            }
        }
        if t.points.is_empty() {
            return Err("no points".into());
        }
        let current: Vec<f64> = self.loops.iter().map(|l| qpos[l.qpos_adr]).collect();
        let mut times = Vec::with_capacity(t.points.len());
        let mut positions = Vec::with_capacity(t.points.len());
        for (k, p) in t.points.iter().enumerate() {
            if p.positions.len() != columns.len() {
                return Err(format!("point {k} has {} positions for {} joints", p.positions.len(), columns.len()));
            }
            if let Some(i) = p.positions.iter().position(|x| !x.is_finite()) {
                return Err(format!("point {k}: position {i} is {}", p.positions[i]));
            }
            let secs = p.time_from_start_nanos as f64 * 1e-9;
            if times.last().is_some_and(|&last| secs <= last) || secs < 0.0 {
                return Err(format!("point {k}: time_from_start {secs} s does not increase"));
            }
            let mut row = current.clone();
            for (c, &i) in columns.iter().enumerate() {
                row[i] = p.positions[c];
            }
            times.push(secs);
            positions.push(row);
        }
        // Start from where the joints are (time 0) unless the first point is at 0.
        if times[0] > 0.0 {
            times.insert(0, 0.0);
            positions.insert(0, current);
        }
        self.mode = Mode::Trajectory { start_secs: now_secs, times_secs: times, positions };
        Ok(())
    }

    /// Holds the pose in `qpos` (safe hold after a silent controller).
    pub fn hold_current(&mut self, qpos: &[f64]) {
        self.mode = Mode::Hold(self.loops.iter().map(|l| qpos[l.qpos_adr]).collect());
    }

    /// The actuator command for the state `qpos`, `qvel` at `now_secs` into `command`.
    pub fn compute(&self, now_secs: f64, qpos: &[f64], qvel: &[f64], command: &mut [f64]) {
        command.fill(0.0);
        for (i, l) in self.loops.iter().enumerate() {
            let setpoint = match &self.mode {
                Mode::Hold(targets) => Setpoint::hold(targets[i]),
                Mode::Direct(setpoints) => setpoints[i],
                Mode::Trajectory { start_secs, times_secs, positions } => {
                    let t = now_secs - start_secs;
                    let k = times_secs.partition_point(|&x| x <= t);
                    let target = if k == 0 {
                        positions[0][i]
                    } else if k >= times_secs.len() {
                        positions[times_secs.len() - 1][i]
                    } else {
                        let (t0, t1) = (times_secs[k - 1], times_secs[k]);
                        let a = (t - t0) / (t1 - t0);
                        positions[k - 1][i] + a * (positions[k][i] - positions[k - 1][i])
                    };
                    Setpoint::hold(target)
                }
            };
            command[l.command] = servo(l, &setpoint, qpos[l.qpos_adr], qvel[l.dof]);
        }
    }
}

/// PdHold's law for one loop and setpoint at position `q`, velocity `qd`, in command units,
/// clamped to the loop's limits (see the module docs).
fn servo(l: &PdLoop, s: &Setpoint, q: f64, qd: f64) -> f64 {
    let u = match l.interface {
        Interface::Effort => {
            let feedback = match (s.position, s.velocity) {
                (Some(p), v) => l.kp * (p - q) + l.kd * (v.unwrap_or(0.0) - qd),
                (None, Some(v)) => l.kd * (v - qd),
                (None, None) => 0.0,
            };
            feedback + s.effort / l.gear
        }
        // Servo actuators close their own loop on `gear · q` (`gear · q̇`).
        Interface::Position => l.gear * s.position.unwrap_or(q),
        Interface::Velocity => l.gear * s.velocity.unwrap_or(0.0),
    };
    u.clamp(l.limits[0], l.limits[1])
}

/// What the tracking metrics ([`twin_core::tracking`]) compare the joints with.
impl Commander {
    /// The position targets of the current command: `emit(qpos address, target)` for a hold
    /// and for commands with positions (none for velocity or effort commands, nor trajectories).
    pub fn position_targets(&self, emit: &mut dyn FnMut(usize, f64)) {
        match &self.mode {
            Mode::Hold(t) => {
                for (l, &t) in self.loops.iter().zip(t) {
                    emit(l.qpos_adr, t);
                }
            }
            Mode::Direct(s) => {
                for (l, s) in self.loops.iter().zip(s) {
                    if let Some(p) = s.position {
                        emit(l.qpos_adr, p);
                    }
                }
            }
            Mode::Trajectory { .. } => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use twin_core::log::{Header, JointTrajectoryPoint};

    fn humanoid() -> twin_core::robot::Robot {
        twin_core::robot::Robot::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap()
    }

    /// A position controller as a ROS 2 node would be: each joint held at the pose of the first
    /// observation after `start_secs` (what a node that holds its first `/joint_states` does),
    /// through the bridge's [`Commander`].
    struct HoldFirstPose {
        commander: Commander,
        start_secs: f64,
        set: bool,
    }

    impl twin_core::control::Controller for HoldFirstPose {
        fn name(&self) -> &'static str {
            "hold-first-pose"
        }
        fn compute(&mut self, _: &Model, o: &twin_core::control::Observation<'_>, command: &mut [f64]) {
            if !self.set && o.time_secs >= self.start_secs {
                let m = Float64MultiArray {
                    data: self.commander.loops.iter().map(|l| o.qpos[l.qpos_adr]).collect(),
                    ..Default::default()
                };
                self.commander.set_direct(&m);
                self.set = true;
            }
            self.commander.compute(o.time_secs, o.qpos, o.qvel, command);
        }
    }

    /// Height (m) and tilt from upright (rad) of the humanoid's base after `secs` under
    /// `controller`, from the physics.
    fn base_after(
        robot: &twin_core::robot::Robot,
        controller: &mut dyn twin_core::control::Controller,
        secs: f64,
    ) -> (f64, f64) {
        use rand::SeedableRng;
        let steps = twin_core::sim::steps_for(&robot.model, secs);
        let episode = twin_core::engine::Episode { steps, ..Default::default() };
        let mut engine = twin_core::engine::Engine::new();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        engine.run(&robot.model, &episode, controller, &mut [], &mut [], &mut rng).unwrap();
        let data = engine.data().unwrap();
        let base = robot.base.unwrap();
        let q = &data.qpos()[base.qpos_adr..base.qpos_adr + 7];
        (q[2], (1.0 - 2.0 * (q[4] * q[4] + q[5] * q[5])).clamp(-1.0, 1.0).acos())
    }

    /// The same robot for every controller: a node holding the pose it first saw (0.1 s in,
    /// after the first sag) keeps the humanoid standing for 10 s as pd-hold does.
    #[test]
    fn holding_the_first_observed_pose_stands_as_long_as_pd_hold() {
        let robot = humanoid();
        let mut hold = PdHold::new(&robot.model, PdHoldOptions::default());
        let (z_pd, tilt_pd) = base_after(&robot, &mut hold, 10.0);
        let mut node = HoldFirstPose {
            commander: Commander::new(&robot.model, CommandInterface::Position),
            start_secs: 0.1,
            set: false,
        };
        let (z, tilt) = base_after(&robot, &mut node, 10.0);
        let home = nominal_pose(&robot.model)[robot.base.unwrap().qpos_adr + 2];
        assert!(z_pd > 0.9 * home && tilt_pd < 0.2, "pd-hold: base at {z_pd} m (home {home}), tilt {tilt_pd}");
        assert!(z > 0.9 * home && tilt < 0.2 && (z - z_pd).abs() < 0.03, "base at {z} m (pd-hold {z_pd}), tilt {tilt}");
    }

    #[test]
    fn joint_state_commands_by_name_set_the_named_joints_only() {
        let robot = humanoid();
        let mut c = Commander::new(&robot.model, CommandInterface::Position);
        let qpos = nominal_pose(&robot.model);
        let elbow = c.names.iter().position(|n| n == "left_elbow_joint").unwrap();
        let bad = JointState { name: vec!["left_elbow_joint".into()], position: vec![0.1, 0.2], ..Default::default() };
        assert!(c.set_by_name(&bad, &qpos).unwrap_err().contains("2 position values for 1 names"));
        let unknown = JointState { name: vec!["tail".into()], position: vec![0.1], ..Default::default() };
        assert!(c.set_by_name(&unknown, &qpos).unwrap_err().contains("`tail`"));
        let m = JointState {
            name: vec!["left_elbow_joint".into()],
            position: vec![-0.6],
            velocity: vec![0.5],
            effort: vec![2.0],
            ..Default::default()
        };
        c.set_by_name(&m, &qpos).unwrap();
        let mut command = vec![0.0; robot.model.nu()];
        let qvel = vec![0.0; robot.model.nv()];
        c.compute(0.0, &qpos, &qvel, &mut command);
        let l = &c.loops[elbow];
        let want = l.kp * (-0.6 - qpos[l.qpos_adr]) + l.kd * 0.5 + 2.0 / l.gear;
        assert!((command[l.command] - want.clamp(l.limits[0], l.limits[1])).abs() < 1e-9);
        // Every other joint still holds home: no error, no torque.
        for (i, l) in c.loops.iter().enumerate() {
            if i != elbow {
                assert!(command[l.command].abs() < 1e-9, "{} {}", c.names[i], command[l.command]);
            }
        }
    }

    #[test]
    fn commands_of_the_wrong_length_or_with_nan_are_refused() {
        let robot = humanoid();
        let c = Commander::new(&robot.model, CommandInterface::Position);
        assert_eq!(c.joint_names().len(), 23);
        let good = Float64MultiArray { data: vec![0.0; 23], ..Default::default() };
        assert!(c.check(&good).is_ok());
        let short = Float64MultiArray { data: vec![0.0; 22], ..Default::default() };
        assert!(c.check(&short).unwrap_err().contains("22 values, expected 23"));
        let mut nan = good.clone();
        nan.data[6] = f64::NAN;
        assert!(c.check(&nan).unwrap_err().contains("left_elbow_joint"));
    }

    #[test]
    fn trajectories_interpolate_and_name_bad_joints() {
        let robot = humanoid();
        let mut c = Commander::new(&robot.model, CommandInterface::Position);
        let qpos = vec![0.0; robot.model.nq()];
        let point = |q: f64, secs: i64| JointTrajectoryPoint {
            positions: vec![q],
            time_from_start_nanos: secs * 1_000_000_000,
            ..Default::default()
        };
        let bad = JointTrajectory {
            header: Header::default(),
            joint_names: vec!["no_such_joint".into()],
            points: vec![point(0.1, 1)],
        };
        assert!(c.set_trajectory(&bad, 0.0, &qpos).unwrap_err().contains("no_such_joint"));
        let t = JointTrajectory {
            header: Header::default(),
            joint_names: vec!["left_elbow_joint".into()],
            points: vec![point(-0.4, 2)],
        };
        c.set_trajectory(&t, 1.0, &qpos).unwrap();
        // Halfway (t = 2 s, one second after the start at 1 s): target -0.2; at rest the PD
        // output is kp times that error.
        let mut command = vec![0.0; robot.model.nu()];
        c.compute(2.0, &qpos, &vec![0.0; robot.model.nv()], &mut command);
        let i = c.names.iter().position(|n| n == "left_elbow_joint").unwrap();
        let elbow = &c.loops[i];
        let expected = elbow.kp * -0.2;
        assert!((command[elbow.command] - expected.clamp(elbow.limits[0], elbow.limits[1])).abs() < 1e-9);
    }
}
