//! The one ROS 2 topic table of a twin, derived from its [`Robot`]: each topic's name, message
//! type, rate, `frame_id` and QoS intent. Recordings ([`crate::sim::Recording`]) turn the
//! simulation into these topics' typed messages ([`TypedMessage`], the types of [`crate::log`])
//! once per step and hand them to their sinks ([`Sink`]: the MCAP file
//! [`crate::sim::McapSink`], the rerun recording `crate::sim::RerunSink`, the live DDS bridge
//! `twin_bridges::live::LiveSink`, a user's own), each of which encodes what it takes. A controller adds
//! topics of its own ([`crate::control::Controller::topics`], e.g. a walking controller's
//! footsteps), recorded the same way.
//!
//! Topics (`<robot>` = [`Robot::name`]):
//! - `/joint_states` (`sensor_msgs/msg/JointState`) at the state rate;
//! - each IMU on its topic (`sensor_msgs/msg/Imu`) at its rate (else the state rate);
//! - `/odom` (`nav_msgs/msg/Odometry`, floating bases) at the state rate;
//! - `/tf` (`tf2_msgs/msg/TFMessage`) at the tf rate; `/tf_static` once (latched), when an IMU
//!   frame is not a body;
//! - `/contacts/<body>` (`geometry_msgs/msg/WrenchStamped`) per body, from its first contact on;
//! - `/<robot>/joint_commands` (`std_msgs/msg/Float64MultiArray`): the command sent;
//! - `/cmd_vel` (`geometry_msgs/msg/Twist`, [`CMD_VEL_TOPIC`]), an input: under `twin sim --ros
//!   --controller walk` it steers the walker (linear.x forward, linear.y left, angular.z yaw
//!   rate, the robot's heading frame), the topic `teleop_twist_keyboard` and Nav2 publish by
//!   default (`twin_bridges::live`, `twin_controllers::walk::steer`);
//! - each ray-cast sensor's topics ([`crate::sense::rig`]): depth cameras
//!   `<prefix>/depth/image_raw`, `<prefix>/depth/camera_info`, `<prefix>/points`; LiDARs a
//!   `LaserScan` or `PointCloud2`, at the sensor's rate.

use crate::error::Result;
use crate::log::cdr::CdrWriter;
use crate::log::{
    Clock, Float64MultiArray, Imu, JointState, Odometry, PointStamped, PoseArray, RosMessage, TfMessage, WrenchStamped,
};
use crate::mj::ObjType;
use crate::robot::Robot;

/// The velocity command input of a walking robot on a live graph: `geometry_msgs/msg/Twist`
/// in the heading frame (what navigation stacks and `teleop_twist_keyboard` publish by default;
/// remap theirs to it, e.g. `--ros-args -r cmd_vel:=/cmd_vel`).
pub const CMD_VEL_TOPIC: &str = "/cmd_vel";

/// Whether every message must arrive (`Reliable`) or the newest matters (`BestEffort`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reliability {
    /// Retransmit until received.
    Reliable,
    /// Send once; drop when late.
    BestEffort,
}

/// Whether late joiners get the last message (`TransientLocal`, "latched") or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Durability {
    /// Only messages published after subscribing.
    Volatile,
    /// The last `depth` messages are kept for late joiners.
    TransientLocal,
}

/// The QoS a topic is offered with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    pub durability: Durability,
    /// History depth (keep-last); 0: keep all (what rosbag2 records).
    pub depth: u32,
}

impl Qos {
    /// Streams: reliable, volatile, keep all (rosbag2's recorded profile).
    pub const STREAM: Qos = Qos { reliability: Reliability::Reliable, durability: Durability::Volatile, depth: 0 };
    /// Latched: reliable, transient-local, keep last 1 (`/tf_static`).
    pub const LATCHED: Qos =
        Qos { reliability: Reliability::Reliable, durability: Durability::TransientLocal, depth: 1 };
    /// High-rate sensor data: best effort, volatile, keep last 5 (ROS 2's sensor-data profile).
    pub const SENSOR_DATA: Qos =
        Qos { reliability: Reliability::BestEffort, durability: Durability::Volatile, depth: 5 };
}

