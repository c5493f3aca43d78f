//! Joint-state logs: the [`JointLog`] struct every reader fills (CSV here; ROS 2 MCAP
//! `/joint_states` elsewhere) and the CSV format of `twin sysid --log FILE.csv`.
//!
//! ## CSV format
//! One header line, then one line per sample, comma separated:
//!
//! ```text
//! time_sec,shoulder/position,shoulder/velocity,shoulder/effort,elbow/position,elbow/effort
//! 0.000,0.1,0.0,1.25,-0.3,0.4
//! 0.001,0.1001,0.1,1.26,-0.3,0.41
//! ```
//!
//! - `time_sec`: time in seconds (any origin), non-decreasing.
//! - `<joint>/position` (rad or m) and `<joint>/effort` (N·m or N) for each joint;
//!   `<joint>/velocity` is optional (twin differentiates the filtered positions instead).
//! - An empty cell, `nan` or `NaN` means "missing" (stored as NaN).
//! - Lines starting with `#` are comments.

use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::Path;

/// Joint states of one log, matched to the model by joint name. Data are per joint:
/// `position[j][k]` is joint `joint_names[j]` at sample `k`, taken at `t_nanos[k]`.
/// Missing values are NaN (a joint without velocity has all-NaN `velocity[j]`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointLog {
    /// Joint names, as in the URDF.
    pub joint_names: Vec<String>,
    /// Sample times, nanoseconds (any origin), non-decreasing.
    pub t_nanos: Vec<i64>,
    /// Positions, rad or m, `[joint][sample]`.
    pub position: Vec<Vec<f64>>,
    /// Velocities, rad/s or m/s, `[joint][sample]` (NaN when not logged).
    pub velocity: Vec<Vec<f64>>,
    /// Efforts, N·m or N, `[joint][sample]` (NaN when not logged).
    pub effort: Vec<Vec<f64>>,
    /// Where the data came from (file, topic), for messages.
    pub source: String,
    /// Motion of a floating base (`None`: none logged).
    pub base: Option<BaseTrajectory>,
    /// External (contact) wrenches on bodies of the robot.
    pub wrenches: Vec<WrenchSeries>,
}

/// Pose of a floating base over time, from `nav_msgs/msg/Odometry` (REP-105: pose of the child
/// frame, the base link, in the odometry/world frame).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BaseTrajectory {
    /// Where it came from (topic).
    pub topic: String,
    /// Sample times, nanoseconds, same clock as [`JointLog::t_nanos`].
    pub t_nanos: Vec<i64>,
    /// Position of the base link's origin in the world (odom) frame, m.
    pub position: Vec<[f64; 3]>,
    /// Orientation world_from_base, quaternion `w x y z`.
    pub orientation_wxyz: Vec<[f64; 4]>,
    /// Twist of the base in the base frame (REP-105), `[vx, vy, vz, wx, wy, wz]` (m/s, rad/s),
    /// one per sample, or empty when the odometry carries none (all zero): the base velocity
    /// then comes from differentiating the pose, which is noisier.
    pub twist: Vec<[f64; 6]>,
}

/// An external wrench on one body over time, from `geometry_msgs/msg/WrenchStamped`: force (N)
/// and torque (N·m) expressed in the frame of body `body` (the message's `header.frame_id`),
/// the torque about that frame's origin: the convention of `twin sim`'s contact wrench topics
/// (`/contacts/<link>`). Outside the topic's time span the wrench is zero (no contact).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WrenchSeries {
    /// The topic.
    pub topic: String,
    /// The body (URDF link) the wrench acts on and is expressed in.
    pub body: String,
    /// Sample times, nanoseconds.
    pub t_nanos: Vec<i64>,
    /// `[fx, fy, fz, nx, ny, nz]` per sample.
    pub wrench: Vec<[f64; 6]>,
}

