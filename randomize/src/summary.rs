//! Per-episode CSV rows and the batch summary computed from them.
//!
//! The summary is a pure function of the rows in episode order, so a single machine and the
//! merge of its shards produce the same bytes. It keeps a handful of numbers per episode (for
//! exact quantiles) and running sums per parameter, not the episodes themselves.

use crate::episode::EpisodeResult;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::path::Path;
use twin_core::engine::{Measurement, Verdict};

/// The fixed leading CSV columns; the drawn parameters follow.
pub const METRIC_COLUMNS: [&str; 13] = [
    "episode",
    "success",
    "fell",
    "fall_time_secs",
    "unstable",
    "unstable_reason",
    "sim_secs",
    "distance_m",
    "avg_speed_mps",
    "steps_taken",
    "max_tilt_rad",
    "saturation_secs",
    "energy_j",
];

/// The column of check verdicts (`name=PASS;name=FAIL`), after [`METRIC_COLUMNS`], in
/// batches with checks only.
pub const CHECKS_COLUMN: &str = "checks";

/// The column of the failed checks' causes (`controller: exited: exit status: 3 at t = …`,
/// several joined by ` | `), right after the [`CHECKS_COLUMN`] (files written before it
/// existed lack it and still read).
pub const FAILURE_COLUMN: &str = "failure";

/// Separator of several causes in the [`FAILURE_COLUMN`].
const CAUSE_SEPARATOR: &str = " | ";

/// What a failed check's cause counts as in [`Summary::failures`]: the check's name and the
/// cause up to its first `:` (`controller: never joined`).
pub fn failure_kind(check: &str, cause: &str) -> String {
    format!("{check}: {}", cause.split(':').next().unwrap_or(cause).trim())
}

/// Prefix of the columns holding the checks' numbers (`metric:scenario.slip_mean_m`), between
/// the [`CHECKS_COLUMN`] and the drawn parameters (no parameter kind is called `metric`).
pub const CHECK_METRIC_PREFIX: &str = "metric:";

/// The name of check `check`'s measurement `m` as a CSV column (without
/// [`CHECK_METRIC_PREFIX`]) and a summary row: `check.name` with the unit as a suffix
/// (`scenario.average_speed_mps`), so that a summary read back from the CSV, where units are
/// not kept, names it the same.
pub fn check_metric_name(check: &str, m: &Measurement) -> String {
    let unit = match m.unit {
        "" => String::new(),
        "m/s" => "_mps".into(),
        u => format!("_{}", u.replace(|c: char| !c.is_ascii_alphanumeric(), "_")),
    };
    format!("{check}.{}{unit}", m.name)
}

/// The check metric columns of the verdicts `checks` (the same in every episode of a batch).
pub fn check_metric_names(checks: &[Verdict]) -> Vec<String> {
    checks.iter().flat_map(|c| c.metrics.iter().map(|m| check_metric_name(&c.name, m))).collect()
}

/// The CSV header for parameter columns `params`, with the [`CHECKS_COLUMN`] and the checks'
/// metric columns `check_metrics` (from [`check_metric_names`]) when the batch has checks.
pub fn csv_header(params: &[String], with_checks: bool, check_metrics: &[String]) -> Vec<String> {
    METRIC_COLUMNS
        .iter()
        .map(|s| s.to_string())
        .chain(with_checks.then(|| CHECKS_COLUMN.to_string()))
        .chain(with_checks.then(|| FAILURE_COLUMN.to_string()))
        .chain(check_metrics.iter().map(|m| format!("{CHECK_METRIC_PREFIX}{m}")))
        .chain(params.iter().cloned())
        .collect()
}

