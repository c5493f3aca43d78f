//! ROS 2 logs, the floor beside the MuJoCo wrapper: what twin reads from a robot's bags and
//! writes as its recordings. Bytes come in (an `.mcap` file or a rosbag2 folder), are walked
//! record by record ([`reader`], with damage recovery), decoded from CDR ([`cdr`]) with the
//! `ros2msg` schema each channel carries ([`msgdef`]) or through the typed fast paths
//! ([`typed`]), and come out as series ([`series`]); recordings go the other way through
//! [`writer`]. Nothing here knows a robot or MuJoCo.
//!
//! ROS 2 logs in MCAP: reading (any message type, decoded from the `ros2msg` schema text the
//! file carries, with typed fast paths for the hot types), damage recovery, and writing.
//!
//! ```no_run
//! use twin_log::{Log, ReadOptions};
//!
//! let log = Log::open("rosbag2_2024_05_01", ReadOptions::default())?;
//! let series = log.joint_states("/joint_states")?;
//! for warning in series.report.warnings() {
//!     eprintln!("warning: {warning}");
//! }
//! let knee = series.joint("left_knee_joint").expect("joint logged");
//! println!("{} samples of {}", knee.time_nanos.len(), knee.name);
//! # Ok::<(), twin_log::Error>(())
//! ```
//!
//! ## Limitations
//! - Only plain CDR (`00 00` / `00 01` encapsulation) is decoded; XCDR2 and `wstring` fields are
//!   refused with an error naming the topic.
//! - JSON is read for `sensor_msgs/msg/JointState` only; protobuf channels are listed by
//!   `info` but not decoded.
//! - A chunk cut off mid-write is lost whole (its messages are not salvaged from the partial
//!   compressed stream); the warning gives its byte count and log-time range.

pub mod cdr;
pub mod error;
pub mod info;
pub mod msgdef;
pub mod reader;
pub mod series;
pub mod typed;
pub mod writer;

pub use cdr::Value;
pub use error::{Error, Result};
pub use info::{LogInfo, TopicInfo};
pub use reader::{Channel, Damage, DamageKind, RawMessage, ScanReport, Schema};
pub use series::{JointSeries, JointStateReport, JointStateSeries};
pub use typed::{
    CameraInfo, Clock, Float64MultiArray, Header, Image, Imu, JointState, JointTrajectory, JointTrajectoryPoint,
    LaserScan, MultiArrayDimension, Odometry, PointCloud2, PointField, PointStamped, Pose, PoseArray, RegionOfInterest,
    RosMessage, RosString, TfMessage, TransformStamped, Twist, WrenchStamped,
};
pub use writer::{Compression, LogWriter, Topic, WriteSummary, WriterOptions};

use msgdef::MsgDefs;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How to read a log.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReadOptions {
    /// Refuse a damaged file (cut off, bad chunk CRC, corrupt record) with an error instead of
    /// skipping the damaged part with a warning (default: false).
    pub strict: bool,
}

/// What reading a log found, over all its files.
#[derive(Debug, Clone, Default)]
pub struct ReadReport {
    /// One report per `.mcap` file, in order.
    pub files: Vec<(PathBuf, ScanReport)>,
}

impl ReadReport {
    /// Every damage found.
    pub fn damage(&self) -> impl Iterator<Item = &Damage> {
        self.files.iter().flat_map(|(_, r)| r.damage.iter())
    }

    /// Messages handed over.
    pub fn messages_delivered(&self) -> u64 {
        self.files.iter().map(|(_, r)| r.messages_delivered).sum()
    }

    /// One line per damage plus, for a file whose statistics survive, how many of its messages
    /// were recovered.
    pub fn warnings(&self) -> Vec<String> {
        let mut out: Vec<String> = self.damage().map(ToString::to_string).collect();
        for (path, r) in &self.files {
            if let Some(total) = r.statistics_message_count
                && r.messages_seen < total
            {
                out.push(format!(
                    "{}: {} of the {total} messages the file's statistics list were read; {} lost",
                    path.display(),
                    r.messages_seen,
                    total - r.messages_seen
                ));
            }
        }
        out
    }
}

