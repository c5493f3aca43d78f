//! Walks an MCAP file record by record, streaming (memory bounded by the largest chunk), and
//! survives damage: a file cut off mid-write yields every message of its complete records and
//! chunks; a chunk whose CRC or compression is broken is reported with its offset and skipped
//! (or refused with [`ReadOptions::strict`]).
//!
//! The mcap crate parses each record body ([`mcap::parse_record`]); framing, chunk
//! decompression and CRC checks are done here so that one bad record never stops the walk.

use super::ReadOptions;
use crate::{Error, Result};
use mcap::records::{Record, op};
use std::collections::BTreeMap;
use std::fmt;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The 8 bytes at the start and end of every MCAP file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// A partial chunk's log-time range and (messages, uncompressed bytes) recovered from it.
type Salvage = Option<(u64, u64, (u64, usize))>;

/// Chunks claiming more than this uncompressed are treated as corrupt rather than allocated.
const MAX_CHUNK_BYTES: u64 = 1 << 31;

/// A schema record.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    /// Schema id in the file.
    pub id: u16,
    /// Message type, e.g. `sensor_msgs/msg/JointState`.
    pub name: String,
    /// `ros2msg`, `jsonschema`, …
    pub encoding: String,
    /// The schema text.
    pub data: Vec<u8>,
}

/// A channel record, linked to its schema.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Channel id in the file.
    pub id: u16,
    /// Topic name.
    pub topic: String,
    /// `cdr`, `json`, …
    pub message_encoding: String,
    /// Channel metadata (`offered_qos_profiles` for ROS 2).
    pub metadata: BTreeMap<String, String>,
    /// The schema, `None` for schemaless channels.
    pub schema: Option<Arc<Schema>>,
}

impl Channel {
    /// The message type name, or `""` for schemaless channels.
    pub fn type_name(&self) -> &str {
        self.schema.as_ref().map_or("", |s| s.name.as_str())
    }
}

/// One message, borrowed from the reader's buffers.
#[derive(Debug, Clone, Copy)]
pub struct RawMessage<'a> {
    /// Its channel.
    pub channel: &'a Arc<Channel>,
    /// Publisher sequence number (0 when the writer does not set it).
    pub sequence: u32,
    /// When the recorder received it.
    pub log_time_nanos: u64,
    /// When it was published (often equal to the log time).
    pub publish_time_nanos: u64,
    /// The serialized message (CDR with its 4-byte header, JSON, …).
    pub data: &'a [u8],
}

/// What kind of damage a file has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DamageKind {
    /// The file ends in the middle of a record or without its summary: the recording was cut.
    Truncated,
    /// A chunk's CRC does not match, or it does not decompress: its messages are skipped.
    CorruptChunk,
    /// A record could not be parsed; it is skipped.
    CorruptRecord,
    /// Messages refer to a channel whose record was lost; they are skipped.
    UnknownChannel,
}

/// One piece of damage found while reading.
#[derive(Debug, Clone, PartialEq)]
pub struct Damage {
    /// The file.
    pub path: PathBuf,
    /// Byte offset of the damaged record.
    pub offset: u64,
    /// What kind.
    pub kind: DamageKind,
    /// Bytes of the file that could not be used (for a cut chunk some of whose messages were
    /// salvaged: the bytes missing from it).
    pub lost_bytes: u64,
    /// Messages lost, when the file says (message indexes after a chunk, statistics).
    pub lost_messages: Option<u64>,
    /// Human-readable details.
    pub message: String,
}

impl fmt::Display for Damage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (byte {}): {}", self.path.display(), self.offset, self.message)?;
        write!(f, "; {} bytes lost", self.lost_bytes)?;
        match self.lost_messages {
            Some(n) => write!(f, ", {n} messages lost"),
            None => Ok(()),
        }
    }
}