/// What a topic carries, with the indices it needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TopicKind {
    /// Every 1-DOF joint of [`Robot::joints`].
    JointStates,
    /// IMU `k` of [`Robot::imus`].
    Imu(usize),
    /// The floating base in `odom`.
    Odometry,
    /// Every body relative to its parent.
    Tf,
    /// IMU and ray-cast sensor frames that are no body, relative to their body (once).
    TfStatic,
    /// Net contact wrench on this body.
    Contacts(usize),
    /// The command sent.
    Commands,
    /// Topic `k` of the controller's own ([`crate::control::Controller::topics`]): its
    /// diagnostics, or what a bridge exchanged.
    Controller(usize),
    /// Stream `stream` of ray-cast sensor `sensor` of [`crate::sense::ray_sensors`] (depth
    /// image, camera info, points, laser scan), at the sensor's rate.
    Sensor {
        /// Index in [`crate::sense::ray_sensors`].
        sensor: usize,
        /// Which of its messages.
        stream: crate::sense::SensorStream,
    },
}

/// One topic of the table.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    /// Topic name (e.g. `/joint_states`).
    pub name: String,
    /// ROS 2 message type (`pkg/msg/Type`).
    pub type_name: &'static str,
    /// Publication rate, Hz (`None`: once).
    pub rate_hz: Option<f64>,
    /// `frame_id` of its headers (empty when it has none or several).
    pub frame_id: String,
    /// QoS intent.
    pub qos: Qos,
    /// What it carries.
    pub kind: TopicKind,
}

/// Rates of the table's streams.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct TopicRates {
    /// `/joint_states`, `/odom`, contacts, commands, and IMUs without their own rate, Hz.
    /// (default: 500)
    #[default(500.0)]
    pub state_rate_hz: f64,
    /// `/tf`, Hz. (default: 100)
    #[default(100.0)]
    pub tf_rate_hz: f64,
}

/// The topics of a robot, in publication order.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicTable {
    /// The topics.
    pub topics: Vec<TopicInfo>,
}

/// A topic-name-safe version of `name` (ASCII letters, digits, `_`).
pub fn topic_safe(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect()
}

/// Name of body `b` as a frame (`body_<b>` when unnamed).
pub fn body_frame(robot: &Robot, b: usize) -> String {
    match robot.model.name(ObjType::Body, b) {
        "" => format!("body_{b}"),
        n => n.to_string(),
    }
}

