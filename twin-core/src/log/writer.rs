//! Writes ROS 2 MCAP logs: profile `ros2`, one `ros2msg` schema per type with its full
//! definition, CDR messages, zstd-compressed chunks, `offered_qos_profiles` channel metadata,
//! and `twin/<version>` as library.
//!
//! Memory is bounded by one chunk: each chunk is built in memory and written whole once it
//! reaches [`WriterOptions::chunk_size_bytes`], so a run that is killed leaves a file whose
//! complete chunks [`super::Log`] recovers (only the chunk being filled is lost).
//! Encoding a message reuses one buffer: a simulation loop can call [`LogWriter::write`] every
//! step without allocating.

use super::cdr::CdrWriter;
use super::typed::{RosMessage, schema_text};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

/// Stamped in every MCAP header twin writes.
pub const LIBRARY_IDENTIFIER: &str = concat!("twin/", env!("CARGO_PKG_VERSION"));

/// The QoS rosbag2 records for an ordinary topic (reliable, volatile, keep-last).
const QOS_VOLATILE: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  \
deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    \
nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    \
nsec: 854775807\n  avoid_ros_namespace_conventions: false";

/// How to write.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// Uncompressed bytes after which a chunk is compressed and written; also the most a killed
    /// run can lose (default: 1 MiB).
    pub chunk_size_bytes: u64,
    /// Compress chunks with zstd (default: true).
    pub compress: bool,
    /// zstd level; low levels keep the cost per message small in a simulation loop
    /// (default: 1).
    pub zstd_level: u32,
    /// Keep an existing file at the path as `<name>.bak` instead of failing (default: true).
    pub backup_existing: bool,
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            chunk_size_bytes: 1 << 20,
            compress: true,
            zstd_level: 1,
            backup_existing: true,
        }
    }
}

/// A typed topic handle from [`LogWriter::add_topic`].
#[derive(Debug)]
pub struct Topic<T> {
    channel_id: u16,
    _type: PhantomData<fn(&T)>,
}

impl<T> Clone for Topic<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Topic<T> {}

/// What was written.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteSummary {
    /// Messages written.
    pub messages: u64,
    /// Chunks written.
    pub chunks: usize,
    /// File size, bytes.
    pub bytes: u64,
}

/// Streams messages into an MCAP file.
pub struct LogWriter {
    path: PathBuf,
    inner: Option<mcap::Writer<BufWriter<File>>>,
    cdr: CdrWriter,
    sequences: BTreeMap<u16, u32>,
    messages: u64,
}

impl std::fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

