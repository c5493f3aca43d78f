//! Recording a run: ROS 2 topics into an MCAP file and a rerun recording, all stamped in
//! simulation time (log time = publish time = header stamp).
//!
//! Topics (`<robot>` = [`Robot::name`]):
//! - `/joint_states` (`sensor_msgs/msg/JointState`): every hinge/slide joint, position and
//!   velocity as the controller observed them ([`StepView::observation`]: the engine's one
//!   sensor model, noise and latency included); effort = the actuator torque (force) on the
//!   joint, N·m (N); at [`RecordOptions::state_rate_hz`].
//! - each IMU on its topic (`sensor_msgs/msg/Imu`) at its update rate: orientation from the
//!   framequat sensor, angular velocity from the gyro, linear acceleration (specific force) from
//!   the accelerometer, all as the controller observed them (the IMU's noise and biases are
//!   the engine's, [`crate::engine::SensorModel`], seeded by the run); covariances = σ² of the
//!   configured white noise.
//! - `/odom` (`nav_msgs/msg/Odometry`, floating bases): pose of the base in `odom` (= the
//!   simulation's world frame); twist in the child (base) frame, as REP-105 defines it. Ground
//!   truth, like `/tf`: no sensor of the robot measures it.
//! - `/tf` (`tf2_msgs/msg/TFMessage`): `odom` → base and every body relative to its parent, at
//!   [`RecordOptions::tf_rate_hz`]; `/tf_static` once: IMU and ray-cast sensor frames that are
//!   not bodies.
//! - `/contacts/<body>` (`geometry_msgs/msg/WrenchStamped`): the net contact force and torque on
//!   each body that has touched something, in the body frame about its origin (zero while it
//!   touches nothing); from its first contact on, at the state rate.
//! - `/<robot>/joint_commands` (`std_msgs/msg/Float64MultiArray`): the command sent (actuator
//!   controls, or joint forces for models without actuators), at the state rate.
//! - each ray-cast sensor's topics ([`crate::sense::rig`]: depth image, camera info and points
//!   of a depth camera; a LiDAR's scan or points) at the sensor's rate, cast on other threads
//!   on its ticks only ([`crate::sense::Pipelined`]); rerun shows depth images and clouds at
//!   `world/sensors/<sensor>`.
//!
//! - the controller's own topics ([`crate::control::Controller::topics`]: a walking controller's
//!   footsteps and CoM/ZMP/DCM, the live bridge's `/clock` and received commands), from their
//!   first message on.
//!
//! The recorder turns `Data` into these typed messages ([`TypedMessage`]) once per step, for the
//! topics that are due, and hands them to its [`Sink`]s: the MCAP file ([`McapSink`]), the rerun
//! recording (`RerunSink`, with the `rerun` feature) and any given to [`Recording::with_sinks`]
//! (the live ROS 2 bridge). Each sink encodes what it takes its own way.
//!
//! The rerun recording shows, at [`RecordOptions::rerun_rate_hz`], the posed geometry (from
//! `/tf`) and scalars: `series/joints/<joint>`, `series/imu/<imu>/{gyro,accel}_{x,y,z}`,
//! `series/contacts/<body>/force_{x,y,z}`; the controller's points and pose arrays as points at
//! `diagnostics/<topic>`.

use super::Robot;
use crate::engine::StepView;
use crate::error::{Error, Result};
use crate::log::cdr::CdrWriter;
use crate::log::{
    Float64MultiArray, Header, Imu, JointState, LogWriter, Odometry, TfMessage, TransformStamped, WrenchStamped,
    WriteSummary, WriterOptions,
};
use crate::mj::{Data, ObjType};
use crate::topics::{Sink, TopicInfo, TopicKind, TopicRates, TopicTable, TypedMessage, body_frame};
use nalgebra::{Quaternion, Vector3};
use std::path::PathBuf;

/// What to record and how often.
#[derive(Debug, Clone, smart_default::SmartDefault)]
pub struct RecordOptions {
    /// MCAP file to write (default: none).
    pub mcap: Option<PathBuf>,
    /// rerun `.rrd` file to write (default: none; needs the `rerun` feature).
    pub rrd: Option<PathBuf>,
    /// rerun viewer to stream to, e.g. `rerun+http://127.0.0.1:9876/proxy` (default: none).
    pub connect: Option<String>,
    /// Rate of `/joint_states`, `/odom`, contacts and commands, Hz; every step when the
    /// timestep is longer than its period (default: 500).
    #[default(500.0)]
    pub state_rate_hz: f64,
    /// Rate of `/tf`, Hz (default: 100: enough for RViz, a fifth of the bytes of 500 Hz).
    #[default(100.0)]
    pub tf_rate_hz: f64,
    /// Rate of the rerun poses and scalars, Hz (default: 50).
    #[default(50.0)]
    pub rerun_rate_hz: f64,
    /// MCAP writer options (default: [`WriterOptions::default`]).
    pub writer: WriterOptions,
    /// Only these topics of the table in the MCAP file and on the live bridge, by exact name
    /// (`/contacts/*` stands for every contact topic); the rerun recording and the controller's
    /// own topics are not filtered (default: none given = all).
    pub topics: Option<Vec<String>>,
    /// Topic of the command the controller sent each step (default: none given =
    /// `/<robot>/joint_commands`; the live bridge moves it aside, as that name is its input).
    pub command_topic: Option<String>,
    /// Names of the topics the run's controller declares ([`crate::control::Controller::topics`]),
    /// which `topics` may name too (default: none).
    pub controller_topics: Vec<String>,
}