/// An opened log: a bare `.mcap` file or a rosbag2 folder (`metadata.yaml` + `.mcap` files).
#[derive(Debug, Clone)]
pub struct Log {
    path: PathBuf,
    files: Vec<PathBuf>,
    options: ReadOptions,
}

/// How a channel's messages are decoded.
#[derive(Debug, Clone)]
pub(crate) enum Decoder {
    /// CDR with the parsed schema; `fast` when the layout is the canonical one of the type.
    Cdr { defs: Arc<MsgDefs>, fast: bool },
    /// JSON text.
    Json,
    /// Cannot be decoded, with the reason.
    Unsupported(String),
}

impl Decoder {
    pub(crate) fn for_channel(channel: &Channel) -> Decoder {
        match channel.message_encoding.as_str() {
            "cdr" => {
                let Some(schema) = &channel.schema else {
                    return Decoder::Unsupported("CDR channel without a schema".into());
                };
                if schema.encoding != "ros2msg" {
                    return Decoder::Unsupported(format!(
                        "schema encoding `{}` (only ros2msg is decoded)",
                        schema.encoding
                    ));
                }
                let text = String::from_utf8_lossy(&schema.data);
                match MsgDefs::parse(&schema.name, &text) {
                    Ok(defs) => {
                        let fast = typed::canonical_layout(&defs.root().name).is_some_and(|l| l == defs.layout());
                        Decoder::Cdr { defs: Arc::new(defs), fast }
                    }
                    Err(e) => Decoder::Unsupported(e.to_string()),
                }
            }
            "json" => Decoder::Json,
            other => Decoder::Unsupported(format!("message encoding `{other}`")),
        }
    }
}

impl Log {
    /// Opens a `.mcap` file or a rosbag2 folder. Nothing is read yet but the folder listing.
    ///
    /// # Errors
    /// [`Error::LogFormat`] when the path is neither, or a folder is an sqlite3 bag.
    pub fn open(path: impl AsRef<Path>, options: ReadOptions) -> Result<Log> {
        let path = path.as_ref().to_path_buf();
        if path.exists() {
            twin_fsio::check_input(&path, twin_fsio::InputKind::FileOrDir)?;
        }
        let files = if path.is_dir() {
            bag_files(&path)?
        } else if path.is_file() {
            vec![path.clone()]
        } else {
            return Err(Error::LogFormat {
                path,
                offset: None,
                message: "no such file or folder; give a .mcap file or a rosbag2 folder".into(),
            });
        };
        Ok(Log { path, files, options })
    }

