//! Shards of one batch: what each records about itself (`shard.json`), their progress while
//! they run, and merging their outputs into what one machine would have written.
//!
//! A shard run (`twin randomize --shard K/N --out DIR`) writes `DIR/shard.json` before its first
//! episode: the batch identity ([`RunInfo`]), the twin version, the spec's SHA-256 and the
//! command that ran it. Finished rows are flushed to `DIR/.episodes.csv.tmp` chunk by chunk, which
//! becomes `episodes.csv` (with `summary.json`) when the shard completes. So a folder tells
//! [`status`] how far its shard got, tells [`merge`] whether it belongs with the others, and gives
//! the exact command that reruns only a shard that died.

use crate::episode::EpisodeResult;
use crate::error::{Error, Result};
use crate::run::{PARTIAL_CSV, RunInfo, Shard, SummaryFile, write_atomic, write_summary};
use crate::summary::{Summary, SummaryBuilder, read_csv, write_csv};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A shard's record of itself, written before its first episode.
pub const MANIFEST: &str = "shard.json";

/// `shard.json`: what a shard ran, with which binary, and how to run it again.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardManifest {
    /// The binary's version line (`twin --version`); shards of one merge must agree.
    pub twin_version: String,
    /// SHA-256 (hex) of the randomization spec as TOML ([`RunInfo::spec`]).
    pub spec_sha256: String,
    /// Master seed of the batch.
    pub seed: u64,
    /// This shard.
    pub shard: Shard,
    /// Episodes of this shard (its share of [`RunInfo::episodes`]).
    pub shard_episodes: u64,
    /// The batch (with `shard` set).
    pub run: RunInfo,
    /// The command line that ran it (argv).
    pub command: Vec<String>,
    /// The folder it ran from.
    pub cwd: PathBuf,
}

impl ShardManifest {
    /// The manifest of a run of `run.shard` by binary `twin_version`, started as `command` from
    /// `cwd`. `None` when `run` is not a shard.
    pub fn new(run: &RunInfo, twin_version: &str, command: Vec<String>, cwd: PathBuf) -> Option<ShardManifest> {
        let shard = run.shard?;
        Some(ShardManifest {
            twin_version: twin_version.to_string(),
            spec_sha256: spec_sha256(&run.spec),
            seed: run.seed,
            shard,
            shard_episodes: shard_episodes(run.episodes, shard),
            run: run.clone(),
            command,
            cwd,
        })
    }

    /// Whether `other` runs the same shard of the same batch with the same binary (the command
    /// line may differ, e.g. in `--threads`).
    pub fn same_work(&self, other: &ShardManifest) -> bool {
        self.twin_version == other.twin_version && self.spec_sha256 == other.spec_sha256 && self.run == other.run
    }

    /// The shell command that reruns shard `index` of this batch into `dir`: this shard's own
    /// command line with `--shard` and `--out` replaced.
    pub fn rerun_command(&self, index: u64, dir: &Path) -> String {
        let mut args = Vec::with_capacity(self.command.len());
        let mut it = self.command.iter().peekable();
        let shard = format!("{index}/{}", self.shard.count);
        while let Some(a) = it.next() {
            match a.as_str() {
                "--shard" | "--out" => {
                    args.push(a.clone());
                    it.next();
                    args.push(if a == "--shard" { shard.clone() } else { dir.display().to_string() });
                }
                _ if a.starts_with("--shard=") => args.push(format!("--shard={shard}")),
                _ if a.starts_with("--out=") => args.push(format!("--out={}", dir.display())),
                _ => args.push(a.clone()),
            }
        }
        let line = args.iter().map(|a| shell_quote(a)).collect::<Vec<_>>().join(" ");
        match std::env::current_dir() {
            Ok(here) if here == self.cwd => line,
            _ => format!("cd {} && {line}", shell_quote(&self.cwd.display().to_string())),
        }
    }
}

/// Quotes `s` for a POSIX shell when it needs it.
fn shell_quote(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+%@".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// SHA-256 (hex) of a spec's TOML text.
pub fn spec_sha256(spec_toml: &str) -> String {
    Sha256::digest(spec_toml.as_bytes()).iter().map(|b| format!("{b:02x}")).collect()
}

/// Episodes of shard `shard` in a batch of `episodes`.
pub fn shard_episodes(episodes: u64, shard: Shard) -> u64 {
    // Episode i belongs to shard K when i % N == K − 1.
    let (k, n) = (shard.index - 1, shard.count);
    if episodes > k { (episodes - k).div_ceil(n) } else { 0 }
}

/// Reads `dir/shard.json`; `None` when there is none.
///
/// # Errors
/// [`Error::Io`], [`Error::Results`] for a file that is not a shard manifest.
pub fn read_manifest(dir: &Path) -> Result<Option<ShardManifest>> {
    let path = dir.join(MANIFEST);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(Error::Io { path, source }),
    };
    serde_json::from_str(&text).map(Some).map_err(|e| Error::Results {
        path: path.clone(),
        line: Some(e.line() as u64),
        message: format!("not a `twin randomize --shard` manifest: {e}"),
    })
}