/// What was recorded.
#[derive(Debug, Clone, Default)]
pub struct RecordSummary {
    /// Messages per topic taken by the MCAP file or the live bridge, in the order the topics
    /// were added.
    pub topics: Vec<(String, u64)>,
    /// The MCAP file and what was written into it.
    pub mcap: Option<(PathBuf, WriteSummary)>,
    /// The `.rrd` file and its size, bytes.
    pub rrd: Option<(PathBuf, u64)>,
    /// What each ray-cast sensor that was read cost ([`SensorCost`]), in the robot's order.
    pub sensors: Vec<SensorCost>,
}

/// What a ray-cast sensor cost a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorCost {
    /// The sensor's name.
    pub name: String,
    /// Rays per reading (pixels of a camera, beams of a LiDAR).
    pub rays: usize,
    /// Its rate, Hz.
    pub rate_hz: f64,
    /// Readings taken.
    pub readings: u64,
    /// Mean wall time of a reading on its thread pool, seconds.
    pub secs_per_reading: f64,
}

impl SensorCost {
    /// The sensor's time per simulated second, seconds: above 1 it alone keeps a run from real
    /// time on the core that casts its rays.
    pub fn secs_per_sim_sec(&self) -> f64 {
        self.secs_per_reading * self.rate_hz
    }
}

impl RecordSummary {
    /// Messages written, all topics.
    pub fn messages(&self) -> u64 {
        self.topics.iter().map(|(_, n)| n).sum()
    }
}

/// Publication times on a fixed period, in integer nanoseconds of simulation time.
#[derive(Debug, Clone, Copy)]
struct Schedule {
    period_nanos: u64,
    next_nanos: u64,
    half_step_nanos: u64,
}

impl Schedule {
    fn new(rate_hz: f64, dt_nanos: u64) -> Schedule {
        let period = if rate_hz > 0.0 { (1e9 / rate_hz).round() as u64 } else { u64::MAX / 4 };
        Schedule { period_nanos: period.max(dt_nanos).max(1), next_nanos: 0, half_step_nanos: dt_nanos / 2 }
    }

    /// Whether a message is due at `t_nanos` (the step nearest each period boundary).
    fn due(&mut self, t_nanos: u64) -> bool {
        if t_nanos + self.half_step_nanos < self.next_nanos {
            return false;
        }
        while self.next_nanos <= t_nanos + self.half_step_nanos {
            self.next_nanos += self.period_nanos;
        }
        true
    }
}

/// The MCAP file as a [`Sink`]: one channel per topic it is offered, each message CDR-encoded.
pub struct McapSink {
    writer: Option<LogWriter>,
    path: PathBuf,
    /// Channel of each topic id.
    channels: crate::topics::ById<u16>,
    cdr: CdrWriter,
    summary: Option<WriteSummary>,
}

impl McapSink {
    /// Creates the file at `path` (see [`LogWriter::create`]).
    ///
    /// # Errors
    /// [`Error::File`] / [`Error::McapWrite`] when the file can't be created.
    pub fn create(path: &std::path::Path, options: &WriterOptions) -> Result<McapSink> {
        let writer = LogWriter::create(path, options)?;
        Ok(McapSink {
            writer: Some(writer),
            path: path.to_path_buf(),
            channels: Default::default(),
            cdr: CdrWriter::new(),
            summary: None,
        })
    }

    /// The file and what was written into it, once finished.
    pub fn summary(&self) -> Option<(PathBuf, WriteSummary)> {
        self.summary.clone().map(|s| (self.path.clone(), s))
    }

    fn closed(&self) -> Error {
        Error::Options(format!("{}: the MCAP file is closed already (twin bug)", self.path.display()))
    }
}

impl Sink for McapSink {
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool> {
        let Some(writer) = self.writer.as_mut() else { return Err(self.closed()) };
        let channel = writer.add_topic_of_type(&topic.name, topic.type_name)?;
        self.channels.set(id, channel);
        Ok(true)
    }

    fn write(&mut self, id: usize, _topic: &TopicInfo, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        let (Some(writer), Some(&channel)) = (self.writer.as_mut(), self.channels.get(id)) else {
            return Ok(());
        };
        Ok(writer.write_encoded(channel, log_time_nanos, message.to_cdr(&mut self.cdr))?)
    }

    fn finish(&mut self) -> Result<()> {
        if let Some(writer) = self.writer.take() {
            self.summary = Some(writer.finish()?);
        }
        Ok(())
    }
}

/// The rerun recording (a `.rrd` file and/or a viewer) as a [`Sink`]: it takes `/joint_states`,
/// the IMUs, `/tf` (the posed bodies), the contacts and the controller's points and pose
/// arrays, each at most at its own rate.
#[cfg(feature = "rerun")]
pub struct RerunSink {
    recorders: Vec<crate::viz::Recorder>,
    rate_hz: f64,
    dt_nanos: u64,
    /// Per topic id: its schedule at the rerun rate, when taken.
    schedules: Vec<Option<Schedule>>,
    /// Per topic id: its scalar series or entity prefix.
    names: Vec<String>,
    parents: Vec<usize>,
    xpos: Vec<[f64; 3]>,
    xquat: Vec<[f64; 4]>,
    points: Vec<[f64; 3]>,
    imu_names: Vec<String>,
}

#[cfg(feature = "rerun")]
impl RerunSink {
    /// A sink into `recorders` (see [`crate::viz::Recorder`]) for `robot`, at `rate_hz`.
    pub fn new(robot: &Robot, recorders: Vec<crate::viz::Recorder>, rate_hz: f64) -> RerunSink {
        let model = &robot.model;
        let nbody = model.nbody();
        RerunSink {
            recorders,
            rate_hz,
            dt_nanos: ((model.timestep_secs() * 1e9).round() as u64).max(1),
            schedules: Vec::new(),
            names: Vec::new(),
            parents: (0..nbody).map(|b| model.body_parentid()[b] as usize).collect(),
            xpos: vec![[0.0; 3]; nbody],
            xquat: vec![[1.0, 0.0, 0.0, 0.0]; nbody],
            points: Vec::new(),
            imu_names: robot.imus.iter().map(|i| i.meta.name.clone()).collect(),
        }
    }

