//! Recording a run: ROS 2 topics into an MCAP file and a rerun recording, all stamped in
//! simulation time (log time = publish time = header stamp).
//!
//! Topics (`<robot>` = [`Robot::name`]):
//! - `/joint_states` (`sensor_msgs/msg/JointState`): every hinge/slide joint; effort = the
//!   actuator torque (force) on the joint, N·m (N); at [`RecordOptions::state_rate_hz`].
//! - each IMU on its topic (`sensor_msgs/msg/Imu`) at its update rate: orientation from the
//!   framequat sensor, angular velocity from the gyro, linear acceleration (specific force) from
//!   the accelerometer, plus the IMU's configured Gaussian noise (seeded), covariances = σ².
//! - `/odom` (`nav_msgs/msg/Odometry`, floating bases): pose of the base in `odom` (= the
//!   simulation's world frame); twist in the child (base) frame, as REP-105 defines it.
//! - `/tf` (`tf2_msgs/msg/TFMessage`): `odom` → base and every body relative to its parent, at
//!   [`RecordOptions::tf_rate_hz`]; `/tf_static` once: IMU and ray-cast sensor frames that are
//!   not bodies.
//! - `/contacts/<body>` (`geometry_msgs/msg/WrenchStamped`): the net contact force and torque on
//!   each body that has touched something, in the body frame about its origin (zero while it
//!   touches nothing); from its first contact on, at the state rate.
//! - `/<robot>/joint_commands` (`std_msgs/msg/Float64MultiArray`): the command sent (actuator
//!   controls, or joint forces for models without actuators), at the state rate.
//! - each ray-cast sensor's topics ([`crate::sense::rig`]: depth image, camera info and points
//!   of a depth camera; a LiDAR's scan or points) at the sensor's rate, cast only on its ticks.
//!
//! The rerun recording gets the posed geometry at [`RecordOptions::rerun_rate_hz`] and scalars:
//! `series/joints/<joint>`, `series/imu/<imu>/{gyro,accel}_{x,y,z}`,
//! `series/contacts/<body>/force_{x,y,z}`.

use super::Robot;
use crate::error::{Error, Result};
use crate::log::cdr::CdrWriter;
use crate::log::{
    CameraInfo, Float64MultiArray, Image, Imu, JointState, LaserScan, LogWriter, Odometry, PointCloud2, RosMessage,
    TfMessage, Topic, WrenchStamped, WriteSummary, WriterOptions,
};
use crate::mj::{Data, ObjType};
use crate::topics::{TopicInfo, TopicKind, TopicRates, TopicTable};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use std::path::PathBuf;

/// What to record and how often.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// MCAP file to write (default: none).
    pub mcap: Option<PathBuf>,
    /// rerun `.rrd` file to write (default: none; needs the `rerun` feature).
    pub rrd: Option<PathBuf>,
    /// rerun viewer to stream to, e.g. `rerun+http://127.0.0.1:9876/proxy` (default: none).
    pub connect: Option<String>,
    /// Rate of `/joint_states`, `/odom`, contacts and commands, Hz; every step when the
    /// timestep is longer than its period (default: 500).
    pub state_rate_hz: f64,
    /// Rate of `/tf`, Hz (default: 100: enough for RViz, a fifth of the bytes of 500 Hz).
    pub tf_rate_hz: f64,
    /// Rate of the rerun poses and scalars, Hz (default: 50).
    pub rerun_rate_hz: f64,
    /// Seed of the IMU noise (default: 0).
    pub seed: u64,
    /// MCAP writer options (default: [`WriterOptions::default`]).
    pub writer: WriterOptions,
    /// Only these MCAP topics, by exact name (`/contacts/*` stands for every contact topic)
    /// (default: none given = all).
    pub topics: Option<Vec<String>>,
    /// Topic of the command the controller sent each step (default: none given =
    /// `/<robot>/joint_commands`; the live bridge moves it aside, as that name is its input).
    pub command_topic: Option<String>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            mcap: None,
            rrd: None,
            connect: None,
            state_rate_hz: 500.0,
            tf_rate_hz: 100.0,
            rerun_rate_hz: 50.0,
            seed: 0,
            writer: WriterOptions::default(),
            topics: None,
            command_topic: None,
        }
    }
}

