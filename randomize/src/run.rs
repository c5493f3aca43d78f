//! Running a batch on all cores and writing its outputs (merging shards: [`crate::merge`]).

use crate::episode::{Batch, EpisodeResult, Trajectory, Worker};
use crate::error::{Error, Result};
use crate::summary::{Summary, SummaryBuilder};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// A deterministic share of the episodes: shard `index` of `count` (1-based) runs the episodes
/// whose index `i` has `i % count == index − 1`. Interleaving balances shards whose episodes
/// get slower with the index... and keeps every shard's episodes identical to the unsharded run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// 1-based shard number.
    pub index: u64,
    /// Number of shards.
    pub count: u64,
}

impl std::str::FromStr for Shard {
    type Err = Error;

    /// Parses `K/N` with 1 ≤ K ≤ N.
    fn from_str(s: &str) -> Result<Shard> {
        let bad = || {
            Error::Options(format!(
                "--shard {s:?}: expected K/N with 1 ≤ K ≤ N, e.g. 3/8 (Slurm: \
                 $((SLURM_ARRAY_TASK_ID+1))/N; Kubernetes: $((JOB_COMPLETION_INDEX+1))/N)"
            ))
        };
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (k.trim().parse::<u64>().map_err(|_| bad())?, n.trim().parse::<u64>().map_err(|_| bad())?);
        if index == 0 || index > count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// Whether episode `i` belongs to this shard.
    pub fn contains(&self, i: u64) -> bool {
        i % self.count == self.index - 1
    }
}

/// Options of a batch run.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct RunOptions {
    /// Number of episodes of the whole batch (all shards together). (default: 100)
    #[default(100)]
    pub episodes: u64,
    /// Worker threads; 0 uses every core. (default: 0)
    pub threads: usize,
    /// Run only this shard of the episodes. (default: all episodes)
    pub shard: Option<Shard>,
    /// Folder for `episodes.csv`, `summary.json`, `spec.toml` and `worst/`. (default: none)
    pub out_dir: Option<PathBuf>,
    /// Re-simulate the K worst episodes and write their trajectories to `worst/`. (default: 0)
    pub record_worst: usize,
    /// Run the first episode again and compare its row ([`crate::repeat`]): one episode more,
    /// for controllers outside twin (a ROS 2 node). (default: false)
    pub repeat_first: bool,
}

/// What identifies a batch: equal for all shards of one batch (except `shard`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    /// Model file as given.
    pub model: String,
    /// Master seed.
    pub seed: u64,
    /// Episodes of the whole batch.
    pub episodes: u64,
    /// Simulated seconds per episode.
    pub duration_secs: f64,
    /// Simulation timestep, seconds.
    pub timestep_secs: f64,
    /// Controller name.
    pub controller: String,
    /// Fall threshold: fraction of the initial base height.
    pub fall_height_fraction: f64,
    /// Fall threshold: base tilt, radians.
    pub fall_tilt_rad: f64,
    /// Bodies counted as feet.
    pub feet: Vec<String>,
    /// The randomization spec, as TOML.
    pub spec: String,
    /// The shard this output covers (`None`: the whole batch or a merge).
    pub shard: Option<Shard>,
}

/// `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SummaryFile {
    /// The batch.
    pub run: RunInfo,
    /// Its summary.
    pub summary: Summary,
}

/// The outcome of [`run_batch`].
#[derive(Debug, Clone)]
pub struct Report {
    /// Batch identity.
    pub run: RunInfo,
    /// Summary of the finished episodes.
    pub summary: Summary,
    /// Episodes this run was asked for (its shard's share).
    pub requested: u64,
    /// The worst episodes, worst first (up to `record_worst`).
    pub worst: Vec<u64>,
    /// Whether a stop request ended the run early.
    pub interrupted: bool,
    /// Simulation steps taken by the finished episodes (falls end episodes early).
    pub simulated_steps: u64,
    /// The first episode run again ([`RunOptions::repeat_first`]), if it was.
    pub repeat: Option<crate::repeat::Repeat>,
}

/// How bad an episode is, for `--record-worst`: diverged, then fell (earlier is worse), then
/// larger tilt; ties by index.
fn badness(r: &EpisodeResult) -> (u8, f64, f64, u64) {
    let class = if r.unstable {
        2
    } else if r.fell {
        1
    } else {
        0
    };
    (class, -r.fall_time_secs.unwrap_or(f64::INFINITY), r.max_tilt_rad, u64::MAX - r.index)
}