    /// The `.rrd` files written, with their sizes, once finished.
    fn files(&self) -> Vec<PathBuf> {
        self.recorders.iter().filter_map(|r| r.path().map(std::path::Path::to_path_buf)).collect()
    }
}

#[cfg(feature = "rerun")]
use crate::log::RosMessage;

#[cfg(feature = "rerun")]
impl Sink for RerunSink {
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool> {
        let name = match topic.kind {
            TopicKind::JointStates => "joints".to_string(),
            TopicKind::Imu(k) => format!("imu/{}", self.imu_names.get(k).cloned().unwrap_or_default()),
            TopicKind::Tf => String::new(),
            TopicKind::Contacts(_) => format!("contacts/{}", topic.frame_id),
            TopicKind::Controller(_)
                if [
                    <crate::log::PointStamped as RosMessage>::TYPE_NAME,
                    <crate::log::PoseArray as RosMessage>::TYPE_NAME,
                ]
                .contains(&topic.type_name) =>
            {
                format!("diagnostics{}", topic.name)
            }
            _ => return Ok(false),
        };
        if self.schedules.len() <= id {
            self.schedules.resize(id + 1, None);
            self.names.resize(id + 1, String::new());
        }
        self.schedules[id] = Some(Schedule::new(self.rate_hz, self.dt_nanos));
        self.names[id] = name;
        Ok(true)
    }

    fn write(&mut self, id: usize, _topic: &TopicInfo, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        let Some(Some(schedule)) = self.schedules.get_mut(id) else { return Ok(()) };
        if !schedule.due(log_time_nanos) {
            return Ok(());
        }
        let t_secs = log_time_nanos as f64 * 1e-9;
        let name = &self.names[id];
        if let TypedMessage::Tf(tf) = message {
            // Transform k is body k + 1 relative to its parent (see `Recording`): compose down the tree.
            if tf.transforms.len() + 1 != self.parents.len() {
                return Ok(());
            }
            for (k, t) in tf.transforms.iter().enumerate() {
                let b = k + 1;
                let q = [t.rotation_xyzw[3], t.rotation_xyzw[0], t.rotation_xyzw[1], t.rotation_xyzw[2]];
                let p = self.parents[b];
                let (pp, pq) = (self.xpos[p], self.xquat[p]);
                let r = quat_rotate(pq, t.translation);
                self.xpos[b] = [pp[0] + r[0], pp[1] + r[1], pp[2] + r[2]];
                self.xquat[b] = wxyz(quat(pq) * quat(q));
            }
        }
        self.points.clear();
        match message {
            TypedMessage::Point(m) => self.points.push(m.point),
            TypedMessage::Poses(m) => self.points.extend(m.poses.iter().map(|p| p.position)),
            _ => {}
        }
        for rec in &self.recorders {
            rec.set_time_secs(t_secs);
            match message {
                TypedMessage::Tf(_) => rec.log_world_poses(t_secs, &self.xpos, &self.xquat)?,
                TypedMessage::JointState(js) => {
                    for (joint, q) in js.name.iter().zip(&js.position) {
                        rec.scalar(&format!("{name}/{joint}"), *q)?;
                    }
                }
                TypedMessage::Imu(imu) => {
                    let v = imu.angular_velocity.iter().chain(&imu.linear_acceleration);
                    for (axis, x) in ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"].iter().zip(v) {
                        rec.scalar(&format!("{name}/{axis}"), *x)?;
                    }
                }
                TypedMessage::Wrench(w) => {
                    for (axis, f) in ["force_x", "force_y", "force_z"].iter().zip(&w.force) {
                        rec.scalar(&format!("{name}/{axis}"), *f)?;
                    }
                }
                TypedMessage::Point(_) | TypedMessage::Poses(_) => rec.points(name, &self.points)?,
                _ => {}
            }
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<()> {
        for rec in std::mem::take(&mut self.recorders) {
            rec.finish()?;
        }
        Ok(())
    }
}

/// A sink of a recording, kept by kind for its summary.
enum SinkSlot {
    // Both boxed: either is the one large variant, depending on the rerun feature.
    Mcap(Box<McapSink>),
    #[cfg(feature = "rerun")]
    Rerun(Box<RerunSink>, Vec<PathBuf>),
    Other(Box<dyn Sink>),
}

impl SinkSlot {
    fn sink(&mut self) -> &mut dyn Sink {
        match self {
            SinkSlot::Mcap(s) => s.as_mut(),
            #[cfg(feature = "rerun")]
            SinkSlot::Rerun(s, _) => s.as_mut(),
            SinkSlot::Other(s) => s.as_mut(),
        }
    }

    /// ROS outputs (the file, the bridge) follow `--topics` and are counted; rerun is neither.
    fn is_ros(&self) -> bool {
        match self {
            #[cfg(feature = "rerun")]
            SinkSlot::Rerun(..) => false,
            _ => true,
        }
    }
}

/// The sinks and which topic goes to which.
struct Outputs {
    sinks: Vec<SinkSlot>,
    /// The table's topics, then the controller's.
    topics: Vec<TopicInfo>,
    /// Per topic id: the sinks that took it (`None`: not offered yet).
    routes: Vec<Option<Vec<usize>>>,
    /// Per topic id: its entry in `counts`, when a ROS sink took it.
    count_of: Vec<Option<usize>>,
    counts: Vec<(String, u64)>,
    /// `None`: all topics; else the topics asked for.
    wanted: Option<Vec<String>>,
}

impl Outputs {
    fn wants(&self, topic: &str) -> bool {
        self.wanted
            .as_ref()
            .is_none_or(|w| w.iter().any(|t| t == topic || (t == "/contacts/*" && topic.starts_with("/contacts/"))))
    }