/// What [`start_shard`] found in the shard's folder.
#[derive(Debug, Clone)]
pub enum ShardStart {
    /// Run the shard (its manifest is written).
    Run,
    /// The folder already holds this shard, finished by the same binary with the same batch:
    /// its summary. Running it again would write the same bytes.
    AlreadyDone(Box<SummaryFile>),
}

/// Prepares `dir` for the shard of `manifest`: if it already holds that shard, complete, from
/// the same binary and batch, says so (re-running a finished shard, e.g. a requeued Slurm task,
/// is then a no-op); otherwise writes `dir/shard.json` (atomically).
///
/// # Errors
/// [`Error::Io`]; [`Error::Results`] for unreadable files already in `dir`.
pub fn start_shard(dir: &Path, manifest: &ShardManifest) -> Result<ShardStart> {
    if let Some(old) = read_manifest(dir)?
        && old.same_work(manifest)
        && dir.join("episodes.csv").is_file()
        && dir.join("summary.json").is_file()
    {
        let done = read_summary(dir)?;
        if done.run == manifest.run && done.summary.outcomes.episodes == manifest.shard_episodes {
            return Ok(ShardStart::AlreadyDone(Box::new(done)));
        }
    }
    std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
    let path = dir.join(MANIFEST);
    let mut text = serde_json::to_string_pretty(manifest).expect("manifest serializes");
    text.push('\n');
    write_atomic(&path, |f| f.write_all(text.as_bytes()).map_err(|source| Error::Io { path: path.clone(), source }))?;
    Ok(ShardStart::Run)
}

/// Reads one output folder's `summary.json`.
///
/// # Errors
/// [`Error::Io`], [`Error::Results`] for a file that is not a `twin randomize` summary.
pub fn read_summary(dir: &Path) -> Result<SummaryFile> {
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).map_err(|source| Error::Io { path: path.clone(), source })?;
    serde_json::from_str(&text).map_err(|e| Error::Results {
        path: path.clone(),
        line: Some(e.line() as u64),
        message: format!("not a `twin randomize` summary: {e}"),
    })
}

/// Where a shard's folder stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShardState {
    /// Every episode finished; `episodes.csv` and `summary.json` written.
    Done,
    /// Stopped by a stop request with only some episodes finished (summary of those written).
    Interrupted,
    /// Started, not finished: still running, or killed (cancelled, node lost).
    Started,
    /// No folder among the arguments holds this shard.
    Missing,
}

impl ShardState {
    fn label(self) -> &'static str {
        match self {
            ShardState::Done => "done",
            ShardState::Interrupted => "interrupted",
            ShardState::Started => "running (or killed)",
            ShardState::Missing => "missing",
        }
    }
}

/// Progress of one shard, from [`status`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShardProgress {
    /// The shard.
    pub shard: Shard,
    /// Its folder (`None` when missing).
    pub dir: Option<PathBuf>,
    /// Episodes finished.
    pub done: u64,
    /// Episodes of the shard.
    pub total: u64,
    /// Where it stands.
    pub state: ShardState,
}

