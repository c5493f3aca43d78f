//! Writes ROS 2 MCAP logs: profile `ros2`, one `ros2msg` schema per type with its full
//! definition, CDR messages, zstd-compressed chunks, `offered_qos_profiles` channel metadata,
//! and `twin/<version>` as library.
//!
//! Memory is bounded by one chunk: each chunk is built in memory and written whole once it
//! reaches [`WriterOptions::chunk_size_bytes`], so a run that is killed leaves a file whose
//! complete chunks [`super::Log`] recovers (only the chunk being filled is lost).
//! The caller's thread only encodes (into a reusable buffer, appended to a batch); compression
//! and I/O run on a writer thread that receives whole batches, so a simulation loop can call
//! [`LogWriter::write`] / [`LogWriter::write_with`] every step cheaply.

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

/// How chunks are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// No compression.
    None,
    /// zstd at the given level (1 = fastest).
    Zstd(i32),
    /// LZ4 frames: several times cheaper than zstd level 1, files ~1.5–2× larger.
    Lz4,
}

/// How to write.
#[derive(Debug, Clone, smart_default::SmartDefault)]
pub struct WriterOptions {
    /// Uncompressed bytes after which a chunk is compressed and written; also the most a killed
    /// run can lose (default: 1 MiB).
    #[default(1 << 20)]
    pub chunk_size_bytes: u64,
    /// Chunk compression (default: zstd level 1: cheap enough for a simulation loop).
    #[default(Compression::Zstd(1))]
    pub compression: Compression,
    /// Keep an existing file at the path as a numbered backup (`<name>.bak`, `.bak.1`, …, see
    /// [`twin_fsio::Backup::Numbered`]) instead of failing (default: true).
    #[default(true)]
    pub backup_existing: bool,
    /// Compress and write on a background thread; the caller only encodes (default: true).
    /// Either way the file's bytes are identical.
    #[default(true)]
    pub background: bool,
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

impl<T> Topic<T> {
    /// The MCAP channel id.
    pub fn channel_id(self) -> u16 {
        self.channel_id
    }
}

/// What was written.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriteSummary {
    /// Messages written.
    pub messages: u64,
    /// Chunks written.
    pub chunks: usize,
    /// File size, bytes.
    pub bytes: u64,
    /// Times the caller waited because the writer thread's queue was full (it could not keep
    /// up: compression and I/O slower than the messages came, or no free core).
    pub queue_full_waits: u64,
}

/// Encoded messages handed over together: one queue operation (and at most one wake-up of the
/// writer thread) per batch instead of per message.
#[derive(Default)]
struct Batch {
    /// Each message's header and the end of its bytes in `bytes`.
    headers: Vec<(mcap::records::MessageHeader, usize)>,
    bytes: Vec<u8>,
}

impl Batch {
    fn clear(&mut self) {
        self.headers.clear();
        self.bytes.clear();
    }
}

/// Bytes after which a batch is handed to the writer.
pub const BATCH_BYTES: usize = 64 * 1024;

/// Work for the writer.
enum Job {
    AddTopic {
        type_name: &'static str,
        schema: String,
        topic: String,
        metadata: BTreeMap<String, String>,
        reply: mpsc::Sender<Result<u16>>,
    },
    Batch(Batch),
    Flush(mpsc::Sender<Result<()>>),
}

/// The MCAP file and what writes into it (on the writer thread, or inline).
struct Sink {
    path: PathBuf,
    w: mcap::Writer<BufWriter<File>>,
    messages: u64,
}

impl Sink {
    fn err(&self, source: mcap::McapError) -> Error {
        Error::McapWrite { path: self.path.clone(), source }
    }

