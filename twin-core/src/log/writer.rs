//! Writes ROS 2 MCAP logs: profile `ros2`, one `ros2msg` schema per type with its full
//! definition, CDR messages, zstd-compressed chunks, `offered_qos_profiles` channel metadata,
//! and `twin/<version>` as library.
//!
//! Memory is bounded by one chunk: each chunk is built in memory and written whole once it
//! reaches [`WriterOptions::chunk_size_bytes`], so a run that is killed leaves a file whose
//! complete chunks [`super::Log`] recovers (only the chunk being filled is lost).
//! The caller's thread only encodes (into recycled buffers); compression and I/O run on a
//! writer thread, so a simulation loop can call [`LogWriter::write`] every step cheaply.

use super::cdr::CdrWriter;
use super::typed::{RosMessage, schema_text};
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::mpsc;

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
        Self { chunk_size_bytes: 1 << 20, compress: true, zstd_level: 1, backup_existing: true }
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

/// Work for the writer thread.
enum Job {
    AddTopic {
        type_name: &'static str,
        schema: String,
        topic: String,
        metadata: BTreeMap<String, String>,
        reply: mpsc::Sender<Result<u16>>,
    },
    Message {
        header: mcap::records::MessageHeader,
        bytes: Vec<u8>,
    },
    Flush(mpsc::Sender<Result<()>>),
}

/// Streams messages into an MCAP file.
///
/// The calling thread only encodes CDR into a recycled buffer and hands it over; compression
/// and file writes run on one writer thread, so a simulation loop pays a few hundred
/// nanoseconds per message. At most [`QUEUE_MESSAGES`] messages wait in memory: a caller
/// faster than the disk is slowed down, never made to buffer without bound.
pub struct LogWriter {
    path: PathBuf,
    tx: Option<mpsc::SyncSender<Job>>,
    recycled: mpsc::Receiver<Vec<u8>>,
    thread: Option<std::thread::JoinHandle<Result<WriteSummary>>>,
    cdr: CdrWriter,
    sequences: BTreeMap<u16, u32>,
    messages: u64,
}

/// Messages that may wait for the writer thread.
pub const QUEUE_MESSAGES: usize = 4096;

impl std::fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter").field("path", &self.path).field("messages", &self.messages).finish_non_exhaustive()
    }
}

fn writer_thread(
    path: PathBuf,
    mut w: mcap::Writer<BufWriter<File>>,
    rx: mpsc::Receiver<Job>,
    recycle: mpsc::Sender<Vec<u8>>,
) -> Result<WriteSummary> {
    let err = |source| Error::McapWrite { path: path.clone(), source };
    let mut messages = 0u64;
    for job in rx {
        match job {
            Job::Message { header, bytes } => {
                w.write_to_known_channel(&header, &bytes).map_err(err)?;
                messages += 1;
                let _ = recycle.send(bytes); // the caller may be gone: nothing to do
            }
            Job::AddTopic { type_name, schema, topic, metadata, reply } => {
                let id = w
                    .add_schema(type_name, "ros2msg", schema.as_bytes())
                    .and_then(|sid| w.add_channel(sid, &topic, "cdr", &metadata))
                    .map_err(err);
                let _ = reply.send(id);
            }
            Job::Flush(reply) => {
                let _ = reply.send(w.flush().map_err(err));
            }
        }
    }
    let summary = w.finish().map_err(err)?;
    let file = w.into_inner().into_inner().map_err(|e| Error::Io { path: path.clone(), source: e.into_error() })?;
    let io = |source| Error::Io { path: path.clone(), source };
    file.sync_all().map_err(io)?;
    let bytes = file.metadata().map_err(io)?.len();
    Ok(WriteSummary { messages, chunks: summary.chunk_indexes.len(), bytes })
}

