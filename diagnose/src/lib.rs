//! Why the robot fell, from any ROS 2 log (`twin log analyze`): simulated by twin or recorded on
//! the real robot.
//!
//! Data flow: [`analyze`] reads the log through [`twin_core::log`] (the JointState topic, the first
//! IMU and odometry topics, every `WrenchStamped` contact topic and the joint command topic),
//! turns each into [`Signal`]s on one time axis (header stamps, seconds from the first sample;
//! commands, which have no header, are mapped from log time onto that axis by a fit of the
//! JointState stamps against their log times), and then finds, each on its own:
//! - the fall ([`fall`]): when the base tilt or height crosses the engine's fall thresholds
//!   ([`FallOptions`], the ones `twin randomize` counts), the onset (where the tilt left its
//!   standing band and kept growing) and the direction in the robot's heading frame;
//! - with a model ([`stability`]): the base pose and joint positions posed on the model give the
//!   CoM, the capture point (CoM + v/ω) and the support polygon of the feet on the ground; when
//!   each left the polygon, and foot slip (a loaded, flat foot sliding);
//! - the sensor window before the onset: which IMU axis, contact force, joint position or
//!   effort changed first;
//! - command tracking ([`tracking`]): commanded against actual per joint (RMS, max, lag,
//!   saturation), the worst joints, and joints that oscillate;
//! - timing: the real-time factor when the stamps are simulated time and the log time is wall
//!   time.
//!
//! The findings become a [`Diagnosis`] list in the workflow's troubleshooting terms (falls
//! forward → CoM ahead; feet slip → friction; oscillation → gains; slow simulation →
//! timestep), each with the numbers behind it; [`Analysis::plots`] draws the window as SVG.

#![deny(unsafe_code)]

pub mod fall;
pub mod signal;
pub mod stability;
pub mod tracking;

pub use signal::Signal;

use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;
use twin_core::engine::observers::FallOptions;
use twin_core::error::{Error, Result};
use twin_core::log::{Float64MultiArray, Imu, JointState, JointTrajectory, Log, Odometry, RosMessage, WrenchStamped};
use twin_core::robot::Robot;

/// What a joint command means (`--command-interface`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CommandKind {
    /// Joint positions, rad (m).
    Position,
    /// Joint velocities, rad/s (m/s).
    Velocity,
    /// Joint efforts, N·m (N).
    Effort,
}

impl CommandKind {
    /// `position`, `velocity` or `effort`.
    pub fn as_str(self) -> &'static str {
        match self {
            CommandKind::Position => "position",
            CommandKind::Velocity => "velocity",
            CommandKind::Effort => "effort",
        }
    }

    fn unit(self) -> &'static str {
        match self {
            CommandKind::Position => "rad",
            CommandKind::Velocity => "rad/s",
            CommandKind::Effort => "N·m",
        }
    }
}

/// Options of [`analyze`].
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct AnalyzeOptions {
    /// The `sensor_msgs/msg/JointState` topic. (default: `/joint_states`)
    #[default("/joint_states")]
    pub joint_states_topic: String,
    /// The IMU topic. (default: none given = the first `sensor_msgs/msg/Imu` topic)
    pub imu_topic: Option<String>,
    /// The base pose topic. (default: none given = the first `nav_msgs/msg/Odometry` topic)
    pub odom_topic: Option<String>,
    /// The joint command topic: `std_msgs/msg/Float64MultiArray` (an array per actuator) or
    /// `trajectory_msgs/msg/JointTrajectory` (positions by joint name, interpolated in time).
    /// (default: none given = the Float64MultiArray topic whose name ends in `joint_commands`,
    /// else the only one; without one, the JointTrajectory topic whose name ends in
    /// `joint_trajectory`, else the only one)
    pub command_topic: Option<String>,
    /// What the commands are. (default: none given = the model's actuators' interface, else the
    /// JointState field the commands match best)
    pub command_kind: Option<CommandKind>,
    /// Fall thresholds: the engine's, those `twin randomize` counts. (default: 0.6 of the
    /// initial base height, 1.0 rad of tilt)
    pub fall: FallOptions,
    /// Length of the sensor window before the onset, s. (default: 1.0)
    #[default(1.0)]
    pub window_secs: f64,
    /// Horizontal speed of a loaded, flat foot above which it slips, m/s. (default: 0.1)
    #[default(0.1)]
    pub slip_speed_mps: f64,
    /// How many of the worst-tracking joints to report and plot. (default: 5)
    #[default(5)]
    pub worst_joints: usize,
}

/// One signal's first change in the window before the onset.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Change {
    /// The signal (`/imu gyro_y`, `left_knee effort`, `/contacts/left_foot |F|`…).
    pub signal: String,
    /// When it left its baseline, s.
    pub time_secs: f64,
    /// That time minus the onset, s (negative: before it).
    pub before_onset_secs: f64,
    /// Its baseline (mean over the window's first half).
    pub baseline: f64,
    /// Its value at the change.
    pub value: f64,
    /// The threshold it crossed (|value − baseline|).
    pub threshold: f64,
}

/// One finding in the workflow's troubleshooting terms.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnosis {
    /// The symptom → cause (`falls forward → CoM ahead of the feet`).
    pub cause: String,
    /// The numbers behind it.
    pub evidence: String,
    /// What to change.
    pub advice: String,
}

