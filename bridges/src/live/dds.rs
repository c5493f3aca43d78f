//! The DDS side: a rustdds participant restricted to one interface, and writers/readers of
//! already-encoded CDR (twin's own encoder, [`twin_core::log::CdrWriter`], makes the bytes; rustdds
//! only carries them).

use rustdds::bytes::Bytes;
use rustdds::no_key::{DataReader, DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter};
use rustdds::policy::{Durability, History, Reliability};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, GUID, Publisher, QosPolicies, QosPolicyBuilder, RTPSEntity,
    RepresentationIdentifier, Subscriber, TopicKind,
};
use std::net::IpAddr;
use twin_core::error::{Error, Result};

/// One message as CDR bytes, encapsulation header included (as MCAP stores it).
#[derive(Debug, Clone)]
pub struct RawCdr(pub Vec<u8>);

/// Error of the raw adapters (a payload that is not plain CDR).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct RawCdrError(String);

/// Passes [`RawCdr`] through: rustdds writes the encapsulation header itself from
/// `output_encoding`, so the payload is the bytes after twin's 4-byte header.
pub struct RawAdapter;

impl SerializerAdapter<RawCdr> for RawAdapter {
    type Error = RawCdrError;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &RawCdr) -> std::result::Result<Bytes, RawCdrError> {
        match value.0.get(..4) {
            Some([0, 1, _, _]) => Ok(Bytes::copy_from_slice(&value.0[4..])),
            _ => Err(RawCdrError("twin encodes little-endian CDR only".into())),
        }
    }
}

const ENCODINGS: [RepresentationIdentifier; 2] = [RepresentationIdentifier::CDR_LE, RepresentationIdentifier::CDR_BE];

impl DeserializerAdapter<RawCdr> for RawAdapter {
    type Error = RawCdrError;
    type Decoded = RawCdr;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }
    fn transform_decoded(decoded: RawCdr) -> RawCdr {
        decoded
    }
}

/// Rebuilds the encapsulation header so [`twin_core::log::CdrReader`] reads the sample.
#[derive(Clone, Copy)]
pub struct RawDecoder;

impl<'de> Decode<'de, RawCdr> for RawDecoder {
    type Error = RawCdrError;
    fn decode_bytes(
        self,
        input: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> std::result::Result<RawCdr, RawCdrError> {
        let header: [u8; 4] = if encoding == RepresentationIdentifier::CDR_LE {
            [0, 1, 0, 0]
        } else if encoding == RepresentationIdentifier::CDR_BE {
            [0, 0, 0, 0]
        } else {
            return Err(RawCdrError(format!("unsupported encoding {encoding:?}")));
        };
        let mut v = Vec::with_capacity(input.len() + 4);
        v.extend_from_slice(&header);
        v.extend_from_slice(input);
        Ok(RawCdr(v))
    }
}

impl DefaultDecoder<RawCdr> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

/// A writer of one topic.
pub type RawWriter = DataWriter<RawCdr, RawAdapter>;
/// A reader of one topic.
pub type RawReader = DataReader<RawCdr, RawAdapter>;

/// QoS of a published topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TopicQos {
    /// Reliable, volatile, keep last `depth`: matches rclpy/rclcpp default and sensor-data
    /// (best-effort) subscriptions alike.
    Stream {
        /// History depth.
        depth: i32,
    },
    /// Reliable, transient-local, keep last 1 (`/tf_static`, `/robot_description`): late
    /// subscribers still get the message.
    Latched,
}

impl TopicQos {
    /// The DDS QoS for a topic of the table: transient-local topics are latched (keep last
    /// 1); the others stream with keep last `depth` (100 where the table says
    /// keep all, so a slow reader can't make the twin's memory grow). Always reliable: a
    /// reliable writer matches reliable and best-effort readers alike.
    pub fn of(qos: twin_core::topics::Qos) -> TopicQos {
        match qos.durability {
            twin_core::topics::Durability::TransientLocal => TopicQos::Latched,
            twin_core::topics::Durability::Volatile => TopicQos::Stream {
                depth: if qos.depth == 0 { 100 } else { i32::try_from(qos.depth).unwrap_or(i32::MAX) },
            },
        }
    }

