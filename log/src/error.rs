//! The error type of the ROS 2 log reader and writer. `twin-core`'s `Error` has a variant of the
//! same name and text for each of these (its `From<twin_log::Error>`), so a message reads the same
//! whichever floor reports it.

use std::path::PathBuf;

/// What can go wrong reading or writing a ROS 2 log. Variants carry the file, the byte offset
/// or topic, and what to do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read or written, or a path is not what it must be (twin-fsio's error,
    /// with its text).
    #[error(transparent)]
    File(#[from] twin_fsio::Error),

    /// A log file is not MCAP, or is damaged and strict reading was asked for. `offset` is the
    /// byte offset of the offending record.
    #[error("{}{}: {message}", path.display(), offset.map_or_else(String::new, |o| format!(" (byte {o})")))]
    LogFormat {
        /// The `.mcap` file or bag folder.
        path: PathBuf,
        /// Byte offset in the file, when known.
        offset: Option<u64>,
        /// What is wrong and what to do about it.
        message: String,
    },

    /// A `ros2msg` schema text could not be parsed; `line` is 1-based within the schema text
    /// (0 when not tied to a line).
    #[error("message definition of {type_name}, line {line}: {message}")]
    MsgDef {
        /// The message type, e.g. `sensor_msgs/msg/JointState`.
        type_name: String,
        /// Line in the schema text.
        line: usize,
        /// What is wrong.
        message: String,
    },

    /// A message could not be decoded with its channel's schema.
    #[error("{}: topic {topic} ({type_name}), message at log time {log_time_nanos} ns: {message}", path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The message type.
        type_name: String,
        /// Log time of the message.
        log_time_nanos: u64,
        /// What went wrong (with the byte offset in the message where known).
        message: String,
    },

    /// A topic asked for is missing from a log or has an unexpected type.
    #[error("{}: {message}", path.display())]
    LogTopic {
        /// The file or bag folder.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// What is wrong, with the topics that are there.
        message: String,
    },

    /// Writing an MCAP file failed.
    #[error("{}: writing MCAP", path.display())]
    McapWrite {
        /// The file being written.
        path: PathBuf,
        /// The mcap crate's error.
        source: mcap::McapError,
    },
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A failed read or write of `path` ([`twin_fsio::Error::File`]).
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Error {
        Error::File(twin_fsio::Error::Io { path: path.into(), source })
    }
}