/// A second destination of the recorded topics besides the MCAP file (the live ROS 2 bridge):
/// it gets every message the file gets, encoded once, plus it hands back the messages it
/// exchanged itself (commands received, `/clock` sent) for the file to hold.
pub trait TopicSink {
    /// A topic of the robot's topic table appears (name, type, QoS); called before its first
    /// message.
    ///
    /// # Errors
    /// When the sink can't offer the topic.
    fn add_topic(&mut self, topic: &TopicInfo) -> Result<()>;
    /// One message: CDR bytes (encapsulation header included), stamped `log_time_nanos`
    /// (simulation time).
    ///
    /// # Errors
    /// When the sink fails (a slow reader is not an error: messages are dropped for it).
    fn write(&mut self, topic: &str, log_time_nanos: u64, cdr: &[u8]) -> Result<()>;
    /// Moves the messages the sink exchanged since the last call into `out`, to be recorded.
    fn take_exchanged(&mut self, out: &mut Vec<ExchangedMessage>);
}

/// A message a [`TopicSink`] exchanged on its own (see [`TopicSink::take_exchanged`]).
#[derive(Debug, Clone)]
pub struct ExchangedMessage {
    /// ROS topic.
    pub topic: String,
    /// `pkg/msg/Type` (one of the typed messages of [`crate::log`]).
    pub type_name: &'static str,
    /// Simulation time it belongs to, ns.
    pub log_time_nanos: u64,
    /// CDR bytes, encapsulation header included.
    pub cdr: Vec<u8>,
}

/// The state of one instant, handed to [`Recording::record`] together with a `Data` whose
/// derived quantities (body poses, sensors, contacts, actuator forces) belong to the same
/// instant.
#[derive(Debug, Clone, Copy)]
pub struct StepSample<'a> {
    /// Simulation time, seconds.
    pub time_secs: f64,
    /// Joint positions (len `nq`).
    pub qpos: &'a [f64],
    /// Joint velocities (len `nv`).
    pub qvel: &'a [f64],
    /// The command sent at this instant.
    pub command: &'a [f64],
}

/// What was recorded.
#[derive(Debug, Clone, Default)]
pub struct RecordSummary {
    /// Messages per topic, in the order the topics were added.
    pub topics: Vec<(String, u64)>,
    /// The MCAP file and what was written into it.
    pub mcap: Option<(PathBuf, WriteSummary)>,
    /// The `.rrd` file and its size, bytes.
    pub rrd: Option<(PathBuf, u64)>,
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

/// One `/tf` entry: `parent_from_child` of a body.
struct TfLink {
    parent: Option<usize>,
    child: usize,
    parent_frame: String,
    child_frame: String,
}

/// A recorded topic: its index in the counts, and its MCAP channel when there is a file.
struct Stream<T> {
    index: usize,
    mcap: Option<Topic<T>>,
}

impl<T> Clone for Stream<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Stream<T> {}

struct ImuStream {
    topic: Option<Stream<Imu>>,
    schedule: Schedule,
}

/// The topic side: the MCAP file and/or a live [`TopicSink`].
struct McapOut {
    writer: Option<LogWriter>,
    live: Option<Box<dyn TopicSink>>,
    /// Encoding buffer when a message goes to both the file and the sink.
    cdr: CdrWriter,
    /// `None`: all topics; else the topics asked for.
    wanted: Option<Vec<String>>,
    joint_states: Option<Stream<JointState>>,
    commands: Option<Stream<Float64MultiArray>>,
    odom: Option<Stream<Odometry>>,
    tf: Option<Stream<TfMessage>>,
    imus: Vec<ImuStream>,
    /// Per body: its `/contacts/<body>` topic once it has touched something.
    contacts: Vec<Option<Stream<WrenchStamped>>>,
    /// Messages per stream index.
    counts: Vec<(String, u64)>,
    /// The robot's topic table (names, types, QoS of what is added).
    table: TopicTable,
    /// Topics the sink exchanged: name, stream index, MCAP channel.
    exchanged_topics: Vec<(String, usize, Option<u16>)>,
    exchanged: Vec<ExchangedMessage>,
}

impl McapOut {
    /// Encodes one message once and hands it to the file and the sink.
    fn emit<T: RosMessage>(
        &mut self,
        s: Stream<T>,
        log_time_nanos: u64,
        encode: impl FnOnce(&mut CdrWriter),
    ) -> Result<()> {
        self.counts[s.index].1 += 1;
        match self.live.as_mut() {
            None => {
                if let (Some(w), Some(topic)) = (self.writer.as_mut(), s.mcap) {
                    w.write_with(topic, log_time_nanos, encode)?;
                }
            }
            Some(live) => {
                self.cdr.reset();
                encode(&mut self.cdr);
                if let (Some(w), Some(topic)) = (self.writer.as_mut(), s.mcap) {
                    w.write_encoded(topic.channel_id(), log_time_nanos, self.cdr.bytes())?;
                }
                live.write(&self.counts[s.index].0, log_time_nanos, self.cdr.bytes())?;
            }
        }
        Ok(())
    }