/// Timing of the log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Timing {
    /// JointState messages.
    pub joint_state_messages: u64,
    /// Median JointState interval, s.
    pub median_interval_secs: f64,
    /// Largest JointState interval, s, and when it ended.
    pub largest_gap_secs: f64,
    /// When the largest gap ended, s.
    pub largest_gap_end_secs: f64,
    /// Stamp seconds per log-time second over the JointState messages: the real-time factor
    /// when the stamps are simulated time and the log time is wall time (None: stamps are the
    /// log time, as in twin's own recordings, or too few messages).
    pub real_time_factor: Option<f64>,
}

/// Everything [`analyze`] found.
#[derive(Debug, Clone, Serialize)]
pub struct Analysis {
    /// The log.
    pub log: PathBuf,
    /// The time origin: stamp of the first sample read, ns; times are seconds from it.
    pub time_origin_nanos: i64,
    /// Span of the samples read, s.
    pub duration_secs: f64,
    /// Topics read, with what each gave.
    pub sources: Vec<String>,
    /// The fall, if the robot fell.
    pub fall: Option<fall::Fall>,
    /// CoM, capture point and slip (with a model and a base pose).
    pub stability: Option<stability::Stability>,
    /// What changed first in the window before the onset, earliest first.
    pub first_changes: Vec<Change>,
    /// Commanded against actual.
    pub tracking: Option<tracking::Tracking>,
    /// Joints that oscillate.
    pub oscillations: Vec<tracking::Oscillation>,
    /// Timing.
    pub timing: Option<Timing>,
    /// The diagnosis.
    pub diagnosis: Vec<Diagnosis>,
    /// What could not be analysed, and why.
    pub notes: Vec<String>,
    /// Warnings of the log reader (damage, odd stamps).
    pub warnings: Vec<String>,
    #[serde(skip)]
    data: Data,
}

/// A base pose: time (s), orientation (x, y, z, w), position (m) when known.
pub(crate) type Pose = (f64, [f64; 4], Option<[f64; 3]>);

/// A contact topic with its force magnitude and tangential/normal signals.
pub(crate) type ContactSignals<'a> = (String, &'a Signal, &'a Signal);

/// The signals read, for the window and the plots.
#[derive(Debug, Clone, Default)]
pub(crate) struct Data {
    pub tilt: Signal,
    pub height: Signal,
    pub gyro: Vec<Signal>,
    pub accel: Vec<Signal>,
    pub contacts: Vec<Signal>,
    /// Per contact topic: tangential over normal force in its frame.
    pub contact_ratios: Vec<Signal>,
    pub positions: Vec<Signal>,
    pub velocities: Vec<Signal>,
    pub efforts: Vec<Signal>,
    pub com_margin: Signal,
    pub cp_margin: Signal,
    pub commands: Vec<(String, Signal, Signal)>,
}

fn secs(nanos: i64, origin: i64) -> f64 {
    (nanos - origin) as f64 * 1e-9
}

/// Header stamp, or the log time where the stamp is zero.
fn stamp(header_nanos: i64, log_nanos: u64) -> i64 {
    if header_nanos == 0 { log_nanos as i64 } else { header_nanos }
}

/// The topics of a type, in the order `info` lists them.
fn topics_of(info: &twin_core::log::LogInfo, type_name: &str) -> Vec<String> {
    info.topics
        .iter()
        .filter(|t| twin_core::log::msgdef::normalize_type_name(&t.type_name) == type_name)
        .map(|t| t.topic.clone())
        .collect()
}