    /// The rustdds QoS.
    pub fn policies(self) -> QosPolicies {
        // A reliable writer never blocks the simulation: with keep-last history a full queue
        // drops the oldest sample instead of waiting for a slow reader.
        let b =
            QosPolicyBuilder::new().reliability(Reliability::Reliable { max_blocking_time: rustdds::Duration::ZERO });
        match self {
            TopicQos::Stream { depth } => {
                b.durability(Durability::Volatile).history(History::KeepLast { depth }).build()
            }
            TopicQos::Latched => {
                b.durability(Durability::TransientLocal).history(History::KeepLast { depth: 1 }).build()
            }
        }
    }
}

/// ROS 2 topic name → DDS topic name (`/joint_states` → `rt/joint_states`).
pub fn dds_topic(ros_topic: &str) -> String {
    format!("rt/{}", ros_topic.trim_start_matches('/'))
}

/// ROS 2 type name → DDS type name (`sensor_msgs/msg/JointState` →
/// `sensor_msgs::msg::dds_::JointState_`).
pub fn dds_type(ros_type: &str) -> String {
    let mut parts: Vec<&str> = ros_type.split('/').collect();
    let name = parts.pop().unwrap_or_default();
    let mut out = parts.join("::");
    out.push_str("::dds_::");
    out.push_str(name);
    out.push('_');
    out
}

/// A DDS participant with one publisher and one subscriber, announced to the ROS 2 graph as
/// one node ([`NODE_NAME`]): every writer and reader it creates is listed in its
/// `ros_discovery_info` announcement, so `ros2 node list` shows `/twin` and `ros2 node info
/// /twin` its topics and services.
pub struct Node {
    participant: DomainParticipant,
    publisher: Publisher,
    subscriber: Subscriber,
    discovery: RawWriter,
    /// GUIDs of the node's readers and writers, in creation order.
    entities: std::sync::Mutex<Entities>,
}

/// Another participant's reader or writer of one of twin's topics, as discovery saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SeenEndpoint {
    /// Its GUID (a new process's endpoints have new ones).
    pub guid: GUID,
    /// Reliable (it acknowledges what it gets) or best effort (it cannot).
    pub reliable: bool,
}

/// The ROS 2 node name of the bridge.
pub const NODE_NAME: &str = "twin";
/// The ROS 2 namespace of the bridge's node.
pub const NODE_NAMESPACE: &str = "/";
/// The graph-announcement topic of ROS 2's rmw layer (`rmw_dds_common`).
pub const DISCOVERY_TOPIC: &str = "ros_discovery_info";
/// Its DDS type: `rmw_dds_common/msg/ParticipantEntitiesInfo`.
pub const DISCOVERY_TYPE: &str = "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_";

#[derive(Default)]
struct Entities {
    readers: Vec<GUID>,
    writers: Vec<GUID>,
}

fn dds_err(what: impl std::fmt::Display, e: impl std::fmt::Display) -> Error {
    Error::Live { message: format!("{what}: {e}") }
}

/// `rmw_dds_common/msg/ParticipantEntitiesInfo` with one node: the participant's GID, then
/// the node's namespace, name, reader GIDs and writer GIDs. A GID is the entity's 16-byte
/// DDS GUID (`rmw_dds_common/msg/Gid` is `uint8[16]` since ROS 2 Iron; Jazzy and later).
pub fn participant_entities_info(participant: GUID, readers: &[GUID], writers: &[GUID]) -> Vec<u8> {
    let mut w = twin_core::log::cdr::CdrWriter::new();
    w.u8_fixed(&participant.to_bytes());
    w.seq_len(1);
    w.string(NODE_NAMESPACE);
    w.string(NODE_NAME);
    for gids in [readers, writers] {
        w.seq_len(gids.len());
        for g in gids {
            w.u8_fixed(&g.to_bytes());
        }
    }
    w.bytes().to_vec()
}

