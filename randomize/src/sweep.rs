//! Success against one parameter: `twin randomize --sweep NAME=FROM:TO:STEP`.
//!
//! A sweep runs one batch per level of a parameter, with the same master seed at every level
//! (so the levels differ by that parameter only: each episode's other draws are the same), and
//! tabulates per level the success rate with its 95 % Wilson interval and the medians of key
//! metrics ([`LevelRow`]), the first level whose success falls below a threshold, as text, CSV
//! ([`to_csv`]) and an SVG plot ([`to_svg`], [`twin_core::plot`]).
//!
//! The parameter is either a term of the randomization spec ([`Target::Spec`], e.g.
//! `push.speed_mps`, `friction`, `imu_noise_std`: at each level the term's draw is fixed to the
//! level, in the term's own mode — `push.speed_mps = 0.4` kicks at 0.4 m/s, `friction = 0.6`
//! scales every friction by 0.6) or a key of the scenario file ([`Target::Scenario`], e.g.
//! `terrain.difficulty`, `terrain.amplitude_m`, `walk.vx`: the file as written with that key
//! set). `spec.NAME` or `scenario.NAME` says which when a name is both.
//!
//! Each level is a batch of its own in `OUT/level-NN/` (`episodes.csv`, `summary.json`, and with
//! `--shard` its `shard.json`); `OUT/sweep.json` ([`SweepManifest`]) names the parameter and
//! levels, so `twin randomize merge` merges shard folders level by level and writes the same
//! `sweep.csv` and `sweep.svg` one machine would.

use crate::error::{Error, Result};
use crate::spec::{Dist, Spec, Term};
use crate::summary::{Outcomes, Summary};
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The sweep's record in its output folder.
pub const MANIFEST: &str = "sweep.json";

/// Default success threshold of [`first_below`] (0.8).
pub const DEFAULT_THRESHOLD: f64 = 0.8;

/// Most levels of one sweep.
pub const MAX_LEVELS: usize = 1000;

/// A parsed `--sweep NAME=FROM:TO:STEP`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sweep {
    /// The parameter as given.
    pub name: String,
    /// Levels, FROM to TO (included, within 1e-9 of a step) by STEP.
    pub levels: Vec<f64>,
}

/// Where a swept parameter lives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// A term of the randomization spec, by its key ([`Spec::terms`]).
    Spec(String),
    /// A dotted key of the scenario file.
    Scenario(String),
}

impl std::str::FromStr for Sweep {
    type Err = Error;

    fn from_str(arg: &str) -> Result<Sweep> {
        let bad = |m: String| {
            Error::Options(format!("--sweep {arg}: {m} (expected NAME=FROM:TO:STEP, e.g. terrain.difficulty=0:1:0.2)"))
        };
        let (name, range) = arg.split_once('=').ok_or_else(|| bad("no `=`".into()))?;
        let name = name.trim();
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.') {
            return Err(bad(format!("`{name}` is not a parameter name (letters, digits, `_` and `.`)")));
        }
        let parts: Vec<&str> = range.split(':').collect();
        if parts.len() != 3 {
            return Err(bad(format!("`{range}` is not FROM:TO:STEP")));
        }
        let num = |s: &str, what: &str| -> Result<f64> {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(format!("{what} `{s}` is not a finite number")))
        };
        let (from, to, step) = (num(parts[0], "FROM")?, num(parts[1], "TO")?, num(parts[2], "STEP")?);
        if step <= 0.0 {
            return Err(bad(format!("STEP must be positive (got {step})")));
        }
        if to < from {
            return Err(bad(format!("TO ({to}) is below FROM ({from})")));
        }
        let n = ((to - from) / step + 1e-9).floor() + 1.0;
        if n > MAX_LEVELS as f64 {
            return Err(bad(format!("{n} levels: at most {MAX_LEVELS}")));
        }
        // Each level from FROM and its index (no accumulated rounding), rounded to 12 digits so
        // that 0.1·3 prints as 0.3.
        let levels = (0..n as usize).map(|i| round12(from + step * i as f64)).collect();
        Ok(Sweep { name: name.to_string(), levels })
    }
}

