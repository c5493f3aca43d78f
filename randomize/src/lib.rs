//! Domain-randomized batch rollouts (`twin randomize`).
//!
//! Runs a twin many times with its physics and sensors shaken the way reality will shake them
//! ([`spec::Spec`]), under a controller from `twin_core::control`, and reports how often and
//! how it fails ([`summary::Summary`]).
//!
//! - [`spec`]: the randomization spec (TOML): scale | add | absolute of uniform | log-uniform |
//!   gaussian draws, always from the nominal model.
//! - [`draw`]: the spec bound to a model ([`draw::Layout`]) and one episode's draw, applied
//!   through `Model::edit()…finish()` (which runs `mj_setConst`).
//! - [`episode`]: one rollout with noise, latency, pushes, fall and divergence detection, and
//!   its metrics.
//! - [`run`]: the batch on a rayon pool, per-episode random streams from (seed, index), shards,
//!   outputs (`episodes.csv`, `summary.json`, `worst/`).
//! - [`merge`]: what each shard records (`shard.json`: twin version, spec hash, command), shard
//!   progress, and merging shards into the single-machine outputs.
//! - [`repeat`]: the first episode run again and compared (is a user's node reproducible?).
//! - [`summary`]: success rate with a Wilson interval, metric quantiles, and the parameters
//!   that separate failures from successes.
//! - [`sweep`]: success against one parameter (`--sweep NAME=FROM:TO:STEP`): a batch per level,
//!   a table, CSV and SVG, shards merged level by level.
//!
//! ```no_run
//! use std::sync::Arc;
//! use std::sync::atomic::AtomicBool;
//! use randomize::{Batch, EpisodeOptions, Layout, RunOptions, Spec};
//! use twin_core::mj::Model;
//!
//! let model = Arc::new(Model::from_file("randomize/tests/fixtures/humanoid.xml")?);
//! let spec = Spec::default_spec();
//! let layout = Layout::new(&spec, &model)?;
//! let batch = Batch::new(model, layout, EpisodeOptions::default(), 7)?;
//! let run = randomize::run_info(&batch, "humanoid.xml", &spec, 20, None);
//! let options = RunOptions { episodes: 20, ..RunOptions::default() };
//! let report = randomize::run_batch(&batch, run, &options, &AtomicBool::new(false), &|| {})?;
//! print!("{}", report.summary.to_text(report.requested));
//! # Ok::<(), randomize::Error>(())
//! ```
//!
//! ## Limitations
//! - Friction is randomized per geom (sliding coefficient); explicit `<pair>` contacts keep
//!   their own friction.
//! - Pushes change the floating base's velocity; fixed-base models can't be pushed.

#![forbid(unsafe_code)]

pub mod draw;
pub mod episode;
pub mod error;
pub mod merge;
pub mod repeat;
pub mod run;
pub mod spec;
pub mod summary;
pub mod sweep;

pub use draw::Layout;
pub use episode::{Batch, CheckFactory, ControllerFactory, DisturbanceFactory, EpisodeOptions, EpisodeResult, Worker};
pub use error::{Error, Result};
pub use merge::{Merged, ShardManifest, ShardStart, merge};
pub use repeat::Repeat;
pub use run::{Report, RunInfo, RunOptions, Shard, run_batch};
pub use spec::{Mode, Spec, Term};
pub use summary::{Outcomes, Summary};

/// The identity of a batch as written into `summary.json`.
pub fn run_info(batch: &Batch, model: &str, spec: &Spec, episodes: u64, shard: Option<Shard>) -> RunInfo {
    RunInfo {
        model: model.to_string(),
        seed: batch.seed,
        episodes,
        duration_secs: batch.options.duration_secs,
        timestep_secs: batch.nominal.timestep_secs(),
        controller: batch.controller_name().to_string(),
        fall_height_fraction: batch.options.fall_height_fraction,
        fall_tilt_rad: batch.options.fall_tilt_rad,
        feet: batch.feet(),
        spec: spec.to_toml(),
        shard,
    }
}