    /// The path given to [`Log::open`].
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The `.mcap` files read, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Calls `f` for each message of the channels `wanted` selects, in file order.
    ///
    /// # Errors
    /// I/O errors, a file that is not MCAP, damage in strict mode, or what `f` returns.
    pub fn for_each_raw(
        &self,
        wanted: &dyn Fn(&Channel) -> bool,
        mut f: impl FnMut(RawMessage<'_>) -> Result<()>,
    ) -> Result<ReadReport> {
        let mut report = ReadReport::default();
        for file in &self.files {
            let scan = reader::Scanner::new(file, self.options, wanted).run(&mut f)?;
            report.files.push((file.clone(), scan));
        }
        Ok(report)
    }

    /// Calls `f` with each message of `topic` decoded generically.
    ///
    /// # Errors
    /// As [`Log::for_each_raw`]; [`Error::LogTopic`] when the topic is absent; [`Error::Decode`]
    /// for a message that does not match its schema (in non-strict mode such messages are
    /// skipped and counted in the report's warnings instead).
    pub fn for_each_value(
        &self,
        topic: &str,
        mut f: impl FnMut(&Channel, u64, &Value) -> Result<()>,
    ) -> Result<ReadReport> {
        let mut decoders: HashMap<*const Channel, Decoder> = HashMap::new();
        let mut bad = BadMessages::default();
        let mut report = self.for_each_raw(&|c| c.topic == topic, |m| {
            let dec = decoders.entry(Arc::as_ptr(m.channel)).or_insert_with(|| Decoder::for_channel(m.channel));
            let value = match dec {
                Decoder::Cdr { defs, .. } => {
                    cdr::decode(defs, m.data).map_err(|e| format!("{} (at byte {})", e.message, e.offset))
                }
                Decoder::Json => serde_json::from_slice::<serde_json::Value>(m.data)
                    .map(json_to_value)
                    .map_err(|e| format!("invalid JSON: {e}")),
                Decoder::Unsupported(why) => Err(format!("cannot decode: {why}")),
            };
            match value {
                Ok(v) => f(m.channel, m.log_time_nanos, &v),
                Err(message) => bad.push(self, &m, message),
            }
        })?;
        self.check_topic(&report, topic)?;
        bad.into_report(&mut report);
        Ok(report)
    }

    /// All messages of a topic of a typed message type, with their log times.
    ///
    /// # Errors
    /// [`Error::LogTopic`] when the topic is absent or of another type; otherwise as
    /// [`Log::for_each_value`].
    pub fn read_typed<T: RosMessage>(&self, topic: &str) -> Result<(Vec<(u64, T)>, ReadReport)> {
        let mut decoders: HashMap<*const Channel, Decoder> = HashMap::new();
        let mut out = Vec::new();
        let mut bad = BadMessages::default();
        let mut report = self.for_each_raw(&|c| c.topic == topic, |m| {
            let name = msgdef::normalize_type_name(m.channel.type_name());
            if name != T::TYPE_NAME {
                return Err(Error::LogTopic {
                    path: self.path.clone(),
                    topic: topic.to_string(),
                    message: format!("topic {topic} has type {name}, expected {}", T::TYPE_NAME),
                });
            }
            let dec = decoders.entry(Arc::as_ptr(m.channel)).or_insert_with(|| Decoder::for_channel(m.channel));
            let result = match dec {
                Decoder::Cdr { fast: true, .. } => cdr::CdrReader::new(m.data)
                    .and_then(|mut r| T::decode(&mut r))
                    .map_err(|e| format!("{} (at byte {})", e.message, e.offset)),
                Decoder::Cdr { fast: false, .. } => Err(format!(
                    "the file's definition of {} differs from the standard one; use \
                     for_each_value to read it generically",
                    T::TYPE_NAME
                )),
                Decoder::Json => Err("JSON is decoded for JointState only".into()),
                Decoder::Unsupported(why) => Err(format!("cannot decode: {why}")),
            };
            match result {
                Ok(v) => {
                    out.push((m.log_time_nanos, v));
                    Ok(())
                }
                Err(message) => bad.push(self, &m, message),
            }
        })?;
        self.check_topic(&report, topic)?;
        bad.into_report(&mut report);
        Ok((out, report))
    }

    /// Per-joint time series of a `sensor_msgs/msg/JointState` topic (CDR or JSON), merged
    /// over publishers by joint name. See [`JointStateSeries`].
    ///
    /// # Errors
    /// As [`Log::read_typed`].
    pub fn joint_states(&self, topic: &str) -> Result<JointStateSeries> {
        series::read_joint_states(self, topic)
    }

    /// Topics, types, counts, rates, time span and gaps.
    ///
    /// # Errors
    /// As [`Log::for_each_raw`].
    pub fn info(&self) -> Result<LogInfo> {
        info::log_info(self)
    }

    pub(crate) fn check_topic(&self, report: &ReadReport, topic: &str) -> Result<()> {
        let channels: Vec<&Arc<Channel>> = report.files.iter().flat_map(|(_, r)| &r.channels).collect();
        if channels.iter().any(|c| c.topic == topic) {
            return Ok(());
        }
        let mut topics: Vec<&str> = channels.iter().map(|c| c.topic.as_str()).collect();
        topics.sort_unstable();
        topics.dedup();
        Err(Error::LogTopic {
            path: self.path.clone(),
            topic: topic.to_string(),
            message: format!(
                "no topic {topic} in the log; topics: {}",
                if topics.is_empty() { "none".to_string() } else { topics.join(", ") }
            ),
        })
    }

    /// The options given to [`Log::open`].
    pub fn options(&self) -> ReadOptions {
        self.options
    }
}

/// Messages that did not decode: an error in strict mode, else counted into one warning.
#[derive(Default)]
pub(crate) struct BadMessages {
    count: u64,
    first: Option<String>,
}

impl BadMessages {
    pub(crate) fn push(&mut self, log: &Log, m: &RawMessage<'_>, message: String) -> Result<()> {
        let err = Error::Decode {
            path: log.path.clone(),
            topic: m.channel.topic.clone(),
            type_name: m.channel.type_name().to_string(),
            log_time_nanos: m.log_time_nanos,
            message,
        };
        if log.options.strict {
            return Err(err);
        }
        self.count += 1;
        self.first.get_or_insert_with(|| err.to_string());
        Ok(())
    }