/// Analyses `log` (with `robot` when given: CoM, capture point, support polygon, slip, joint
/// limits and the command interface of its actuators).
///
/// # Errors
/// Reading the log ([`Log::info`] and the topics' reads); [`Error::LogTopic`] when a topic
/// asked for is absent; [`Error::Options`] for options out of range.
pub fn analyze(log: &Log, robot: Option<&Robot>, options: &AnalyzeOptions) -> Result<Analysis> {
    if !(options.window_secs > 0.0 && options.window_secs.is_finite()) {
        return Err(Error::Options(format!(
            "window must be a positive number of seconds, got {}",
            options.window_secs
        )));
    }
    if !(options.slip_speed_mps > 0.0 && options.slip_speed_mps.is_finite()) {
        return Err(Error::Options(format!("slip speed must be positive, got {} m/s", options.slip_speed_mps)));
    }
    let info = log.info()?;
    let mut warnings = info.read.warnings();
    let mut notes = Vec::new();
    let mut sources = Vec::new();
    let has = |topic: &str| info.topics.iter().any(|t| t.topic == topic);
    let pick = |given: &Option<String>, type_name: &str, what: &str| -> Result<Option<String>> {
        match given {
            Some(t) if has(t) => Ok(Some(t.clone())),
            Some(t) => Err(Error::Log(twin_core::log::Error::LogTopic {
                path: log.path().to_path_buf(),
                topic: t.clone(),
                message: format!(
                    "no {what} topic {t} in the log; its {type_name} topics: {}",
                    none_if_empty(&topics_of(&info, type_name))
                ),
            })),
            None => Ok(topics_of(&info, type_name).into_iter().next()),
        }
    };
    let imu_topic = pick(&options.imu_topic, Imu::TYPE_NAME, "IMU")?;
    let odom_topic = pick(&options.odom_topic, Odometry::TYPE_NAME, "odometry")?;
    let trajectory_topics = topics_of(&info, JointTrajectory::TYPE_NAME);
    let command_topic = match &options.command_topic {
        Some(t) if trajectory_topics.contains(t) => Some(t.clone()),
        Some(t) if has(t) && !topics_of(&info, Float64MultiArray::TYPE_NAME).contains(t) => {
            return Err(Error::Log(twin_core::log::Error::LogTopic {
                path: log.path().to_path_buf(),
                topic: t.clone(),
                message: format!(
                    "{t} is neither std_msgs/msg/Float64MultiArray nor trajectory_msgs/msg/JointTrajectory; command \
                     topics: {}",
                    none_if_empty(
                        &[topics_of(&info, Float64MultiArray::TYPE_NAME), trajectory_topics.clone()].concat()
                    )
                ),
            }));
        }
        Some(_) => pick(&options.command_topic, Float64MultiArray::TYPE_NAME, "command")?,
        None => {
            let by_name = |all: Vec<String>, suffix: &str| {
                all.iter()
                    .find(|t| t.ends_with(suffix))
                    .cloned()
                    .or_else(|| if all.len() == 1 { all.first().cloned() } else { None })
            };
            by_name(topics_of(&info, Float64MultiArray::TYPE_NAME), "joint_commands")
                .or_else(|| by_name(trajectory_topics.clone(), "joint_trajectory"))
        }
    };
    let command_is_trajectory = command_topic.as_ref().is_some_and(|t| trajectory_topics.contains(t));

    // Joint states, and their stamps against log times (commands are mapped through it).
    let joint_states = if has(&options.joint_states_topic) {
        let js = log.joint_states(&options.joint_states_topic)?;
        warnings.extend(js.report.warnings().into_iter().map(|w| format!("{}: {w}", options.joint_states_topic)));
        sources.push(format!(
            "{}: {} messages, {} joints",
            options.joint_states_topic,
            js.report.messages,
            js.joints.len()
        ));
        Some(js)
    } else {
        notes.push(format!(
            "no {} in the log (JointState topics: {}): no joint analysis",
            options.joint_states_topic,
            none_if_empty(&topics_of(&info, JointState::TYPE_NAME))
        ));
        None
    };
    let stamp_map = match &joint_states {
        Some(_) => stamp_fit(log, &options.joint_states_topic),
        None => None,
    };
    let imu = match &imu_topic {
        Some(t) => {
            let (msgs, report) = log.read_typed::<Imu>(t)?;
            warnings.extend(report.warnings().into_iter().map(|w| format!("{t}: {w}")));
            sources.push(format!("{t}: {} IMU messages", msgs.len()));
            msgs.into_iter().map(|(lt, m)| (stamp(m.header.stamp_nanos, lt), m)).collect()
        }
        None => {
            notes.push("no sensor_msgs/msg/Imu topic: no IMU in the window".into());
            Vec::new()
        }
    };
    let odom = match &odom_topic {
        Some(t) => {
            let (msgs, report) = log.read_typed::<Odometry>(t)?;
            warnings.extend(report.warnings().into_iter().map(|w| format!("{t}: {w}")));
            sources.push(format!("{t}: {} poses", msgs.len()));
            msgs.into_iter().map(|(lt, m)| (stamp(m.header.stamp_nanos, lt), m)).collect()
        }
        None => Vec::new(),
    };
    let mut contacts_raw: Vec<(String, Vec<(i64, WrenchStamped)>)> = Vec::new();
    for t in topics_of(&info, WrenchStamped::TYPE_NAME) {
        let (msgs, report) = log.read_typed::<WrenchStamped>(&t)?;
        warnings.extend(report.warnings().into_iter().map(|w| format!("{t}: {w}")));
        contacts_raw.push((t, msgs.into_iter().map(|(lt, m)| (stamp(m.header.stamp_nanos, lt), m)).collect()));
    }
    if !contacts_raw.is_empty() {
        sources.push(format!("{} WrenchStamped (contact) topics", contacts_raw.len()));
    }
    let mut trajectories_raw: Vec<(u64, JointTrajectory)> = Vec::new();
    let commands_raw = match &command_topic {
        Some(t) if command_is_trajectory => {
            let (msgs, report) = log.read_typed::<JointTrajectory>(t)?;
            warnings.extend(report.warnings().into_iter().map(|w| format!("{t}: {w}")));
            sources.push(format!("{t}: {} trajectories", msgs.len()));
            if options.command_kind.is_some_and(|k| k != CommandKind::Position) {
                notes.push(format!("{t}: trajectory points are compared as positions, whatever --command-kind says"));
            }
            trajectories_raw = msgs;
            Vec::new()
        }
        Some(t) => {
            let (msgs, report) = log.read_typed::<Float64MultiArray>(t)?;
            warnings.extend(report.warnings().into_iter().map(|w| format!("{t}: {w}")));
            sources.push(format!("{t}: {} commands", msgs.len()));
            msgs
        }
        None => {
            notes.push(format!(
                "no joint command topic (Float64MultiArray or JointTrajectory topics: {}): give --commands TOPIC to \
                 compare commanded with actual",
                none_if_empty(&[topics_of(&info, Float64MultiArray::TYPE_NAME), trajectory_topics].concat())
            ));
            Vec::new()
        }
    };

    // One time origin: the first sample read.
    let firsts = [
        joint_states.as_ref().and_then(|js| js.joints.iter().filter_map(|j| j.time_nanos.first().copied()).min()),
        imu.iter().map(|(t, _)| *t).min(),
        odom.iter().map(|(t, _)| *t).min(),
    ];
    let origin = firsts.iter().flatten().copied().min().unwrap_or(0);
    let mut data = Data::default();
    if let Some(js) = &joint_states {
        for j in &js.joints {
            let t: Vec<f64> = j.time_nanos.iter().map(|&n| secs(n, origin)).collect();
            let mk =
                |what: &str, v: &[f64]| Signal { name: format!("{} {what}", j.name), t_secs: t.clone(), v: v.to_vec() };
            data.positions.push(mk("position", &j.position));
            data.velocities.push(mk("velocity", &j.velocity));
            data.efforts.push(mk("effort", &j.effort));
        }
    }
    if let Some(t) = &imu_topic {
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            data.gyro.push(Signal::new(
                format!("{t} gyro_{axis}"),
                imu.iter().map(|(s, m)| (secs(*s, origin), m.angular_velocity[k])).collect(),
            ));
            data.accel.push(Signal::new(
                format!("{t} accel_{axis}"),
                imu.iter().map(|(s, m)| (secs(*s, origin), m.linear_acceleration[k])).collect(),
            ));
        }
    }
    for (t, msgs) in &contacts_raw {
        data.contacts.push(Signal::new(
            format!("{t} |F|"),
            msgs.iter().map(|(s, m)| (secs(*s, origin), nalgebra::Vector3::from(m.force).norm())).collect(),
        ));
        data.contact_ratios.push(Signal::new(
            format!("{t} tangential/normal"),
            msgs.iter()
                .filter(|(_, m)| m.force[2].abs() > 1e-9)
                .map(|(s, m)| (secs(*s, origin), m.force[0].hypot(m.force[1]) / m.force[2].abs()))
                .collect(),
        ));
    }

    // Orientation and height: odometry (world-referenced), else the IMU's orientation.
    let imu_has_orientation =
        imu.iter().any(|(_, m)| m.orientation_covariance[0] != -1.0 && m.orientation_xyzw.iter().any(|q| *q != 0.0));
    let poses: Vec<Pose> = if !odom.is_empty() {
        odom.iter().map(|(s, m)| (secs(*s, origin), m.orientation_xyzw, Some(m.position))).collect()
    } else if imu_has_orientation {
        notes.push("no odometry: tilt from the IMU's orientation, no base height".into());
        imu.iter().map(|(s, m)| (secs(*s, origin), m.orientation_xyzw, None)).collect()
    } else {
        notes.push("no odometry and no IMU orientation: no fall analysis (no base tilt or height)".into());
        Vec::new()
    };
    let fall = fall::find(&poses, &options.fall, &mut data, &mut notes);
    let fall_source = if !odom.is_empty() { odom_topic.clone() } else { imu_topic.clone() };

    let mut stability = None;
    if let Some(robot) = robot {
        match (&joint_states, odom.is_empty(), robot.base.is_some()) {
            (_, _, false) => notes.push(format!("{} has no floating base: no CoM or support polygon", robot.name)),
            (None, _, _) => {}
            (Some(_), true, _) => notes.push(
                "no odometry (base pose): the CoM, capture point and slip need the base pose with --model".into(),
            ),
            (Some(_), false, true) => {
                let contact_by_topic: Vec<ContactSignals<'_>> = contacts_raw
                    .iter()
                    .zip(data.contacts.iter().zip(&data.contact_ratios))
                    .map(|((t, _), (f, r))| (t.clone(), f, r))
                    .collect();
                let s = stability::compute(
                    robot,
                    &poses,
                    &data.positions,
                    &contact_by_topic,
                    fall.as_ref(),
                    options.slip_speed_mps,
                )?;
                data.com_margin = s.com_margin_signal.clone();
                data.cp_margin = s.cp_margin_signal.clone();
                stability = Some(s);
            }
        }
    }

    // Commands against actual.
    let tracking = match (&joint_states, commands_raw.is_empty() && trajectories_raw.is_empty()) {
        (Some(js), false) => {
            let t_map = |log_nanos: u64| match stamp_map {
                Some((a, b)) => secs((a + b * log_nanos as f64).round() as i64, origin),
                None => secs(log_nanos as i64, origin),
            };
            // Trajectories: the positions they command, sampled at the joint states' times.
            let trajectories: Vec<tracking::TrajectoryCommand<'_>> = trajectories_raw
                .iter()
                .map(|(lt, m)| {
                    let start = if m.header.stamp_nanos == 0 { t_map(*lt) } else { secs(m.header.stamp_nanos, origin) };
                    (start, m)
                })
                .collect();
            let sampled = (!trajectories.is_empty()).then(|| {
                let actual = |name: &str, t: f64| {
                    js.joints.iter().position(|j| j.name == name).map_or(f64::NAN, |j| data.positions[j].at(t))
                };
                let times = data.positions.iter().max_by_key(|s| s.len()).map(|s| s.t_secs.clone()).unwrap_or_default();
                tracking::sample_trajectories(&trajectories, &times, &actual)
            });
            let commands: Vec<(f64, &[f64])> = match &sampled {
                Some((_, rows)) => rows.iter().map(|(t, q)| (*t, q.as_slice())).collect(),
                None => commands_raw.iter().map(|(lt, m)| (t_map(*lt), m.data.as_slice())).collect(),
            };
            let end = fall.as_ref().map(|f| f.fall_time_secs);
            match tracking::compare(
                command_topic.as_deref().unwrap_or(""),
                &commands,
                sampled.as_ref().map(|(names, _)| names.as_slice()),
                js,
                &data,
                robot,
                options.command_kind,
                end,
                options.worst_joints,
            ) {
                Ok((t, pairs)) => {
                    data.commands = pairs;
                    Some(t)
                }
                Err(why) => {
                    notes.push(why);
                    None
                }
            }
        }
        _ => None,
    };
    let oscillations = tracking::oscillations(&data.positions, fall.as_ref().map(|f| f.onset_secs));

    let first_changes = match &fall {
        Some(f) => window_changes(&data, f.onset_secs, options.window_secs, robot),
        None => Vec::new(),
    };
    let timing = joint_states.as_ref().map(|js| timing(js, stamp_map, origin));
    let duration_secs = [&data.tilt, data.positions.first().unwrap_or(&Signal::default())]
        .iter()
        .filter_map(|s| s.t_secs.last().copied())
        .fold(0.0, f64::max);

    let mut analysis = Analysis {
        log: log.path().to_path_buf(),
        time_origin_nanos: origin,
        duration_secs,
        sources,
        fall,
        stability,
        first_changes,
        tracking,
        oscillations,
        timing,
        diagnosis: Vec::new(),
        notes,
        warnings,
        data,
    };
    if let (Some(f), Some(src)) = (analysis.fall.as_mut(), fall_source) {
        f.source = src;
    }
    analysis.diagnosis = diagnose(&analysis, robot);
    Ok(analysis)
}

