//! The error type of `twin-convert`. Every variant names the file and, for URDF content, the
//! line and element, and says what to do. `twin_core::Error` wraps it (`Error::Convert`), so a
//! conversion error reads the same from the library and from `twin`.

use std::path::PathBuf;

/// What can go wrong converting a URDF.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The URDF, a world file or a mesh could not be read, or a converted mesh written.
    #[error(transparent)]
    File(#[from] twin_fsio::Error),

    /// A URDF element is invalid; `line` is 1-based.
    #[error("{}:{line}: <{element}{}>: {message}", path.display(), name.as_deref().map_or_else(String::new, |n| format!(" name=\"{n}\"")))]
    Urdf {
        /// The URDF file.
        path: PathBuf,
        /// Line of the offending element (1-based).
        line: u32,
        /// The element's tag, e.g. `inertia`.
        element: String,
        /// The `name` of the enclosing link or joint, if any.
        name: Option<String>,
        /// What is wrong and what to do about it.
        message: String,
    },

    /// A link asked for by name (a contact sensor's, `ConvertOptions::contact_sensors`) is not
    /// in the robot.
    #[error(
        "{}: no link \"{link}\" for the contact sensor asked for (`--contact-sensor`, a scenario's `contact_sensors`): name one of its links: {}",
        path.display(),
        links.join(", ")
    )]
    NoSuchLink {
        /// The URDF file.
        path: PathBuf,
        /// The name asked for.
        link: String,
        /// The robot's links, in file order.
        links: Vec<String>,
    },

    /// The file is not well-formed XML.
    #[error("{}:{line}:{column}: not well-formed XML: {message}", path.display())]
    Xml {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u32,
        /// 1-based column.
        column: u32,
        /// The parser's message.
        message: String,
    },

    /// The engine refused the generated model at a place no URDF element accounts for;
    /// `message` is the engine's text with the way to see the generated MJCF.
    #[error("{}: MuJoCo could not load the model: {message}", path.as_deref().map_or_else(|| "<string>".into(), |p| p.display().to_string()))]
    Load {
        /// The URDF file.
        path: Option<PathBuf>,
        /// What the engine said.
        message: String,
    },
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
