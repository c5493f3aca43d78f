//! [`Replay`]: tracks a [`JointTrajectory`] from a ROS 2 log or a CSV file.

use super::{Controller, Observation, PdHold, PdHoldOptions};
use crate::error::{Error, Result};
use crate::mj::{Model, ObjType};

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
    /// What was odd about the file's times (time going backwards or standing still), one line
    /// each, for the caller to print; empty when nothing was.
    pub warnings: Vec<String>,
}

/// Refuses a joint's sample times that go backwards or jump forward by more than
/// `max(1 s, 1000 × the median step)`: a broken clock (e.g. one flipped bit in a header stamp)
/// would otherwise make a replay or a `twin view` span months of log time.
fn check_time_jumps(path: &std::path::Path, topic: &str, joint: &str, times_nanos: &[i64]) -> Result<()> {
    let mut steps: Vec<i64> = times_nanos.windows(2).map(|w| w[1].saturating_sub(w[0])).collect();
    if steps.is_empty() {
        return Ok(());
    }
    let bad = |k: usize, what: &str| Error::Trajectory {
        path: path.to_path_buf(),
        line: None,
        message: format!(
            "topic {topic}, joint {joint}: the time {what} from {:.6} s to {:.6} s at sample {} (of {}); the \
             log's clock is broken there: cut the log before it (or fix its header stamps)",
            (times_nanos[k] - times_nanos[0]) as f64 * 1e-9,
            (times_nanos[k + 1] - times_nanos[0]) as f64 * 1e-9,
            k + 1,
            times_nanos.len()
        ),
    };
    let original = steps.clone();
    let mid = steps.len() / 2;
    let median = *steps.select_nth_unstable(mid).1;
    let limit = median.saturating_mul(1000).max(1_000_000_000);
    match original.iter().position(|&s| s < 0 || s > limit) {
        Some(k) if original[k] < 0 => Err(bad(k, "goes backwards")),
        Some(k) => Err(bad(k, "jumps")),
        None => Ok(()),
    }
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
    /// of a joint's samples has one. A `trajectory_msgs/msg/JointTrajectory` topic (e.g. the
    /// output of `twin excite`) is read with [`JointTrajectory::from_trajectory_messages`].
    ///
    /// # Errors
    /// As [`crate::log::Log::joint_states`]; [`Error::Trajectory`] when the topic has no samples.
    pub fn from_log(path: &std::path::Path, topic: &str) -> Result<JointTrajectory> {
        let log = crate::log::Log::open(path, crate::log::ReadOptions::default())?;
        let trajectory_type = <crate::log::JointTrajectory as crate::log::RosMessage>::TYPE_NAME;
        if log
            .info()?
            .topics
            .iter()
            .any(|t| t.topic == topic && crate::log::msgdef::normalize_type_name(&t.type_name) == trajectory_type)
        {
            return JointTrajectory::from_trajectory_messages(&log, topic);
        }
        let series = log.joint_states(topic)?;
        let t0 = series.joints.iter().filter_map(|j| j.time_nanos.first().copied()).min().ok_or_else(|| {
            Error::Trajectory {
                path: path.to_path_buf(),
                line: None,
                message: format!("topic {topic} has no joint samples"),
            }
        })?;
        for j in &series.joints {
            check_time_jumps(path, topic, &j.name, &j.time_nanos)?;
        }
        let warnings = series.report.warnings();
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
        Ok(JointTrajectory { source: path.to_path_buf(), start_nanos: t0, joints, warnings })
    }

    /// From a `trajectory_msgs/msg/JointTrajectory` topic: each message's points start at its
    /// header stamp (its log time when the stamp is 0) plus `time_from_start`; as on a ROS 2
    /// controller, a later message replaces the earlier ones' points from its first point on.
    /// Velocities are kept when every point has them.
    ///
    /// # Errors
    /// As [`crate::log::Log::read_typed`]; [`Error::Trajectory`] for no points, messages naming
    /// different joints, a point whose positions don't match the joint names, or times that
    /// don't increase.
    pub fn from_trajectory_messages(log: &crate::log::Log, topic: &str) -> Result<JointTrajectory> {
        let path = log.path();
        let bad = |message: String| Error::Trajectory { path: path.to_path_buf(), line: None, message };
        let (messages, _) = log.read_typed::<crate::log::JointTrajectory>(topic)?;
        let mut names: Option<Vec<String>> = None;
        // (time ns, positions, velocities)
        let mut points: Vec<(i64, Vec<f64>, Vec<f64>)> = Vec::new();
        for (i, (log_time, m)) in messages.iter().enumerate() {
            match &names {
                None => names = Some(m.joint_names.clone()),
                Some(n) if *n != m.joint_names => {
                    return Err(bad(format!(
                        "topic {topic}: message {} names joints [{}], the first named [{}]; replay needs one set                          of joints",
                        i + 1,
                        m.joint_names.join(", "),
                        n.join(", ")
                    )));
                }
                Some(_) => {}
            }
            let start = if m.header.stamp_nanos != 0 { m.header.stamp_nanos } else { *log_time as i64 };
            if let Some(first) = m.points.first() {
                let from = start + first.time_from_start_nanos;
                points.retain(|p| p.0 < from);
            }
            for (k, p) in m.points.iter().enumerate() {
                if p.positions.len() != m.joint_names.len() {
                    return Err(bad(format!(
                        "topic {topic}: message {}, point {}: {} positions for {} joints",
                        i + 1,
                        k + 1,
                        p.positions.len(),
                        m.joint_names.len()
                    )));
                }
                let velocities =
                    if p.velocities.len() == m.joint_names.len() { p.velocities.clone() } else { Vec::new() };
                points.push((start + p.time_from_start_nanos, p.positions.clone(), velocities));
            }
        }
        let names = names.unwrap_or_default();
        if points.is_empty() || names.is_empty() {
            return Err(bad(format!("topic {topic} has no trajectory points")));
        }
        if let Some(k) = (1..points.len()).find(|&k| points[k].0 <= points[k - 1].0) {
            return Err(bad(format!(
                "topic {topic}: point times do not increase at point {} ({:.6} s after {:.6} s)",
                k + 1,
                (points[k].0 - points[0].0) as f64 * 1e-9,
                (points[k - 1].0 - points[0].0) as f64 * 1e-9
            )));
        }
        let t0 = points[0].0;
        let time_secs: Vec<f64> = points.iter().map(|p| (p.0 - t0) as f64 * 1e-9).collect();
        let with_velocity = points.iter().all(|p| !p.2.is_empty());
        let joints = names
            .iter()
            .enumerate()
            .map(|(j, name)| TrajectoryJoint {
                name: name.clone(),
                time_secs: time_secs.clone(),
                position: points.iter().map(|p| p.1[j]).collect(),
                velocity: with_velocity.then(|| points.iter().map(|p| p.2[j]).collect()),
            })
            .collect();
        Ok(JointTrajectory { source: path.to_path_buf(), start_nanos: t0, joints, warnings: Vec::new() })
    }

    /// From a CSV file: a header `time_sec,<joint>,<joint>,…` (a column `<joint>_vel` next to a
    /// column `<joint>` gives its velocity), then one row per sample, times in seconds,
    /// increasing.
    ///
    /// # Errors
    /// [`Error::Io`]; [`Error::Trajectory`] naming the line for a bad header, a non-number, a
    /// short row or a time that does not increase.
    pub fn from_csv(path: &std::path::Path) -> Result<JointTrajectory> {
        let text = crate::fsio::read_to_string(path)?;
        let bad =
            |line: usize, message: String| Error::Trajectory { path: path.to_path_buf(), line: Some(line), message };
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let Some((_, header)) = lines.next() else {
            return Err(bad(1, "empty file; expected a header `time_sec,<joint>,…`".into()));
        };
        let columns: Vec<&str> = header.split(',').map(str::trim).collect();
        if columns.first().is_none_or(|c| !matches!(*c, "time_sec" | "time_secs" | "time" | "t")) || columns.len() < 2 {
            return Err(bad(
                1,
                format!(
                    "header must be `time_sec,<joint>,…` (got `{}`)",
                    crate::fsio::excerpt(header, crate::fsio::EXCERPT_CHARS)
                ),
            ));
        }
        let mut rows: Vec<Vec<f64>> = vec![Vec::new(); columns.len()];
        for (i, line) in lines {
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            if cells.len() != columns.len() {
                return Err(bad(i + 1, format!("{} values, the header has {} columns", cells.len(), columns.len())));
            }
            for (k, cell) in cells.iter().enumerate() {
                let v: f64 = cell.parse().ok().filter(|v: &f64| v.is_finite()).ok_or_else(|| {
                    bad(
                        i + 1,
                        format!(
                            "column {}: `{}` is not a finite number",
                            crate::fsio::excerpt(columns[k], crate::fsio::EXCERPT_CHARS),
                            crate::fsio::excerpt(cell, crate::fsio::EXCERPT_CHARS)
                        ),
                    )
                })?;
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
        Ok(JointTrajectory { source: path.to_path_buf(), start_nanos: 0, joints, warnings: Vec::new() })
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
    pub(super) hold: PdHold,
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