/// The shards of one batch found in `dirs`.
struct Found<'a> {
    /// The first manifest read (and its folder).
    first: (&'a Path, ShardManifest),
    /// Per shard (index − 1): its folder and manifest.
    shards: Vec<Option<(&'a Path, ShardManifest)>>,
    /// Folders with no files of a shard yet (with `starting_ok`).
    starting: Vec<&'a Path>,
}

/// Reads every folder's manifest and checks they are shards of one batch, made by one binary.
/// With `starting_ok`, a folder holding none of a shard's files yet (a shard between creating
/// its folder and writing `shard.json`) is listed in [`Found::starting`] instead of refused.
fn find_shards(dirs: &[PathBuf], starting_ok: bool) -> Result<Found<'_>> {
    if dirs.is_empty() {
        return Err(Error::Options("merge needs at least one shard output folder".into()));
    }
    let mut first: Option<(&Path, ShardManifest)> = None;
    let mut shards: Vec<Option<(&Path, ShardManifest)>> = Vec::new();
    let mut starting = Vec::new();
    for dir in dirs {
        let path = dir.join(MANIFEST);
        let Some(m) = read_manifest(dir)? else {
            let shard_files = [MANIFEST, PARTIAL_CSV, "episodes.csv", "summary.json"];
            if starting_ok && dir.is_dir() && !shard_files.iter().any(|f| dir.join(f).exists()) {
                starting.push(dir.as_path());
                continue;
            }
            let message = if dir.join("summary.json").is_file() {
                "no shard.json next to summary.json: not the output of `twin randomize --shard` \
                 (or of a twin before 0.1 recorded shards): rerun the shard"
            } else {
                "no shard.json: not the output folder of `twin randomize --shard K/N --out DIR`"
            };
            return Err(Error::Results { path, line: None, message: message.into() });
        };
        if m.shard.index == 0 || m.shard.index > m.shard.count {
            return Err(Error::Results {
                path,
                line: None,
                message: format!("shard {} is not a shard K/N with 1 ≤ K ≤ N: the file was edited", m.shard),
            });
        }
        let Some((first_dir, f)) = &first else {
            shards = vec![None; m.shard.count as usize];
            let index = (m.shard.index - 1) as usize;
            first = Some((dir, m.clone()));
            shards[index] = Some((dir, m));
            continue;
        };
        let differ = |what: String| Error::Results {
            path: path.clone(),
            line: None,
            message: format!(
                "{what} than {}: shards of one batch must match; rerun it with the others' settings: {}",
                first_dir.join(MANIFEST).display(),
                f.rerun_command(m.shard.index, dir)
            ),
        };
        if m.twin_version != f.twin_version {
            return Err(differ(format!("made by twin {:?}, another binary", m.twin_version)));
        }
        if m.seed != f.seed {
            return Err(differ(format!("ran with seed {}, another seed", m.seed)));
        }
        if m.spec_sha256 != f.spec_sha256 {
            return Err(differ(format!("ran with a different randomization spec (sha256 {})", &m.spec_sha256[..12])));
        }
        if m.shard.count != f.shard.count {
            return Err(differ(format!("is shard {}, of another number of shards", m.shard)));
        }
        let (mut a, mut b) = (m.run.clone(), f.run.clone());
        (a.shard, b.shard) = (None, None);
        if a != b {
            return Err(differ(
                "belongs to a different batch (model, episodes, duration, controller or fall thresholds)".into(),
            ));
        }
        let slot = &mut shards[(m.shard.index - 1) as usize];
        if let Some((other, _)) = slot {
            return Err(Error::Results {
                path,
                line: None,
                message: format!("shard {} is also in {}: pass each shard once", m.shard, other.display()),
            });
        }
        *slot = Some((dir, m));
    }
    let first = first.ok_or_else(|| Error::Results {
        path: dirs[0].join(MANIFEST),
        line: None,
        message: "no shard has written its shard.json yet: ask again in a moment".into(),
    })?;
    Ok(Found { first, shards, starting })
}

/// Rows finished so far in `dir` (complete lines of the partial CSV, header excluded).
fn partial_rows(dir: &Path) -> Result<u64> {
    let path = dir.join(PARTIAL_CSV);
    match std::fs::read(&path) {
        Ok(bytes) => Ok((bytes.iter().filter(|&&b| b == b'\n').count() as u64).saturating_sub(1)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(0),
        Err(source) => Err(Error::Io { path, source }),
    }
}

/// Progress of a batch's shards, from [`status`].
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// One entry per shard 1…N, missing ones included.
    pub shards: Vec<ShardProgress>,
    /// Folders given that hold nothing yet (a shard starting up).
    pub starting: Vec<PathBuf>,
}

/// Progress of every shard of the batch in `dirs`, for `twin randomize merge --status` while
/// the shards run.
///
/// # Errors
/// As [`merge`] for folders that are not shards of one batch.
pub fn status(dirs: &[PathBuf]) -> Result<Status> {
    let found = find_shards(dirs, true)?;
    Ok(Status { shards: progress(&found)?, starting: found.starting.iter().map(|d| d.to_path_buf()).collect() })
}