    /// Records what the sink exchanged on its own since the last call.
    fn record_exchanged(&mut self) -> Result<()> {
        let Some(live) = self.live.as_mut() else { return Ok(()) };
        live.take_exchanged(&mut self.exchanged);
        for m in std::mem::take(&mut self.exchanged) {
            let (index, channel) = match self.exchanged_topics.iter().find(|(t, _, _)| *t == m.topic) {
                Some(&(_, index, channel)) => (index, channel),
                None => {
                    let channel = match self.writer.as_mut() {
                        Some(w) => Some(w.add_topic_of_type(&m.topic, m.type_name)?),
                        None => None,
                    };
                    self.counts.push((m.topic.clone(), 0));
                    self.exchanged_topics.push((m.topic.clone(), self.counts.len() - 1, channel));
                    (self.counts.len() - 1, channel)
                }
            };
            self.counts[index].1 += 1;
            if let (Some(w), Some(channel)) = (self.writer.as_mut(), channel) {
                w.write_encoded(channel, m.log_time_nanos, &m.cdr)?;
            }
        }
        Ok(())
    }

    fn wants(&self, topic: &str) -> bool {
        self.wanted
            .as_ref()
            .is_none_or(|w| w.iter().any(|t| t == topic || (t == "/contacts/*" && topic.starts_with("/contacts/"))))
    }

    /// Adds `topic` if it is wanted.
    fn add_wanted<T: RosMessage>(&mut self, topic: &str) -> Result<Option<Stream<T>>> {
        if self.wants(topic) { self.add(topic).map(Some) } else { Ok(None) }
    }

    fn add<T: RosMessage>(&mut self, topic: &str) -> Result<Stream<T>> {
        let mcap = match self.writer.as_mut() {
            Some(w) => Some(w.add_topic::<T>(topic)?),
            None => None,
        };
        if let Some(live) = self.live.as_mut() {
            match self.table.find(topic) {
                Some(info) => live.add_topic(info)?,
                None => {
                    return Err(Error::Options(format!(
                        "{topic} is not in the robot's topic table (twin bug: recorded topics come from it)"
                    )));
                }
            }
        }
        self.counts.push((topic.to_string(), 0));
        Ok(Stream { index: self.counts.len() - 1, mcap })
    }
}

#[cfg(feature = "rerun")]
struct RerunOut {
    recorders: Vec<crate::viz::Recorder>,
    schedule: Schedule,
    joint_series: Vec<String>,
}

/// Records a run. Create it before the loop, call [`Recording::record`] once per step with the
/// state of that step, then [`Recording::finish`].
pub struct Recording {
    imus: Vec<crate::robot::Imu>,
    base: Option<(usize, usize)>,
    /// (qpos address, dof) of each `/joint_states` joint.
    joints: Vec<(usize, usize)>,
    joint_names: Vec<String>,
    body_frames: Vec<String>,
    tf_links: Vec<TfLink>,
    state: Schedule,
    tf_schedule: Schedule,
    rng: rand_chacha::ChaCha8Rng,
    mcap: Option<McapOut>,
    #[cfg(feature = "rerun")]
    rerun: Option<RerunOut>,
    /// Net contact wrench per body this tick: force then torque, world frame, about the body
    /// origin.
    wrench: Vec<[f64; 6]>,
    touching: Vec<bool>,
    /// IMU values this tick (for rerun): gyro and accel, with noise.
    imu_values: Vec<[f64; 6]>,
    /// Which IMU topics are due this tick.
    imu_due: Vec<bool>,
    /// `/contacts/<body>` topic of each body (from the topic table).
    contact_topics: Vec<String>,
    /// Ray-cast sensors (depth cameras, LiDARs), read on their own ticks only.
    sense: Vec<SenseOut>,
}

/// The MCAP stream of one topic of a ray-cast sensor.
#[derive(Clone, Copy)]
enum SenseStreamOut {
    Image(Stream<Image>),
    CameraInfo(Stream<CameraInfo>),
    Points(Stream<PointCloud2>),
    Scan(Stream<LaserScan>),
}

/// A ray-cast sensor being recorded.
struct SenseOut {
    sensor: crate::sense::RaySensor,
    pipe: crate::sense::Pipelined,
    schedule: Schedule,
    /// Per topic of `sensor.topics`: its stream when recorded.
    streams: Vec<Option<SenseStreamOut>>,
}

/// The error for rerun outputs in a build without the `rerun` feature.
pub fn rerun_unavailable() -> Error {
    Error::FeatureMissing { feature: "rerun", what: "a rerun recording (.rrd file or viewer)".into() }
}

fn frame_name(robot: &Robot, body: usize) -> String {
    match robot.model.name(ObjType::Body, body) {
        "" => format!("body_{body}"),
        n => n.to_string(),
    }
}

impl Recording {
    /// Opens the outputs `options` names for `robot`.
    ///
    /// # Errors
    /// [`Error::Io`] / [`Error::McapWrite`] when the MCAP file can't be created;
    /// [`Error::Rerun`] when the `.rrd` can't be created, the viewer can't be reached, or the
    /// `rerun` feature is off.
    pub fn new(robot: &Robot, options: &RecordOptions) -> Result<Recording> {
        Self::with_sink(robot, options, None)
    }