fn none_if_empty(v: &[String]) -> String {
    if v.is_empty() { "none".into() } else { v.join(", ") }
}

/// `stamp ≈ a + b · log_time` (ns) over the JointState messages, by least squares; `None` when
/// the stamps are the log times (b = 1, a = 0 within a microsecond) or cannot be read.
fn stamp_fit(log: &Log, topic: &str) -> Option<(f64, f64)> {
    let (msgs, _) = log.read_typed::<JointState>(topic).ok()?;
    let pairs: Vec<(f64, f64)> = msgs
        .iter()
        .filter(|(_, m)| m.header.stamp_nanos != 0)
        .map(|(lt, m)| (*lt as f64, m.header.stamp_nanos as f64))
        .collect();
    if pairs.len() < 10 {
        return None;
    }
    if pairs.iter().all(|(l, s)| (l - s).abs() < 1e3) {
        return None;
    }
    // Centre for conditioning.
    let n = pairs.len() as f64;
    let (ml, ms) = (pairs.iter().map(|p| p.0).sum::<f64>() / n, pairs.iter().map(|p| p.1).sum::<f64>() / n);
    let (mut sll, mut sls) = (0.0, 0.0);
    for (l, s) in &pairs {
        sll += (l - ml) * (l - ml);
        sls += (l - ml) * (s - ms);
    }
    if sll <= 0.0 {
        return None;
    }
    let b = sls / sll;
    Some((ms - b * ml, b))
}