fn round12(v: f64) -> f64 {
    let r = (v * 1e12).round() / 1e12;
    if r == 0.0 { 0.0 } else { r }
}

impl Sweep {
    /// Where the parameter lives: `spec.`/`scenario.` prefixes decide; otherwise a term of
    /// `spec` (or of the default spec) by that key, else a scenario key.
    pub fn target(&self, spec: &Spec) -> Target {
        if let Some(k) = self.name.strip_prefix("spec.") {
            return Target::Spec(k.to_string());
        }
        if let Some(k) = self.name.strip_prefix("scenario.") {
            return Target::Scenario(k.to_string());
        }
        let known = |s: &Spec| s.terms().iter().any(|(k, _)| *k == self.name);
        if known(spec) || known(&Spec::default_spec()) || SPEC_KEYS.contains(&self.name.as_str()) {
            Target::Spec(self.name.clone())
        } else {
            Target::Scenario(self.name.clone())
        }
    }

    /// Output folder of level `i`.
    pub fn level_dir(out: &Path, i: usize) -> PathBuf {
        out.join(format!("level-{i:02}"))
    }
}

/// The spec's single terms (those `--sweep` can name without a `spec.` prefix).
const SPEC_KEYS: [&str; 17] = [
    "friction",
    "mass",
    "com_offset",
    "damping",
    "frictionloss",
    "armature",
    "actuator_strength",
    "gravity",
    "imu_noise_std",
    "imu_bias",
    "encoder_noise_std",
    "latency_steps",
    "delay_secs",
    "init_qpos",
    "camera_noise_std",
    "push.interval_secs",
    "push.speed_mps",
];

/// `spec` with term `key`'s draw fixed to `level` (its mode, selection and independence kept).
///
/// # Errors
/// [`Error::Options`] when the spec has no such term (naming the terms it has), or the level
/// is out of the term's range (e.g. a negative friction).
pub fn spec_at(spec: &Spec, key: &str, level: f64) -> Result<Spec> {
    let mut out = spec.clone();
    let term = out.term_mut(key).ok_or_else(|| {
        let have: Vec<String> = spec.terms().into_iter().map(|(k, _)| k).collect();
        Error::Options(format!(
            "--sweep {key}: the randomization spec has no `{key}` term (it has: {}); add one to the spec (--config) to sweep it",
            have.join(", ")
        ))
    })?;
    *term = Term { dist: Dist::Uniform, low: Some(level), high: Some(level), mean: None, std: None, ..term.clone() };
    out.validate(None).map_err(|e| Error::Options(format!("--sweep {key} = {level}: {e}")))?;
    Ok(out)
}

/// The scenario file `text` with dotted `key` set to `level` (an integer where the file has
/// one, or the level is whole and the key is `seed` or `count`).
///
/// # Errors
/// [`Error::Options`] when the file is not TOML, a part of the key is not a table, or an
/// integer key gets a fractional level.
pub fn scenario_text_at(text: &str, key: &str, level: f64) -> Result<String> {
    let bad = |m: String| Error::Options(format!("--sweep {key} = {level}: {m}"));
    let mut doc: toml::Table =
        toml::from_str(text).map_err(|e| bad(format!("the scenario is not TOML: {}", e.message())))?;
    let parts: Vec<&str> = key.split('.').collect();
    let (last, path) = parts.split_last().ok_or_else(|| bad("empty key".into()))?;
    let mut table = &mut doc;
    for p in path {
        let entry = table.entry(p.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        table = entry.as_table_mut().ok_or_else(|| bad(format!("`{p}` is not a table in the scenario")))?;
    }
    let integer = matches!(table.get(*last), Some(toml::Value::Integer(_))) || ["seed", "count"].contains(last);
    let value = if integer {
        if level.fract() != 0.0 || level < 0.0 {
            return Err(bad(format!("`{last}` takes a whole number ≥ 0")));
        }
        toml::Value::Integer(level as i64)
    } else {
        toml::Value::Float(level)
    };
    table.insert(last.to_string(), value);
    toml::to_string(&doc).map_err(|e| bad(format!("cannot write the scenario: {e}")))
}

/// One level's results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LevelRow {
    /// The parameter's value.
    pub level: f64,
    /// How its episodes ended.
    #[serde(flatten)]
    pub outcomes: Outcomes,
    /// Medians of [`KEY_METRICS`] (NaN where the batch has no such metric).
    pub medians: Vec<f64>,
}