    /// Offers topic `id` to every sink (ROS sinks only when `--topics` wants it).
    fn offer(&mut self, id: usize) -> Result<()> {
        let topic = &self.topics[id];
        let wanted = matches!(topic.kind, TopicKind::Controller(_)) || self.wants(&topic.name);
        let mut route = Vec::new();
        let mut counted = false;
        for (k, slot) in self.sinks.iter_mut().enumerate() {
            if slot.is_ros() && !wanted {
                continue;
            }
            if slot.sink().add_topic(id, topic)? {
                route.push(k);
                counted |= slot.is_ros();
            }
        }
        if counted {
            self.counts.push((topic.name.clone(), 0));
            self.count_of[id] = Some(self.counts.len() - 1);
        }
        self.routes[id] = Some(route);
        Ok(())
    }

    /// Whether some sink takes topic `id`.
    fn takes(&self, id: usize) -> bool {
        self.routes[id].as_ref().is_some_and(|r| !r.is_empty())
    }

    fn write(&mut self, id: usize, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        let Some(route) = &self.routes[id] else { return Ok(()) };
        for &k in route {
            self.sinks[k].sink().write(id, &self.topics[id], log_time_nanos, message)?;
        }
        if let Some(c) = self.count_of[id] {
            self.counts[c].1 += 1;
        }
        Ok(())
    }

    /// A message on the controller's topic `k` (offered with its first message).
    fn controller_message(&mut self, ntable: usize, k: usize, log_time_nanos: u64, m: &TypedMessage<'_>) -> Result<()> {
        let id = ntable + k;
        if id >= self.topics.len() {
            return Err(Error::Options(format!(
                "the controller emitted a message on its topic #{k}, but declares only {} topics (Controller::topics)",
                self.topics.len() - ntable
            )));
        }
        if self.routes[id].is_none() {
            self.offer(id)?;
        }
        self.write(id, log_time_nanos, m)
    }
}

/// One `/tf` entry: `parent_from_child` of a body.
struct TfLink {
    parent: Option<usize>,
    child: usize,
}

/// Records a run: an [`crate::engine::Observer`] that turns each step into the due messages of
/// the robot's topic table and the controller's topics, and hands them to its sinks. Create it
/// before the run, let the engine call it, then [`Recording::finish`].
pub struct Recording {
    out: Outputs,
    /// Number of the table's topics (the controller's follow).
    ntable: usize,
    controller_topics_known: bool,
    imus: Vec<crate::robot::Imu>,
    base: Option<(usize, usize)>,
    /// (qpos address, dof) of each `/joint_states` joint.
    joints: Vec<(usize, usize)>,
    tf_links: Vec<TfLink>,
    state: Schedule,
    tf_schedule: Schedule,
    imu_schedules: Vec<Schedule>,
    /// Topic ids: `/joint_states`, `/odom`, `/tf`, the command, each IMU's, each body's contacts.
    joint_states_id: Option<usize>,
    odom_id: Option<usize>,
    tf_id: Option<usize>,
    commands_id: Option<usize>,
    imu_ids: Vec<Option<usize>>,
    contact_ids: Vec<Option<usize>>,
    /// The messages, reused from step to step (nothing is allocated per step).
    joint_state: JointState,
    odometry: Odometry,
    imu_messages: Vec<Imu>,
    tf: TfMessage,
    wrenches: Vec<WrenchStamped>,
    command: Float64MultiArray,
    /// Net contact wrench per body this tick: force then torque, world frame, about the body
    /// origin.
    wrench: Vec<[f64; 6]>,
    touching: Vec<bool>,
    /// Ray-cast sensors (depth cameras, LiDARs), read on their own ticks only.
    sense: Vec<SenseOut>,
}

/// A ray-cast sensor being recorded.
struct SenseOut {
    sensor: crate::sense::RaySensor,
    pipe: crate::sense::Pipelined,
    schedule: Schedule,
    /// Topic id of each of `sensor.topics`.
    ids: Vec<Option<usize>>,
}

/// The error for rerun outputs in a build without the `rerun` feature.
pub fn rerun_unavailable() -> Error {
    Error::FeatureMissing { feature: "rerun", what: "a rerun recording (.rrd file or viewer)".into() }
}

impl Recording {
    /// Opens the outputs `options` names for `robot`.
    ///
    /// # Errors
    /// [`Error::File`] / [`Error::McapWrite`] when the MCAP file can't be created;
    /// [`Error::Rerun`] when the `.rrd` can't be created, the viewer can't be reached, or the
    /// `rerun` feature is off.
    pub fn new(robot: &Robot, options: &RecordOptions) -> Result<Recording> {
        Self::with_sinks(robot, options, Vec::new())
    }