fn timing(js: &twin_core::log::JointStateSeries, stamp_map: Option<(f64, f64)>, origin: i64) -> Timing {
    // The joint with the most samples stands for the topic.
    let longest = js.joints.iter().max_by_key(|j| j.len());
    let (mut median_dt, mut gap, mut gap_end) = (f64::NAN, 0.0, 0.0);
    if let Some(j) = longest {
        let t: Vec<f64> = j.time_nanos.iter().map(|&n| secs(n, origin)).collect();
        let s = Signal { name: String::new(), t_secs: t.clone(), v: vec![0.0; t.len()] };
        median_dt = s.median_dt();
        for w in t.windows(2) {
            if w[1] - w[0] > gap {
                gap = w[1] - w[0];
                gap_end = w[1];
            }
        }
    }
    Timing {
        joint_state_messages: js.report.messages,
        median_interval_secs: median_dt,
        largest_gap_secs: gap,
        largest_gap_end_secs: gap_end,
        real_time_factor: stamp_map.map(|(_, b)| b),
    }
}

/// The first change of each signal in `[onset − window, onset + window/4]`, against its
/// baseline over the window's first half.
fn window_changes(data: &Data, onset: f64, window: f64, robot: Option<&Robot>) -> Vec<Change> {
    let (w0, base_end, w1) = (onset - window, onset - window / 2.0, onset + window / 4.0);
    let weight = robot.map(|r| r.model.total_mass_kg() * -r.model.gravity()[2]);
    let max_abs = |s: &Signal| s.v.iter().filter(|x| x.is_finite()).fold(0.0f64, |m, x| m.max(x.abs()));
    let mut candidates: Vec<(&Signal, f64)> = Vec::new();
    for s in &data.gyro {
        candidates.push((s, 0.1));
    }
    for s in &data.accel {
        candidates.push((s, 0.5));
    }
    for s in &data.contacts {
        candidates.push((s, weight.map_or(5.0, |w| 0.05 * w)));
    }
    for s in &data.positions {
        candidates.push((s, 0.02));
    }
    for s in &data.efforts {
        candidates.push((s, (0.05 * max_abs(s)).max(0.5)));
    }
    let mut out = Vec::new();
    for (s, floor) in candidates {
        let base = s.values(w0, base_end);
        if base.len() < 3 {
            continue;
        }
        let (mean, sd) = signal::mean_std(base);
        if !mean.is_finite() {
            continue;
        }
        let threshold = (5.0 * sd).max(floor);
        let (a, b) = (s.index_at(base_end), s.index_at(w1));
        // Two samples in a row beyond the threshold (a single spike is noise).
        let hit = (a..b.saturating_sub(1))
            .find(|&i| (s.v[i] - mean).abs() > threshold && (s.v[i + 1] - mean).abs() > threshold);
        if let Some(i) = hit {
            out.push(Change {
                signal: s.name.clone(),
                time_secs: s.t_secs[i],
                before_onset_secs: s.t_secs[i] - onset,
                baseline: mean,
                value: s.v[i],
                threshold,
            });
        }
    }
    out.sort_by(|a, b| a.time_secs.total_cmp(&b.time_secs).then(a.signal.cmp(&b.signal)));
    out
}