/// Metrics whose medians each level reports: distance from the start, average speed,
/// touch-downs, largest tilt, and (with a walking scenario's checks) the distance along the
/// initial heading.
pub const KEY_METRICS: [&str; 5] = ["distance_m", "avg_speed_mps", "steps_taken", "max_tilt_rad", "scenario.forward_m"];

impl LevelRow {
    /// The row of a level from its batch summary.
    pub fn new(level: f64, s: &Summary) -> LevelRow {
        let median = |m: &str| s.quantiles.iter().find(|q| q.metric == m).map_or(f64::NAN, |q| q.p50);
        LevelRow { level, outcomes: s.outcomes, medians: KEY_METRICS.iter().map(|m| median(m)).collect() }
    }
}

/// The first level whose success rate is below `threshold`, if any.
pub fn first_below(rows: &[LevelRow], threshold: f64) -> Option<f64> {
    rows.iter().find(|r| r.outcomes.success_rate < threshold).map(|r| r.level)
}

fn fmt_num(v: f64) -> String {
    if v.is_nan() { String::new() } else { format!("{v}") }
}

/// The table as CSV: one row per level.
pub fn to_csv(name: &str, rows: &[LevelRow]) -> String {
    let mut s = format!("{name},episodes,succeeded,fell,unstable,success_rate,ci95_low,ci95_high");
    for m in KEY_METRICS {
        let _ = write!(s, ",median_{m}");
    }
    s.push('\n');
    for r in rows {
        let _ = write!(
            s,
            "{},{},{},{},{},{},{},{}",
            r.level,
            r.outcomes.episodes,
            r.outcomes.succeeded,
            r.outcomes.fell,
            r.outcomes.unstable,
            r.outcomes.success_rate,
            r.outcomes.success_rate_ci95[0],
            r.outcomes.success_rate_ci95[1]
        );
        for m in &r.medians {
            let _ = write!(s, ",{}", fmt_num(*m));
        }
        s.push('\n');
    }
    s
}

/// The table for the terminal, with the first level below `threshold`.
pub fn to_text(name: &str, rows: &[LevelRow], threshold: f64) -> String {
    let mut s = String::new();
    let w = name.chars().count().max(8);
    let _ = writeln!(
        s,
        "{name:<w$} {:>9} {:>8} {:>15} {:>6} {:>9} {:>11} {:>11}",
        "episodes", "success", "95 % CI", "fell", "unstable", "distance_m", "forward_m"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<w$} {:>9} {:>7.1}% {:>6.1}–{:>5.1} % {:>6} {:>9} {:>11.3} {:>11.3}",
            r.level,
            r.outcomes.episodes,
            100.0 * r.outcomes.success_rate,
            100.0 * r.outcomes.success_rate_ci95[0],
            100.0 * r.outcomes.success_rate_ci95[1],
            r.outcomes.fell,
            r.outcomes.unstable,
            r.medians[0],
            r.medians[4]
        );
    }
    match first_below(rows, threshold) {
        Some(l) => {
            let _ = writeln!(s, "success first below {:.0} % at {name} = {l}", 100.0 * threshold);
        }
        None => {
            let _ = writeln!(s, "success stays at or above {:.0} % at every level", 100.0 * threshold);
        }
    }
    s
}