/// What a walk over one file found.
#[derive(Debug, Clone, Default)]
pub struct ScanReport {
    /// Messages handed to the callback (after topic filtering).
    pub messages_delivered: u64,
    /// Messages seen in all channels.
    pub messages_seen: u64,
    /// Chunks read.
    pub chunks: u64,
    /// Header profile (`ros2` for ROS 2 bags).
    pub profile: String,
    /// Header library (`rosbag2`, `twin/0.1.0`, …).
    pub library: String,
    /// Whether the file has a readable summary section (a cleanly closed recording).
    pub has_summary: bool,
    /// The total message count the file's statistics record claims, if it has one.
    pub statistics_message_count: Option<u64>,
    /// Every damage found, in file order.
    pub damage: Vec<Damage>,
    /// Every channel found.
    pub channels: Vec<Arc<Channel>>,
}

struct ChannelSlot {
    channel: Arc<Channel>,
    wanted: bool,
}

/// Streams the records of one `.mcap` file.
pub(crate) struct Scanner<'f> {
    path: PathBuf,
    options: ReadOptions,
    wanted: &'f dyn Fn(&Channel) -> bool,
    schemas: BTreeMap<u16, Arc<Schema>>,
    channels: Vec<Option<ChannelSlot>>,
    report: ScanReport,
    zstd: Option<zstd::bulk::Decompressor<'static>>,
    chunk_buf: Vec<u8>,
    orphans: BTreeMap<u16, (u64, u64)>,
}

fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

impl<'f> Scanner<'f> {
    pub(crate) fn new(path: &Path, options: ReadOptions, wanted: &'f dyn Fn(&Channel) -> bool) -> Self {
        Self {
            path: path.to_path_buf(),
            options,
            wanted,
            schemas: BTreeMap::new(),
            channels: Vec::new(),
            report: ScanReport::default(),
            zstd: None,
            chunk_buf: Vec::new(),
            orphans: BTreeMap::new(),
        }
    }

    fn io(&self, source: std::io::Error) -> Error {
        Error::io(self.path.clone(), source)
    }

    fn format_err(&self, offset: Option<u64>, message: String) -> Error {
        Error::LogFormat { path: self.path.clone(), offset, message }
    }

    /// Records damage; in strict mode it becomes the error.
    fn damage(&mut self, d: Damage) -> Result<()> {
        if self.options.strict {
            return Err(Error::LogFormat {
                path: d.path.clone(),
                offset: Some(d.offset),
                message: format!("{} (strict reading refuses damaged files; drop --strict to skip it)", d.message),
            });
        }
        self.report.damage.push(d);
        Ok(())
    }