    /// As [`Recording::new`], and every topic also goes to `sink` (the live ROS 2 bridge), which
    /// gets the topics even when no MCAP file is asked for.
    ///
    /// # Errors
    /// As [`Recording::new`]; errors of the sink's `add_topic`.
    pub fn with_sink(robot: &Robot, options: &RecordOptions, sink: Option<Box<dyn TopicSink>>) -> Result<Recording> {
        let model = &robot.model;
        let dt_nanos = ((model.timestep_secs() * 1e9).round() as u64).max(1);
        let joints: Vec<usize> = robot.joints.iter().map(|j| j.id).collect();
        let joint_names: Vec<String> = joints.iter().map(|&j| model.name(ObjType::Joint, j).to_string()).collect();
        let base = robot.base.map(|b| (b.body, b.dof));
        let body_frames: Vec<String> = (0..model.nbody()).map(|b| frame_name(robot, b)).collect();
        let root_frame = if base.is_some() { "odom" } else { "world" };
        let tf_links = (1..model.nbody())
            .map(|b| {
                let p = model.body_parentid()[b] as usize;
                TfLink {
                    parent: (p != 0).then_some(p),
                    child: b,
                    parent_frame: if p == 0 { root_frame.to_string() } else { body_frames[p].clone() },
                    child_frame: body_frames[b].clone(),
                }
            })
            .collect();

        let mut rec = Recording {
            imus: robot.imus.clone(),
            base,
            joints: joints.iter().map(|&j| (model.jnt_qposadr()[j] as usize, model.jnt_dofadr()[j] as usize)).collect(),
            joint_names,
            body_frames,
            tf_links,
            state: Schedule::new(options.state_rate_hz, dt_nanos),
            tf_schedule: Schedule::new(options.tf_rate_hz, dt_nanos),
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(options.seed),
            mcap: None,
            #[cfg(feature = "rerun")]
            rerun: None,
            wrench: vec![[0.0; 6]; model.nbody()],
            touching: vec![false; model.nbody()],
            imu_values: vec![[0.0; 6]; robot.imus.len()],
            imu_due: Vec::new(),
            contact_topics: Vec::new(),
            sense: Vec::new(),
        };

        if let (Some(path), Some(wanted)) = (&options.mcap, &options.topics) {
            // A topic twin never publishes is a typo: refuse it before creating the file.
            let mut known: Vec<String> = vec!["/joint_states".into(), "/tf".into(), "/tf_static".into()];
            known.extend(robot.imus.iter().map(|i| i.topic().to_string()));
            if base.is_some() {
                known.push("/odom".into());
            }
            known.push(options.command_topic.clone().unwrap_or_else(|| format!("/{}/joint_commands", robot.name)));
            known.push("/contacts/*".into());
            known.extend(
                crate::sense::ray_sensors(robot).into_iter().flat_map(|s| s.topics.into_iter().map(|(n, _)| n)),
            );
            for t in wanted {
                if !known.contains(t) && !t.starts_with("/contacts/") {
                    return Err(Error::LogTopic {
                        path: path.clone(),
                        topic: t.clone(),
                        message: format!(
                            "--topics: twin sim publishes no topic {}; its topics are {} (and /contacts/<body>)",
                            crate::fsio::excerpt(t, crate::fsio::EXCERPT_CHARS),
                            known.join(", ")
                        ),
                    });
                }
            }
        }
        if options.mcap.is_some() || sink.is_some() {
            let writer = match &options.mcap {
                Some(path) => Some(LogWriter::create(path, &options.writer)?),
                None => None,
            };
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
            let mut out = McapOut {
                live: sink,
                cdr: CdrWriter::new(),
                exchanged_topics: Vec::new(),
                exchanged: Vec::new(),
                wanted: options.topics.clone(),
                joint_states: None,
                commands: None,
                odom: None,
                tf: None,
                imus: Vec::new(),
                contacts: vec![None; model.nbody()],
                counts: Vec::new(),
                writer,
                table,
            };
            let name = |kind| out.table.of_kind(kind).map(|t| t.name.clone());
            let (js, odom, tf, commands, tf_static) = (
                name(TopicKind::JointStates).unwrap_or_default(),
                name(TopicKind::Odometry),
                name(TopicKind::Tf).unwrap_or_default(),
                name(TopicKind::Commands).unwrap_or_default(),
                name(TopicKind::TfStatic),
            );
            rec.contact_topics = (0..model.nbody()).map(|b| name(TopicKind::Contacts(b)).unwrap_or_default()).collect();
            out.joint_states = out.add_wanted(&js)?;
            for imu in &robot.imus {
                let rate = imu.meta.update_rate_hz.unwrap_or(options.state_rate_hz);
                let topic = out.add_wanted(imu.topic())?;
                out.imus.push(ImuStream { topic, schedule: Schedule::new(rate, dt_nanos) });
            }
            if let Some(odom) = odom {
                out.odom = out.add_wanted(&odom)?;
            }
            out.tf = out.add_wanted(&tf)?;
            out.commands = out.add_wanted(&commands)?;
            // IMU frames that are no body: a static transform from their body.
            // IMU and ray-cast sensor frames that are no body: a static transform from their
            // body, `(parent, child, translation, rotation w x y z)`.
            let mut statics: Vec<(&str, String, [f64; 3], [f64; 4])> = robot
                .imus
                .iter()
                .filter(|i| !rec.body_frames.contains(&i.meta.frame_id))
                .map(|i| {
                    (rec.body_frames[i.body].as_str(), i.meta.frame_id.clone(), i.body_from_imu.0, i.body_from_imu.1)
                })
                .collect();
            for s in crate::sense::ray_sensors(robot) {
                if let (false, Some((body, p, q))) = (rec.body_frames.contains(&s.frame_id), s.body_from_frame(model)) {
                    statics.push((rec.body_frames[body].as_str(), s.frame_id, p, q));
                }
            }
            if let Some(tf_static) = tf_static.filter(|t| out.wants(t)) {
                let topic: Stream<TfMessage> = out.add(&tf_static)?;
                out.emit(topic, 0, |w| {
                    w.seq_len(statics.len());
                    for (parent, child, p, q) in &statics {
                        w.header(0, parent);
                        w.string(child);
                        w.f64_fixed(p);
                        w.f64_fixed(&xyzw(*q));
                    }
                })?;
            }
            rec.mcap = Some(out);
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
                rec.rerun = Some(RerunOut {
                    recorders,
                    schedule: Schedule::new(options.rerun_rate_hz, dt_nanos),
                    joint_series: rec.joint_names.iter().map(|n| format!("joints/{n}")).collect(),
                });
            }
        }
        // Ray-cast sensors: only when something takes their readings.
        for sensor in crate::sense::ray_sensors(robot) {
            let mut streams = Vec::new();
            if let Some(out) = rec.mcap.as_mut() {
                for (name, stream) in &sensor.topics {
                    use crate::sense::SensorStream as S;
                    streams.push(if !out.wants(name) {
                        None
                    } else {
                        Some(match stream {
                            S::DepthImage => SenseStreamOut::Image(out.add(name)?),
                            S::CameraInfo => SenseStreamOut::CameraInfo(out.add(name)?),
                            S::Points => SenseStreamOut::Points(out.add(name)?),
                            S::Scan => SenseStreamOut::Scan(out.add(name)?),
                        })
                    });
                }
            }
            #[cfg(feature = "rerun")]
            let to_rerun = rec.rerun.is_some();
            #[cfg(not(feature = "rerun"))]
            let to_rerun = false;
            if streams.iter().any(Option::is_some) || to_rerun {
                rec.sense.push(SenseOut {
                    pipe: crate::sense::Pipelined::new(sensor.build(robot)?, robot.model.clone())?,
                    schedule: Schedule::new(sensor.rate_hz, dt_nanos),
                    sensor,
                    streams,
                });
            }
        }
        Ok(rec)
    }

