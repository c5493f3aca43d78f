//! Turning `/<robot>/joint_commands` and `/<robot>/joint_trajectory` into actuator commands.
//!
//! The commanded joints are the actuated 1-DOF joints in `/joint_states` order (model order).
//! Each joint is driven through the loop [`PdHold`] builds for it, so the gains follow the one
//! PD rule of [`crate::control`]:
//! - position (rad, m): `u = kp·(q* − q) − kd·q̇ + i`, with the integral
//!   `i += kp·INTEGRAL_RATE·(q* − q)·dt` (clamped to the control range) so that a joint loaded
//!   by gravity still reaches its target, as a real position-controlled servo does;
//! - velocity (rad/s, m/s): `u = kd·(q̇* − q̇)`;
//! - effort (N·m, N): `u = τ* / gear`;
//!
//! each clamped to the actuator's control range (the joint's effort limit without actuators).

use crate::control::{PdHold, PdHoldOptions, PdLoop, nominal_pose};
use crate::log::{Float64MultiArray, JointTrajectory};
use crate::mj::{Model, ObjType};

/// Integral rate of the position servo, 1/s: `ki = kp · INTEGRAL_RATE`. Slow next to the
/// joints' PD bandwidth (tens of rad/s), fast enough to remove a gravity offset well within a
/// second.
pub const INTEGRAL_RATE: f64 = 5.0;

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

/// What the joints are told to do now.
#[derive(Debug, Clone, PartialEq)]
enum Mode {
    /// Hold these positions (home pose at start, the current pose after a silent controller).
    Hold(Vec<f64>),
    /// The last good `Float64MultiArray`, in the command interface's units.
    Direct(Vec<f64>),
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
    /// Integral term of each position loop, command units.
    integral: Vec<f64>,
    dt_secs: f64,
}

impl Commander {
    /// The commanded joints of `model` (actuated hinge/slide joints, model order), holding the
    /// home pose until a command arrives.
    pub fn new(model: &Model, interface: CommandInterface) -> Commander {
        let hold = PdHold::new(model, PdHoldOptions::default());
        let mut loops = hold.loops().to_vec();
        loops.sort_by_key(|l| l.joint);
        let names = loops.iter().map(|l| model.name(ObjType::Joint, l.joint).to_string()).collect();
        let home = nominal_pose(model);
        let targets = loops.iter().map(|l| home[l.qpos_adr]).collect();
        let integral = vec![0.0; loops.len()];
        Commander { loops, names, interface, mode: Mode::Hold(targets), integral, dt_secs: model.timestep_secs() }
    }

    /// The commanded joints, in command order.
    pub fn joint_names(&self) -> &[String] {
        &self.names
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
        self.mode = Mode::Direct(m.data.clone());
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

    /// The actuator command for the state `qpos`, `qvel` at `now_secs` into `command`; called
    /// once per simulation step (it advances the integral terms).
    pub fn compute(&mut self, now_secs: f64, qpos: &[f64], qvel: &[f64], command: &mut [f64]) {
        command.fill(0.0);
        let dt = self.dt_secs;
        let integral = &mut self.integral;
        let mut servo = |i: usize, l: &PdLoop, target: f64| {
            let error = target - qpos[l.qpos_adr];
            integral[i] = (integral[i] + l.kp * INTEGRAL_RATE * error * dt).clamp(l.limits[0], l.limits[1]);
            l.kp * error - l.kd * qvel[l.dof] + integral[i]
        };
        for (i, l) in self.loops.iter().enumerate() {
            let u = match &self.mode {
                Mode::Hold(targets) => servo(i, l, targets[i]),
                Mode::Direct(values) => match self.interface {
                    CommandInterface::Position => servo(i, l, values[i]),
                    CommandInterface::Velocity => l.kd * (values[i] - qvel[l.dof]),
                    CommandInterface::Effort => values[i] / l.gear,
                },
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
                    servo(i, l, target)
                }
            };
            command[l.command] = u.clamp(l.limits[0], l.limits[1]);
        }
    }
}

/// What the tracking metrics ([`crate::tracking`]) compare the joints with.
impl Commander {
    /// The position targets of the current command: `emit(qpos address, target)` for a hold
    /// and for position commands (none for velocity and effort commands, nor trajectories).
    pub fn position_targets(&self, emit: &mut dyn FnMut(usize, f64)) {
        let targets = match (&self.mode, self.interface) {
            (Mode::Hold(t), _) | (Mode::Direct(t), CommandInterface::Position) => t,
            _ => return,
        };
        for (l, &t) in self.loops.iter().zip(targets) {
            emit(l.qpos_adr, t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log::{Header, JointTrajectoryPoint};

    fn humanoid() -> crate::robot::Robot {
        crate::robot::Robot::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap()
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
        // output is kp times that error (the integral starts from zero, one step's worth).
        let mut command = vec![0.0; robot.model.nu()];
        c.compute(2.0, &qpos, &vec![0.0; robot.model.nv()], &mut command);
        let i = c.names.iter().position(|n| n == "left_elbow_joint").unwrap();
        let elbow = &c.loops[i];
        let expected = elbow.kp * -0.2 * (1.0 + INTEGRAL_RATE * robot.model.timestep_secs());
        assert!((command[elbow.command] - expected.clamp(elbow.limits[0], elbow.limits[1])).abs() < 1e-9);
    }
}