    /// Walks the whole file, calling `f` for every message of a wanted channel.
    pub(crate) fn run(mut self, f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>) -> Result<ScanReport> {
        let file = twin_fsio::open(&self.path)?;
        let file_len = file.metadata().map_err(|e| self.io(e))?.len();
        let mut r = BufReader::with_capacity(1 << 20, file);
        let mut magic = [0u8; 8];
        let n = read_up_to(&mut r, &mut magic).map_err(|e| self.io(e))?;
        if n < 8 || &magic != MAGIC {
            return Err(self.format_err(
                None,
                "not an MCAP file (the first 8 bytes are not the MCAP magic); give a .mcap \
                 file or a rosbag2 folder recorded with `-s mcap`"
                    .into(),
            ));
        }
        self.read_summary(&mut r, file_len)?;
        r.seek(SeekFrom::Start(8)).map_err(|e| self.io(e))?;

        let mut offset = 8u64;
        let mut body = Vec::new();
        let mut clean_end = false;
        // The chunk whose damage the following message-index records count.
        let mut counting_lost: Option<usize> = None;
        loop {
            let mut head = [0u8; 9];
            let got = read_up_to(&mut r, &mut head).map_err(|e| self.io(e))?;
            if got == 0 {
                break;
            }
            if got < 9 {
                self.damage(Damage {
                    path: self.path.clone(),
                    offset,
                    kind: DamageKind::Truncated,
                    lost_bytes: got as u64,
                    lost_messages: None,
                    message: format!("file cut off inside a record header ({got} of 9 bytes present)"),
                })?;
                break;
            }
            let opcode = head[0];
            let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
            let available = file_len - offset - 9;
            if len > available {
                self.truncated_record(&mut r, offset, opcode, len, available, &mut body, f)?;
                break;
            }
            body.resize(len as usize, 0);
            r.read_exact(&mut body).map_err(|e| self.io(e))?;
            let record_offset = offset;
            offset += 9 + len;

            if opcode != op::MESSAGE_INDEX {
                counting_lost = None;
            }
            match opcode {
                op::DATA_END | op::FOOTER => {
                    // Closed cleanly only if the summary, footer and end magic are whole too.
                    let tail_from = if opcode == op::FOOTER { record_offset } else { offset };
                    clean_end = true;
                    self.check_tail(&mut r, tail_from, file_len)?;
                    break;
                }
                op::CHUNK => {
                    if !self.chunk(record_offset, &body, f)? {
                        counting_lost = Some(self.report.damage.len().wrapping_sub(1));
                    }
                }
                op::MESSAGE_INDEX => {
                    if let Some(i) = counting_lost
                        && let Ok(Record::MessageIndex(idx)) = mcap::parse_record(opcode, &body)
                        && let Some(d) = self.report.damage.get_mut(i)
                    {
                        *d.lost_messages.get_or_insert(0) += idx.records.len() as u64;
                        d.message = d.message.replace(
                            "its messages are skipped",
                            "its messages (counted by the message index) are skipped",
                        );
                    }
                }
                _ => self.record(record_offset, opcode, &body, 0, f)?,
            }
        }
        if !clean_end && self.report.damage.iter().all(|d| d.kind != DamageKind::Truncated) {
            self.damage(Damage {
                path: self.path.clone(),
                offset,
                kind: DamageKind::Truncated,
                lost_bytes: 0,
                lost_messages: None,
                message: "file ends without its data-end record and summary: the recording was \
                          cut off (after a complete record; nothing after it is known)"
                    .into(),
            })?;
        }
        for (id, (count, first_offset)) in std::mem::take(&mut self.orphans) {
            self.damage(Damage {
                path: self.path.clone(),
                offset: first_offset,
                kind: DamageKind::UnknownChannel,
                lost_bytes: 0,
                lost_messages: Some(count),
                message: format!("{count} messages on channel id {id}, whose channel record was lost, are skipped"),
            })?;
        }
        self.report.channels = self.channels.into_iter().flatten().map(|s| s.channel).collect();
        Ok(self.report)
    }

    /// A record that runs past the end of the file: the recording was cut during it. For a
    /// chunk, the complete messages at the start of its partial compressed stream are
    /// salvaged (zstd and lz4 decode block by block; uncompressed chunks record by record).
    #[allow(clippy::too_many_arguments)]
    fn truncated_record(
        &mut self,
        r: &mut BufReader<File>,
        offset: u64,
        opcode: u8,
        len: u64,
        available: u64,
        body: &mut Vec<u8>,
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>,
    ) -> Result<()> {
        let mut message = if len == u64::MAX {
            format!(
                "file cut off inside a chunk that was being written ({available} bytes of it \
                 present)"
            )
        } else {
            format!(
                "file cut off inside a record (opcode 0x{opcode:02x}) of {len} bytes, {available} \
                 present"
            )
        };
        let mut lost_bytes = available + 9;
        if opcode == op::CHUNK && available <= MAX_CHUNK_BYTES {
            body.resize(available as usize, 0);
            let n = read_up_to(r, body).map_err(|e| self.io(e))?;
            body.truncate(n);
            if let Some((start, end, salvaged)) = self.salvage_chunk(offset, body, f)? {
                if len != u64::MAX {
                    message = format!(
                        "file cut off inside a chunk of {len} bytes ({available} present), \
                         holding messages with log times {start}..={end} ns"
                    );
                }
                message.push_str(&format!(
                    "; {} complete messages ({} bytes uncompressed) recovered from it, the rest \
                     of it is lost",
                    salvaged.0, salvaged.1
                ));
                if salvaged.0 > 0 {
                    lost_bytes = len.saturating_sub(available).min(lost_bytes);
                    if len == u64::MAX {
                        lost_bytes = 0;
                    }
                }
            }
        }
        self.damage(Damage {
            path: self.path.clone(),
            offset,
            kind: DamageKind::Truncated,
            lost_bytes,
            lost_messages: None,
            message,
        })
    }