/// One CSV record. Floats use Rust's shortest round-trip form, so parsing gives back the exact
/// value.
pub fn csv_record(r: &EpisodeResult) -> Vec<String> {
    let mut out = vec![
        r.index.to_string(),
        u8::from(r.success()).to_string(),
        u8::from(r.fell).to_string(),
        r.fall_time_secs.map_or_else(String::new, |t| t.to_string()),
        u8::from(r.unstable).to_string(),
        r.unstable_reason.clone(),
        r.sim_secs.to_string(),
        r.distance_m.to_string(),
        r.avg_speed_mps.to_string(),
        r.steps_taken.to_string(),
        r.max_tilt_rad.to_string(),
        r.saturation_secs.to_string(),
        r.energy_j.to_string(),
    ];
    if !r.checks.is_empty() {
        let verdicts: Vec<String> =
            r.checks.iter().map(|c| format!("{}={}", c.name, if c.passed { "PASS" } else { "FAIL" })).collect();
        out.push(verdicts.join(";"));
        let causes: Vec<String> = r
            .checks
            .iter()
            .filter(|c| !c.passed)
            .map(|c| format!("{}: {}", c.name, c.cause.as_deref().unwrap_or("failed").replace(CAUSE_SEPARATOR, " / ")))
            .collect();
        out.push(causes.join(CAUSE_SEPARATOR));
        out.extend(r.checks.iter().flat_map(|c| c.metrics.iter().map(|m| m.value.to_string())));
    }
    out.extend(r.params.iter().map(f64::to_string));
    out
}

/// Reads a per-episode CSV back: the parameter column names and the rows, in file order.
///
/// # Errors
/// [`Error::Results`] naming the file and line for anything that is not such a CSV.
pub fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<EpisodeResult>)> {
    let file = std::fs::File::open(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    read_csv_from(path, file)
}

fn read_csv_from(path: &Path, reader: impl Read) -> Result<(Vec<String>, Vec<EpisodeResult>)> {
    let err = |line: Option<u64>, message: String| Error::Results { path: path.to_path_buf(), line, message };
    let mut rdr = csv::ReaderBuilder::new().has_headers(true).from_reader(reader);
    let header = rdr.headers().map_err(|e| err(Some(1), e.to_string()))?.clone();
    let names: Vec<&str> = header.iter().collect();
    if names.len() < METRIC_COLUMNS.len() || names[..METRIC_COLUMNS.len()] != METRIC_COLUMNS {
        return Err(err(
            Some(1),
            format!("not a `twin randomize` episodes file: the header must start with {}", METRIC_COLUMNS.join(",")),
        ));
    }
    let with_checks = names.get(METRIC_COLUMNS.len()) == Some(&CHECKS_COLUMN);
    let with_failure = with_checks && names.get(METRIC_COLUMNS.len() + 1) == Some(&FAILURE_COLUMN);
    let first_metric = METRIC_COLUMNS.len() + usize::from(with_checks) + usize::from(with_failure);
    // The checks' metric columns: (check, measurement name), as written by `csv_header`.
    let check_metrics: Vec<(&str, &str)> = names[first_metric..]
        .iter()
        .map_while(|n| n.strip_prefix(CHECK_METRIC_PREFIX))
        .map(|n| n.split_once('.').unwrap_or((n, "")))
        .collect();
    let first_param = first_metric + check_metrics.len();
    let params: Vec<String> = names[first_param..].iter().map(|s| s.to_string()).collect();
    let mut rows = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let line = i as u64 + 2;
        let rec = rec.map_err(|e| err(Some(line), e.to_string()))?;
        let f = |k: usize| -> Result<f64> {
            rec[k].parse::<f64>().map_err(|_| {
                err(
                    Some(line),
                    format!("column {}: {:?} is not a number", names[k], twin_core::fsio::excerpt(&rec[k], 200)),
                )
            })
        };
        let b = |k: usize| -> Result<bool> {
            match &rec[k] {
                "0" => Ok(false),
                "1" => Ok(true),
                v => Err(err(Some(line), format!("column {}: expected 0 or 1, got {v:?}", names[k]))),
            }
        };
        let u = |k: usize| -> Result<u64> {
            rec[k].parse::<u64>().map_err(|_| {
                err(
                    Some(line),
                    format!("column {}: {:?} is not a count", names[k], twin_core::fsio::excerpt(&rec[k], 200)),
                )
            })
        };
        let r = EpisodeResult {
            index: u(0)?,
            fell: b(2)?,
            fall_time_secs: if rec[3].is_empty() { None } else { Some(f(3)?) },
            unstable: b(4)?,
            unstable_reason: rec[5].to_string(),
            sim_secs: f(6)?,
            distance_m: f(7)?,
            avg_speed_mps: f(8)?,
            steps_taken: u(9)?,
            max_tilt_rad: f(10)?,
            saturation_secs: f(11)?,
            energy_j: f(12)?,
            params: (first_param..names.len()).map(f).collect::<Result<_>>()?,
            checks: if with_checks {
                let mut verdicts = read_verdicts(&rec[METRIC_COLUMNS.len()]).map_err(|m| err(Some(line), m))?;
                if with_failure {
                    for cause in rec[METRIC_COLUMNS.len() + 1].split(CAUSE_SEPARATOR).filter(|c| !c.is_empty()) {
                        let (name, why) = cause.split_once(": ").unwrap_or((cause, "failed"));
                        if let Some(v) = verdicts.iter_mut().find(|v| v.name == name && !v.passed) {
                            v.cause = Some(why.to_string());
                        }
                    }
                }
                for (k, (check, name)) in check_metrics.iter().enumerate() {
                    let value = f(first_metric + k)?;
                    let Some(v) = verdicts.iter_mut().find(|v| v.name == *check) else {
                        return Err(err(
                            Some(line),
                            format!("column {}: the checks column has no check {check:?}", names[first_metric + k]),
                        ));
                    };
                    v.metrics.push(Measurement::new(*name, value, ""));
                }
                verdicts
            } else {
                Vec::new()
            },
        };
        if b(1)? != r.success() {
            return Err(err(Some(line), "column success disagrees with fell/unstable/checks".into()));
        }
        rows.push(r);
    }
    Ok((params, rows))
}