fn worse(a: &EpisodeResult, b: &EpisodeResult) -> std::cmp::Ordering {
    let (x, y) = (badness(a), badness(b));
    y.0.cmp(&x.0).then(y.1.total_cmp(&x.1)).then(y.2.total_cmp(&x.2)).then(y.3.cmp(&x.3))
}

/// Rows finished so far by a running batch or shard (renamed to `episodes.csv` when it
/// completes; `twin randomize merge --status` counts them).
pub const PARTIAL_CSV: &str = ".episodes.csv.tmp";

/// Writes what `f` produces to `path` with twin's one atomic writer ([`twin_core::fsio`]),
/// keeping an existing file as a numbered backup (`<name>.bak`, `.bak.1`, …).
pub(crate) fn write_atomic(path: &Path, f: impl FnOnce(&mut Vec<u8>) -> Result<()>) -> Result<()> {
    let mut bytes = Vec::new();
    f(&mut bytes)?;
    twin_core::fsio::write_atomic(path, &bytes, twin_core::fsio::Backup::Numbered)?;
    Ok(())
}

/// Runs the batch (or its shard) on `options.threads` threads. Episodes run in chunks; each
/// chunk's results are written in episode order, so outputs are identical for any thread
/// count and memory does not grow with the number of episodes. `stop` (e.g. set by Ctrl-C)
/// ends the run after the episodes in flight; finished episodes are kept and summarized.
/// `progress` is called once per finished episode.
///
/// # Errors
/// [`Error::Options`] for a bad thread count, [`Error::Io`] for output files, errors of
/// [`Worker::run`] (a drawn parameter that can't be applied stops the batch).
pub fn run_batch(
    batch: &Batch,
    run: RunInfo,
    options: &RunOptions,
    stop: &AtomicBool,
    progress: &(dyn Fn() + Sync),
) -> Result<Report> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.threads)
        .build()
        .map_err(|e| Error::Options(format!("could not start {} threads: {e}", options.threads)))?;
    let threads = pool.current_num_threads();
    let indices: Vec<u64> = (0..options.episodes).filter(|&i| options.shard.is_none_or(|s| s.contains(i))).collect();
    let params = &batch.layout.columns;
    let mut builder = SummaryBuilder::new(params);
    let mut worst: Vec<EpisodeResult> = Vec::new();

    // episodes.csv streams through fsio's one atomic writer: rows reach `PARTIAL_CSV` chunk by
    // chunk, and the file is renamed into place (an existing one kept as a backup) at the end.
    let mut csv_writer = None;
    let tmp_csv;
    if let Some(dir) = &options.out_dir {
        std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.clone(), source })?;
        tmp_csv = dir.join(PARTIAL_CSV);
        let file = twin_core::fsio::StreamingFile::create(
            &dir.join("episodes.csv"),
            &tmp_csv,
            twin_core::fsio::Backup::Numbered,
        )?;
        let mut w = csv::Writer::from_writer(file);
        let checks = batch.check_verdicts()?;
        let check_metrics = crate::summary::check_metric_names(&checks);
        w.write_record(crate::summary::csv_header(params, !checks.is_empty(), &check_metrics))
            .map_err(|e| csv_io(&tmp_csv, e))?;
        csv_writer = Some(w);
    } else {
        tmp_csv = PathBuf::new();
    }

    // Enough episodes per chunk to keep every thread busy; small enough to stream.
    let chunk = (threads * 32).max(1);
    let mut interrupted = false;
    let mut simulated_steps = 0u64;
    let mut first: Option<EpisodeResult> = None;
    let dt = batch.nominal.timestep_secs();
    for ids in indices.chunks(chunk) {
        if stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let results: Vec<Option<Result<EpisodeResult>>> = pool.install(|| {
            ids.par_iter()
                .map_init(
                    || Worker::new(batch),
                    |worker, &i| {
                        if stop.load(Ordering::Relaxed) {
                            return None;
                        }
                        let r = match worker {
                            Ok(w) => w.run(batch, i, None),
                            Err(e) => Err(Error::Options(e.to_string())),
                        };
                        progress();
                        Some(r)
                    },
                )
                .collect()
        });
        for r in results {
            // After an interrupted episode, later finished ones are dropped too: the kept set is
            // always a prefix of the (shard's) episodes, so it can be reproduced and resumed.
            if interrupted {
                continue;
            }
            let Some(r) = r else {
                interrupted = true;
                continue;
            };
            let r = r?;
            simulated_steps += (r.sim_secs / dt).round() as u64;
            builder.push(&r);
            if options.repeat_first && first.is_none() {
                first = Some(r.clone());
            }
            if let Some(w) = csv_writer.as_mut() {
                w.write_record(crate::summary::csv_record(&r)).map_err(|e| csv_io(&tmp_csv, e))?;
            }
            if options.record_worst > 0 {
                let pos = worst.binary_search_by(|x| worse(x, &r)).unwrap_or_else(|p| p);
                if pos < options.record_worst {
                    worst.insert(pos, r);
                    worst.truncate(options.record_worst);
                }
            }
        }
        // Finished rows reach the disk chunk by chunk: `twin randomize merge --status` counts them.
        if let Some(w) = csv_writer.as_mut() {
            w.flush().map_err(|source| Error::Io { path: tmp_csv.clone(), source })?;
        }
    }
    let summary = builder.finish();
    let repeat = match first.filter(|_| !interrupted) {
        Some(r) => Some(crate::repeat::check(batch, &r)?),
        None => None,
    };

    if let (Some(dir), Some(w)) = (&options.out_dir, csv_writer) {
        let file = w
            .into_inner()
            .map_err(|e| Error::Io { path: tmp_csv.clone(), source: std::io::Error::other(e.to_string()) })?;
        file.commit()?;
        write_summary(dir, &run, &summary)?;
        let spec_path = dir.join("spec.toml");
        write_atomic(&spec_path, |f| {
            f.write_all(run.spec.as_bytes()).map_err(|source| Error::Io { path: spec_path.clone(), source })
        })?;
        if !worst.is_empty() {
            record_worst(batch, &worst, &dir.join("worst"))?;
        }
    }
    Ok(Report {
        run,
        summary,
        requested: indices.len() as u64,
        worst: worst.iter().map(|r| r.index).collect(),
        interrupted,
        simulated_steps,
        repeat,
    })
}