    /// As [`Recording::new`], and every topic also goes to each of `sinks` (e.g. the live ROS 2
    /// bridge, `twin_bridges::live::LiveSink`), which follow `--topics` like the MCAP file.
    ///
    /// # Errors
    /// As [`Recording::new`]; errors of the sinks' `add_topic`.
    pub fn with_sinks(robot: &Robot, options: &RecordOptions, sinks: Vec<Box<dyn Sink>>) -> Result<Recording> {
        let model = &robot.model;
        let dt_nanos = ((model.timestep_secs() * 1e9).round() as u64).max(1);
        // Topic names, types and QoS come from the robot's one topic table.
        let mut table = TopicTable::new(
            robot,
            &TopicRates { state_rate_hz: options.state_rate_hz, tf_rate_hz: options.tf_rate_hz },
        );
        if let Some(name) = &options.command_topic
            && let Some(t) = table.topics.iter_mut().find(|t| t.kind == TopicKind::Commands)
        {
            t.name.clone_from(name);
        }
        if let (Some(path), Some(wanted)) = (&options.mcap, &options.topics) {
            // A topic twin never publishes is a typo: refuse it before creating the file.
            let name_of = |kind: TopicKind| table.topics.iter().find(|t| t.kind == kind).map(|t| t.name.clone());
            let mut known: Vec<String> = vec!["/joint_states".into(), "/tf".into(), "/tf_static".into()];
            known.extend(robot.imus.iter().map(|i| i.topic().to_string()));
            known.extend(name_of(TopicKind::Odometry));
            known.extend(name_of(TopicKind::Commands));
            known.push("/contacts/*".into());
            known.extend(options.controller_topics.iter().cloned());
            known.extend(
                crate::sense::ray_sensors(robot).into_iter().flat_map(|s| s.topics.into_iter().map(|(n, _)| n)),
            );
            for t in wanted {
                if !known.contains(t) && !t.starts_with("/contacts/") {
                    return Err(Error::Log(twin_log::Error::LogTopic {
                        path: path.clone(),
                        topic: t.clone(),
                        message: format!(
                            "--topics: twin sim publishes no topic {}; its topics are {} (and /contacts/<body>)",
                            crate::fsio::excerpt(t, crate::fsio::EXCERPT_CHARS),
                            known.join(", ")
                        ),
                    }));
                }
            }
        }

        let mut slots = Vec::new();
        if let Some(path) = &options.mcap {
            slots.push(SinkSlot::Mcap(Box::new(McapSink::create(path, &options.writer)?)));
        }
        if options.rrd.is_some() || options.connect.is_some() {
            #[cfg(not(feature = "rerun"))]
            return Err(rerun_unavailable());
            #[cfg(feature = "rerun")]
            {
                let mut recorders = Vec::new();
                if let Some(path) = &options.rrd {
                    recorders.push(crate::viz::Recorder::to_file(model, "twin", path)?);
                }
                if let Some(url) = &options.connect {
                    recorders.push(crate::viz::Recorder::to_viewer(model, "twin", url)?);
                }
                let sink = RerunSink::new(robot, recorders, options.rerun_rate_hz);
                let files = sink.files();
                slots.push(SinkSlot::Rerun(Box::new(sink), files));
            }
        }
        slots.extend(sinks.into_iter().map(SinkSlot::Other));

        let ntopics = table.topics.len();
        let id_of = |kind: TopicKind| table.topics.iter().position(|t| t.kind == kind);
        let base = robot.base.map(|b| (b.body, b.dof));
        let body_frames: Vec<String> = (0..model.nbody()).map(|b| body_frame(robot, b)).collect();
        let root_frame = if base.is_some() { "odom" } else { "world" };
        let mut tf_links = Vec::new();
        let mut transforms = Vec::new();
        for b in 1..model.nbody() {
            let p = model.body_parentid()[b] as usize;
            tf_links.push(TfLink { parent: (p != 0).then_some(p), child: b });
            transforms.push(TransformStamped {
                header: Header {
                    stamp_nanos: 0,
                    frame_id: if p == 0 { root_frame.to_string() } else { body_frames[p].clone() },
                },
                child_frame_id: body_frames[b].clone(),
                translation: [0.0; 3],
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            });
        }
        let joints: Vec<usize> = robot.joints.iter().map(|j| j.id).collect();
        let imu_messages = robot
            .imus
            .iter()
            .map(|imu| {
                let (g2, a2) = (imu.meta.gyro_noise_std.powi(2), imu.meta.accel_noise_std.powi(2));
                Imu {
                    header: Header { stamp_nanos: 0, frame_id: imu.meta.frame_id.clone() },
                    angular_velocity_covariance: [g2, 0.0, 0.0, 0.0, g2, 0.0, 0.0, 0.0, g2],
                    linear_acceleration_covariance: [a2, 0.0, 0.0, 0.0, a2, 0.0, 0.0, 0.0, a2],
                    ..Imu::default()
                }
            })
            .collect();
        let mut rec = Recording {
            out: Outputs {
                sinks: slots,
                topics: table.topics.clone(),
                routes: vec![None; ntopics],
                count_of: vec![None; ntopics],
                counts: Vec::new(),
                wanted: options.topics.clone(),
            },
            ntable: ntopics,
            controller_topics_known: false,
            imus: robot.imus.clone(),
            base,
            joints: joints.iter().map(|&j| (model.jnt_qposadr()[j] as usize, model.jnt_dofadr()[j] as usize)).collect(),
            tf_links,
            state: Schedule::new(options.state_rate_hz, dt_nanos),
            tf_schedule: Schedule::new(options.tf_rate_hz, dt_nanos),
            imu_schedules: robot
                .imus
                .iter()
                .map(|imu| Schedule::new(imu.meta.update_rate_hz.unwrap_or(options.state_rate_hz), dt_nanos))
                .collect(),
            joint_states_id: id_of(TopicKind::JointStates),
            odom_id: id_of(TopicKind::Odometry),
            tf_id: id_of(TopicKind::Tf),
            commands_id: id_of(TopicKind::Commands),
            imu_ids: (0..robot.imus.len()).map(|k| id_of(TopicKind::Imu(k))).collect(),
            contact_ids: (0..model.nbody()).map(|b| id_of(TopicKind::Contacts(b))).collect(),
            joint_state: JointState {
                name: joints.iter().map(|&j| model.name(ObjType::Joint, j).to_string()).collect(),
                ..JointState::default()
            },
            odometry: Odometry {
                header: Header { stamp_nanos: 0, frame_id: "odom".into() },
                child_frame_id: base.map(|(b, _)| body_frames[b].clone()).unwrap_or_default(),
                ..Odometry::default()
            },
            imu_messages,
            tf: TfMessage { transforms },
            wrenches: body_frames
                .iter()
                .map(|f| WrenchStamped { header: Header { stamp_nanos: 0, frame_id: f.clone() }, ..Default::default() })
                .collect(),
            command: Float64MultiArray::default(),
            wrench: vec![[0.0; 6]; model.nbody()],
            touching: vec![false; model.nbody()],
            sense: Vec::new(),
        };

        // Every topic but the contacts (which appear with a body's first contact) now, in table
        // order; `/tf_static` is written once, here.
        for id in 0..ntopics {
            match rec.out.topics[id].kind {
                TopicKind::Contacts(_) => {}
                TopicKind::TfStatic => {
                    rec.out.offer(id)?;
                    if rec.out.takes(id) {
                        let statics = robot.imus.iter().filter(|i| !body_frames.contains(&i.meta.frame_id));
                        let mut tf_static = TfMessage {
                            transforms: statics
                                .map(|imu| TransformStamped {
                                    header: Header { stamp_nanos: 0, frame_id: body_frames[imu.body].clone() },
                                    child_frame_id: imu.meta.frame_id.clone(),
                                    translation: imu.body_from_imu.0,
                                    rotation_xyzw: xyzw(imu.body_from_imu.1),
                                })
                                .collect(),
                        };
                        // Ray-cast sensor frames (a camera's optical frame, a LiDAR's site).
                        for s in crate::sense::ray_sensors(robot) {
                            if let (false, Some((body, p, q))) =
                                (body_frames.contains(&s.frame_id), s.body_from_frame(model))
                            {
                                tf_static.transforms.push(TransformStamped {
                                    header: Header { stamp_nanos: 0, frame_id: body_frames[body].clone() },
                                    child_frame_id: s.frame_id,
                                    translation: p,
                                    rotation_xyzw: xyzw(q),
                                });
                            }
                        }
                        rec.out.write(id, 0, &TypedMessage::Tf(&tf_static))?;
                    }
                }
                _ => rec.out.offer(id)?,
            }
        }
        // Ray-cast sensors: only when something takes their readings.
        #[cfg(feature = "rerun")]
        let to_rerun = rec.out.sinks.iter().any(|s| matches!(s, SinkSlot::Rerun(..)));
        #[cfg(not(feature = "rerun"))]
        let to_rerun = false;
        for (k, sensor) in crate::sense::ray_sensors(robot).into_iter().enumerate() {
            let ids: Vec<Option<usize>> = sensor
                .topics
                .iter()
                .map(|(_, stream)| id_of(TopicKind::Sensor { sensor: k, stream: *stream }))
                .collect();
            if ids.iter().flatten().any(|&id| rec.out.takes(id)) || to_rerun {
                rec.sense.push(SenseOut {
                    pipe: crate::sense::Pipelined::new(sensor.build(robot)?, robot.model.clone())?,
                    schedule: Schedule::new(sensor.rate_hz, dt_nanos),
                    sensor,
                    ids,
                });
            }
        }
        Ok(rec)
    }