/// The verdicts of a [`CHECKS_COLUMN`] cell (names and PASS/FAIL; the numbers stay in memory).
fn read_verdicts(cell: &str) -> std::result::Result<Vec<twin_core::engine::Verdict>, String> {
    cell.split(';')
        .filter(|v| !v.is_empty())
        .map(|v| {
            let (name, verdict) =
                v.rsplit_once('=').ok_or_else(|| format!("column checks: {v:?} is not name=PASS|FAIL"))?;
            let passed = match verdict {
                "PASS" => true,
                "FAIL" => false,
                _ => return Err(format!("column checks: {v:?} is not name=PASS|FAIL")),
            };
            Ok(twin_core::engine::Verdict {
                name: name.to_string(),
                passed,
                metrics: Vec::new(),
                details: Vec::new(),
                cause: None,
            })
        })
        .collect()
}

/// Writes rows as CSV (header first).
///
/// # Errors
/// [`Error::Io`] naming `path`.
pub fn write_csv<'a>(
    path: &Path,
    w: impl Write,
    params: &[String],
    rows: impl IntoIterator<Item = &'a EpisodeResult>,
) -> Result<()> {
    let io = |e: csv::Error| Error::Io { path: path.to_path_buf(), source: std::io::Error::other(e) };
    let rows: Vec<&EpisodeResult> = rows.into_iter().collect();
    let first_checked = rows.iter().find(|r| !r.checks.is_empty());
    let check_metrics = first_checked.map(|r| check_metric_names(&r.checks)).unwrap_or_default();
    let mut wtr = csv::Writer::from_writer(w);
    wtr.write_record(csv_header(params, first_checked.is_some(), &check_metrics)).map_err(io)?;
    for r in rows {
        wtr.write_record(csv_record(r)).map_err(io)?;
    }
    wtr.flush().map_err(|source| Error::Io { path: path.to_path_buf(), source })
}