impl TopicTable {
    /// The table of `robot` at `rates`.
    pub fn new(robot: &Robot, rates: &TopicRates) -> TopicTable {
        let model = &robot.model;
        let state = Some(rates.state_rate_hz);
        let root_frame = if robot.base.is_some() { "odom" } else { "world" };
        let mut topics = vec![TopicInfo {
            name: "/joint_states".into(),
            type_name: JointState::TYPE_NAME,
            rate_hz: state,
            frame_id: String::new(),
            qos: Qos::STREAM,
            kind: TopicKind::JointStates,
        }];
        for (k, imu) in robot.imus.iter().enumerate() {
            topics.push(TopicInfo {
                name: imu.topic().to_string(),
                type_name: Imu::TYPE_NAME,
                rate_hz: Some(imu.meta.update_rate_hz.unwrap_or(rates.state_rate_hz)),
                frame_id: imu.meta.frame_id.clone(),
                qos: Qos::STREAM,
                kind: TopicKind::Imu(k),
            });
        }
        if robot.base.is_some() {
            topics.push(TopicInfo {
                name: "/odom".into(),
                type_name: Odometry::TYPE_NAME,
                rate_hz: state,
                frame_id: "odom".into(),
                qos: Qos::STREAM,
                kind: TopicKind::Odometry,
            });
        }
        topics.push(TopicInfo {
            name: "/tf".into(),
            type_name: TfMessage::TYPE_NAME,
            rate_hz: Some(rates.tf_rate_hz),
            frame_id: root_frame.into(),
            qos: Qos::STREAM,
            kind: TopicKind::Tf,
        });
        topics.push(TopicInfo {
            name: format!("/{}/joint_commands", robot.name),
            type_name: Float64MultiArray::TYPE_NAME,
            rate_hz: state,
            frame_id: String::new(),
            qos: Qos::STREAM,
            kind: TopicKind::Commands,
        });
        let frames: Vec<String> = (0..model.nbody()).map(|b| body_frame(robot, b)).collect();
        let sensors = crate::sense::ray_sensors(robot);
        if robot.imus.iter().any(|i| !frames.contains(&i.meta.frame_id))
            || sensors.iter().any(|s| !frames.contains(&s.frame_id))
        {
            topics.push(TopicInfo {
                name: "/tf_static".into(),
                type_name: TfMessage::TYPE_NAME,
                rate_hz: None,
                frame_id: String::new(),
                qos: Qos::LATCHED,
                kind: TopicKind::TfStatic,
            });
        }
        for (b, frame) in frames.iter().enumerate().skip(1) {
            topics.push(TopicInfo {
                name: format!("/contacts/{}", topic_safe(frame)),
                type_name: WrenchStamped::TYPE_NAME,
                rate_hz: state,
                frame_id: frame.clone(),
                qos: Qos::STREAM,
                kind: TopicKind::Contacts(b),
            });
        }
        for (k, s) in sensors.iter().enumerate() {
            for (name, stream) in &s.topics {
                topics.push(TopicInfo {
                    name: name.clone(),
                    type_name: stream.type_name(),
                    rate_hz: Some(s.rate_hz),
                    frame_id: s.frame_id.clone(),
                    qos: Qos::STREAM,
                    kind: TopicKind::Sensor { sensor: k, stream: *stream },
                });
            }
        }
        TopicTable { topics }
    }

    /// The topic called `name`.
    pub fn find(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// The first topic of `kind`.
    pub fn of_kind(&self, kind: TopicKind) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.kind == kind)
    }
}