    fn add_topic(
        &mut self,
        type_name: &str,
        schema: &str,
        topic: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<u16> {
        let id = self
            .w
            .add_schema(type_name, "ros2msg", schema.as_bytes())
            .and_then(|sid| self.w.add_channel(sid, topic, "cdr", metadata));
        id.map_err(|e| self.err(e))
    }

    fn write_batch(&mut self, batch: &Batch) -> Result<()> {
        let mut start = 0;
        for (header, end) in &batch.headers {
            if let Err(e) = self.w.write_to_known_channel(header, &batch.bytes[start..*end]) {
                return Err(self.err(e));
            }
            start = *end;
            self.messages += 1;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        self.w.flush().map_err(|e| self.err(e))
    }

    fn finish(mut self) -> Result<WriteSummary> {
        let summary = self.w.finish().map_err(|e| Error::McapWrite { path: self.path.clone(), source: e })?;
        let path = self.path;
        let file = self.w.into_inner().into_inner().map_err(|e| Error::io(path.clone(), e.into_error()))?;
        let io = |source| Error::io(path.clone(), source);
        file.sync_all().map_err(io)?;
        let bytes = file.metadata().map_err(io)?.len();
        Ok(WriteSummary { messages: self.messages, chunks: summary.chunk_indexes.len(), bytes, queue_full_waits: 0 })
    }
}

fn writer_thread(mut sink: Sink, rx: mpsc::Receiver<Job>, recycle: mpsc::Sender<Batch>) -> Result<WriteSummary> {
    for job in rx {
        match job {
            Job::Batch(batch) => {
                sink.write_batch(&batch)?;
                let _ = recycle.send(batch); // the caller may be gone: nothing to do
            }
            Job::AddTopic { type_name, schema, topic, metadata, reply } => {
                let _ = reply.send(sink.add_topic(type_name, &schema, &topic, &metadata));
            }
            Job::Flush(reply) => {
                let _ = reply.send(sink.flush());
            }
        }
    }
    sink.finish()
}

/// Where batches go.
enum Backend {
    Thread {
        tx: Option<mpsc::SyncSender<Job>>,
        recycled: mpsc::Receiver<Batch>,
        thread: Option<std::thread::JoinHandle<Result<WriteSummary>>>,
    },
    Inline(Option<Box<Sink>>),
}

/// Streams messages into an MCAP file.
///
/// The calling thread encodes CDR into a reusable buffer and appends it to a batch; full
/// batches ([`BATCH_BYTES`]) go to the writer thread, which compresses and writes them (or,
/// with [`WriterOptions::background`] off, are written inline). At most [`QUEUE_BATCHES`]
/// batches wait in memory: a caller faster than the disk is slowed down, never made to buffer
/// without bound.
pub struct LogWriter {
    path: PathBuf,
    backend: Backend,
    batch: Batch,
    cdr: CdrWriter,
    sequences: Vec<u32>,
    messages: u64,
    queue_full_waits: u64,
}

/// Batches that may wait for the writer thread (each about [`BATCH_BYTES`]).
pub const QUEUE_BATCHES: usize = 16;

impl std::fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter").field("path", &self.path).field("messages", &self.messages).finish_non_exhaustive()
    }
}