/// Quantiles of one metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Quantiles {
    /// Metric name and unit, e.g. `distance_m`.
    pub metric: String,
    /// Number of values (episodes, or falls for `fall_time_secs`).
    pub count: u64,
    /// Minimum.
    pub min: f64,
    /// 5th percentile.
    pub p05: f64,
    /// Median.
    pub p50: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Maximum.
    pub max: f64,
}

/// How one drawn parameter differs between failed and successful episodes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Separation {
    /// Parameter column.
    pub parameter: String,
    /// Mean over failed episodes (fell or unstable).
    pub mean_failed: f64,
    /// Mean over successful episodes.
    pub mean_succeeded: f64,
    /// Standardized mean difference (mean_failed − mean_succeeded) / pooled standard deviation.
    pub smd: f64,
}

/// How a batch's episodes ended: the counts, and the success rate with its interval. A batch's
/// [`Summary`] and each level of a sweep ([`crate::sweep::LevelRow`]) carry one (flattened
/// into their JSON).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Outcomes {
    /// Episodes in the summary.
    pub episodes: u64,
    /// Episodes that neither fell nor diverged.
    pub succeeded: u64,
    /// Episodes that fell.
    pub fell: u64,
    /// Episodes that diverged.
    pub unstable: u64,
    /// succeeded / episodes (0 for no episode).
    pub success_rate: f64,
    /// 95 % Wilson score interval of the success rate.
    pub success_rate_ci95: [f64; 2],
}

impl Outcomes {
    /// The outcomes of `episodes` of which `succeeded` succeeded, `fell` fell and `unstable`
    /// diverged: the rate and its 95 % Wilson interval ([`wilson`]) follow.
    pub fn of(episodes: u64, succeeded: u64, fell: u64, unstable: u64) -> Outcomes {
        let success_rate = if episodes > 0 { succeeded as f64 / episodes as f64 } else { 0.0 };
        Outcomes { episodes, succeeded, fell, unstable, success_rate, success_rate_ci95: wilson(succeeded, episodes) }
    }
}

/// The batch summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// How the episodes ended.
    #[serde(flatten)]
    pub outcomes: Outcomes,
    /// Quantiles of each metric.
    pub quantiles: Vec<Quantiles>,
    /// Parameters ranked by |SMD|, largest first (empty unless both groups have ≥ 2 episodes).
    pub separation: Vec<Separation>,
    /// Failed episodes per failure kind ([`failure_kind`]: a failed check and its cause's
    /// kind, e.g. `controller: exited`), most frequent first; an episode counts once per
    /// failed check.
    #[serde(default)]
    pub failures: Vec<FailureCount>,
}

/// How many episodes failed one way.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FailureCount {
    /// The failure kind ([`failure_kind`]).
    pub kind: String,
    /// Episodes.
    pub episodes: u64,
}

/// Running per-group moments (Welford) of one parameter.
#[derive(Debug, Clone, Default)]
struct Moments {
    n: f64,
    mean: f64,
    m2: f64,
}

impl Moments {
    fn push(&mut self, x: f64) {
        self.n += 1.0;
        let d = x - self.mean;
        self.mean += d / self.n;
        self.m2 += d * (x - self.mean);
    }
}

/// Builds a [`Summary`] from rows pushed in episode order.
#[derive(Debug, Clone)]
pub struct SummaryBuilder {
    params: Vec<String>,
    episodes: u64,
    succeeded: u64,
    fell: u64,
    unstable: u64,
    metrics: [Vec<f64>; 7],
    /// The checks' metrics (e.g. a scenario's gait metrics), by [`check_metric_name`], in the
    /// order first seen.
    check_metrics: Vec<(String, Vec<f64>)>,
    groups: Vec<[Moments; 2]>,
    failures: Vec<FailureCount>,
}