    /// Decodes what it can of a partial chunk record body. Returns the chunk's log-time range
    /// and (messages, uncompressed bytes) recovered, or `None` if even its header is cut.
    fn salvage_chunk(
        &mut self,
        offset: u64,
        body: &[u8],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>,
    ) -> Result<Salvage> {
        let u64_at = |p: usize| body.get(p..p + 8).map(|b| u64::from_le_bytes(b.try_into().expect("8")));
        let (Some(start), Some(end)) = (u64_at(0), u64_at(8)) else {
            return Ok(None);
        };
        let Some(name_len) = body.get(28..32).map(|b| u32::from_le_bytes(b.try_into().expect("4")) as usize) else {
            return Ok(None);
        };
        let data_at = 32 + name_len + 8;
        if body.len() < data_at {
            return Ok(None);
        }
        let compression = String::from_utf8_lossy(&body[32..32 + name_len]).into_owned();
        let data = &body[data_at..];
        let mut out = Vec::new();
        let mut pull = |mut rd: Box<dyn Read + '_>| {
            // Keep every block that decodes; the cut one ends the stream with an error.
            let mut buf = vec![0u8; 1 << 16];
            while let Ok(n) = rd.read(&mut buf) {
                if n == 0 || out.len() as u64 > MAX_CHUNK_BYTES {
                    break;
                }
                out.extend_from_slice(&buf[..n]);
            }
        };
        match compression.as_str() {
            "" => out.extend_from_slice(data),
            "zstd" => {
                if let Ok(d) = zstd::stream::read::Decoder::new(data) {
                    pull(Box::new(d));
                }
            }
            "lz4" => {
                if let Ok(d) = lz4::Decoder::new(data) {
                    pull(Box::new(d));
                }
            }
            _ => return Ok(Some((start, end, (0, 0)))),
        }
        let before = self.report.messages_seen;
        // Only whole records are used; the partial one at the end is dropped.
        let mut pos = 0usize;
        while out.len() - pos >= 9 {
            let opcode = out[pos];
            let len = u64::from_le_bytes(out[pos + 1..pos + 9].try_into().expect("8"));
            if len > (out.len() - pos - 9) as u64 {
                break;
            }
            let rec_end = pos + 9 + len as usize;
            self.record(offset, opcode, &out[pos + 9..rec_end], pos as u64 + 1, f)?;
            pos = rec_end;
        }
        Ok(Some((start, end, (self.report.messages_seen - before, pos))))
    }

    /// Returns `false` when the chunk was damaged and skipped.
    fn chunk(&mut self, offset: u64, body: &[u8], f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>) -> Result<bool> {
        self.report.chunks += 1;
        let lost_bytes = body.len() as u64 + 9;
        let corrupt = |message: String| Damage {
            path: self.path.clone(),
            offset,
            kind: DamageKind::CorruptChunk,
            lost_bytes,
            lost_messages: None,
            message,
        };
        let (header, data) = match mcap::parse_record(op::CHUNK, body) {
            Ok(Record::Chunk { header, data }) => (header, data),
            Ok(_) => unreachable!("parse_record(CHUNK) returns a chunk"),
            Err(e) => {
                let d = corrupt(format!("chunk header is corrupt ({e}); its messages are skipped"));
                self.damage(d)?;
                return Ok(false);
            }
        };
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            let d = corrupt(format!(
                "chunk claims {} bytes uncompressed (corrupt header); its messages are skipped",
                header.uncompressed_size
            ));
            self.damage(d)?;
            return Ok(false);
        }
        let mut buf = std::mem::take(&mut self.chunk_buf);
        buf.clear();
        let decompressed: std::result::Result<(), String> = match header.compression.as_str() {
            "" => {
                buf.extend_from_slice(&data);
                Ok(())
            }
            "zstd" => {
                buf.reserve(header.uncompressed_size as usize);
                let dec = match &mut self.zstd {
                    Some(d) => Ok(d),
                    None => zstd::bulk::Decompressor::new().map(|d| self.zstd.insert(d)).map_err(|e| e.to_string()),
                };
                dec.and_then(|d| {
                    d.decompress_to_buffer(&data[..], &mut buf).map(|_| ()).map_err(|e| format!("zstd: {e}"))
                })
            }
            "lz4" => {
                buf.reserve(header.uncompressed_size as usize);
                lz4::Decoder::new(&data[..])
                    .and_then(|mut d| d.read_to_end(&mut buf))
                    .map(|_| ())
                    .map_err(|e| format!("lz4: {e}"))
            }
            other => Err(format!("unsupported compression `{other}`")),
        };
        let problem = match decompressed {
            Err(e) => Some(format!("chunk does not decompress ({e})")),
            Ok(()) if buf.len() as u64 != header.uncompressed_size => {
                Some(format!("chunk decompresses to {} bytes, header says {}", buf.len(), header.uncompressed_size))
            }
            Ok(()) => {
                let crc = crc32fast::hash(&buf);
                (header.uncompressed_crc != 0 && crc != header.uncompressed_crc)
                    .then(|| format!("chunk CRC mismatch (stored {:08x}, computed {crc:08x})", header.uncompressed_crc))
            }
        };
        if let Some(p) = problem {
            self.chunk_buf = buf;
            self.damage(corrupt(format!("{p}; its messages are skipped")))?;
            return Ok(false);
        }
        let result = self.inner_records(offset, &buf, f);
        self.chunk_buf = buf;
        result.map(|()| true)
    }

    fn inner_records(
        &mut self,
        chunk_offset: u64,
        buf: &[u8],
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>,
    ) -> Result<()> {
        let mut pos = 0usize;
        while pos < buf.len() {
            if buf.len() - pos < 9 {
                break;
            }
            let opcode = buf[pos];
            let len = u64::from_le_bytes(buf[pos + 1..pos + 9].try_into().expect("8"));
            let start = pos + 9;
            if len > (buf.len() - start) as u64 {
                // The CRC passed (or was absent), so the writer produced this: report it.
                self.damage(Damage {
                    path: self.path.clone(),
                    offset: chunk_offset,
                    kind: DamageKind::CorruptRecord,
                    lost_bytes: (buf.len() - pos) as u64,
                    lost_messages: None,
                    message: format!(
                        "record at byte {pos} inside the chunk claims {len} bytes, past the \
                         chunk's end; the rest of the chunk is skipped"
                    ),
                })?;
                return Ok(());
            }
            let end = start + len as usize;
            self.record(chunk_offset, opcode, &buf[start..end], pos as u64 + 1, f)?;
            pos = end;
        }
        Ok(())
    }

    /// One record outside (`in_chunk == 0`) or inside a chunk (`in_chunk` = position + 1).
    fn record(
        &mut self,
        offset: u64,
        opcode: u8,
        body: &[u8],
        in_chunk: u64,
        f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>,
    ) -> Result<()> {
        if opcode == op::MESSAGE {
            return self.message(offset, body, f);
        }
        if !matches!(opcode, op::HEADER | op::SCHEMA | op::CHANNEL) {
            return Ok(());
        }
        let record = match mcap::parse_record(opcode, body) {
            Ok(r) => r,
            Err(e) => {
                let where_ = if in_chunk > 0 {
                    format!(" inside the chunk (at its byte {})", in_chunk - 1)
                } else {
                    String::new()
                };
                return self.damage(Damage {
                    path: self.path.clone(),
                    offset,
                    kind: DamageKind::CorruptRecord,
                    lost_bytes: body.len() as u64 + 9,
                    lost_messages: None,
                    message: format!("record (opcode 0x{opcode:02x}){where_} is corrupt: {e}"),
                });
            }
        };
        match record {
            Record::Header(h) => {
                self.report.profile = h.profile;
                self.report.library = h.library;
            }
            Record::Schema { header, data } => {
                self.add_schema(Schema {
                    id: header.id,
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                });
            }
            Record::Channel(c) => self.add_channel(c),
            _ => {}
        }
        Ok(())
    }

    fn add_schema(&mut self, s: Schema) {
        self.schemas.entry(s.id).or_insert_with(|| Arc::new(s));
    }

    fn add_channel(&mut self, c: mcap::records::Channel) {
        let id = c.id as usize;
        if self.channels.len() <= id {
            self.channels.resize_with(id + 1, || None);
        }
        if self.channels[id].is_some() {
            return;
        }
        let channel = Arc::new(Channel {
            id: c.id,
            topic: c.topic,
            message_encoding: c.message_encoding,
            metadata: c.metadata,
            schema: self.schemas.get(&c.schema_id).cloned(),
        });
        let wanted = (self.wanted)(&channel);
        self.channels[id] = Some(ChannelSlot { channel, wanted });
    }

    #[inline]
    fn message(&mut self, offset: u64, body: &[u8], f: &mut dyn FnMut(RawMessage<'_>) -> Result<()>) -> Result<()> {
        // channel_id u16, sequence u32, log_time u64, publish_time u64, data.
        if body.len() < 22 {
            return self.damage(Damage {
                path: self.path.clone(),
                offset,
                kind: DamageKind::CorruptRecord,
                lost_bytes: body.len() as u64 + 9,
                lost_messages: Some(1),
                message: "message record shorter than its 22-byte header".into(),
            });
        }
        let channel_id = u16::from_le_bytes([body[0], body[1]]);
        self.report.messages_seen += 1;
        let Some(Some(slot)) = self.channels.get(channel_id as usize) else {
            self.orphans.entry(channel_id).or_insert((0, offset)).0 += 1;
            return Ok(());
        };
        if !slot.wanted {
            return Ok(());
        }
        let msg = RawMessage {
            channel: &slot.channel,
            sequence: u32::from_le_bytes(body[2..6].try_into().expect("4")),
            log_time_nanos: u64::from_le_bytes(body[6..14].try_into().expect("8")),
            publish_time_nanos: u64::from_le_bytes(body[14..22].try_into().expect("8")),
            data: &body[22..],
        };
        self.report.messages_delivered += 1;
        f(msg)
    }

    /// Checks what follows the data section (from `offset`, the byte after the data-end record,
    /// or a footer record met in the data section): whole summary records, then the footer
    /// whose offsets point into them and whose CRC matches, then the end magic, exactly to the
    /// end of the file. A file cut anywhere in there was not closed cleanly: every message is
    /// intact, but a strict reader must not call it complete.
    fn check_tail(&mut self, r: &mut BufReader<File>, offset: u64, file_len: u64) -> Result<()> {
        let Some(problem) = self.tail_problem(r, offset, file_len)? else { return Ok(()) };
        self.damage(Damage {
            path: self.path.clone(),
            offset,
            kind: DamageKind::Truncated,
            lost_bytes: 0,
            lost_messages: Some(0),
            message: format!("{problem}: the recording was not closed cleanly (every message before it is intact)"),
        })
    }

    fn tail_problem(&mut self, r: &mut BufReader<File>, offset: u64, file_len: u64) -> Result<Option<String>> {
        r.seek(SeekFrom::Start(offset)).map_err(|e| self.io(e))?;
        let mut tail = Vec::new();
        r.read_to_end(&mut tail).map_err(|e| self.io(e))?;
        if tail.len() as u64 != file_len - offset {
            return Ok(Some("the file changed while it was read".into()));
        }
        // Record starts inside the tail (file offsets), for the footer's pointers.
        let mut starts = Vec::new();
        let mut pos = 0usize;
        loop {
            let at = offset + pos as u64;
            if pos == tail.len() {
                return Ok(Some(format!("the file ends at byte {at}, without its footer and end magic")));
            }
            if tail.len() - pos < 9 {
                return Ok(Some(format!("the file is cut inside a summary or footer record header at byte {at}")));
            }
            let opcode = tail[pos];
            let len = u64::from_le_bytes(tail[pos + 1..pos + 9].try_into().expect("8"));
            if len > (tail.len() - pos - 9) as u64 {
                let what = if opcode == op::FOOTER { "footer" } else { "summary section" };
                return Ok(Some(format!("the file is cut inside its {what} (record at byte {at})")));
            }
            starts.push(at);
            let body = &tail[pos + 9..pos + 9 + len as usize];
            pos += 9 + len as usize;
            if opcode != op::FOOTER {
                continue;
            }
            if len != 20 {
                return Ok(Some(format!("the footer at byte {at} has {len} bytes instead of 20")));
            }
            let rest = &tail[pos..];
            if rest.len() < MAGIC.len() {
                return Ok(Some(format!("the file is cut inside its end magic ({} of 8 bytes)", rest.len())));
            }
            if rest[..8] != MAGIC[..] {
                return Ok(Some("the file does not end with the MCAP magic after its footer".into()));
            }
            if rest.len() > 8 {
                return Ok(Some(format!("{} bytes follow the end magic", rest.len() - 8)));
            }
            let summary_start = u64::from_le_bytes(body[0..8].try_into().expect("8"));
            let summary_offset_start = u64::from_le_bytes(body[8..16].try_into().expect("8"));
            let crc = u32::from_le_bytes(body[16..20].try_into().expect("4"));
            for (name, p) in [("summary", summary_start), ("summary offset", summary_offset_start)] {
                if p != 0 && !starts.contains(&p) {
                    return Ok(Some(format!("the footer's {name} start {p} is not a record after the data section")));
                }
            }
            if summary_start != 0 && crc != 0 {
                // CRC of the summary section up to the footer's summary_offset_start field.
                let from = (summary_start - offset) as usize;
                let to = pos - 4;
                let calculated = crc32fast::hash(&tail[from..to]);
                if calculated != crc {
                    return Ok(Some(format!(
                        "the summary section's CRC does not match (saved {crc:#010x}, calculated {calculated:#010x})"
                    )));
                }
            }
            return Ok(None);
        }
    }

    /// Reads schemas, channels and statistics from the summary section when the file has one,
    /// so that messages stay decodable even if the chunk holding their channel record is lost.
    fn read_summary(&mut self, r: &mut BufReader<File>, file_len: u64) -> Result<()> {
        const FOOTER_RECORD: u64 = 9 + 20;
        if file_len < 8 + FOOTER_RECORD + 8 {
            return Ok(());
        }
        let mut tail = [0u8; (FOOTER_RECORD + 8) as usize];
        r.seek(SeekFrom::Start(file_len - tail.len() as u64)).map_err(|e| self.io(e))?;
        r.read_exact(&mut tail).map_err(|e| self.io(e))?;
        if &tail[29..] != MAGIC || tail[0] != op::FOOTER {
            return Ok(());
        }
        let summary_start = u64::from_le_bytes(tail[9..17].try_into().expect("8"));
        let footer_offset = file_len - tail.len() as u64;
        if summary_start == 0 || summary_start < 8 || summary_start > footer_offset {
            // A footer without summary still means the file was closed cleanly.
            self.report.has_summary = summary_start == 0;
            return Ok(());
        }
        r.seek(SeekFrom::Start(summary_start)).map_err(|e| self.io(e))?;
        let mut summary = vec![0u8; (footer_offset - summary_start) as usize];
        r.read_exact(&mut summary).map_err(|e| self.io(e))?;
        let mut pos = 0usize;
        let mut channels = Vec::new();
        while summary.len() - pos >= 9 {
            let opcode = summary[pos];
            let len = u64::from_le_bytes(summary[pos + 1..pos + 9].try_into().expect("8"));
            let start = pos + 9;
            if len > (summary.len() - start) as u64 {
                return Ok(()); // a damaged summary is only a lost convenience
            }
            let body = &summary[start..start + len as usize];
            match mcap::parse_record(opcode, body) {
                Ok(Record::Schema { header, data }) => self.add_schema(Schema {
                    id: header.id,
                    name: header.name,
                    encoding: header.encoding,
                    data: data.into_owned(),
                }),
                Ok(Record::Channel(c)) => channels.push(c),
                Ok(Record::Statistics(s)) => {
                    self.report.statistics_message_count = Some(s.message_count);
                }
                _ => {}
            }
            pos = start + len as usize;
        }
        for c in channels {
            self.add_channel(c);
        }
        self.report.has_summary = true;
        Ok(())
    }
}