impl JointLog {
    /// An empty log for `joint_names`.
    pub fn new(joint_names: Vec<String>, source: impl Into<String>) -> JointLog {
        let n = joint_names.len();
        JointLog {
            joint_names,
            t_nanos: Vec::new(),
            position: vec![Vec::new(); n],
            velocity: vec![Vec::new(); n],
            effort: vec![Vec::new(); n],
            source: source.into(),
            base: None,
            wrenches: Vec::new(),
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_nanos.len()
    }

    /// Whether the log has no samples.
    pub fn is_empty(&self) -> bool {
        self.t_nanos.is_empty()
    }

    /// Appends one sample; `position`, `velocity`, `effort` have one entry per joint.
    pub fn push(&mut self, t_nanos: i64, position: &[f64], velocity: &[f64], effort: &[f64]) {
        self.t_nanos.push(t_nanos);
        for j in 0..self.joint_names.len() {
            self.position[j].push(position.get(j).copied().unwrap_or(f64::NAN));
            self.velocity[j].push(velocity.get(j).copied().unwrap_or(f64::NAN));
            self.effort[j].push(effort.get(j).copied().unwrap_or(f64::NAN));
        }
    }

    /// Index of joint `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joint_names.iter().position(|n| n == name)
    }

    /// Checks shapes: every per-joint series as long as `t_nanos`.
    ///
    /// # Errors
    /// [`Error::BadLog`] naming the joint whose series has the wrong length.
    pub fn check_shape(&self) -> Result<()> {
        let n = self.t_nanos.len();
        let nj = self.joint_names.len();
        for (what, series) in [("position", &self.position), ("velocity", &self.velocity), ("effort", &self.effort)] {
            if series.len() != nj {
                return Err(self.bad(format!("{what} has {} joints, the log names {nj}", series.len())));
            }
            for (j, s) in series.iter().enumerate() {
                if s.len() != n {
                    return Err(self.bad(format!(
                        "{what} of joint \"{}\" has {} samples, the log has {n} timestamps",
                        self.joint_names[j],
                        s.len()
                    )));
                }
            }
        }
        Ok(())
    }

    pub(crate) fn bad(&self, message: String) -> Error {
        Error::BadLog { source_name: self.source.clone(), message }
    }

