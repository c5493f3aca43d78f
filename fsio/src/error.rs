//! The error type of `twin-fsio`: a path that could not be read or written, or that is not what
//! it must be. `twin_core::Error` has the same two variants with the same text.

use std::path::PathBuf;

/// What can go wrong opening an input or writing an output.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },

    /// A path is not what it must be (a FIFO or device as input, a folder or an input as
    /// output, …); `message` says what it is and what to do.
    #[error("{}: {message}", path.display())]
    BadPath {
        /// The path as given.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