/// The success rate (with its 95 % band) and the threshold against the level, as SVG.
pub fn to_svg(name: &str, rows: &[LevelRow], threshold: f64) -> String {
    use twin_core::plot::{COLORS, Plot, stack_svg};
    let mut p = Plot::new(&format!("Success against {name}"), name, "success rate");
    p.band(
        rows.iter().map(|r| (r.level, r.outcomes.success_rate_ci95[0], r.outcomes.success_rate_ci95[1])).collect(),
        COLORS[0],
    );
    let xy: Vec<(f64, f64)> = rows.iter().map(|r| (r.level, r.outcomes.success_rate)).collect();
    p.line("success", xy.clone(), COLORS[0]);
    p.points("", xy, COLORS[0]);
    if let (Some(a), Some(b)) = (rows.first(), rows.last()) {
        p.line(&format!("threshold {threshold}"), vec![(a.level, threshold), (b.level, threshold)], COLORS[1]);
        // Keep 0 and 1 in view.
        p.points("", vec![(a.level, 0.0), (a.level, 1.0)], "none");
    }
    stack_svg(&[p])
}

/// `sweep.json`: the parameter, its levels and the threshold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepManifest {
    /// The sweep.
    pub sweep: Sweep,
    /// Success threshold.
    pub threshold: f64,
}

impl SweepManifest {
    /// Writes it into `out` (atomically).
    ///
    /// # Errors
    /// [`Error::Io`] from writing.
    pub fn write(&self, out: &Path) -> Result<()> {
        crate::run::write_atomic(&out.join(MANIFEST), |b| {
            b.extend_from_slice(serde_json::to_string_pretty(self).unwrap_or_default().as_bytes());
            b.push(b'\n');
            Ok(())
        })
    }

    /// Reads `dir/sweep.json`; `None` if there is none (not a sweep's folder).
    ///
    /// # Errors
    /// [`Error::Results`] for a file that is not a sweep manifest.
    pub fn read(dir: &Path) -> Result<Option<SweepManifest>> {
        let path = dir.join(MANIFEST);
        if !path.exists() {
            return Ok(None);
        }
        let text = twin_core::fsio::read_to_string(&path)?;
        serde_json::from_str(&text).map(Some).map_err(|e| Error::Results {
            path,
            line: Some(e.line() as u64),
            message: format!("not a sweep manifest: {e}"),
        })
    }
}

/// Writes `sweep.csv` and `sweep.svg` into `out`.
///
/// # Errors
/// [`Error::Io`] from writing.
pub fn write_outputs(out: &Path, manifest: &SweepManifest, rows: &[LevelRow]) -> Result<()> {
    let name = &manifest.sweep.name;
    crate::run::write_atomic(&out.join("sweep.csv"), |b| {
        b.extend_from_slice(to_csv(name, rows).as_bytes());
        Ok(())
    })?;
    crate::run::write_atomic(&out.join("sweep.svg"), |b| {
        b.extend_from_slice(to_svg(name, rows, manifest.threshold).as_bytes());
        Ok(())
    })
}