    /// Records the instant `sample` (see [`StepSample`]): writes every stream that is due.
    ///
    /// # Errors
    /// Write errors of the MCAP or rerun outputs.
    pub fn record(&mut self, sample: &StepSample<'_>, data: &Data) -> Result<()> {
        let t_nanos = (sample.time_secs * 1e9).round().max(0.0) as u64;
        let stamp = t_nanos as i64;
        let state_due = self.state.due(t_nanos);
        let tf_due = self.tf_schedule.due(t_nanos);
        #[cfg(feature = "rerun")]
        let rerun_due = self.rerun.as_mut().is_some_and(|r| r.schedule.due(t_nanos));
        #[cfg(not(feature = "rerun"))]
        let rerun_due = false;

        if state_due || rerun_due {
            self.accumulate_contacts(data);
        }
        // Reused buffer: nothing is allocated per step.
        let mut imu_due = std::mem::take(&mut self.imu_due);
        imu_due.clear();
        imu_due.resize(self.imus.len(), false);
        if let Some(out) = self.mcap.as_mut() {
            out.record_exchanged()?;
            for (k, s) in out.imus.iter_mut().enumerate() {
                imu_due[k] = s.schedule.due(t_nanos);
            }
        }
        for (k, imu) in self.imus.iter().enumerate() {
            if imu_due[k] || rerun_due {
                let s = data.sensordata();
                let mut v = [0.0; 6];
                for i in 0..3 {
                    v[i] = s[imu.gyro_adr + i] + imu.meta.gyro_noise_std * self.rng.sample::<f64, _>(StandardNormal);
                    v[3 + i] =
                        s[imu.accel_adr + i] + imu.meta.accel_noise_std * self.rng.sample::<f64, _>(StandardNormal);
                }
                self.imu_values[k] = v;
            }
        }

        if let Some(out) = self.mcap.as_mut() {
            if state_due {
                let (joints, names) = (&self.joints, &self.joint_names);
                let (qpos, qvel) = (sample.qpos, sample.qvel);
                let (actuator, applied) = (data.qfrc_actuator(), data.qfrc_applied());
                if let Some(topic) = out.joint_states {
                    out.emit(topic, t_nanos, |w| {
                        w.header(stamp, "");
                        w.seq_len(names.len());
                        for n in names {
                            w.string(n);
                        }
                        let n = joints.len();
                        w.f64_seq_iter(n, joints.iter().map(|&(adr, _)| qpos[adr]));
                        w.f64_seq_iter(n, joints.iter().map(|&(_, dof)| qvel[dof]));
                        w.f64_seq_iter(n, joints.iter().map(|&(_, dof)| actuator[dof] + applied[dof]));
                    })?;
                }

                if let (Some(topic), Some((body, dof))) = (out.odom, self.base) {
                    let child = &self.body_frames[body];
                    let m = data.xmat()[body];
                    let v_world = [qvel[dof], qvel[dof + 1], qvel[dof + 2]];
                    let linear_body = rotate_t(&m, v_world);
                    let angular_body = [qvel[dof + 3], qvel[dof + 4], qvel[dof + 5]];
                    let (p, q) = (data.xpos()[body], data.xquat()[body]);
                    out.emit(topic, t_nanos, |w| {
                        w.header(stamp, "odom");
                        w.string(child);
                        w.f64_fixed(&p);
                        w.f64_fixed(&xyzw(q));
                        w.f64_fixed(&[0.0; 36]);
                        w.f64_fixed(&linear_body);
                        w.f64_fixed(&angular_body);
                        w.f64_fixed(&[0.0; 36]);
                    })?;
                }

                for b in 1..self.touching.len() {
                    if self.touching[b] && out.contacts[b].is_none() && out.wants("/contacts/*") {
                        out.contacts[b] = Some(out.add(&self.contact_topics[b])?);
                    }
                    let Some(topic) = out.contacts[b] else { continue };
                    let m = data.xmat()[b];
                    let wr = self.wrench[b];
                    let force = rotate_t(&m, [wr[0], wr[1], wr[2]]);
                    let torque = rotate_t(&m, [wr[3], wr[4], wr[5]]);
                    let frame = &self.body_frames[b];
                    out.emit(topic, t_nanos, |w| {
                        w.header(stamp, frame);
                        w.f64_fixed(&force);
                        w.f64_fixed(&torque);
                    })?;
                }

                let command = sample.command;
                if let Some(topic) = out.commands {
                    out.emit(topic, t_nanos, |w| {
                        w.seq_len(0);
                        w.u32(0);
                        w.f64_seq(command);
                    })?;
                }
            }

            for (k, imu) in self.imus.iter().enumerate() {
                if !imu_due[k] {
                    continue;
                }
                let s = data.sensordata();
                let q = match imu.quat_adr {
                    Some(a) => [s[a], s[a + 1], s[a + 2], s[a + 3]],
                    None => quat_mul(data.xquat()[imu.body], imu.body_from_imu.1),
                };
                let v = self.imu_values[k];
                let (g2, a2) = (imu.meta.gyro_noise_std.powi(2), imu.meta.accel_noise_std.powi(2));
                let Some(topic) = out.imus[k].topic else { continue };
                out.emit(topic, t_nanos, |w| {
                    w.header(stamp, &imu.meta.frame_id);
                    w.f64_fixed(&xyzw(q));
                    w.f64_fixed(&[0.0; 9]);
                    w.f64_fixed(&v[..3]);
                    w.f64_fixed(&[g2, 0.0, 0.0, 0.0, g2, 0.0, 0.0, 0.0, g2]);
                    w.f64_fixed(&v[3..]);
                    w.f64_fixed(&[a2, 0.0, 0.0, 0.0, a2, 0.0, 0.0, 0.0, a2]);
                })?;
            }

            if let (true, Some(tf)) = (tf_due, out.tf) {
                let (xpos, xquat) = (data.xpos(), data.xquat());
                let links = &self.tf_links;
                out.emit(tf, t_nanos, |w| {
                    w.seq_len(links.len());
                    for l in links {
                        let (p, q) = match l.parent {
                            None => (xpos[l.child], xquat[l.child]),
                            Some(parent) => relative(xpos[parent], xquat[parent], xpos[l.child], xquat[l.child]),
                        };
                        w.header(stamp, &l.parent_frame);
                        w.string(&l.child_frame);
                        w.f64_fixed(&p);
                        w.f64_fixed(&xyzw(q));
                    }
                })?;
            }
        }

        self.imu_due = imu_due;

        // Ray-cast sensors on their ticks, cast on other threads: the reading of the previous
        // tick comes back now (stamped with its own time), the last one in `finish`.
        for s in &mut self.sense {
            if !s.schedule.due(t_nanos) {
                continue;
            }
            if let Some(reading) = s.pipe.submit(data, t_nanos)? {
                #[cfg(feature = "rerun")]
                write_reading(&mut self.mcap, self.rerun.as_ref(), s, &reading)?;
                #[cfg(not(feature = "rerun"))]
                write_reading(&mut self.mcap, s, &reading)?;
            }
        }

        #[cfg(feature = "rerun")]
        if rerun_due && let Some(r) = self.rerun.as_ref() {
            for rec in &r.recorders {
                rec.log_poses_at(sample.time_secs, data)?;
                for (&(adr, _), series) in self.joints.iter().zip(&r.joint_series) {
                    rec.scalar(series, sample.qpos[adr])?;
                }
                for (imu, v) in self.imus.iter().zip(&self.imu_values) {
                    for (i, axis) in ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"].iter().enumerate()
                    {
                        rec.scalar(&format!("imu/{}/{axis}", imu.meta.name), v[i])?;
                    }
                }
                for b in 1..self.touching.len() {
                    if self.touching[b] {
                        let m = data.xmat()[b];
                        let wr = self.wrench[b];
                        let f = rotate_t(&m, [wr[0], wr[1], wr[2]]);
                        for (i, axis) in ["force_x", "force_y", "force_z"].iter().enumerate() {
                            rec.scalar(&format!("contacts/{}/{axis}", self.body_frames[b]), f[i])?;
                        }
                    }
                }
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
                let rxf = cross(r, f);
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
    /// Write errors of the MCAP or rerun outputs.
    pub fn finish(mut self) -> Result<RecordSummary> {
        for s in &mut self.sense {
            if let Some(reading) = s.pipe.finish()? {
                #[cfg(feature = "rerun")]
                write_reading(&mut self.mcap, self.rerun.as_ref(), s, &reading)?;
                #[cfg(not(feature = "rerun"))]
                write_reading(&mut self.mcap, s, &reading)?;
            }
        }
        let mut summary = RecordSummary::default();
        if let Some(mut out) = self.mcap {
            out.record_exchanged()?;
            summary.topics = out.counts;
            if let Some(writer) = out.writer {
                let path = writer.path().to_path_buf();
                let written = writer.finish()?;
                summary.mcap = Some((path, written));
            }
        }
        #[cfg(feature = "rerun")]
        if let Some(r) = self.rerun {
            for rec in r.recorders {
                let path = rec.path().map(std::path::Path::to_path_buf);
                rec.finish()?;
                if let Some(path) = path {
                    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
                    summary.rrd = Some((path, bytes));
                }
            }
        }
        Ok(summary)
    }
}

/// A recording is the engine's recorder: it records each step's instant t (see
/// [`crate::engine::StepView`]).
impl crate::engine::Observer for Recording {
    fn observe(&mut self, step: &crate::engine::StepView<'_>) -> Result<crate::engine::Flow> {
        let sample = StepSample { time_secs: step.time_secs, qpos: step.qpos, qvel: step.qvel, command: step.command };
        self.record(&sample, step.data)?;
        Ok(crate::engine::Flow::Continue)
    }
}

/// Writes one reading of a ray-cast sensor to the MCAP streams and rerun, stamped with the
/// reading's own time.
fn write_reading(
    mcap: &mut Option<McapOut>,
    #[cfg(feature = "rerun")] rerun: Option<&RerunOut>,
    s: &SenseOut,
    reading: &crate::sense::Reading,
) -> Result<()> {
    let stamp = match reading {
        crate::sense::Reading::Depth(f) => f.stamp_nanos,
        crate::sense::Reading::Lidar(l) => l.stamp_nanos,
    };
    if let Some(out) = mcap.as_mut()
        && s.streams.iter().any(Option::is_some)
    {
        for (stream, message) in s.streams.iter().zip(s.sensor.messages(reading)) {
            match stream {
                Some(SenseStreamOut::Image(t)) => out.emit(*t, stamp, |w| message.encode(w))?,
                Some(SenseStreamOut::CameraInfo(t)) => out.emit(*t, stamp, |w| message.encode(w))?,
                Some(SenseStreamOut::Points(t)) => out.emit(*t, stamp, |w| message.encode(w))?,
                Some(SenseStreamOut::Scan(t)) => out.emit(*t, stamp, |w| message.encode(w))?,
                None => {}
            }
        }
    }
    #[cfg(feature = "rerun")]
    if let Some(r) = rerun {
        for rec in &r.recorders {
            rec.set_time_secs(stamp as f64 * 1e-9);
            match reading {
                crate::sense::Reading::Depth(f) => rec.depth_frame(&s.sensor.name, f)?,
                crate::sense::Reading::Lidar(l) => {
                    let pts: Vec<_> =
                        l.points_sensor().into_iter().flatten().map(|p| l.world_from_sensor * p).collect();
                    rec.points(&s.sensor.name, &pts)?;
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

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// Hamilton product of w x y z quaternions.
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// Rotates `v` by the unit quaternion `q` (w x y z).
fn quat_rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let p = quat_mul(quat_mul(q, [0.0, v[0], v[1], v[2]]), [q[0], -q[1], -q[2], -q[3]]);
    [p[1], p[2], p[3]]
}

/// `parent_from_child` from two world poses: translation in the parent frame and rotation.
fn relative(p_pos: [f64; 3], p_quat: [f64; 4], c_pos: [f64; 3], c_quat: [f64; 4]) -> ([f64; 3], [f64; 4]) {
    let inv = [p_quat[0], -p_quat[1], -p_quat[2], -p_quat[3]];
    let d = [c_pos[0] - p_pos[0], c_pos[1] - p_pos[1], c_pos[2] - p_pos[2]];
    (quat_rotate(inv, d), quat_mul(inv, c_quat))
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