/// The findings in troubleshooting terms.
fn diagnose(a: &Analysis, robot: Option<&Robot>) -> Vec<Diagnosis> {
    let mut out = Vec::new();
    if let Some(f) = &a.fall {
        let dir = f.direction.as_str();
        let mut evidence = format!(
            "fell at {:.3} s ({}); onset at {:.3} s; lean {:.0} % forward, {:.0} % left in the heading frame",
            f.fall_time_secs,
            f.criterion,
            f.onset_secs,
            100.0 * f.lean_forward,
            100.0 * f.lean_left
        );
        let mut outside = false;
        if let Some(s) = &a.stability {
            if let Some(c) = &s.com_exit {
                outside = true;
                let _ = write!(
                    evidence,
                    "; CoM left the support polygon at {:.3} s, {:.3} m ahead / {:.3} m left of it",
                    c.time_secs, c.beyond_forward_m, c.beyond_left_m
                );
            }
            if let Some(c) = &s.cp_exit {
                outside = true;
                let _ = write!(
                    evidence,
                    "; capture point left it at {:.3} s, {:.3} m ahead / {:.3} m left",
                    c.time_secs, c.beyond_forward_m, c.beyond_left_m
                );
            }
        }
        let (cause, advice) = if a.stability.is_some() && !outside {
            (
                format!("falls {dir} with the CoM and capture point over the feet → joints too weak"),
                "the support held the CoM: the joints gave way (effort limits or gains too low; see the tracking)"
                    .to_string(),
            )
        } else {
            let what = match f.direction {
                fall::Direction::Forward => "CoM ahead of the feet",
                fall::Direction::Backward => "CoM behind the heels",
                fall::Direction::Left | fall::Direction::Right => "CoM outside the feet sideways",
            };
            (
                format!("falls {dir} → {what}"),
                "move the CoM back over the support (balance gains, ZMP/DCM feedback) or step sooner; check the \
                 push or command that started it"
                    .to_string(),
            )
        };
        out.push(Diagnosis { cause, evidence, advice });
    }
    if let Some(s) = &a.stability
        && let Some(slip) = &s.slip
    {
        let ratio = slip.tangential_over_normal.map_or_else(String::new, |r| {
            format!(", tangential/normal contact force {r:.2} (the friction it reached)")
        });
        out.push(Diagnosis {
            cause: "feet slip → friction".into(),
            evidence: format!(
                "{} slid at {:.3} m/s from {:.3} s while carrying {:.0} N{ratio}; largest slip speed {:.3} m/s",
                slip.foot, slip.speed_mps, slip.time_secs, slip.normal_force_n, slip.max_speed_mps
            ),
            advice: "raise the foot/floor friction (URDF <mu1>/<mu2>, MJCF friction) to the real contact's, or \
                     ask less tangential force (smaller steps, slower CoM)"
                .into(),
        });
    }
    for o in a.oscillations.iter().take(3) {
        out.push(Diagnosis {
            cause: "oscillation → gains".into(),
            evidence: format!(
                "{} oscillates at {:.1} Hz, amplitude {:.4} rad (from {:.3} to {:.3} s)",
                o.joint, o.frequency_hz, o.amplitude, o.from_secs, o.to_secs
            ),
            advice: "lower that joint's kp/kd (explicit PD on a light link goes unstable when kd·dt/I ≳ 2), add \
                     armature or joint damping, or use integrator=\"implicitfast\""
                .into(),
        });
    }
    if let Some(t) = &a.tracking {
        for j in t.joints.iter().filter(|j| j.saturated_fraction >= 0.01).take(3) {
            out.push(Diagnosis {
                cause: "command saturates → effort/range limit".into(),
                evidence: format!(
                    "{}: command beyond {} for {:.1} % of the time (peak command {:.3} {}, limit {})",
                    j.joint,
                    j.limit_source,
                    100.0 * j.saturated_fraction,
                    j.peak_command,
                    t.kind.unit(),
                    j.limit.map_or_else(|| "-".into(), |l| format!("{:.3} … {:.3}", l[0], l[1]))
                ),
                advice: "the controller asks more than the joint gives: lower its gains or the motion's speed, or \
                         check the effort limit in the URDF"
                    .into(),
            });
        }
        for j in t.joints.iter().filter(|j| j.lag_secs.is_some_and(|l| l >= 0.05)).take(2) {
            out.push(Diagnosis {
                cause: "actual lags the command → gains or delay".into(),
                evidence: format!(
                    "{} follows its command {:.3} s late (RMS error {:.4} {})",
                    j.joint,
                    j.lag_secs.unwrap_or(0.0),
                    j.rms_error,
                    t.kind.unit()
                ),
                advice: "stiffen the joint's servo or reduce the latency between command and actuator".into(),
            });
        }
    }
    if let Some(rtf) = a.timing.as_ref().and_then(|t| t.real_time_factor)
        && rtf < 0.9
    {
        let dt = robot.map_or_else(String::new, |r| format!(" (model timestep {} ms)", r.model.timestep_secs() * 1e3));
        out.push(Diagnosis {
            cause: "slow simulation → timestep".into(),
            evidence: format!("the stamps advanced {rtf:.3} s per second of log time: real-time factor {rtf:.3}{dt}"),
            advice: "raise the timestep (keep √(kp/I)·dt ≲ 0.3 and solref ≥ 2·dt), simplify collision geometry, or \
                     run the controller against --lockstep"
                .into(),
        });
    }
    if out.is_empty() {
        out.push(Diagnosis {
            cause: "no fall, slip, oscillation or saturation found".into(),
            evidence: format!("{:.3} s analysed", a.duration_secs),
            advice: "nothing to change from this log".into(),
        });
    }
    out
}