    /// Records the step `step`: the controller's messages, then every table topic that is due
    /// at the step's start time t (state, body poses, sensors, contacts and actuator forces of
    /// the same instant; see [`StepView`]).
    ///
    /// # Errors
    /// Errors of the sinks; a controller message on a topic it did not declare.
    pub fn record(&mut self, step: &StepView<'_>) -> Result<()> {
        let data = step.data;
        let t_nanos = (step.time_secs * 1e9).round().max(0.0) as u64;
        let stamp = t_nanos as i64;

        // The controller's own topics first: what it exchanged or planned for this instant.
        if !self.controller_topics_known {
            self.controller_topics_known = true;
            for (k, mut t) in step.controller.topics().into_iter().enumerate() {
                t.kind = TopicKind::Controller(k);
                self.out.topics.push(t);
                self.out.routes.push(None);
                self.out.count_of.push(None);
            }
        }
        if self.out.topics.len() > self.ntable {
            let mut failed = None;
            let (out, ntable) = (&mut self.out, self.ntable);
            step.controller.diagnostics(&mut |k, log_time_nanos, message| {
                if failed.is_none()
                    && let Err(e) = out.controller_message(ntable, k, log_time_nanos, &message)
                {
                    failed = Some(e);
                }
            });
            if let Some(e) = failed {
                return Err(e);
            }
        }

        let state_due = self.state.due(t_nanos);
        let tf_due = self.tf_schedule.due(t_nanos);
        if state_due {
            self.accumulate_contacts(data);
        }
        // /joint_states and the IMUs: what the controller observed; the rest is ground truth.
        let observed = &step.observation;
        let qvel = step.qvel;
        if state_due {
            if let Some(id) = self.joint_states_id.filter(|&id| self.out.takes(id)) {
                let (actuator, applied) = (data.qfrc_actuator(), data.qfrc_applied());
                let js = &mut self.joint_state;
                js.header.stamp_nanos = stamp;
                js.position.clear();
                js.position.extend(self.joints.iter().map(|&(adr, _)| observed.qpos[adr]));
                js.velocity.clear();
                js.velocity.extend(self.joints.iter().map(|&(_, dof)| observed.qvel[dof]));
                js.effort.clear();
                js.effort.extend(self.joints.iter().map(|&(_, dof)| actuator[dof] + applied[dof]));
                self.out.write(id, t_nanos, &TypedMessage::JointState(&self.joint_state))?;
            }

            if let (Some(id), Some((body, dof))) = (self.odom_id.filter(|&id| self.out.takes(id)), self.base) {
                let m = data.xmat()[body];
                let o = &mut self.odometry;
                o.header.stamp_nanos = stamp;
                o.position = data.xpos()[body];
                o.orientation_xyzw = xyzw(data.xquat()[body]);
                o.linear_velocity = rotate_t(&m, [qvel[dof], qvel[dof + 1], qvel[dof + 2]]);
                o.angular_velocity = [qvel[dof + 3], qvel[dof + 4], qvel[dof + 5]];
                self.out.write(id, t_nanos, &TypedMessage::Odometry(&self.odometry))?;
            }

            for b in 1..self.touching.len() {
                let Some(id) = self.contact_ids[b] else { continue };
                if self.touching[b] && self.out.routes[id].is_none() {
                    self.out.offer(id)?;
                }
                if !self.out.takes(id) {
                    continue;
                }
                let m = data.xmat()[b];
                let wr = self.wrench[b];
                let w = &mut self.wrenches[b];
                w.header.stamp_nanos = stamp;
                w.force = rotate_t(&m, [wr[0], wr[1], wr[2]]);
                w.torque = rotate_t(&m, [wr[3], wr[4], wr[5]]);
                self.out.write(id, t_nanos, &TypedMessage::Wrench(&self.wrenches[b]))?;
            }

            if let Some(id) = self.commands_id.filter(|&id| self.out.takes(id)) {
                self.command.data.clear();
                self.command.data.extend_from_slice(step.command);
                self.out.write(id, t_nanos, &TypedMessage::Float64MultiArray(&self.command))?;
            }
        }

        for (k, imu) in self.imus.iter().enumerate() {
            if !self.imu_schedules[k].due(t_nanos) {
                continue;
            }
            let Some(id) = self.imu_ids[k].filter(|&id| self.out.takes(id)) else { continue };
            let s = observed.sensordata;
            let msg = &mut self.imu_messages[k];
            for i in 0..3 {
                msg.angular_velocity[i] = s[imu.gyro_adr + i];
                msg.linear_acceleration[i] = s[imu.accel_adr + i];
            }
            let q = match imu.quat_adr {
                Some(a) => [s[a], s[a + 1], s[a + 2], s[a + 3]],
                None => wxyz(quat(data.xquat()[imu.body]) * quat(imu.body_from_imu.1)),
            };
            msg.header.stamp_nanos = stamp;
            msg.orientation_xyzw = xyzw(q);
            self.out.write(id, t_nanos, &TypedMessage::Imu(&self.imu_messages[k]))?;
        }

        if let (true, Some(id)) = (tf_due, self.tf_id.filter(|&id| self.out.takes(id))) {
            let (xpos, xquat) = (data.xpos(), data.xquat());
            for (l, t) in self.tf_links.iter().zip(&mut self.tf.transforms) {
                let (p, q) = match l.parent {
                    None => (xpos[l.child], xquat[l.child]),
                    Some(parent) => relative(xpos[parent], xquat[parent], xpos[l.child], xquat[l.child]),
                };
                t.header.stamp_nanos = stamp;
                t.translation = p;
                t.rotation_xyzw = xyzw(q);
            }
            self.out.write(id, t_nanos, &TypedMessage::Tf(&self.tf))?;
        }

        // Ray-cast sensors on their ticks, cast on other threads: the reading of the previous
        // tick comes back now (stamped with its own time), the last one in `finish`.
        for s in &mut self.sense {
            if !s.schedule.due(t_nanos) {
                continue;
            }
            if let Some(reading) = s.pipe.submit(data, t_nanos)? {
                write_reading(&mut self.out, s, &reading)?;
            }
        }
        Ok(())
    }