    /// Reads a CSV log (format in the [module docs](self)).
    ///
    /// # Errors
    /// [`Error::Core`] if unreadable, [`Error::Csv`] naming the line for a bad header, a wrong
    /// number of cells or a cell that is not a number.
    pub fn read_csv(path: impl AsRef<Path>) -> Result<JointLog> {
        let path = path.as_ref();
        let ex = |s: &str| twin_core::fsio::excerpt(s, twin_core::fsio::EXCERPT_CHARS);
        let text = twin_core::fsio::read_to_string(path)?;
        let csv_err = |line: usize, message: String| Error::Csv { path: path.to_path_buf(), line, message };
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (header_line, header) = lines
            .next()
            .ok_or_else(|| csv_err(1, "empty file: expected a header line starting with time_sec".into()))?;
        let columns: Vec<&str> = header.split(',').map(str::trim).collect();
        if columns.first() != Some(&"time_sec") {
            return Err(csv_err(
                header_line,
                format!(
                    "the first column must be `time_sec`, found `{}` (format: time_sec,<joint>/position,<joint>/velocity,<joint>/effort,...)",
                    columns.first().unwrap_or(&"")
                ),
            ));
        }
        // Column -> (joint index, 0 position / 1 velocity / 2 effort).
        let mut names: Vec<String> = Vec::new();
        let mut slots = Vec::with_capacity(columns.len() - 1);
        for col in &columns[1..] {
            let (joint, field) = col.rsplit_once('/').ok_or_else(|| {
                csv_err(
                    header_line,
                    format!("column `{col}` is not `<joint>/position`, `<joint>/velocity` or `<joint>/effort`"),
                )
            })?;
            let kind = match field {
                "position" => 0,
                "velocity" => 1,
                "effort" => 2,
                other => {
                    return Err(csv_err(
                        header_line,
                        format!("column `{col}`: unknown field `{other}` (expected position, velocity or effort)"),
                    ));
                }
            };
            let j = match names.iter().position(|n| n == joint) {
                Some(j) => j,
                None => {
                    names.push(joint.to_string());
                    names.len() - 1
                }
            };
            if slots.contains(&(j, kind)) {
                return Err(csv_err(header_line, format!("column `{col}` appears twice")));
            }
            slots.push((j, kind));
        }
        let mut log = JointLog::new(names, path.display().to_string());
        let nj = log.joint_names.len();
        let (mut p, mut v, mut e) = (vec![f64::NAN; nj], vec![f64::NAN; nj], vec![f64::NAN; nj]);
        for (line_no, line) in lines {
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            if cells.len() != columns.len() {
                return Err(csv_err(line_no, format!("{} cells, the header has {}", cells.len(), columns.len())));
            }
            let parse = |cell: &str, col: &str| -> Result<f64> {
                if cell.is_empty() || cell.eq_ignore_ascii_case("nan") {
                    return Ok(f64::NAN);
                }
                cell.parse::<f64>()
                    .map_err(|_| csv_err(line_no, format!("column `{}`: `{}` is not a number", ex(col), ex(cell))))
            };
            let t = parse(cells[0], "time_sec")?;
            if !t.is_finite() {
                return Err(csv_err(line_no, "time_sec is missing or not finite".into()));
            }
            p.fill(f64::NAN);
            v.fill(f64::NAN);
            e.fill(f64::NAN);
            for (k, &(j, kind)) in slots.iter().enumerate() {
                let x = parse(cells[k + 1], columns[k + 1])?;
                if x.is_infinite() {
                    // NaN (an empty cell) means "not measured"; an infinity is a broken value.
                    return Err(csv_err(
                        line_no,
                        format!("column `{}`: `{}` is not finite", ex(columns[k + 1]), ex(cells[k + 1])),
                    ));
                }
                match kind {
                    0 => p[j] = x,
                    1 => v[j] = x,
                    _ => e[j] = x,
                }
            }
            log.push((t * 1e9).round() as i64, &p, &v, &e);
        }
        Ok(log)
    }

    /// The log as CSV text (format in the [module docs](self)); NaN is written as an empty cell.
    pub fn to_csv(&self) -> String {
        let mut out = String::from("time_sec");
        for name in &self.joint_names {
            let _ = write!(out, ",{name}/position,{name}/velocity,{name}/effort");
        }
        out.push('\n');
        let cell = |out: &mut String, x: f64| {
            if x.is_finite() {
                let _ = write!(out, ",{x}");
            } else {
                out.push(',');
            }
        };
        for k in 0..self.len() {
            let t = self.t_nanos[k];
            if t >= 0 {
                let _ = write!(out, "{}.{:09}", t / 1_000_000_000, t % 1_000_000_000);
            } else {
                let _ = write!(out, "{}", t as f64 * 1e-9);
            }
            for j in 0..self.joint_names.len() {
                cell(&mut out, self.position[j][k]);
                cell(&mut out, self.velocity[j][k]);
                cell(&mut out, self.effort[j][k]);
            }
            out.push('\n');
        }
        out
    }

