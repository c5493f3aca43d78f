//! The error type of the MuJoCo wrapper. `twin-core`'s `Error` has a variant of the same name and
//! text for each of these (its `From<twin_mj::Error>`), so a message reads the same whichever
//! floor reports it.

use std::path::PathBuf;

/// What can go wrong calling MuJoCo through the wrapper. Variants carry the data needed to act
/// on them (file, element, line, MuJoCo's own message).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file could not be read, or a path is not what it must be (twin-fsio's error, with its
    /// text).
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

    /// A camera can't be rendered: no OpenGL library (EGL, OSMesa) on this machine, or MuJoCo's
    /// renderer failed on it. The message names what to install; ray-cast sensors (depth
    /// cameras, LiDARs) don't need it.
    #[error("rendering: {message}")]
    Render {
        /// What failed and what to do.
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

    /// A model edit would make the model physically invalid (e.g. negative mass).
    #[error("invalid model edit: {0}")]
    InvalidEdit(String),

    /// Options that don't fit together.
    #[error("{0}")]
    Options(String),
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

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
