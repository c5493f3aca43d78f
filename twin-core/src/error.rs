//! The one error type of `twin-core`.

use std::path::PathBuf;

/// Everything that can go wrong in `twin-core`. Variants carry the data needed to act on them
/// (file, element, line, MuJoCo's own message).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read or written, or a path is not what it must be (twin-fsio's error,
    /// with its text).
    #[error(transparent)]
    File(#[from] twin_fsio::Error),

    /// A number in a model or an option is out of its valid range; the message gives the range.
    #[error("{what}: {message}")]
    OutOfRange {
        /// Where the value comes from (file and element, or option).
        what: String,
        /// The value, the valid range and what to do.
        message: String,
    },

    /// MuJoCo refused a model (parse or compile error). `message` is MuJoCo's text, which names
    /// the element and line where it can.
    #[error("{}: MuJoCo could not load the model: {message}", path.as_deref().map_or_else(|| "<string>".into(), |p| p.display().to_string()))]
    Load {
        /// The model file, `None` when loaded from a string.
        path: Option<PathBuf>,
        /// MuJoCo's error text.
        message: String,
    },

    /// A MuJoCo call raised `mju_user_error`; the process keeps running and the data involved
    /// should be reset before further use.
    #[error("MuJoCo error in {call}: {message}")]
    MuJoCo {
        /// The MuJoCo function that raised it.
        call: &'static str,
        /// MuJoCo's error text.
        message: String,
    },

    /// The header MuJoCo was compiled against does not match the loaded library.
    #[error(
        "MuJoCo library version {library} does not match the headers twin was built with ({header}); \
         rebuild twin against the same MuJoCo (unset MUJOCO_DIR to use the pinned one)"
    )]
    Version {
        /// `mj_version()` of the loaded library.
        library: i32,
        /// `mjVERSION_HEADER` of the bindings.
        header: i32,
    },

    /// A URDF is invalid or not well-formed XML (twin-convert's error, with its text: the file,
    /// the line and element, what to do).
    #[error(transparent)]
    Convert(twin_convert::Error),

    /// No object of this kind and name in the model.
    #[error("the model has no {kind} named \"{name}\"")]
    NotFound {
        /// Object kind, e.g. `body`.
        kind: &'static str,
        /// The name asked for.
        name: String,
    },

    /// Perception found nothing usable in a sensor's data (no table plane in a point cloud, no
    /// object on it); `message` says which stage failed and what to check.
    #[error("{what}: {message}")]
    Perception {
        /// What was being perceived, e.g. `cup detection`.
        what: String,
        /// Which stage failed and why.
        message: String,
    },

    /// An index or a slice length does not fit the model.
    #[error("{what}: expected {expected}, got {got}")]
    Size {
        /// What was being set.
        what: &'static str,
        /// Expected length or bound.
        expected: usize,
        /// Given length or index.
        got: usize,
    },

    /// Something needs a cargo feature this build lacks.
    #[error(
        "{what} needs the `{feature}` cargo feature, which this build of twin lacks: rebuild with \
         it (`cargo build --release --features {feature}`; it is on by default)"
    )]
    FeatureMissing {
        /// The cargo feature.
        feature: &'static str,
        /// What was asked for.
        what: String,
    },

    /// The live ROS 2 bridge failed (DDS setup, a lockstep controller that stopped answering).
    #[error("live ROS 2 bridge: {message}")]
    Live {
        /// What went wrong and what to do.
        message: String,
    },

    /// Writing a rerun recording failed.
    #[cfg(feature = "rerun")]
    #[error("{}: rerun recording failed: {message}", path.as_deref().map_or_else(|| "<viewer>".into(), |p| p.display().to_string()))]
    Rerun {
        /// The `.rrd` file, `None` when streaming to a viewer.
        path: Option<PathBuf>,
        /// What rerun said.
        message: String,
    },

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

    /// A model edit would make the model physically invalid (e.g. negative mass).
    /// A joint trajectory (CSV or log) that can't be replayed.
    #[error("{}{}: {message}", path.display(), line.map_or_else(String::new, |l| format!(":{l}")))]
    Trajectory {
        /// The trajectory file.
        path: std::path::PathBuf,
        /// 1-based line, for CSV.
        line: Option<usize>,
        /// What is wrong and what to do.
        message: String,
    },

    #[error("invalid model edit: {0}")]
    InvalidEdit(String),

    /// Options that don't fit together (e.g. the replay controller without a trajectory).
    #[error("{0}")]
    Options(String),

    /// The walking controller can't drive this model with these options (a leg or foot not
    /// found, a step the legs can't reach, an option out of range).
    #[error("walking controller: {message}")]
    Walk {
        /// What is wrong and what to do.
        message: String,
    },

    /// The walker's legs can't reach its longest step with these options (a leg's IK misses the
    /// step's foot pose): an [`Error::Walk`] of its own, so that a search over the crouch
    /// (`twin_controllers::walk::WalkOptions::for_robot`) tells it from the other refusals.
    #[error("walking controller: {message}")]
    WalkReach {
        /// Which leg, by how much, and what to do.
        message: String,
    },

    /// The grasping controller can't drive this model with these options (no gripper or
    /// camera found, an option out of range).
    #[error("grasping controller: {message}")]
    Grasp {
        /// What is wrong and what to do.
        message: String,
    },

    /// A scenario file is invalid: the file, the line and key when known, what is wrong.
    #[error("{}{}{}: {message}", path.display(), line.map_or_else(String::new, |l| format!(":{l}")), key.as_deref().map_or_else(String::new, |k| format!(": `{k}`")))]
    Scenario {
        /// The scenario file.
        path: PathBuf,
        /// 1-based line of the offending key or value, when known.
        line: Option<usize>,
        /// Dotted key (e.g. `controller.params.step_period`), when known.
        key: Option<String>,
        /// What is wrong.
        message: String,
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

impl From<twin_convert::Error> for Error {
    /// The same variant, with the same text.
    fn from(e: twin_convert::Error) -> Error {
        match e {
            twin_convert::Error::File(e) => Error::File(e),
            twin_convert::Error::Load { path, message } => Error::Load { path, message },
            other => Error::Convert(other),
        }
    }
}

impl From<twin_mj::Error> for Error {
    /// The variant of the same name, with the same text.
    fn from(e: twin_mj::Error) -> Error {
        use twin_mj::Error as M;
        match e {
            M::File(e) => Error::File(e),
            M::OutOfRange { what, message } => Error::OutOfRange { what, message },
            M::Load { path, message } => Error::Load { path, message },
            M::MuJoCo { call, message } => Error::MuJoCo { call, message },
            M::Version { library, header } => Error::Version { library, header },
            M::Convert(e) => Error::Convert(e),
            M::NotFound { kind, name } => Error::NotFound { kind, name },
            M::Size { what, expected, got } => Error::Size { what, expected, got },
            M::InvalidEdit(message) => Error::InvalidEdit(message),
            M::Options(message) => Error::Options(message),
            other => Error::Options(other.to_string()),
        }
    }
}

impl From<twin_log::Error> for Error {
    /// The variant of the same name, with the same text.
    fn from(e: twin_log::Error) -> Error {
        use twin_log::Error as L;
        match e {
            L::File(e) => Error::File(e),
            L::LogFormat { path, offset, message } => Error::LogFormat { path, offset, message },
            L::MsgDef { type_name, line, message } => Error::MsgDef { type_name, line, message },
            L::Decode { path, topic, type_name, log_time_nanos, message } => {
                Error::Decode { path, topic, type_name, log_time_nanos, message }
            }
            L::LogTopic { path, topic, message } => Error::LogTopic { path, topic, message },
            L::McapWrite { path, source } => Error::McapWrite { path, source },
            other => Error::Options(other.to_string()),
        }
    }
}