impl LogWriter {
    /// Creates the file (an existing one is kept as `<name>.bak`, see
    /// [`WriterOptions::backup_existing`]) and starts the writer thread.
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
            std::fs::rename(&path, &backup).map_err(|source| Error::Io { path: path.clone(), source })?;
        }
        let file = File::create(&path).map_err(|source| Error::Io { path: path.clone(), source })?;
        let opts = mcap::WriteOptions::new()
            .profile("ros2")
            .library(LIBRARY_IDENTIFIER)
            .compression(options.compress.then_some(mcap::Compression::Zstd))
            .compression_level(options.zstd_level)
            // Single-threaded zstd: output identical whatever the machine.
            .compression_threads(0)
            .chunk_size(Some(options.chunk_size_bytes))
            // Build each chunk in memory and write it whole: a killed run never leaves a
            // chunk with a placeholder header behind.
            .disable_seeking(true);
        let inner = opts
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|source| Error::McapWrite { path: path.clone(), source })?;
        let (tx, rx) = mpsc::sync_channel(QUEUE_MESSAGES);
        let (recycle, recycled) = mpsc::channel();
        let thread_path = path.clone();
        let thread = std::thread::Builder::new()
            .name("twin-mcap-writer".into())
            .spawn(move || writer_thread(thread_path, inner, rx, recycle))
            .map_err(|source| Error::Io { path: path.clone(), source })?;
        Ok(Self {
            path,
            tx: Some(tx),
            recycled,
            thread: Some(thread),
            cdr: CdrWriter::new(),
            sequences: BTreeMap::new(),
            messages: 0,
        })
    }

    /// The writer thread stopped (an I/O error): its error.
    fn thread_error(&mut self) -> Error {
        self.tx = None;
        match self.thread.take().map(std::thread::JoinHandle::join) {
            Some(Ok(Err(e))) => e,
            _ => Error::Io { path: self.path.clone(), source: std::io::Error::other("the MCAP writer thread stopped") },
        }
    }

    fn send(&mut self, job: Job) -> Result<()> {
        match &self.tx {
            Some(tx) if tx.send(job).is_ok() => Ok(()),
            _ => Err(self.thread_error()),
        }
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
        let (reply, answer) = mpsc::channel();
        self.send(Job::AddTopic { type_name: T::TYPE_NAME, schema, topic: topic.to_string(), metadata, reply })?;
        let channel_id = match answer.recv() {
            Ok(id) => id?,
            Err(_) => return Err(self.thread_error()),
        };
        Ok(Topic { channel_id, _type: PhantomData })
    }

    /// Writes one message, stamped `log_time_nanos` (also its publish time).
    ///
    /// # Errors
    /// [`Error::McapWrite`] / [`Error::Io`] when the file cannot be written (reported by the
    /// first call after the writer thread met the error).
    pub fn write<T: RosMessage>(&mut self, topic: Topic<T>, log_time_nanos: u64, message: &T) -> Result<()> {
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
        let mut bytes = self.recycled.try_recv().unwrap_or_default();
        bytes.clear();
        bytes.extend_from_slice(self.cdr.bytes());
        self.send(Job::Message { header, bytes })?;
        self.messages += 1;
        Ok(())
    }

    /// Writes the chunk being filled now, so that a kill after this loses nothing before it.
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written.
    pub fn flush(&mut self) -> Result<()> {
        let (reply, answer) = mpsc::channel();
        self.send(Job::Flush(reply))?;
        match answer.recv() {
            Ok(r) => r,
            Err(_) => Err(self.thread_error()),
        }
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
        self.tx = None;
        match self.thread.take().map(std::thread::JoinHandle::join) {
            Some(Ok(r)) => r,
            _ => Err(Error::Io {
                path: self.path.clone(),
                source: std::io::Error::other("the MCAP writer thread panicked"),
            }),
        }
    }
}

impl Drop for LogWriter {
    /// Closes the file properly (summary included) when the writer is dropped without
    /// [`LogWriter::finish`], e.g. on an error path of the caller.
    fn drop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