/// One message, borrowed from its producer's buffers (the recording's, or a controller's for
/// its own topics).
#[derive(Debug, Clone, Copy)]
pub enum TypedMessage<'a> {
    /// `sensor_msgs/msg/JointState`.
    JointState(&'a JointState),
    /// `sensor_msgs/msg/Imu`.
    Imu(&'a Imu),
    /// `nav_msgs/msg/Odometry`.
    Odometry(&'a Odometry),
    /// `tf2_msgs/msg/TFMessage` (`/tf` and `/tf_static`).
    Tf(&'a TfMessage),
    /// `geometry_msgs/msg/WrenchStamped`.
    Wrench(&'a WrenchStamped),
    /// `std_msgs/msg/Float64MultiArray`.
    Float64MultiArray(&'a Float64MultiArray),
    /// `geometry_msgs/msg/PointStamped` (a controller's CoM, ZMP, DCM…).
    Point(&'a PointStamped),
    /// `geometry_msgs/msg/PoseArray` (a controller's planned footsteps…).
    Poses(&'a PoseArray),
    /// `rosgraph_msgs/msg/Clock`.
    Clock(&'a Clock),
    /// A message of its topic's type that is CDR already (encapsulation header included): one
    /// received off the wire, kept byte for byte even when it does not decode.
    Cdr(&'a [u8]),
    /// `sensor_msgs/msg/Image`, `sensor_msgs/msg/CameraInfo`, `sensor_msgs/msg/PointCloud2`
    /// or `sensor_msgs/msg/LaserScan` of a ray-cast sensor.
    Sensor(&'a crate::sense::SensorMessage),
}

impl TypedMessage<'_> {
    /// Its CDR bytes (encapsulation header included), encoded into `buf` unless it is CDR
    /// already.
    pub fn to_cdr<'b>(&'b self, buf: &'b mut CdrWriter) -> &'b [u8] {
        fn encode<'b, T: RosMessage>(m: &T, buf: &'b mut CdrWriter) -> &'b [u8] {
            buf.reset();
            m.encode(buf);
            buf.bytes()
        }
        match *self {
            TypedMessage::JointState(m) => encode(m, buf),
            TypedMessage::Imu(m) => encode(m, buf),
            TypedMessage::Odometry(m) => encode(m, buf),
            TypedMessage::Tf(m) => encode(m, buf),
            TypedMessage::Wrench(m) => encode(m, buf),
            TypedMessage::Float64MultiArray(m) => encode(m, buf),
            TypedMessage::Point(m) => encode(m, buf),
            TypedMessage::Poses(m) => encode(m, buf),
            TypedMessage::Clock(m) => encode(m, buf),
            TypedMessage::Cdr(bytes) => bytes,
            TypedMessage::Sensor(m) => {
                buf.reset();
                m.encode(buf);
                buf.bytes()
            }
        }
    }
}

/// What a [`Sink`] keeps of each topic it took, by the topic's `id`: set in
/// [`Sink::add_topic`], read in [`Sink::write`]; nothing for an id it did not take.
#[derive(Debug, Clone)]
pub struct ById<T>(Vec<Option<T>>);

impl<T> Default for ById<T> {
    fn default() -> Self {
        ById(Vec::new())
    }
}

impl<T> ById<T> {
    /// Keeps `value` for topic `id`.
    pub fn set(&mut self, id: usize, value: T) {
        if self.0.len() <= id {
            self.0.resize_with(id + 1, || None);
        }
        self.0[id] = Some(value);
    }

    /// What is kept for topic `id`, if any.
    pub fn get(&self, id: usize) -> Option<&T> {
        self.0.get(id)?.as_ref()
    }
}

/// Where a recording's messages go: the MCAP file, the rerun recording, the live DDS bridge, a
/// test's buffer. Topics are offered once each, before their first message, with an `id` (their
/// index among the recording's topics: the [`TopicTable`]'s, then the controller's own, see
/// [`crate::control::Controller::topics`]) that later writes repeat; messages of one topic come
/// in log-time order.
pub trait Sink: Send {
    /// Offers topic `id` (name, type, rate, QoS); returns whether this sink takes its messages
    /// (a sink may take only some topics, e.g. those it can show).
    ///
    /// # Errors
    /// When the sink can't offer it (e.g. the file can't be written).
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool>;

    /// Writes one message of topic `id`, stamped `log_time_nanos` (simulation time).
    ///
    /// # Errors
    /// When the sink can't take it.
    fn write(&mut self, id: usize, topic: &TopicInfo, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()>;

    /// Ends the output (flushes, closes). Called once, after the last message.
    ///
    /// # Errors
    /// When what was written can't be completed.
    fn finish(&mut self) -> Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;
    use std::sync::Arc;

    #[test]
    fn table_follows_the_robot() {
        let xml = r#"<mujoco><worldbody><body name="base" pos="0 0 1"><freejoint/>
            <geom type="box" size="0.1 0.1 0.1"/><site name="imu" pos="0 0 0.1"/>
            <body name="arm"><joint name="j" axis="0 1 0"/><geom type="sphere" size="0.05"/></body></body>
            </worldbody><sensor><gyro name="imu_gyro" site="imu"/><accelerometer name="imu_accel" site="imu"/>
            </sensor></mujoco>"#;
        let model = Arc::new(crate::mj::Model::from_xml_str(xml).unwrap());
        let robot = Robot::from_model(model, "bot", Path::new("bot.xml")).unwrap();
        let table = TopicTable::new(&robot, &TopicRates::default());
        let names: Vec<&str> = table.topics.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(
            names,
            ["/joint_states", "/bot/imu", "/odom", "/tf", "/bot/joint_commands", "/contacts/base", "/contacts/arm"]
        );
        let imu = table.find("/bot/imu").unwrap();
        assert_eq!((imu.type_name, imu.frame_id.as_str(), imu.rate_hz), ("sensor_msgs/msg/Imu", "base", Some(500.0)));
        assert_eq!(table.of_kind(TopicKind::Tf).unwrap().rate_hz, Some(100.0));
    }
}
