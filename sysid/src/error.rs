//! The one error type of `sysid`.

use std::path::PathBuf;

/// Everything that can go wrong while identifying a robot. Variants carry what is needed to act
/// on them: the file, the joint, the line or the time in the log.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A CSV log is malformed; `line` is 1-based.
    #[error("{}:{line}: {message}", path.display())]
    Csv {
        /// The log file.
        path: PathBuf,
        /// Line of the problem (1-based).
        line: usize,
        /// What is wrong and what to do.
        message: String,
    },

    /// The log can't be used as it is (no effort, NaNs, unmatched joints, too short ...).
    #[error("{source_name}: {message}")]
    BadLog {
        /// The log (file or topic) the data came from.
        source_name: String,
        /// What is wrong and what to do.
        message: String,
    },

    /// The log does not excite the robot enough to identify anything, or (with `strict`) the
    /// diagnosis found problems.
    #[error("{source_name}: the log is not exciting enough to identify the robot:\n{}", problems.iter().map(|p| format!("  - {p}")).collect::<Vec<_>>().join("\n"))]
    NotExcited {
        /// The log.
        source_name: String,
        /// One line per problem found.
        problems: Vec<String>,
    },

    /// The URDF can't be used for identification or write-back.
    #[error("{}: {message}", path.display())]
    Urdf {
        /// The URDF file.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },

    /// An option is out of its valid range.
    #[error("invalid option {name}: {message}")]
    Option {
        /// Option name, e.g. `cutoff_hz`.
        name: &'static str,
        /// What is wrong.
        message: String,
    },

    /// The estimation failed numerically.
    #[error("estimation failed: {0}")]
    Numerical(String),

    /// A file, MuJoCo or URDF error from `twin-core` (a file that could not be read or written
    /// is `twin_core::Error::File`).
    #[error(transparent)]
    Core(#[from] twin_core::Error),
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The errors of the floors below (files, the MuJoCo wrapper, logs), as `twin_core::Error`
/// reports them.
macro_rules! as_core_error {
    ($($t:ty),*) => {$(
        impl From<$t> for Error {
            fn from(e: $t) -> Error { Error::Core(e.into()) }
        }
    )*};
}
as_core_error!(twin_core::fsio::Error, twin_core::mj::Error, twin_core::log::Error);