impl Analysis {
    /// The report as text.
    pub fn to_text(&self) -> String {
        let mut o = String::new();
        let _ = writeln!(o, "log: {}", self.log.display());
        let _ = writeln!(
            o,
            "times: s from the first sample (stamp {:.6} s); {:.3} s analysed",
            self.time_origin_nanos as f64 * 1e-9,
            self.duration_secs
        );
        for s in &self.sources {
            let _ = writeln!(o, "  read {s}");
        }
        let _ = writeln!(o, "\nfall:");
        match &self.fall {
            Some(f) => {
                let _ =
                    writeln!(o, "  fell at            {:.3} s ({}, from {})", f.fall_time_secs, f.criterion, f.source);
                let _ = writeln!(
                    o,
                    "  onset at           {:.3} s (tilt {:.3} rad, left its band {:.3} ± {:.3} rad at {:.3} s)",
                    f.onset_secs, f.tilt_at_onset_rad, f.baseline_tilt_rad, f.band_rad, f.band_exit_secs
                );
                let _ = writeln!(
                    o,
                    "  direction          {} (lean {:.2} forward, {:.2} left, heading {:.3} rad)",
                    f.direction.as_str(),
                    f.lean_forward,
                    f.lean_left,
                    f.heading_rad
                );
            }
            None => {
                let _ =
                    writeln!(o, "  none (max tilt {:.3} rad)", self.data.tilt.v.iter().copied().fold(0.0, f64::max));
            }
        }
        if let Some(s) = &self.stability {
            let _ = writeln!(o, "\nbalance (model {}):", s.model);
            if s.com_margin_min_m.is_finite() {
                let _ = writeln!(
                    o,
                    "  CoM margin in the support polygon: min {:.3} m, at onset {:.3} m; capture point: min {:.3} m, \
                     at onset {:.3} m",
                    s.com_margin_min_m, s.com_margin_at_onset_m, s.cp_margin_min_m, s.cp_margin_at_onset_m
                );
            } else {
                let _ = writeln!(o, "  no support polygon: no foot of the model was on the ground");
            }
            for (what, e) in [("CoM", &s.com_exit), ("capture point", &s.cp_exit)] {
                if let Some(e) = e {
                    let _ = writeln!(
                        o,
                        "  {what} left the support polygon at {:.3} s ({:.3} m ahead, {:.3} m left of it)",
                        e.time_secs, e.beyond_forward_m, e.beyond_left_m
                    );
                }
            }
            match &s.slip {
                Some(sl) => {
                    let _ = writeln!(
                        o,
                        "  slip: {} at {:.3} s, {:.3} m/s under {:.0} N (largest {:.3} m/s)",
                        sl.foot, sl.time_secs, sl.speed_mps, sl.normal_force_n, sl.max_speed_mps
                    );
                }
                None => {
                    let _ = writeln!(o, "  slip: none (largest loaded-foot speed {:.3} m/s)", s.max_foot_speed_mps);
                }
            }
        }
        if !self.first_changes.is_empty() {
            let _ = writeln!(o, "\nwhat changed first (window before the onset):");
            for c in self.first_changes.iter().take(12) {
                let _ = writeln!(
                    o,
                    "  {:>+8.3} s  {:<40} {:>10.4} → {:>10.4} (threshold {:.4})",
                    c.before_onset_secs, c.signal, c.baseline, c.value, c.threshold
                );
            }
        }
        if let Some(t) = &self.tracking {
            let _ = writeln!(
                o,
                "\ncommanded vs actual ({} on {}, {} joints, {}):",
                t.kind.as_str(),
                t.topic,
                t.joints.len(),
                t.kind_reason
            );
            let _ = writeln!(
                o,
                "  {:<28} {:>10} {:>10} {:>8} {:>9} {:>10}",
                "joint", "rms", "max", "lag_s", "saturated", "peak_cmd"
            );
            for j in t.joints.iter().take(t.worst) {
                let _ = writeln!(
                    o,
                    "  {:<28} {:>10.4} {:>10.4} {:>8} {:>8.1}% {:>10.3}",
                    j.joint,
                    j.rms_error,
                    j.max_error,
                    j.lag_secs.map_or_else(|| "-".into(), |l| format!("{l:.3}")),
                    100.0 * j.saturated_fraction,
                    j.peak_command
                );
            }
        }
        if !self.oscillations.is_empty() {
            let _ = writeln!(o, "\noscillating joints:");
            for osc in &self.oscillations {
                let _ =
                    writeln!(o, "  {:<28} {:.1} Hz, amplitude {:.4} rad", osc.joint, osc.frequency_hz, osc.amplitude);
            }
        }
        if let Some(t) = &self.timing {
            let _ = writeln!(
                o,
                "\ntiming: {} joint states, median interval {:.4} s, largest gap {:.4} s (ending {:.3} s), real-time \
                 factor {}",
                t.joint_state_messages,
                t.median_interval_secs,
                t.largest_gap_secs,
                t.largest_gap_end_secs,
                t.real_time_factor.map_or_else(|| "- (stamps are the log time)".into(), |r| format!("{r:.3}"))
            );
        }
        let _ = writeln!(o, "\ndiagnosis:");
        for d in &self.diagnosis {
            let _ = writeln!(o, "  {}\n    {}\n    → {}", d.cause, d.evidence, d.advice);
        }
        if !self.notes.is_empty() {
            let _ = writeln!(o, "\nnot analysed:");
            for n in &self.notes {
                let _ = writeln!(o, "  {n}");
            }
        }
        o
    }