impl LogWriter {
    /// Creates the file (an existing one is kept as `<name>.bak`, see
    /// [`WriterOptions::backup_existing`]).
    ///
    /// # Errors
    /// [`Error::Io`] when the file cannot be created; [`Error::LogFormat`] when it exists and
    /// backups are off.
    pub fn create(path: impl AsRef<Path>, options: &WriterOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        if path.exists() {
            if !options.backup_existing {
                return Err(Error::LogFormat {
                    path,
                    offset: None,
                    message: "file exists; remove it or choose another name".into(),
                });
            }
            let mut backup = path.clone().into_os_string();
            backup.push(".bak");
            std::fs::rename(&path, &backup).map_err(|source| Error::Io {
                path: path.clone(),
                source,
            })?;
        }
        let file = File::create(&path).map_err(|source| Error::Io {
            path: path.clone(),
            source,
        })?;
        let opts = mcap::WriteOptions::new()
            .profile("ros2")
            .library(LIBRARY_IDENTIFIER)
            .compression(options.compress.then_some(mcap::Compression::Zstd))
            .compression_level(options.zstd_level)
            // One thread: output identical whatever the machine, no pool to start.
            .compression_threads(0)
            .chunk_size(Some(options.chunk_size_bytes))
            // Build each chunk in memory and write it whole: a killed run never leaves a
            // chunk with a placeholder header behind.
            .disable_seeking(true);
        let inner = opts
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|source| Error::McapWrite {
                path: path.clone(),
                source,
            })?;
        Ok(Self {
            path,
            inner: Some(inner),
            cdr: CdrWriter::new(),
            sequences: BTreeMap::new(),
            messages: 0,
        })
    }

    fn mcap_err(&self, source: mcap::McapError) -> Error {
        Error::McapWrite {
            path: self.path.clone(),
            source,
        }
    }

    fn inner(&mut self) -> &mut mcap::Writer<BufWriter<File>> {
        self.inner
            .as_mut()
            .expect("the writer is only taken by finish(self)")
    }

    /// Registers a topic of type `T` and returns its handle. Adding the same topic twice
    /// returns the same handle.
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written.
    pub fn add_topic<T: RosMessage>(&mut self, topic: &str) -> Result<Topic<T>> {
        let schema = schema_text(T::TYPE_NAME).expect("every RosMessage has a schema text");
        let mut metadata = BTreeMap::new();
        let qos = if topic == "/tf_static" {
            // Latched: durability transient-local, history keep-last 1.
            QOS_VOLATILE
                .replace("durability: 2", "durability: 1")
                .replace("history: 3\n  depth: 0", "history: 1\n  depth: 1")
        } else {
            QOS_VOLATILE.to_string()
        };
        metadata.insert("offered_qos_profiles".to_string(), qos);
        let w = self.inner();
        let schema_id = w.add_schema(T::TYPE_NAME, "ros2msg", schema.as_bytes());
        let channel_id = schema_id
            .and_then(|sid| w.add_channel(sid, topic, "cdr", &metadata))
            .map_err(|e| self.mcap_err(e))?;
        Ok(Topic {
            channel_id,
            _type: PhantomData,
        })
    }

    /// Writes one message, stamped `log_time_nanos` (also its publish time).
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written.
    pub fn write<T: RosMessage>(
        &mut self,
        topic: Topic<T>,
        log_time_nanos: u64,
        message: &T,
    ) -> Result<()> {
        self.cdr.reset();
        message.encode(&mut self.cdr);
        let seq = self.sequences.entry(topic.channel_id).or_insert(0);
        *seq = seq.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: topic.channel_id,
            sequence: *seq,
            log_time: log_time_nanos,
            publish_time: log_time_nanos,
        };
        let Self { inner, cdr, .. } = self;
        let w = inner
            .as_mut()
            .expect("the writer is only taken by finish(self)");
        w.write_to_known_channel(&header, cdr.bytes())
            .map_err(|e| self.mcap_err(e))?;
        self.messages += 1;
        Ok(())
    }

    /// Writes the chunk being filled now, so that a kill after this loses nothing before it.
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written.
    pub fn flush(&mut self) -> Result<()> {
        self.inner().flush().map_err(|e| self.mcap_err(e))
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.messages
    }

    /// Writes the last chunk and the summary (statistics, indexes) and closes the file.
    ///
    /// # Errors
    /// [`Error::McapWrite`] / [`Error::Io`] when the file cannot be written.
    pub fn finish(mut self) -> Result<WriteSummary> {
        let mut w = self
            .inner
            .take()
            .expect("the writer is only taken by finish(self)");
        let summary = w.finish().map_err(|e| self.mcap_err(e))?;
        let buf = w.into_inner();
        let file = buf.into_inner().map_err(|e| Error::Io {
            path: self.path.clone(),
            source: e.into_error(),
        })?;
        file.sync_all().map_err(|source| Error::Io {
            path: self.path.clone(),
            source,
        })?;
        let bytes = file
            .metadata()
            .map_err(|source| Error::Io {
                path: self.path.clone(),
                source,
            })?
            .len();
        Ok(WriteSummary {
            messages: self.messages,
            chunks: summary.chunk_indexes.len(),
            bytes,
        })
    }
}
