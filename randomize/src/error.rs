//! The one error type of `randomize`.

use std::path::PathBuf;

/// Everything that can go wrong in a randomized batch. Variants carry the file, the spec key or
/// the episode involved and what to do about it.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// MuJoCo or the safe wrapper failed outside an episode (loading, editing the model).
    #[error(transparent)]
    Core(#[from] twin_core::Error),

    /// Reading or writing a file failed.
    #[error("{}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },

    /// The randomization spec is not valid TOML or has unknown keys; `message` is the TOML
    /// parser's, with line and column.
    #[error("{}: invalid randomization spec: {message}", path.display())]
    SpecSyntax {
        /// The spec file.
        path: PathBuf,
        /// The parser's message (line, column, key).
        message: String,
    },

    /// A spec entry is well-formed TOML but makes no sense (e.g. `low > high`, a pattern that
    /// matches nothing).
    #[error("{}: [{key}]: {message}", path.as_deref().map_or_else(|| "<spec>".into(), |p| p.display().to_string()))]
    Spec {
        /// The spec file, `None` for a spec built in code.
        path: Option<PathBuf>,
        /// The entry, e.g. `friction` or `object_mass.0`.
        key: String,
        /// What is wrong and how to fix it.
        message: String,
    },

    /// Applying the drawn parameters to the model failed (e.g. a negative mass).
    #[error("episode {episode}: could not apply the drawn parameters")]
    Apply {
        /// Episode index.
        episode: u64,
        /// The model edit that failed.
        source: twin_core::Error,
    },

    /// An episode could not run: its controller failed on its copy of the robot, or MuJoCo
    /// failed resetting it (`source` says which). The episode and the master seed reproduce it:
    /// `--seed SEED --episodes EPISODE+1` ends with it.
    #[error("episode {episode} (master seed {seed}) could not run")]
    Episode {
        /// Episode index.
        episode: u64,
        /// The batch's master seed.
        seed: u64,
        /// What failed (boxed: the variant stays as small as the others).
        source: Box<twin_core::Error>,
    },

    /// A per-episode CSV or summary from a shard can't be read or doesn't fit the others.
    #[error("{}{}: {message}", path.display(), line.map_or_else(String::new, |l| format!(":{l}")))]
    Results {
        /// The file.
        path: PathBuf,
        /// 1-based line, when known.
        line: Option<u64>,
        /// What is wrong and what to do.
        message: String,
    },

    /// A bad option value (shard, thread count, duration).
    #[error("{0}")]
    Options(String),

    /// Re-simulating an episode for `--record-worst` did not reproduce its recorded metrics.
    #[error(
        "episode {episode}: re-simulation differs from the batch run ({what}): results are not \
         deterministic; please report this"
    )]
    NotReproducible {
        /// Episode index.
        episode: u64,
        /// Which metric differed.
        what: String,
    },
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