    pub(crate) fn into_report(self, report: &mut ReadReport) {
        if let (Some(first), Some((path, last))) = (self.first, report.files.last_mut()) {
            last.damage.push(Damage {
                path: path.clone(),
                offset: 0,
                kind: DamageKind::CorruptRecord,
                lost_bytes: 0,
                lost_messages: Some(self.count),
                message: format!("{} messages could not be decoded, first: {first}", self.count),
            });
        }
    }
}

fn json_to_value(v: serde_json::Value) -> Value {
    match v {
        serde_json::Value::Null => Value::Float(f64::NAN),
        serde_json::Value::Bool(b) => Value::Bool(b),
        serde_json::Value::Number(n) => match (n.as_i64(), n.as_u64()) {
            (Some(i), _) => Value::Int(i),
            (None, Some(u)) => Value::UInt(u),
            _ => Value::Float(n.as_f64().unwrap_or(f64::NAN)),
        },
        serde_json::Value::String(s) => Value::String(s),
        serde_json::Value::Array(a) => Value::Array(a.into_iter().map(json_to_value).collect()),
        serde_json::Value::Object(o) => Value::Struct(o.into_iter().map(|(k, v)| (k, json_to_value(v))).collect()),
    }
}

/// The `.mcap` files of a rosbag2 folder, from `metadata.yaml`'s `relative_file_paths` (or every
/// `.mcap` in the folder, sorted, when there is no metadata).
fn bag_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let meta_path = dir.join("metadata.yaml");
    let mut files = Vec::new();
    if let Ok(meta) = std::fs::read_to_string(&meta_path) {
        if meta.contains("storage_identifier: sqlite3") {
            return Err(Error::LogFormat {
                path: dir.to_path_buf(),
                offset: None,
                message: "this bag is stored in sqlite3 (.db3); twin reads MCAP: convert it with \
                          `ros2 bag convert` to storage `mcap`, or record with `-s mcap`"
                    .into(),
            });
        }
        // The list is a YAML block sequence under `relative_file_paths:`.
        let mut in_list = false;
        for line in meta.lines() {
            let t = line.trim();
            if t.starts_with("relative_file_paths:") {
                in_list = true;
                continue;
            }
            if in_list {
                if let Some(item) = t.strip_prefix("- ") {
                    let item = item.trim().trim_matches(|c| c == '"' || c == '\'');
                    let p = dir.join(item);
                    if !p.is_file() {
                        return Err(Error::LogFormat {
                            path: meta_path.clone(),
                            offset: None,
                            message: format!("lists {item}, which is not in the folder (bag copied partly?)"),
                        });
                    }
                    files.push(p);
                } else if !t.is_empty() {
                    break;
                }
            }
        }
    }
    if files.is_empty() {
        let entries = std::fs::read_dir(dir).map_err(|source| Error::io(dir.to_path_buf(), source))?;
        files = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
            .collect();
        files.sort();
    }
    if files.is_empty() {
        return Err(Error::LogFormat {
            path: dir.to_path_buf(),
            offset: None,
            message: "folder has no .mcap file (is it a rosbag2 folder recorded with `-s mcap`?)".into(),
        });
    }
    Ok(files)
}

#[cfg(test)]
mod tests;