    /// Writes the log as CSV (atomically: temp file + rename).
    ///
    /// # Errors
    /// [`Error::Core`].
    pub fn write_csv(&self, path: impl AsRef<Path>) -> Result<()> {
        twin_core::fsio::write_atomic(path.as_ref(), self.to_csv().as_bytes(), twin_core::fsio::Backup::None)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_and_reports_bad_lines() {
        let dir = tempfile::tempdir().unwrap();
        let mut log = JointLog::new(vec!["a".into(), "b/c".into()], "mem");
        log.push(0, &[0.5, -1.25], &[f64::NAN, 2.0], &[3.0, 4.5]);
        log.push(1_000_000, &[0.51, -1.2], &[0.1, 2.1], &[3.1, f64::NAN]);
        let path = dir.path().join("log.csv");
        log.write_csv(&path).unwrap();
        let back = JointLog::read_csv(&path).unwrap();
        assert_eq!(back.joint_names, log.joint_names);
        assert_eq!(back.t_nanos, log.t_nanos);
        assert_eq!(back.position, log.position);
        assert!(back.velocity[0][0].is_nan() && back.velocity[1][1] == 2.1);
        assert!(back.effort[1][1].is_nan());

        std::fs::write(&path, "time_sec,a/position,a/effort\n0,1,2\n0.001,1,oops\n").unwrap();
        let err = JointLog::read_csv(&path).unwrap_err().to_string();
        assert!(err.contains("log.csv:3: column `a/effort`: `oops` is not a number"), "{err}");
        std::fs::write(&path, "t,a/position\n").unwrap();
        let err = JointLog::read_csv(&path).unwrap_err().to_string();
        assert!(err.contains(":1: the first column must be `time_sec`"), "{err}");
        std::fs::write(&path, "time_sec,a/torque\n").unwrap();
        let err = JointLog::read_csv(&path).unwrap_err().to_string();
        assert!(err.contains("unknown field `torque`"), "{err}");
    }
}

impl JointLog {
    /// Reads `sensor_msgs/msg/JointState` from a ROS 2 bag (a rosbag2 folder or a bare `.mcap`).
    /// `topic` picks one topic; without it every JointState topic is read and merged by joint
    /// name (an arm's driver and its gripper's publish on topics of their own; per-limb
    /// controllers likewise), each topic with its own timestamps (`header.stamp`, or the log
    /// time where a stamp is zero). A joint named on several topics is taken from the one with
    /// the most samples of it (a warning names the others). Publishers of one topic are merged
    /// by joint name too. Joints sampled at different instants are put on the union of their
    /// times within the span they all cover, by linear interpolation between each joint's own
    /// neighbouring samples. Damage the reader recovered from comes back as warnings.
    ///
    /// # Errors
    /// [`Error::Core`] for unreadable or damaged (strict) files and a missing topic;
    /// [`Error::BadLog`] when there is no JointState topic.
    pub fn read_mcap(path: impl AsRef<Path>, topic: Option<&str>) -> Result<(JointLog, Vec<String>)> {
        use twin_core::log::{Log, ReadOptions};
        let path = path.as_ref();
        let log = Log::open(path, ReadOptions::default())?;
        let source_name = path.display().to_string();
        let topics: Vec<String> = match topic {
            Some(t) => vec![t.to_string()],
            None => {
                let info = log.info()?;
                let candidates: Vec<String> =
                    info.topics_of_type("JointState").into_iter().map(str::to_string).collect();
                if candidates.is_empty() {
                    return Err(Error::BadLog {
                        source_name,
                        message: "no sensor_msgs/msg/JointState topic in the log; record /joint_states".into(),
                    });
                }
                candidates
            }
        };
        let mut warnings = Vec::new();
        // Joint name → (topic, series); the topic with the most samples of a joint wins.
        let mut joints: Vec<(String, twin_core::log::JointSeries)> = Vec::new();
        for t in &topics {
            let series = log.joint_states(t)?;
            warnings.extend(series.report.warnings());
            for j in series.joints {
                match joints.iter_mut().find(|(_, have)| have.name == j.name) {
                    Some((other_topic, have)) => {
                        let (kept, dropped) = if j.len() > have.len() {
                            (t.as_str(), other_topic.as_str())
                        } else {
                            (other_topic.as_str(), t.as_str())
                        };
                        warnings.push(format!(
                            "joint \"{}\" is published on {kept} and {dropped}: the samples of {kept} (more of them) are used",
                            j.name
                        ));
                        if j.len() > have.len() {
                            *other_topic = t.clone();
                            *have = j;
                        }
                    }
                    None => joints.push((t.clone(), j)),
                }
            }
        }
        let used: Vec<&str> =
            topics.iter().filter(|t| joints.iter().any(|(jt, _)| jt == *t)).map(String::as_str).collect();
        if used.len() > 1 {
            warnings.push(format!(
                "joint states merged by joint name from {} topics ({}), each with its own timestamps",
                used.len(),
                used.join(", ")
            ));
        }
        let source = if used.len() == 1 {
            format!("{} topic {}", path.display(), used[0])
        } else {
            format!("{} topics {}", path.display(), used.join(", "))
        };
        let series: Vec<twin_core::log::JointSeries> = joints.into_iter().map(|(_, j)| j).collect();
        Ok((JointLog::from_series(&series, source), warnings))
    }