const QUANTILE_METRICS: [&str; 7] =
    ["distance_m", "avg_speed_mps", "steps_taken", "max_tilt_rad", "saturation_secs", "energy_j", "fall_time_secs"];

impl SummaryBuilder {
    /// An empty summary over parameter columns `params`.
    pub fn new(params: &[String]) -> SummaryBuilder {
        SummaryBuilder {
            params: params.to_vec(),
            episodes: 0,
            succeeded: 0,
            fell: 0,
            unstable: 0,
            metrics: Default::default(),
            check_metrics: Vec::new(),
            groups: vec![Default::default(); params.len()],
            failures: Vec::new(),
        }
    }

    /// Adds one episode (in index order).
    pub fn push(&mut self, r: &EpisodeResult) {
        self.episodes += 1;
        self.succeeded += u64::from(r.success());
        self.fell += u64::from(r.fell);
        self.unstable += u64::from(r.unstable);
        for c in r.checks.iter().filter(|c| !c.passed) {
            let kind = failure_kind(&c.name, c.cause.as_deref().unwrap_or("failed"));
            match self.failures.iter_mut().find(|f| f.kind == kind) {
                Some(f) => f.episodes += 1,
                None => self.failures.push(FailureCount { kind, episodes: 1 }),
            }
        }
        // Diverged episodes carry no meaningful motion metrics.
        if !r.unstable {
            let values =
                [r.distance_m, r.avg_speed_mps, r.steps_taken as f64, r.max_tilt_rad, r.saturation_secs, r.energy_j];
            for (m, v) in self.metrics.iter_mut().zip(values) {
                m.push(v);
            }
            for c in &r.checks {
                for m in &c.metrics {
                    let name = check_metric_name(&c.name, m);
                    match self.check_metrics.iter_mut().find(|(n, _)| *n == name) {
                        Some((_, values)) => values.push(m.value),
                        None => self.check_metrics.push((name, vec![m.value])),
                    }
                }
            }
        }
        if let Some(t) = r.fall_time_secs {
            self.metrics[6].push(t);
        }
        let group = usize::from(r.success());
        for (g, &x) in self.groups.iter_mut().zip(&r.params) {
            g[group].push(x);
        }
    }

    /// The summary so far.
    pub fn finish(&self) -> Summary {
        let quantiles = QUANTILE_METRICS
            .iter()
            .map(|name| name.to_string())
            .zip(&self.metrics)
            .chain(self.check_metrics.iter().map(|(name, v)| (name.clone(), v)))
            .filter(|(_, v)| !v.is_empty())
            .map(|(name, v)| {
                let mut s = v.clone();
                s.sort_by(f64::total_cmp);
                Quantiles {
                    metric: name,
                    count: s.len() as u64,
                    min: s[0],
                    p05: quantile(&s, 0.05),
                    p50: quantile(&s, 0.5),
                    p95: quantile(&s, 0.95),
                    max: s[s.len() - 1],
                }
            })
            .collect();
        let mut separation: Vec<Separation> = self
            .params
            .iter()
            .zip(&self.groups)
            .filter(|(_, [f, s])| f.n >= 2.0 && s.n >= 2.0)
            .map(|(name, [f, s])| {
                let pooled = ((f.m2 + s.m2) / (f.n + s.n - 2.0)).sqrt();
                let diff = f.mean - s.mean;
                let smd = if pooled > 0.0 { diff / pooled } else { 0.0 };
                Separation { parameter: name.clone(), mean_failed: f.mean, mean_succeeded: s.mean, smd }
            })
            .collect();
        separation.sort_by(|a, b| b.smd.abs().total_cmp(&a.smd.abs()));
        Summary {
            outcomes: Outcomes::of(self.episodes, self.succeeded, self.fell, self.unstable),
            quantiles,
            separation,
            failures: {
                let mut f = self.failures.clone();
                f.sort_by(|a, b| b.episodes.cmp(&a.episodes).then(a.kind.cmp(&b.kind)));
                f
            },
        }
    }
}