impl LogWriter {
    /// Creates the file (an existing one is kept as a numbered `<name>.bak`, see
    /// [`WriterOptions::backup_existing`]) and starts the writer thread.
    ///
    /// # Errors
    /// [`Error::File`] when the file cannot be created; [`Error::LogFormat`] when it exists and
    /// backups are off.
    pub fn create(path: impl AsRef<Path>, options: &WriterOptions) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        // Not a folder or device; a symlink is written through, mode and hard links kept.
        let target = twin_fsio::check_output(&path, &[])?;
        if target.existing.is_some() {
            if !options.backup_existing {
                return Err(Error::LogFormat {
                    path,
                    offset: None,
                    message: "file exists; remove it or choose another name".into(),
                });
            }
            twin_fsio::backup_numbered(&target.resolved)?;
        }
        let file = File::create(&target.resolved).map_err(|source| Error::io(path.clone(), source))?;
        let (compression, level) = match options.compression {
            Compression::None => (None, 0),
            Compression::Zstd(level) => (Some(mcap::Compression::Zstd), level.max(1) as u32),
            Compression::Lz4 => (Some(mcap::Compression::Lz4), 0),
        };
        let opts = mcap::WriteOptions::new()
            .profile("ros2")
            .library(LIBRARY_IDENTIFIER)
            .compression(compression)
            .compression_level(level)
            // Single-threaded zstd: output identical whatever the machine.
            .compression_threads(0)
            .chunk_size(Some(options.chunk_size_bytes))
            // Build each chunk in memory and write it whole: a killed run never leaves a
            // chunk with a placeholder header behind.
            .disable_seeking(true);
        let inner = opts
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|source| Error::McapWrite { path: path.clone(), source })?;
        let sink = Sink { path: path.clone(), w: inner, messages: 0 };
        let backend = if options.background {
            let (tx, rx) = mpsc::sync_channel(QUEUE_BATCHES);
            let (recycle, recycled) = mpsc::channel();
            let thread = std::thread::Builder::new()
                .name("twin-mcap-writer".into())
                .spawn(move || writer_thread(sink, rx, recycle))
                .map_err(|source| Error::io(path.clone(), source))?;
            Backend::Thread { tx: Some(tx), recycled, thread: Some(thread) }
        } else {
            Backend::Inline(Some(Box::new(sink)))
        };
        Ok(Self {
            path,
            backend,
            batch: Batch::default(),
            cdr: CdrWriter::new(),
            sequences: Vec::new(),
            messages: 0,
            queue_full_waits: 0,
        })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The writer thread stopped (an I/O error): its error.
    fn thread_error(&mut self) -> Error {
        let gone = || std::io::Error::other("the MCAP writer stopped after an earlier error");
        match &mut self.backend {
            Backend::Thread { tx, thread, .. } => {
                *tx = None;
                match thread.take().map(std::thread::JoinHandle::join) {
                    Some(Ok(Err(e))) => e,
                    _ => Error::io(self.path.clone(), gone()),
                }
            }
            Backend::Inline(_) => Error::io(self.path.clone(), gone()),
        }
    }

    fn send(&mut self, job: Job) -> Result<()> {
        match &mut self.backend {
            Backend::Thread { tx: Some(tx), .. } => match tx.try_send(job) {
                Ok(()) => return Ok(()),
                Err(mpsc::TrySendError::Full(job)) => {
                    self.queue_full_waits += 1;
                    if tx.send(job).is_ok() {
                        return Ok(());
                    }
                }
                Err(mpsc::TrySendError::Disconnected(_)) => {}
            },
            Backend::Thread { tx: None, .. } => {}
            Backend::Inline(sink) => {
                let Some(s) = sink.as_mut() else {
                    return Err(Error::io(
                        self.path.clone(),
                        std::io::Error::other("the MCAP writer stopped after an earlier error"),
                    ));
                };
                let r = match job {
                    Job::Batch(b) => {
                        let r = s.write_batch(&b);
                        self.batch = b;
                        r
                    }
                    Job::AddTopic { type_name, schema, topic, metadata, reply } => {
                        let _ = reply.send(s.add_topic(type_name, &schema, &topic, &metadata));
                        Ok(())
                    }
                    Job::Flush(reply) => {
                        let _ = reply.send(s.flush());
                        Ok(())
                    }
                };
                if r.is_err() {
                    *sink = None;
                }
                return r;
            }
        }
        Err(self.thread_error())
    }

    /// Hands the current batch to the writer.
    fn send_batch(&mut self) -> Result<()> {
        if self.batch.headers.is_empty() {
            return Ok(());
        }
        let fresh = match &self.backend {
            Backend::Thread { recycled, .. } => recycled.try_recv().unwrap_or_default(),
            Backend::Inline(_) => Batch::default(),
        };
        let mut full = std::mem::replace(&mut self.batch, fresh);
        self.batch.clear();
        let r = self.send(Job::Batch(std::mem::take(&mut full)));
        if matches!(self.backend, Backend::Inline(_)) {
            // Inline: the written batch came back into self.batch; reuse its capacity.
            self.batch.clear();
        }
        r
    }

    /// Registers a topic of type `T` and returns its handle.
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written.
    pub fn add_topic<T: RosMessage>(&mut self, topic: &str) -> Result<Topic<T>> {
        let channel_id = self.add_topic_of_type(topic, T::TYPE_NAME)?;
        Ok(Topic { channel_id, _type: PhantomData })
    }

    /// Registers a topic of one of the typed message types (see [`RosMessage::TYPE_NAME`]) by
    /// name and returns its channel id, for messages that arrive already encoded (the live
    /// bridge's received commands).
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written or `type_name` has no schema text.
    pub fn add_topic_of_type(&mut self, topic: &str, type_name: &'static str) -> Result<u16> {
        let Some(schema) = schema_text(type_name) else {
            return Err(Error::McapWrite {
                path: self.path.clone(),
                source: mcap::McapError::UnknownSchema(topic.to_string(), 0),
            });
        };
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
        // Messages already batched keep their place before the new channel's.
        self.send_batch()?;
        let (reply, answer) = mpsc::channel();
        self.send(Job::AddTopic { type_name, schema, topic: topic.to_string(), metadata, reply })?;
        match answer.recv() {
            Ok(id) => id,
            Err(_) => Err(self.thread_error()),
        }
    }

    /// Writes one message, stamped `log_time_nanos` (also its publish time).
    ///
    /// # Errors
    /// [`Error::McapWrite`] / [`Error::File`] when the file cannot be written (reported by the
    /// first call after the writer met the error).
    pub fn write<T: RosMessage>(&mut self, topic: Topic<T>, log_time_nanos: u64, message: &T) -> Result<()> {
        self.write_with(topic, log_time_nanos, |w| message.encode(w))
    }

    /// Writes one message of `topic`'s type encoded by `encode`, which must write the fields of
    /// `T` in order (as `T::encode` does): lets a caller write straight from its own arrays
    /// without building a `T` (no name strings cloned per message).
    ///
    /// # Errors
    /// As [`LogWriter::write`].
    pub fn write_with<T: RosMessage>(
        &mut self,
        topic: Topic<T>,
        log_time_nanos: u64,
        encode: impl FnOnce(&mut CdrWriter),
    ) -> Result<()> {
        self.cdr.reset();
        encode(&mut self.cdr);
        let cdr = std::mem::take(&mut self.cdr);
        let r = self.write_encoded(topic.channel_id, log_time_nanos, cdr.bytes());
        self.cdr = cdr;
        r
    }

    /// Writes one already encoded message (CDR bytes, encapsulation header included) on the
    /// channel `channel_id` (from [`LogWriter::add_topic_of_type`] or [`Topic::channel_id`]).
    ///
    /// # Errors
    /// As [`LogWriter::write`].
    pub fn write_encoded(&mut self, channel_id: u16, log_time_nanos: u64, cdr: &[u8]) -> Result<()> {
        let id = usize::from(channel_id);
        if self.sequences.len() <= id {
            self.sequences.resize(id + 1, 0);
        }
        let seq = &mut self.sequences[id];
        *seq = seq.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: *seq,
            log_time: log_time_nanos,
            publish_time: log_time_nanos,
        };
        self.batch.bytes.extend_from_slice(cdr);
        self.batch.headers.push((header, self.batch.bytes.len()));
        self.messages += 1;
        if self.batch.bytes.len() >= BATCH_BYTES {
            self.send_batch()?;
        }
        Ok(())
    }

    /// Writes everything handed over so far, the chunk being filled included, so that a kill
    /// after this loses nothing before it.
    ///
    /// # Errors
    /// [`Error::McapWrite`] when the file cannot be written.
    pub fn flush(&mut self) -> Result<()> {
        self.send_batch()?;
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
    /// [`Error::McapWrite`] / [`Error::File`] when the file cannot be written.
    pub fn finish(mut self) -> Result<WriteSummary> {
        self.send_batch()?;
        let waits = self.queue_full_waits;
        self.close().map(|s| WriteSummary { queue_full_waits: waits, ..s })
    }

    fn close(&mut self) -> Result<WriteSummary> {
        let path = self.path.clone();
        let gone = |what: &str| Error::io(path.clone(), std::io::Error::other(what.to_string()));
        match &mut self.backend {
            Backend::Thread { tx, thread, .. } => {
                *tx = None;
                match thread.take().map(std::thread::JoinHandle::join) {
                    Some(Ok(r)) => r,
                    Some(Err(_)) => Err(gone("the MCAP writer thread panicked")),
                    None => Err(gone("the MCAP writer was already closed")),
                }
            }
            Backend::Inline(sink) => match sink.take() {
                Some(s) => s.finish(),
                None => Err(gone("the MCAP writer stopped after an earlier error")),
            },
        }
    }
}

impl Drop for LogWriter {
    /// Closes the file properly (summary included) when the writer is dropped without
    /// [`LogWriter::finish`], e.g. on an error path of the caller.
    fn drop(&mut self) {
        let already_closed = match &self.backend {
            Backend::Thread { thread, .. } => thread.is_none(),
            Backend::Inline(sink) => sink.is_none(),
        };
        if !already_closed {
            let _ = self.send_batch();
            let _ = self.close();
        }
    }
}
