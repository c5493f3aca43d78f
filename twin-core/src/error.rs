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

    /// The MuJoCo wrapper failed: MuJoCo refused a model, raised `mju_user_error`, a model edit
    /// would be invalid, or the library is not the one twin was built for (twin-mj's error,
    /// with its text).
    #[error(transparent)]
    Mj(twin_mj::Error),

    /// A ROS 2 log could not be read or written: not MCAP, damaged, a message that does not
    /// decode, a topic missing (twin-log's error, with its text).
    #[error(transparent)]
    Log(twin_log::Error),

    /// A URDF is invalid or not well-formed XML (twin-convert's error, with its text: the file,
    /// the line and element, what to do).
    #[error(transparent)]
    Convert(twin_convert::Error),

    /// A number in a model or an option is out of its valid range; the message gives the range.
    #[error("{what}: {message}")]
    OutOfRange {
        /// Where the value comes from (file and element, or option).
        what: String,
        /// The value, the valid range and what to do.
        message: String,
    },

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
            twin_convert::Error::Load { path, message } => Error::Mj(twin_mj::Error::Load { path, message }),
            other => Error::Convert(other),
        }
    }
}

impl From<twin_mj::Error> for Error {
    /// The variants both floors have (a file, a number out of range, a URDF, a name or size the
    /// model lacks, options) stay themselves; the rest is [`Error::Mj`]. The text is the same.
    fn from(e: twin_mj::Error) -> Error {
        use twin_mj::Error as M;
        match e {
            M::File(e) => Error::File(e),
            M::Convert(e) => Error::Convert(e),
            M::OutOfRange { what, message } => Error::OutOfRange { what, message },
            M::NotFound { kind, name } => Error::NotFound { kind, name },
            M::Size { what, expected, got } => Error::Size { what, expected, got },
            M::Options(message) => Error::Options(message),
            other => Error::Mj(other),
        }
    }
}

impl From<twin_log::Error> for Error {
    /// A file error stays [`Error::File`]; the rest is [`Error::Log`], with the same text.
    fn from(e: twin_log::Error) -> Error {
        match e {
            twin_log::Error::File(e) => Error::File(e),
            other => Error::Log(other),
        }
    }
}