/// Linear-interpolation quantile of sorted values (the "type 7" definition).
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    let h = (sorted.len() - 1) as f64 * p;
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

/// 95 % Wilson score interval for `k` successes in `n` trials.
pub fn wilson(k: u64, n: u64) -> [f64; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let z = 1.959_963_984_540_054;
    let (n, p) = (n as f64, k as f64 / n as f64);
    let denom = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / denom;
    let half = z * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt() / denom;
    [(centre - half).max(0.0), (centre + half).min(1.0)]
}

impl Summary {
    /// The terminal report.
    pub fn to_text(&self, requested: u64) -> String {
        let mut s = String::new();
        use std::fmt::Write as _;
        let _ = writeln!(
            s,
            "episodes: {} of {requested}{}",
            self.outcomes.episodes,
            if self.outcomes.episodes < requested { " (interrupted: summary of the finished episodes)" } else { "" }
        );
        let _ = writeln!(
            s,
            "success: {}/{} = {:.1} % (95 % CI {:.1}–{:.1} %); fell {}, unstable {}",
            self.outcomes.succeeded,
            self.outcomes.episodes,
            100.0 * self.outcomes.success_rate,
            100.0 * self.outcomes.success_rate_ci95[0],
            100.0 * self.outcomes.success_rate_ci95[1],
            self.outcomes.fell,
            self.outcomes.unstable
        );
        if !self.failures.is_empty() {
            let kinds: Vec<String> = self.failures.iter().map(|f| format!("{} ×{}", f.kind, f.episodes)).collect();
            let _ = writeln!(s, "failed checks: {}", kinds.join(", "));
        }
        if !self.quantiles.is_empty() {
            let w = self.quantiles.iter().map(|q| q.metric.chars().count()).max().unwrap_or(0).max(18);
            let _ = writeln!(
                s,
                "\n{:<w$} {:>7} {:>10} {:>10} {:>10} {:>10} {:>10}",
                "metric", "n", "min", "p5", "median", "p95", "max"
            );
            for q in &self.quantiles {
                let _ = writeln!(
                    s,
                    "{:<w$} {:>7} {:>10.4} {:>10.4} {:>10.4} {:>10.4} {:>10.4}",
                    q.metric, q.count, q.min, q.p05, q.p50, q.p95, q.max
                );
            }
        }
        if self.separation.is_empty() {
            let _ = writeln!(s, "\nno parameter ranking: needs at least 2 failed and 2 successful episodes");
        } else {
            let _ = writeln!(s, "\nparameters separating failures from successes (standardized mean difference):");
            let _ = writeln!(s, "{:<40} {:>12} {:>12} {:>8}", "parameter", "mean failed", "mean ok", "SMD");
            for p in self.separation.iter().take(8) {
                let _ = writeln!(
                    s,
                    "{:<40} {:>12.4} {:>12.4} {:>+8.2}",
                    p.parameter, p.mean_failed, p.mean_succeeded, p.smd
                );
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_interval_matches_reference_values() {
        // Reference: Wilson (1927) interval for 8/10 successes, z = 1.96: 0.4902–0.9433.
        let [lo, hi] = wilson(8, 10);
        assert!((lo - 0.4902).abs() < 1e-4 && (hi - 0.9433).abs() < 1e-4, "{lo} {hi}");
        let [lo, hi] = wilson(0, 20);
        assert_eq!(lo, 0.0);
        assert!((hi - 0.1611).abs() < 1e-4, "{hi}");
    }

    #[test]
    fn quantiles_interpolate() {
        let s = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&s, 0.5), 3.0);
        assert_eq!(quantile(&s, 0.25), 2.0);
        assert!((quantile(&s, 0.05) - 1.2).abs() < 1e-12);
    }
}