/// Merges the folders of a sweep's shards level by level (each level as [`crate::merge`]) into
/// `out` (with its `sweep.json`, `sweep.csv` and `sweep.svg`); returns the manifest and rows.
///
/// # Errors
/// [`Error::Results`] when the shards swept different parameters or levels; as
/// [`crate::merge`].
pub fn merge(dirs: &[PathBuf], out: Option<&Path>) -> Result<(SweepManifest, Vec<LevelRow>)> {
    let mut manifest: Option<SweepManifest> = None;
    for d in dirs {
        let m = SweepManifest::read(d)?.ok_or_else(|| Error::Results {
            path: d.join(MANIFEST),
            line: None,
            message: "missing: the other folders are a sweep's shards, this one is not".into(),
        })?;
        match &manifest {
            Some(first) if *first != m => {
                return Err(Error::Results {
                    path: d.join(MANIFEST),
                    line: None,
                    message: format!(
                        "this shard swept {} over {:?}, the first one {} over {:?}: not one sweep",
                        m.sweep.name, m.sweep.levels, first.sweep.name, first.sweep.levels
                    ),
                });
            }
            _ => manifest = Some(m),
        }
    }
    let manifest = manifest.ok_or_else(|| Error::Options("no folders to merge".into()))?;
    if let Some(o) = out {
        std::fs::create_dir_all(o).map_err(|source| Error::Io { path: o.to_path_buf(), source })?;
        manifest.write(o)?;
    }
    let mut rows = Vec::new();
    for (i, &level) in manifest.sweep.levels.iter().enumerate() {
        let level_dirs: Vec<PathBuf> = dirs.iter().map(|d| Sweep::level_dir(d, i)).collect();
        let level_out = out.map(|o| Sweep::level_dir(o, i));
        if let Some(lo) = &level_out {
            std::fs::create_dir_all(lo).map_err(|source| Error::Io { path: lo.clone(), source })?;
        }
        let merged = crate::merge(&level_dirs, level_out.as_deref())?;
        rows.push(LevelRow::new(level, &merged.summary));
    }
    if let Some(o) = out {
        write_outputs(o, &manifest, &rows)?;
    }
    Ok((manifest, rows))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_are_parsed_without_drift() {
        let s: Sweep = "terrain.difficulty=0:1:0.2".parse().unwrap();
        assert_eq!(s.name, "terrain.difficulty");
        assert_eq!(s.levels, vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        let s: Sweep = "push.speed_mps=0:0.3:0.1".parse().unwrap();
        assert_eq!(s.levels, vec![0.0, 0.1, 0.2, 0.3]);
        for bad in ["x", "x=0:1", "x=0:1:0", "x=1:0:0.1", "x=a:1:0.1", "=0:1:1", "x y=0:1:1"] {
            let e = bad.parse::<Sweep>().unwrap_err().to_string();
            assert!(e.contains("--sweep") && e.contains("NAME=FROM:TO:STEP"), "{bad}: {e}");
        }
    }

    #[test]
    fn targets_and_overrides() {
        let spec = Spec::default_spec();
        let s = |n: &str| Sweep { name: n.into(), levels: vec![] };
        assert_eq!(s("push.speed_mps").target(&spec), Target::Spec("push.speed_mps".into()));
        assert_eq!(s("terrain.difficulty").target(&spec), Target::Scenario("terrain.difficulty".into()));
        assert_eq!(s("scenario.friction").target(&spec), Target::Scenario("friction".into()));
        let at = spec_at(&spec, "push.speed_mps", 0.4).unwrap();
        let t = &at.push.as_ref().unwrap().speed_mps;
        assert_eq!((t.low, t.high, t.mode), (Some(0.4), Some(0.4), crate::spec::Mode::Absolute));
        let e = spec_at(&spec, "damping", 2.0).unwrap_err().to_string();
        assert!(e.contains("no `damping` term") && e.contains("friction"), "{e}");
        assert!(spec_at(&spec, "friction", -1.0).is_err());
        let text = "duration = 5.0\n[terrain]\nkind = \"rough\"\ncount = 3\n";
        let t = scenario_text_at(text, "terrain.difficulty", 0.4).unwrap();
        assert!(t.contains("difficulty = 0.4") && t.contains("kind = \"rough\""), "{t}");
        assert!(scenario_text_at(text, "terrain.count", 4.0).unwrap().contains("count = 4"));
        assert!(scenario_text_at(text, "terrain.count", 4.5).is_err());
        assert!(scenario_text_at(text, "duration.x", 1.0).is_err());
    }

    #[test]
    fn threshold_and_csv() {
        let row = |level: f64, rate: f64| LevelRow {
            level,
            outcomes: Outcomes::of(10, (rate * 10.0) as u64, 10 - (rate * 10.0) as u64, 0),
            medians: vec![f64::NAN; KEY_METRICS.len()],
        };
        let rows = vec![row(0.0, 1.0), row(0.5, 0.8), row(1.0, 0.3)];
        assert_eq!(first_below(&rows, 0.8), Some(1.0));
        assert_eq!(first_below(&rows, 0.9), Some(0.5));
        let csv = to_csv("terrain.difficulty", &rows);
        assert!(csv.starts_with(
            "terrain.difficulty,episodes,succeeded,fell,unstable,success_rate,ci95_low,ci95_high,median_distance_m"
        ));
        assert_eq!(csv.lines().count(), 4);
        let svg = to_svg("terrain.difficulty", &rows, 0.8);
        assert!(svg.starts_with("<svg") && svg.contains("Success against terrain.difficulty"));
    }
}