    /// Sums each active contact's wrench onto the two bodies (world frame, about the body
    /// origin); the world body is left out.
    fn accumulate_contacts(&mut self, data: &Data) {
        for (w, t) in self.wrench.iter_mut().zip(self.touching.iter_mut()) {
            *w = [0.0; 6];
            *t = false;
        }
        let model = data.model();
        let xpos = data.xpos();
        for i in 0..data.ncon() {
            let Some(c) = data.contact_wrench_world(i) else { continue };
            for (k, sign) in [(0usize, -1.0), (1, 1.0)] {
                let g = c.geoms[k];
                if g < 0 {
                    continue;
                }
                let body = model.geom_bodyid()[g as usize] as usize;
                if body == 0 {
                    continue;
                }
                let f = c.force_n.map(|x| sign * x);
                let r = [c.position[0] - xpos[body][0], c.position[1] - xpos[body][1], c.position[2] - xpos[body][2]];
                let rxf = Vector3::from(r).cross(&Vector3::from(f));
                let w = &mut self.wrench[body];
                for i in 0..3 {
                    w[i] += f[i];
                    w[3 + i] += rxf[i] + sign * c.torque_nm[i];
                }
                self.touching[body] = true;
            }
        }
    }

    /// Closes the outputs.
    ///
    /// # Errors
    /// Errors of the sinks (write errors of the MCAP or rerun outputs).
    pub fn finish(mut self) -> Result<RecordSummary> {
        for s in &mut self.sense {
            if let Some(reading) = s.pipe.finish()? {
                write_reading(&mut self.out, s, &reading)?;
            }
        }
        let sensors = self
            .sense
            .iter()
            .map(|s| {
                let (readings, secs) = s.pipe.cost();
                SensorCost {
                    name: s.sensor.name.clone(),
                    rays: s.sensor.rays(),
                    rate_hz: s.sensor.rate_hz,
                    readings,
                    secs_per_reading: if readings > 0 { secs / readings as f64 } else { 0.0 },
                }
            })
            .collect();
        let mut summary = RecordSummary { topics: self.out.counts, sensors, ..RecordSummary::default() };
        for mut slot in self.out.sinks {
            slot.sink().finish()?;
            match slot {
                SinkSlot::Mcap(s) => summary.mcap = s.summary(),
                #[cfg(feature = "rerun")]
                SinkSlot::Rerun(_, files) => {
                    if let Some(path) = files.into_iter().next() {
                        let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
                        summary.rrd = Some((path, bytes));
                    }
                }
                SinkSlot::Other(_) => {}
            }
        }
        Ok(summary)
    }
}

/// A recording is the engine's recorder: it records each step's instant t (see
/// [`crate::engine::StepView`]).
impl crate::engine::Observer for Recording {
    fn observe(&mut self, step: &StepView<'_>) -> Result<crate::engine::Flow> {
        self.record(step)?;
        Ok(crate::engine::Flow::Continue)
    }
}

/// Writes one reading of a ray-cast sensor to the sinks that take its topics and to rerun
/// (depth image, pinhole and world points), stamped with the reading's own time.
fn write_reading(out: &mut Outputs, s: &SenseOut, reading: &crate::sense::Reading) -> Result<()> {
    let stamp = reading.stamp_nanos();
    if s.ids.iter().flatten().any(|&id| out.takes(id)) {
        for (id, message) in s.ids.iter().zip(s.sensor.messages(reading)) {
            if let Some(id) = id.filter(|&id| out.takes(id)) {
                out.write(id, stamp, &TypedMessage::Sensor(&message))?;
            }
        }
    }
    #[cfg(feature = "rerun")]
    for slot in &out.sinks {
        let SinkSlot::Rerun(sink, _) = slot else { continue };
        for rec in &sink.recorders {
            rec.set_time_secs(stamp as f64 * 1e-9);
            match reading {
                crate::sense::Reading::Depth(f) => rec.depth_frame(&s.sensor.name, f)?,
                crate::sense::Reading::Colour(f) => rec.colour_frame(&s.sensor.name, f)?,
                crate::sense::Reading::Lidar(l) => {
                    let pts: Vec<_> =
                        l.points_sensor().into_iter().flatten().map(|p| l.world_from_sensor * p).collect();
                    rec.sensor_points(&s.sensor.name, &pts)?;
                }
            }
        }
    }
    Ok(())
}

/// Quaternion w x y z → x y z w (ROS order).
fn xyzw(q: [f64; 4]) -> [f64; 4] {
    [q[1], q[2], q[3], q[0]]
}

/// `Rᵀ v` for a row-major rotation matrix `R` (world from body): world → body.
fn rotate_t(m: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
    [
        m[0] * v[0] + m[3] * v[1] + m[6] * v[2],
        m[1] * v[0] + m[4] * v[1] + m[7] * v[2],
        m[2] * v[0] + m[5] * v[1] + m[8] * v[2],
    ]
}

/// MuJoCo's `w x y z` array as a nalgebra quaternion.
fn quat(q: [f64; 4]) -> Quaternion<f64> {
    Quaternion::new(q[0], q[1], q[2], q[3])
}

/// A nalgebra quaternion as MuJoCo's `w x y z` array.
fn wxyz(q: Quaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Rotates `v` by the unit quaternion `q` (w x y z): `q ⊗ (0, v) ⊗ q*`.
fn quat_rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let q = quat(q);
    (q * Quaternion::from_imag(Vector3::from(v)) * q.conjugate()).imag().into()
}

/// `parent_from_child` from two world poses: translation in the parent frame and rotation.
fn relative(p_pos: [f64; 3], p_quat: [f64; 4], c_pos: [f64; 3], c_quat: [f64; 4]) -> ([f64; 3], [f64; 4]) {
    let inv = [p_quat[0], -p_quat[1], -p_quat[2], -p_quat[3]];
    let d = [c_pos[0] - p_pos[0], c_pos[1] - p_pos[1], c_pos[2] - p_pos[2]];
    (quat_rotate(inv, d), wxyz(quat(inv) * quat(c_quat)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_hits_each_period_once() {
        // 200 Hz on a 2 ms step: 5 ms periods fall between steps; one message per period.
        let mut s = Schedule::new(200.0, 2_000_000);
        let n = (0..500u64).filter(|k| s.due(k * 2_000_000)).count();
        assert_eq!(n, 200);
        // A rate above 1/dt publishes every step.
        let mut s = Schedule::new(1000.0, 2_000_000);
        assert_eq!((0..500u64).filter(|k| s.due(k * 2_000_000)).count(), 500);
    }

    #[test]
    fn relative_pose_inverts_composition() {
        let p_quat = [0.9f64.cos(), 0.0, 0.0, 0.9f64.sin()];
        let (pp, cp) = ([1.0, 2.0, 3.0], [1.5, 2.0, 3.0]);
        let (t, q) = relative(pp, p_quat, cp, p_quat);
        // The child is 0.5 m along world x; in the parent (rotated 1.8 rad about z) frame:
        assert!((t[0] - 0.5 * 1.8f64.cos()).abs() < 1e-12 && (t[1] + 0.5 * 1.8f64.sin()).abs() < 1e-12);
        assert!((q[0] - 1.0).abs() < 1e-12);
    }
}