fn csv_io(path: &Path, e: csv::Error) -> Error {
    Error::Io { path: path.to_path_buf(), source: std::io::Error::other(e) }
}

/// Writes `summary.json` in `dir`.
///
/// # Errors
/// [`Error::Io`].
pub fn write_summary(dir: &Path, run: &RunInfo, summary: &Summary) -> Result<()> {
    let path = dir.join("summary.json");
    let file = SummaryFile { run: run.clone(), summary: summary.clone() };
    let mut text = serde_json::to_string_pretty(&file).expect("summary serializes");
    text.push('\n');
    write_atomic(&path, |f| f.write_all(text.as_bytes()).map_err(|source| Error::Io { path: path.clone(), source }))
}

/// Re-simulates `worst` episodes with recording, checks that each reproduces its batch
/// metrics bit for bit, and writes into `dir`, per episode: `episode_<index>.csv` (a row per
/// step), `worst_<index>.mcap` (the topics of `twin sim`, see `twin_core::sim::record`) and,
/// with the `rerun` feature, `worst_<index>.rrd`, with the topics of the batch's robot.
///
/// # Errors
/// [`Error::NotReproducible`] if a re-run differs; [`Error::Io`]; recording errors.
pub fn record_worst(batch: &Batch, worst: &[EpisodeResult], dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    let mut worker = Worker::new(batch)?;
    let robot = &batch.robot;
    let mut written = Vec::new();
    for original in worst {
        let mut trajectory = Trajectory::default();
        let mcap = dir.join(format!("worst_{:06}.mcap", original.index));
        let rrd = dir.join(format!("worst_{:06}.rrd", original.index));
        let options = twin_core::sim::RecordOptions {
            mcap: Some(mcap.clone()),
            rrd: cfg!(feature = "rerun").then(|| rrd.clone()),
            // The IMU and /joint_states recorded are the episode's observations (its own noise).
            ..Default::default()
        };
        let mut recording = twin_core::sim::Recording::new(robot, &options)?;
        let again = worker.run_recorded(batch, original.index, Some(&mut trajectory), Some(&mut recording))?;
        recording.finish()?;
        if &again != original {
            return Err(Error::NotReproducible { episode: original.index, what: format!("{again:?} vs {original:?}") });
        }
        let path = dir.join(format!("episode_{:06}.csv", original.index));
        write_atomic(&path, |f| {
            let mut w = csv::Writer::from_writer(std::io::BufWriter::new(f));
            w.write_record(&trajectory.columns).map_err(|e| csv_io(&path, e))?;
            for row in &trajectory.rows {
                w.write_record(row.iter().map(f64::to_string)).map_err(|e| csv_io(&path, e))?;
            }
            w.flush().map_err(|source| Error::Io { path: path.clone(), source })
        })?;
        written.push(path);
        written.push(mcap);
        if cfg!(feature = "rerun") {
            written.push(rrd);
        }
    }
    Ok(written)
}