impl Node {
    /// Joins domain `domain_id` on the interface with address `interface` only: discovery is
    /// announced and multicast joined/sent only there (loopback has no multicast, so on `lo`
    /// discovery is unicast to 127.0.0.1's well-known ports).
    ///
    /// # Errors
    /// [`Error::Live`] when the participant can't be created (no free port, bad domain id).
    pub fn new(domain_id: u16, interface: IpAddr) -> Result<Node> {
        let participant = DomainParticipantBuilder::new(domain_id)
            .with_only_networks([interface])
            .build()
            .map_err(|e| dds_err(format!("creating a DDS participant on domain {domain_id}"), e))?;
        let qos = QosPolicies::qos_none();
        let publisher = participant.create_publisher(&qos).map_err(|e| dds_err("creating a DDS publisher", e))?;
        let subscriber = participant.create_subscriber(&qos).map_err(|e| dds_err("creating a DDS subscriber", e))?;
        // rmw_dds_common's QoS for the graph topic: reliable, transient-local, keep last 1.
        let policies = TopicQos::Latched.policies();
        let topic = participant
            .create_topic(DISCOVERY_TOPIC.into(), DISCOVERY_TYPE.into(), &policies, TopicKind::NoKey)
            .map_err(|e| dds_err(format!("creating DDS topic {DISCOVERY_TOPIC}"), e))?;
        let discovery = publisher
            .create_datawriter_no_key::<RawCdr, RawAdapter>(&topic, Some(policies))
            .map_err(|e| dds_err(format!("creating a writer of {DISCOVERY_TOPIC}"), e))?;
        let node = Node { participant, publisher, subscriber, discovery, entities: Default::default() };
        node.announce()?;
        Ok(node)
    }

    /// The participant's GUID (its ROS 2 GID).
    pub fn guid(&self) -> GUID {
        self.participant.guid()
    }

    /// Publishes the node's entities on `ros_discovery_info` (again: after each new one).
    fn announce(&self) -> Result<()> {
        let cdr = {
            let e = self.entities.lock().map_err(|_| dds_err("announcing the node", "a thread panicked"))?;
            participant_entities_info(self.participant.guid(), &e.readers, &e.writers)
        };
        self.discovery.write(RawCdr(cdr), None).map_err(|e| dds_err(format!("publishing {DISCOVERY_TOPIC}"), e))
    }

    fn added(&self, guid: GUID, writer: bool) -> Result<()> {
        if let Ok(mut e) = self.entities.lock() {
            if writer { e.writers.push(guid) } else { e.readers.push(guid) }
        }
        self.announce()
    }

    /// The other participants' readers of `ros_topic` that discovery has seen now: the full
    /// current set from rustdds's discovery database ([`DomainParticipant::discovered_readers`]),
    /// not the writer's match events (rustdds keeps 4 of those per writer and drops the rest).
    /// A reader seen here gets what a writer of the topic sends from then on; a reader not seen
    /// yet gets nothing (DDS keeps no volatile sample for a reader it has not met).
    pub fn readers_of(&self, ros_topic: &str) -> Vec<SeenEndpoint> {
        let topic = dds_topic(ros_topic);
        let me = self.participant.guid().prefix;
        self.participant
            .discovered_readers()
            .into_iter()
            .filter(|r| r.subscription_topic_data.topic_name == topic)
            .map(|r| SeenEndpoint {
                guid: r.reader_proxy.remote_reader_guid,
                reliable: r.subscription_topic_data.qos().is_reliable(),
            })
            .filter(|r| r.guid.prefix != me)
            .collect()
    }