/// Progress of each shard of `found`.
fn progress(found: &Found<'_>) -> Result<Vec<ShardProgress>> {
    let f = &found.first.1;
    let mut out = Vec::new();
    for (i, slot) in found.shards.iter().enumerate() {
        let shard = Shard { index: i as u64 + 1, count: f.shard.count };
        let total = shard_episodes(f.run.episodes, shard);
        let Some((dir, m)) = slot else {
            out.push(ShardProgress { shard, dir: None, done: 0, total, state: ShardState::Missing });
            continue;
        };
        let finished = if dir.join("episodes.csv").is_file() && dir.join("summary.json").is_file() {
            let s = read_summary(dir)?;
            (s.run == m.run).then_some(s.summary.outcomes.episodes)
        } else {
            None
        };
        let (done, state) = match finished {
            Some(n) if n == total => (n, ShardState::Done),
            Some(n) => (n, ShardState::Interrupted),
            None => (partial_rows(dir)?, ShardState::Started),
        };
        out.push(ShardProgress { shard, dir: Some(dir.to_path_buf()), done, total, state });
    }
    Ok(out)
}

/// [`status`] as text: a line per shard (`shard K/N  DONE/TOTAL  STATE  FOLDER`), then the total.
pub fn status_text(status: &Status) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let progress = &status.shards;
    for p in progress {
        let dir = p.dir.as_ref().map_or_else(|| "-".into(), |d| d.display().to_string());
        let counts = format!("{}/{}", p.done, p.total);
        let _ = writeln!(s, "shard {:<7} {counts:>17}  {:<19}  {dir}", p.shard.to_string(), p.state.label());
    }
    let (done, total): (u64, u64) = progress.iter().fold((0, 0), |(d, t), p| (d + p.done, t + p.total));
    let finished = progress.iter().filter(|p| p.state == ShardState::Done).count();
    for dir in &status.starting {
        let _ = writeln!(s, "(starting: nothing written yet in {})", dir.display());
    }
    let _ = writeln!(
        s,
        "total: {done}/{total} episodes ({:.1} %), {finished} of {} shards done",
        100.0 * done as f64 / total.max(1) as f64,
        progress.len()
    );
    s
}

/// The result of [`merge`].
#[derive(Debug, Clone)]
pub struct Merged {
    /// The batch (shard `None`).
    pub run: RunInfo,
    /// Parameter columns.
    pub params: Vec<String>,
    /// All rows, in episode order.
    pub rows: Vec<EpisodeResult>,
    /// Their summary: what one machine running the whole batch prints.
    pub summary: Summary,
}

/// Merges the outputs of shards 1/N … N/N of one batch. With `out_dir`, writes the merged
/// `episodes.csv`, `summary.json` and `spec.toml` there: byte for byte what one machine
/// running the whole batch writes.
///
/// # Errors
/// [`Error::Results`] when a folder is not a shard, folders belong to different batches (spec,
/// seed, twin version, …), a shard is repeated, or a file is malformed; when shards are missing
/// or unfinished, one error naming each with the command that reruns only it.
pub fn merge(dirs: &[PathBuf], out_dir: Option<&Path>) -> Result<Merged> {
    let found = find_shards(dirs, false)?;
    let (first_dir, f) = &found.first;
    let progress = progress(&found)?;
    let unfinished: Vec<String> = progress
        .iter()
        .filter(|p| p.state != ShardState::Done)
        .map(|p| {
            let (dir, why) = match &p.dir {
                Some(d) => (
                    d.clone(),
                    format!("{} of {} episodes finished: cancelled, failed or still running", p.done, p.total),
                ),
                None => (sibling_dir(first_dir, f.shard.index, p.shard.index), "no folder of it was given".into()),
            };
            // A shard's own command line when it left one, else the first shard's adapted.
            let own = found.shards[(p.shard.index - 1) as usize].as_ref().map(|(_, m)| m);
            let cmd = own.unwrap_or(f).rerun_command(p.shard.index, &dir);
            format!("shard {} is {} ({why}); rerun only it:\n    {cmd}", p.shard, p.state.label())
        })
        .collect();
    if !unfinished.is_empty() {
        return Err(Error::Results {
            path: first_dir.join(MANIFEST),
            line: None,
            message: format!(
                "cannot merge: {} of {} shards not finished\n  {}\n(then merge again; `twin randomize merge --status DIR…` shows progress)",
                unfinished.len(),
                progress.len(),
                unfinished.join("\n  ")
            ),
        });
    }
    let mut params: Option<Vec<String>> = None;
    let mut rows = Vec::new();
    for (dir, m) in found.shards.iter().flatten() {
        let csv_path = dir.join("episodes.csv");
        let (p, r) = read_csv(&csv_path)?;
        if let Some(r) = r.iter().find(|r| !m.shard.contains(r.index)) {
            return Err(Error::Results {
                path: csv_path,
                line: None,
                message: format!("episode {} does not belong to shard {}", r.index, m.shard),
            });
        }
        if r.len() as u64 != m.shard_episodes {
            return Err(Error::Results {
                path: csv_path,
                line: None,
                message: format!(
                    "{} rows where summary.json counts {}: the folder was changed by hand; rerun the shard: {}",
                    r.len(),
                    m.shard_episodes,
                    m.rerun_command(m.shard.index, dir)
                ),
            });
        }
        match &params {
            None => params = Some(p),
            Some(q) if *q != p => {
                return Err(Error::Results {
                    path: csv_path,
                    line: Some(1),
                    message: "parameter columns differ from the other shards".into(),
                });
            }
            Some(_) => {}
        }
        rows.extend(r);
    }
    let mut run = f.run.clone();
    run.shard = None;
    let params = params.unwrap_or_default();
    rows.sort_by_key(|r| r.index);
    let mut builder = SummaryBuilder::new(&params);
    for r in &rows {
        builder.push(r);
    }
    let summary = builder.finish();
    if let Some(dir) = out_dir {
        std::fs::create_dir_all(dir).map_err(|source| Error::Io { path: dir.to_path_buf(), source })?;
        let csv_path = dir.join("episodes.csv");
        write_atomic(&csv_path, |f| write_csv(&csv_path, std::io::BufWriter::new(f), &params, &rows))?;
        write_summary(dir, &run, &summary)?;
        let spec_path = dir.join("spec.toml");
        write_atomic(&spec_path, |f| {
            f.write_all(run.spec.as_bytes()).map_err(|source| Error::Io { path: spec_path.clone(), source })
        })?;
    }
    Ok(Merged { run, params, rows, summary })
}