    /// SVG plots: `window.svg` (tilt and height, IMU, contact forces, CoM and capture-point
    /// margins around the onset, or the whole log without a fall) and `tracking.svg` (the worst
    /// joints' command against actual). Returns (file name, SVG text).
    pub fn plots(&self) -> Vec<(String, String)> {
        use twin_core::plot::{COLORS, Plot, stack_svg};
        let (t0, t1) = match &self.fall {
            Some(f) => (f.onset_secs - 1.0, f.fall_time_secs + 0.25),
            None => (0.0, self.duration_secs),
        };
        let onset = self.fall.as_ref().map(|f| f.onset_secs);
        let mark = |p: &mut Plot| {
            if let Some(t) = onset {
                p.vline("onset", t, "#000000");
            }
            if let Some(f) = &self.fall {
                p.vline("fall", f.fall_time_secs, "#888888");
            }
        };
        let mut panels = Vec::new();
        if !self.data.tilt.is_empty() {
            let mut p = Plot::new("Base tilt and height", "time (s)", "rad / m");
            p.line("tilt (rad)", self.data.tilt.points(t0, t1), COLORS[0]);
            if !self.data.height.is_empty() {
                p.line("height (m)", self.data.height.points(t0, t1), COLORS[1]);
            }
            mark(&mut p);
            panels.push(p);
        }
        if !self.data.gyro.is_empty() {
            let mut p = Plot::new("IMU angular velocity", "time (s)", "rad/s");
            for (k, s) in self.data.gyro.iter().enumerate() {
                p.line(&s.name, s.points(t0, t1), COLORS[k % COLORS.len()]);
            }
            mark(&mut p);
            panels.push(p);
        }
        if !self.data.contacts.is_empty() {
            let mut p = Plot::new("Contact forces", "time (s)", "N");
            // The feet first (the busiest), at most six lines.
            let mut order: Vec<&Signal> = self.data.contacts.iter().collect();
            order.sort_by(|a, b| {
                let m = |s: &Signal| s.values(t0, t1).iter().copied().fold(0.0, f64::max);
                m(b).total_cmp(&m(a))
            });
            for (k, s) in order.iter().take(6).enumerate() {
                p.line(&s.name, s.points(t0, t1), COLORS[k % COLORS.len()]);
            }
            mark(&mut p);
            panels.push(p);
        }
        if !self.data.com_margin.is_empty() {
            let mut p = Plot::new("Margin inside the support polygon (negative: outside)", "time (s)", "m");
            p.line("CoM", self.data.com_margin.points(t0, t1), COLORS[0]);
            p.line("capture point", self.data.cp_margin.points(t0, t1), COLORS[1]);
            mark(&mut p);
            panels.push(p);
        }
        let mut out = Vec::new();
        if !panels.is_empty() {
            out.push(("window.svg".to_string(), stack_svg(&panels)));
        }
        if let Some(t) = &self.tracking {
            let mut panels = Vec::new();
            for j in t.joints.iter().take(t.worst) {
                if let Some((_, c, a)) = self.data.commands.iter().find(|(n, _, _)| *n == j.joint) {
                    let end = self.fall.as_ref().map_or(f64::INFINITY, |f| f.fall_time_secs + 0.25);
                    let mut p = Plot::new(
                        &format!("{}: {} commanded vs actual", j.joint, t.kind.as_str()),
                        "time (s)",
                        t.kind.unit(),
                    );
                    p.line("command", c.points(f64::NEG_INFINITY, end), COLORS[0]);
                    p.line("actual", a.points(f64::NEG_INFINITY, end), COLORS[1]);
                    mark(&mut p);
                    panels.push(p);
                }
            }
            if !panels.is_empty() {
                out.push(("tracking.svg".to_string(), stack_svg(&panels)));
            }
        }
        out
    }

    /// The report as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}
