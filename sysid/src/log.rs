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
    /// [`Error::Io`] if unreadable, [`Error::Csv`] naming the line for a bad header, a wrong
    /// number of cells or a cell that is not a number.
    pub fn read_csv(path: impl AsRef<Path>) -> Result<JointLog> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
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
                cell.parse::<f64>().map_err(|_| csv_err(line_no, format!("column `{col}`: `{cell}` is not a number")))
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
    /// [`Error::Io`].
    pub fn write_csv(&self, path: impl AsRef<Path>) -> Result<()> {
        crate::writeback::write_atomic(path.as_ref(), self.to_csv().as_bytes())
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
    /// `topic` picks the topic; without it the only JointState topic is used (`/joint_states`
    /// when there are several). Publishers of one topic are merged by joint name; joints
    /// published at different instants are put on the union of their times by linear
    /// interpolation (conditioning resamples to a uniform grid afterwards anyway). Damage the
    /// reader recovered from comes back as warnings.
    ///
    /// # Errors
    /// [`Error::Core`] for unreadable or damaged (strict) files and a missing topic;
    /// [`Error::BadLog`] when there is no JointState topic or several and none chosen.
    pub fn read_mcap(path: impl AsRef<Path>, topic: Option<&str>) -> Result<(JointLog, Vec<String>)> {
        use twin_core::log::{Log, ReadOptions};
        let path = path.as_ref();
        let log = Log::open(path, ReadOptions::default())?;
        let source_name = path.display().to_string();
        let topic = match topic {
            Some(t) => t.to_string(),
            None => {
                let info = log.info()?;
                let candidates: Vec<&str> = info
                    .topics
                    .iter()
                    .filter(|t| t.type_name.ends_with("JointState"))
                    .map(|t| t.topic.as_str())
                    .collect();
                match candidates.as_slice() {
                    [one] => one.to_string(),
                    [] => {
                        return Err(Error::BadLog {
                            source_name,
                            message: "no sensor_msgs/msg/JointState topic in the log; record /joint_states".into(),
                        });
                    }
                    many if many.contains(&"/joint_states") => "/joint_states".to_string(),
                    many => {
                        return Err(Error::BadLog {
                            source_name,
                            message: format!(
                                "several JointState topics ({}): choose one with --topic",
                                many.join(", ")
                            ),
                        });
                    }
                }
            }
        };
        let series = log.joint_states(&topic)?;
        // The series report includes the read report (damage recovered from).
        let warnings = series.report.warnings();
        let source = format!("{} topic {topic}", path.display());
        Ok((JointLog::from_series(&series.joints, source), warnings))
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
        let mut times: Vec<i64> = joints.iter().flat_map(|j| j.time_nanos.iter().copied()).collect();
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
        writer.finish()?;
        Ok(())
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
        assert_eq!(log.t_nanos, vec![0, 5, 10, 15, 20]);
        assert_eq!(log.position[0], vec![0.0, 0.5, 1.0, 1.5, 2.0]);
        assert!(log.position[1][0].is_nan() && log.position[1][4].is_nan());
        assert_eq!(&log.position[1][1..4], &[5.0, 10.0, 15.0]);
        assert_eq!(&log.effort[1][1..4], &[1.0, 2.0, 3.0]);
    }
}