/// The folder shard `index` would have, guessed from shard `known`'s folder `dir`: its name with
/// a trailing `known` replaced (`runs/shard-2` → `runs/shard-3`), else `<dir>-shard-<index>`.
fn sibling_dir(dir: &Path, known: u64, index: u64) -> PathBuf {
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let suffix = known.to_string();
    match name.strip_suffix(&suffix) {
        Some(stem) if !stem.ends_with(|c: char| c.is_ascii_digit()) => dir.with_file_name(format!("{stem}{index}")),
        _ => dir.with_file_name(format!("{name}-shard-{index}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_episode_counts_add_up() {
        for episodes in [0u64, 1, 7, 100, 101] {
            for count in 1..=9u64 {
                let mut total = 0;
                for index in 1..=count {
                    let shard = Shard { index, count };
                    let n = shard_episodes(episodes, shard);
                    assert_eq!(n, (0..episodes).filter(|&i| shard.contains(i)).count() as u64);
                    total += n;
                }
                assert_eq!(total, episodes);
            }
        }
    }

    #[test]
    fn sibling_folders_follow_the_shard_number() {
        assert_eq!(sibling_dir(Path::new("runs/r7/shard-2"), 2, 13), Path::new("runs/r7/shard-13"));
        assert_eq!(sibling_dir(Path::new("runs/s12"), 2, 3), Path::new("runs/s12-shard-3"));
        assert_eq!(sibling_dir(Path::new("out"), 1, 4), Path::new("out-shard-4"));
    }

    #[test]
    fn rerun_command_replaces_shard_and_out() {
        let run = RunInfo {
            model: "m.xml".into(),
            seed: 7,
            episodes: 10,
            duration_secs: 1.0,
            timestep_secs: 0.002,
            controller: "pd-hold".into(),
            fall_height_fraction: 0.6,
            fall_tilt_rad: 1.0,
            feet: vec![],
            spec: "[friction]\n".into(),
            shard: Some(Shard { index: 2, count: 4 }),
        };
        let cwd = std::env::current_dir().unwrap();
        let argv = ["twin", "randomize", "m.xml", "--shard", "2/4", "--out=runs/shard-2", "--config", "a b.toml"];
        let m = ShardManifest::new(&run, "0.1.0", argv.iter().map(|s| s.to_string()).collect(), cwd).unwrap();
        assert_eq!(m.shard_episodes, 3);
        assert_eq!(
            m.rerun_command(3, Path::new("runs/shard-3")),
            "twin randomize m.xml --shard 3/4 --out=runs/shard-3 --config 'a b.toml'"
        );
        assert_eq!(m.spec_sha256, spec_sha256("[friction]\n"));
        assert_eq!(m.spec_sha256.len(), 64);
    }
}