    /// The other participants' writers of `ros_topic` that discovery has seen now (see
    /// [`Node::readers_of`]).
    pub fn writers_of(&self, ros_topic: &str) -> Vec<SeenEndpoint> {
        let topic = dds_topic(ros_topic);
        let me = self.participant.guid().prefix;
        self.participant
            .discovered_writers()
            .into_iter()
            .filter(|w| w.publication_topic_data.topic_name == topic)
            .map(|w| SeenEndpoint {
                guid: w.writer_proxy.remote_writer_guid,
                reliable: matches!(w.publication_topic_data.reliability, Some(Reliability::Reliable { .. })),
            })
            .filter(|w| w.guid.prefix != me)
            .collect()
    }

    /// A writer of `ros_topic` (type `ros_type`, e.g. `sensor_msgs/msg/JointState`).
    ///
    /// # Errors
    /// [`Error::Live`] from rustdds.
    pub fn writer(&self, ros_topic: &str, ros_type: &str, qos: TopicQos) -> Result<RawWriter> {
        self.dds_writer(&dds_topic(ros_topic), &dds_type(ros_type), qos.policies(), ros_topic)
    }

    /// A reader of `ros_topic`: reliable (matches rclpy/rclcpp default publishers), volatile,
    /// keep last `depth`.
    ///
    /// # Errors
    /// [`Error::Live`] from rustdds.
    pub fn reader(&self, ros_topic: &str, ros_type: &str, depth: i32) -> Result<RawReader> {
        self.dds_reader(&dds_topic(ros_topic), &dds_type(ros_type), depth, ros_topic)
    }

    /// The DDS topic `topic` of DDS type `type_name`, keyless, with `policies` (`what` names it
    /// in errors): what a writer and a reader of it are made on.
    fn topic(&self, topic: &str, type_name: &str, policies: &QosPolicies, what: &str) -> Result<rustdds::Topic> {
        self.participant
            .create_topic(topic.into(), type_name.into(), policies, TopicKind::NoKey)
            .map_err(|e| dds_err(format!("creating DDS topic for {what}"), e))
    }

    /// A writer of the DDS topic `topic` of DDS type `type_name` (`what` names it in errors).
    ///
    /// # Errors
    /// [`Error::Live`] from rustdds.
    pub fn dds_writer(&self, topic: &str, type_name: &str, policies: QosPolicies, what: &str) -> Result<RawWriter> {
        let topic = self.topic(topic, type_name, &policies, what)?;
        let w = self
            .publisher
            .create_datawriter_no_key::<RawCdr, RawAdapter>(&topic, Some(policies))
            .map_err(|e| dds_err(format!("creating a writer of {what}"), e))?;
        self.added(w.guid(), true)?;
        Ok(w)
    }

    /// A reader of the DDS topic `topic` of DDS type `type_name`: reliable, volatile, keep
    /// last `depth` (`what` names it in errors).
    ///
    /// # Errors
    /// [`Error::Live`] from rustdds.
    pub fn dds_reader(&self, topic: &str, type_name: &str, depth: i32, what: &str) -> Result<RawReader> {
        let policies = QosPolicyBuilder::new()
            .reliability(Reliability::Reliable { max_blocking_time: rustdds::Duration::ZERO })
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth })
            .build();
        let topic = self.topic(topic, type_name, &policies, what)?;
        let r = self
            .subscriber
            .create_datareader_no_key::<RawCdr, RawAdapter>(&topic, Some(policies))
            .map_err(|e| dds_err(format!("creating a reader of {what}"), e))?;
        self.added(r.guid(), false)?;
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ros_names_map_to_dds_names() {
        assert_eq!(dds_topic("/joint_states"), "rt/joint_states");
        assert_eq!(dds_topic("/humanoid/imu/data"), "rt/humanoid/imu/data");
        assert_eq!(dds_type("sensor_msgs/msg/JointState"), "sensor_msgs::msg::dds_::JointState_");
        assert_eq!(dds_type("rosgraph_msgs/msg/Clock"), "rosgraph_msgs::msg::dds_::Clock_");
    }
}