    /// Builds a log from per-joint series (each with its own sorted times).
    pub fn from_series(joints: &[twin_core::log::JointSeries], source: impl Into<String>) -> JointLog {
        let mut log = JointLog::new(joints.iter().map(|j| j.name.clone()).collect(), source);
        let shared = joints.windows(2).all(|w| w[0].time_nanos == w[1].time_nanos);
        if shared {
            // One publisher (the usual case): copy as is.
            log.t_nanos = joints.first().map(|j| j.time_nanos.clone()).unwrap_or_default();
            for (k, j) in joints.iter().enumerate() {
                log.position[k] = j.position.clone();
                log.velocity[k] = j.velocity.clone();
                log.effort[k] = j.effort.clone();
            }
            return log;
        }
        // The span every joint covers: outside it some joint has no neighbours to interpolate.
        let start = joints.iter().filter_map(|j| j.time_nanos.first()).copied().max().unwrap_or(0);
        let end = joints.iter().filter_map(|j| j.time_nanos.last()).copied().min().unwrap_or(0);
        let mut times: Vec<i64> =
            joints.iter().flat_map(|j| j.time_nanos.iter().copied()).filter(|t| (start..=end).contains(t)).collect();
        times.sort_unstable();
        times.dedup();
        for (k, j) in joints.iter().enumerate() {
            log.position[k] = times.iter().map(|&t| interpolate(&j.time_nanos, &j.position, t)).collect();
            log.velocity[k] = times.iter().map(|&t| interpolate(&j.time_nanos, &j.velocity, t)).collect();
            log.effort[k] = times.iter().map(|&t| interpolate(&j.time_nanos, &j.effort, t)).collect();
        }
        log.t_nanos = times;
        log
    }
}

/// Linear interpolation of `values` (sampled at sorted `times`) at `t`; NaN outside the samples.
fn interpolate(times: &[i64], values: &[f64], t: i64) -> f64 {
    let i = times.partition_point(|&x| x < t);
    match (times.get(i), i.checked_sub(1).and_then(|p| times.get(p).map(|&tp| (p, tp)))) {
        (Some(&ti), _) if ti == t => values[i],
        (Some(&ti), Some((p, tp))) => {
            let a = (t - tp) as f64 / (ti - tp) as f64;
            values[p] + a * (values[i] - values[p])
        }
        _ => f64::NAN,
    }
}

impl JointLog {
    /// Writes the log as a ROS 2 bag (`.mcap`, profile `ros2`): one `sensor_msgs/msg/JointState`
    /// per sample on `topic`, header stamp = log time = the sample time. NaN velocities/efforts
    /// of a joint that has none are written as empty arrays, as drivers that don't report them do.
    ///
    /// # Errors
    /// [`Error::Core`] if the file can't be written.
    pub fn write_mcap(&self, path: impl AsRef<Path>, topic: &str) -> Result<()> {
        use twin_core::log::{Header, JointState, LogWriter, WriterOptions};
        let mut writer = LogWriter::create(path.as_ref(), &WriterOptions::default())?;
        let channel = writer.add_topic::<JointState>(topic)?;
        let all_nan = |v: &[Vec<f64>]| v.iter().all(|j| j.iter().all(|x| x.is_nan()));
        let (has_velocity, has_effort) = (!all_nan(&self.velocity), !all_nan(&self.effort));
        let mut msg = JointState { name: self.joint_names.clone(), ..Default::default() };
        for (k, &t) in self.t_nanos.iter().enumerate() {
            msg.header = Header { stamp_nanos: t, frame_id: String::new() };
            msg.position = self.position.iter().map(|j| j[k]).collect();
            msg.velocity = if has_velocity { self.velocity.iter().map(|j| j[k]).collect() } else { Vec::new() };
            msg.effort = if has_effort { self.effort.iter().map(|j| j[k]).collect() } else { Vec::new() };
            writer.write(channel, t.max(0) as u64, &msg)?;
        }
        if let Some(base) = &self.base {
            use twin_core::log::Odometry;
            let odom = writer.add_topic::<Odometry>(&base.topic)?;
            for (k, &t) in base.t_nanos.iter().enumerate() {
                let [w, x, y, z] = base.orientation_wxyz[k];
                // REP-105 twist: in the child (base) frame, from the neighbouring poses.
                let (a, b) = (k.saturating_sub(1), (k + 1).min(base.t_nanos.len() - 1));
                let (linear_velocity, angular_velocity) = if let Some(t) = base.twist.get(k) {
                    ([t[0], t[1], t[2]], [t[3], t[4], t[5]])
                } else if b > a {
                    let dt = (base.t_nanos[b] - base.t_nanos[a]) as f64 * 1e-9;
                    twist_in_base(
                        base.position[a],
                        base.orientation_wxyz[a],
                        base.position[b],
                        base.orientation_wxyz[b],
                        dt,
                    )
                } else {
                    ([0.0; 3], [0.0; 3])
                };
                let msg = Odometry {
                    header: Header { stamp_nanos: t, frame_id: "odom".into() },
                    child_frame_id: "base_link".into(),
                    position: base.position[k],
                    orientation_xyzw: [x, y, z, w],
                    linear_velocity,
                    angular_velocity,
                    ..Default::default()
                };
                writer.write(odom, t.max(0) as u64, &msg)?;
            }
        }
        for series in &self.wrenches {
            use twin_core::log::WrenchStamped;
            let topic = writer.add_topic::<WrenchStamped>(&series.topic)?;
            for (k, &t) in series.t_nanos.iter().enumerate() {
                let w = series.wrench[k];
                let msg = WrenchStamped {
                    header: Header { stamp_nanos: t, frame_id: series.body.clone() },
                    force: [w[0], w[1], w[2]],
                    torque: [w[3], w[4], w[5]],
                };
                writer.write(topic, t.max(0) as u64, &msg)?;
            }
        }
        writer.finish()?;
        Ok(())
    }
}

/// Twist of the base frame between two poses `dt` apart, in the base frame (REP-105):
/// `(linear, angular)`, m/s and rad/s.
fn twist_in_base(p0: [f64; 3], q0: [f64; 4], p1: [f64; 3], q1: [f64; 4], dt: f64) -> ([f64; 3], [f64; 3]) {
    use nalgebra::{Quaternion, UnitQuaternion, Vector3};
    let r0 = UnitQuaternion::from_quaternion(Quaternion::new(q0[0], q0[1], q0[2], q0[3]));
    let r1 = UnitQuaternion::from_quaternion(Quaternion::new(q1[0], q1[1], q1[2], q1[3]));
    let v_world = (Vector3::from(p1) - Vector3::from(p0)) / dt;
    let v = r0.inverse() * v_world;
    let w = (r0.inverse() * r1).scaled_axis() / dt;
    ([v.x, v.y, v.z], [w.x, w.y, w.z])
}

impl JointLog {
    /// Reads a floating robot's log from a ROS 2 bag: joint states as [`JointLog::read_mcap`],
    /// base motion from the `nav_msgs/msg/Odometry` topic `odom_topic`, and every
    /// `geometry_msgs/msg/WrenchStamped` topic as an external wrench on the body its
    /// `header.frame_id` names (see [`WrenchSeries`]). Joint samples outside the odometry's
    /// time span are dropped (with a warning).
    ///
    /// # Errors
    /// As [`JointLog::read_mcap`]; [`Error::BadLog`] when `odom_topic` is not in the bag (the
    /// message names the topics that are), is not Odometry, or has fewer than 2 messages.
    pub fn read_mcap_floating(
        path: impl AsRef<Path>,
        topic: Option<&str>,
        odom_topic: &str,
    ) -> Result<(JointLog, Vec<String>)> {
        use twin_core::log::{Log, Odometry, ReadOptions, WrenchStamped};
        let path = path.as_ref();
        let (mut log, mut warnings) = JointLog::read_mcap(path, topic)?;
        let bag = Log::open(path, ReadOptions::default())?;
        let info = bag.info()?;
        let source_name = path.display().to_string();
        let listing =
            info.topics.iter().map(|t| format!("{} ({})", t.topic, t.type_name)).collect::<Vec<_>>().join(", ");
        match info.topics.iter().find(|t| t.topic == odom_topic) {
            None => {
                let odoms = info.topics_of_type("Odometry");
                let hint = if odoms.is_empty() {
                    "record the base pose and twist as nav_msgs/msg/Odometry (from motion capture or the state                      estimator), or hang the robot on a gantry and use --base fixed"
                        .to_string()
                } else {
                    format!("choose the odometry topic with --odom-topic ({})", odoms.join(", "))
                };
                return Err(Error::BadLog {
                    source_name,
                    message: format!(
                        "--base floating needs the base motion, but the bag has no topic {odom_topic}; its topics are:                          {listing}; {hint}"
                    ),
                });
            }
            Some(t) if !t.type_name.ends_with("Odometry") => {
                return Err(Error::BadLog {
                    source_name,
                    message: format!(
                        "topic {odom_topic} has type {}, expected nav_msgs/msg/Odometry (choose another with --odom-topic)",
                        t.type_name
                    ),
                });
            }
            Some(_) => {}
        }
        let (odom, report) = bag.read_typed::<Odometry>(odom_topic)?;
        warnings.extend(report.warnings());
        let mut base = BaseTrajectory { topic: odom_topic.to_string(), ..Default::default() };
        for (log_time, msg) in &odom {
            let t = if msg.header.stamp_nanos != 0 { msg.header.stamp_nanos } else { *log_time as i64 };
            let [x, y, z, w] = msg.orientation_xyzw;
            let norm = (w * w + x * x + y * y + z * z).sqrt();
            if !(norm > 0.5 && norm < 1.5) || msg.position.iter().any(|v| !v.is_finite()) {
                return Err(Error::BadLog {
                    source_name,
                    message: format!(
                        "{odom_topic}: pose at t = {:.6} s is not finite or its quaternion is not unit (norm {norm:.3})",
                        t as f64 * 1e-9
                    ),
                });
            }
            if base.t_nanos.last().is_some_and(|&l| t <= l) {
                continue;
            }
            base.t_nanos.push(t);
            base.position.push(msg.position);
            base.orientation_wxyz.push([w / norm, x / norm, y / norm, z / norm]);
            let (v, om) = (msg.linear_velocity, msg.angular_velocity);
            base.twist.push([v[0], v[1], v[2], om[0], om[1], om[2]]);
        }
        if base.twist.iter().all(|t| t.iter().all(|&x| x == 0.0)) || base.twist.iter().flatten().any(|x| !x.is_finite())
        {
            base.twist.clear();
            warnings.push(format!(
                "{odom_topic} carries no usable twist: the base velocity is differentiated from the pose, which \
                 amplifies its noise"
            ));
        }
        if base.t_nanos.len() < 2 {
            return Err(Error::BadLog {
                source_name,
                message: format!(
                    "{odom_topic} has {} usable message(s); the base motion needs a stream",
                    base.t_nanos.len()
                ),
            });
        }
        let (first, last) = (base.t_nanos[0], *base.t_nanos.last().expect("2"));
        let keep: Vec<usize> = (0..log.len()).filter(|&k| (first..=last).contains(&log.t_nanos[k])).collect();
        if keep.len() < log.len() {
            warnings.push(format!(
                "{} of {} joint-state samples lie outside the span of {odom_topic} and were not used",
                log.len() - keep.len(),
                log.len()
            ));
            log.t_nanos = keep.iter().map(|&k| log.t_nanos[k]).collect();
            for series in [&mut log.position, &mut log.velocity, &mut log.effort] {
                for j in series.iter_mut() {
                    *j = keep.iter().map(|&k| j[k]).collect();
                }
            }
        }
        log.base = Some(base);
        for t in info.topics.iter().filter(|t| t.type_name.ends_with("WrenchStamped")) {
            let (msgs, report) = bag.read_typed::<WrenchStamped>(&t.topic)?;
            warnings.extend(report.warnings());
            let mut series = WrenchSeries { topic: t.topic.clone(), ..Default::default() };
            for (log_time, msg) in &msgs {
                let time = if msg.header.stamp_nanos != 0 { msg.header.stamp_nanos } else { *log_time as i64 };
                if series.body.is_empty() {
                    series.body = msg.header.frame_id.clone();
                } else if series.body != msg.header.frame_id {
                    return Err(Error::BadLog {
                        source_name,
                        message: format!(
                            "{}: header.frame_id changes from \"{}\" to \"{}\"; a contact wrench topic must \
                             keep one body frame",
                            t.topic, series.body, msg.header.frame_id
                        ),
                    });
                }
                if series.t_nanos.last().is_some_and(|&l| time <= l) {
                    continue;
                }
                let w = [msg.force[0], msg.force[1], msg.force[2], msg.torque[0], msg.torque[1], msg.torque[2]];
                if w.iter().any(|v| !v.is_finite()) {
                    return Err(Error::BadLog {
                        source_name,
                        message: format!("{}: wrench at t = {:.6} s is not finite", t.topic, time as f64 * 1e-9),
                    });
                }
                series.t_nanos.push(time);
                series.wrench.push(w);
            }
            if !series.t_nanos.is_empty() {
                log.wrenches.push(series);
            }
        }
        log.source = format!("{} (base motion from {odom_topic}, {} wrench topic(s))", log.source, log.wrenches.len());
        Ok((log, warnings))
    }
}

#[cfg(test)]
mod mcap_tests {
    use super::*;

    #[test]
    fn ros2_bag_round_trip_keeps_every_value() {
        let mut log = JointLog::new(vec!["a".into(), "b".into()], "test");
        for k in 0..50 {
            let t = k as f64 * 0.002;
            log.push(1_000_000_000 + k * 2_000_000, &[t.sin(), -t], &[t.cos(), -1.0], &[0.5 * t, 2.0]);
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("js.mcap");
        log.write_mcap(&path, "/joint_states").unwrap();
        let (back, warnings) = JointLog::read_mcap(&path, None).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(back.joint_names, log.joint_names);
        assert_eq!(back.t_nanos, log.t_nanos);
        assert_eq!(back.position, log.position);
        assert_eq!(back.velocity, log.velocity);
        assert_eq!(back.effort, log.effort);
        assert!(back.source.contains("/joint_states"));
    }

    #[test]
    fn publishers_at_different_instants_are_interpolated_onto_one_timeline() {
        use twin_core::log::JointSeries;
        let arm = JointSeries {
            name: "arm".into(),
            time_nanos: vec![0, 10, 20],
            position: vec![0.0, 1.0, 2.0],
            velocity: vec![f64::NAN; 3],
            effort: vec![0.0, 10.0, 20.0],
        };
        let grip = JointSeries {
            name: "grip".into(),
            time_nanos: vec![5, 15],
            position: vec![5.0, 15.0],
            velocity: vec![f64::NAN; 2],
            effort: vec![1.0, 3.0],
        };
        let log = JointLog::from_series(&[arm, grip], "t");
        // The span both cover, each joint's own samples and the other's interpolated there.
        assert_eq!(log.t_nanos, vec![5, 10, 15]);
        assert_eq!(log.position[0], vec![0.5, 1.0, 1.5]);
        assert_eq!(log.position[1], vec![5.0, 10.0, 15.0]);
        assert_eq!(log.effort[1], vec![1.0, 2.0, 3.0]);
    }
}
