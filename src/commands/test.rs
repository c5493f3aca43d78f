//! `twin test [SCENARIO…] [--junit report.xml]`: the command a CI job runs on a controller.
//!
//! Each scenario runs nominal (no randomization: the scenario as `twin sim --scenario` runs it,
//! with fall detection) and, when its `[test]` table asks for `episodes`, randomized (the
//! scenario's `randomize` spec, or twin's default spec) on the `twin randomize` engine. A
//! scenario passes when the nominal run passes its checks and the lower bound of the
//! randomized success rate's 95 % Wilson interval reaches `min_success_lower_95`. twin prints a
//! table, writes JUnit XML (`testsuites/testsuite/testcase/failure`, what CI systems render)
//! and exits 0 only when every scenario passes.

use anyhow::Context as _;
use randomize::{Batch, EpisodeOptions, Layout, RunOptions, Spec};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use twin_scenario::Scenario;

/// Arguments of `twin test`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario files [default: every scenario in ./scenarios, except the randomization specs
    /// they name].
    pub scenarios: Vec<PathBuf>,
    /// Write the results as JUnit XML here (GitHub Actions, GitLab `artifacts:reports:junit`).
    #[arg(long, value_name = "report.xml")]
    pub junit: Option<PathBuf>,
    /// Worker threads of the randomized runs (0: every core). Results do not depend on it.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Keep each randomized run's outputs (episodes.csv, summary.json, controller logs) in
    /// OUT/<scenario>/.
    #[arg(long, value_name = "OUT")]
    pub out: Option<PathBuf>,
}

/// One test case's outcome.
struct Case {
    name: &'static str,
    secs: f64,
    /// `None`: passed; else the failure message.
    failure: Option<String>,
    /// What the table shows.
    summary: String,
}

/// One scenario's outcome.
struct Suite {
    path: PathBuf,
    cases: Vec<Case>,
}

/// Runs `twin test`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let paths =
        if args.scenarios.is_empty() { default_scenarios(Path::new("scenarios"))? } else { args.scenarios.clone() };
    if paths.is_empty() {
        anyhow::bail!(
            "no scenarios: give scenario files (twin test scenarios/stand.toml) or run where ./scenarios has some"
        );
    }
    if let Some(j) = &args.junit {
        let inputs: Vec<&Path> = paths.iter().map(PathBuf::as_path).collect();
        twin_core::fsio::check_outputs(&[("--junit", Some(j.as_path()))], &inputs)?;
    }
    // Every scenario is read before any runs: a typo fails at once.
    let scenarios: Vec<Scenario> = paths.iter().map(Scenario::load).collect::<Result<_, _>>()?;
    twin_core::fsio::cooperate();
    let stop = twin_core::fsio::interrupt_flag();
    let mut suites = Vec::new();
    for s in &scenarios {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            break;
        }
        eprintln!("testing {} …", s.path.display());
        suites.push(test_scenario(s, &args, stop)?);
    }
    let table = table(&suites);
    print!("{table}");
    if let Some(j) = &args.junit {
        twin_core::fsio::write_atomic(j, junit(&suites).as_bytes(), twin_core::fsio::Backup::None)?;
        eprintln!("wrote {}", j.display());
    }
    if twin_core::fsio::interrupted() {
        return Err(super::Interrupted(format!("{} of {} scenarios tested", suites.len(), scenarios.len())).into());
    }
    let failed = suites.iter().filter(|s| s.cases.iter().any(|c| c.failure.is_some())).count();
    if failed > 0 {
        anyhow::bail!("{failed} of {} scenarios failed", suites.len());
    }
    Ok(())
}

/// Every `*.toml` of `dir` that is not the randomization spec of another (sorted).
fn default_scenarios(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Ok(Vec::new()) };
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    let mut specs = Vec::new();
    for f in &files {
        if let Ok(s) = Scenario::load(f)
            && let Some(r) = s.randomize
        {
            specs.push(r.canonicalize().unwrap_or(r));
        }
    }
    Ok(files.into_iter().filter(|f| !specs.contains(&f.canonicalize().unwrap_or_else(|_| f.clone()))).collect())
}

/// A batch of `scenario` under `spec` (nominal: the empty spec).
fn batch(scenario: &Scenario, spec: Option<&Spec>, seed: u64, logs: &Path) -> anyhow::Result<(Batch, Spec)> {
    let model_path = scenario.model.clone().unwrap_or_else(super::default_model);
    let robot = scenario.robot(&model_path)?;
    let mut scenario = scenario.clone();
    scenario.fit_walk(&robot.model)?;
    let scenario = &scenario;
    let (spec, layout) = match spec {
        Some(spec) => {
            let layout = Layout::new(spec, &robot.model)?;
            (spec.clone(), layout)
        }
        None => {
            let mut spec = Spec::default_spec();
            if robot.base.is_none() {
                spec.push = None;
            }
            let (layout, _skipped) = Layout::new_skipping_missing(&spec, &robot.model)?;
            (spec, layout)
        }
    };
    let options = EpisodeOptions { duration_secs: scenario.duration_secs, ..EpisodeOptions::default() };
    let batch = Batch::from_robot(robot, layout, options, seed)?
        .with_scenario_logs(std::sync::Arc::new(scenario.clone()), logs)?;
    Ok((batch, spec))
}

fn test_scenario(s: &Scenario, args: &Args, stop: &std::sync::atomic::AtomicBool) -> anyhow::Result<Suite> {
    let stem = s.path.file_stem().map_or_else(|| "scenario".into(), |n| n.to_string_lossy().into_owned());
    let out = args.out.as_ref().map(|o| o.join(&stem));
    let logs = match &out {
        Some(o) => o.join("controller_logs"),
        None => std::env::temp_dir().join(format!("twin-test-{}-{stem}", std::process::id())),
    };
    let mut cases = Vec::new();

    // Nominal: the empty spec, one episode.
    let started = Instant::now();
    let empty = Spec::from_toml_str("")?;
    let (nominal, _) = batch(s, Some(&empty), s.test.seed, &logs)?;
    let result = randomize::Worker::new(&nominal)?.run(&nominal, 0, None)?;
    let mut why = Vec::new();
    if result.unstable {
        why.push(format!("the simulation diverged: {}", result.unstable_reason));
    }
    if result.fell {
        why.push(format!("fell at {:.3} s", result.fall_time_secs.unwrap_or(result.sim_secs)));
    }
    for c in result.checks.iter().filter(|c| !c.passed) {
        why.push(format!("{}: {}", c.name, c.cause.as_deref().unwrap_or("failed")));
        why.extend(c.details.iter().filter(|d| d.starts_with("FAIL")).map(|d| format!("  {d}")));
    }
    cases.push(Case {
        name: "nominal",
        secs: started.elapsed().as_secs_f64(),
        summary: if why.is_empty() { format!("PASS ({:.2} s simulated)", result.sim_secs) } else { "FAIL".into() },
        failure: (!why.is_empty()).then(|| why.join("; ")),
    });

    // Randomized, when the scenario asks for episodes.
    if s.test.episodes > 0 {
        let started = Instant::now();
        let spec = s.randomize.as_deref().map(Spec::from_file).transpose()?;
        let (batch, spec) = batch(s, spec.as_ref(), s.test.seed, &logs)?;
        let run = randomize::run_info(&batch, &s.path.display().to_string(), &spec, s.test.episodes, None);
        let options = RunOptions {
            episodes: s.test.episodes,
            threads: args.threads,
            out_dir: out.clone(),
            ..RunOptions::default()
        };
        let report = randomize::run_batch(&batch, run, &options, stop, &|| {})
            .with_context(|| format!("randomized episodes of {}", s.path.display()))?;
        let sum = &report.summary.outcomes;
        let threshold = s.test.min_success_lower_95.unwrap_or(0.5);
        let lower = sum.success_rate_ci95[0];
        let passed = lower >= threshold && sum.episodes == report.requested;
        let kinds: Vec<String> =
            report.summary.failures.iter().map(|f| format!("{} ×{}", f.kind, f.episodes)).collect();
        let mut message = format!(
            "success {}/{} = {:.1} %, 95 % lower bound {:.3} {} {threshold}; fell {}, unstable {}",
            sum.succeeded,
            sum.episodes,
            100.0 * sum.success_rate,
            lower,
            if lower >= threshold { ">=" } else { "<" },
            sum.fell,
            sum.unstable
        );
        if !kinds.is_empty() {
            let _ = write!(message, "; failed checks: {}", kinds.join(", "));
        }
        cases.push(Case {
            name: "randomized",
            secs: started.elapsed().as_secs_f64(),
            summary: format!(
                "{} {}/{} lower95 {lower:.3} (min {threshold})",
                if passed { "PASS" } else { "FAIL" },
                sum.succeeded,
                sum.episodes
            ),
            failure: (!passed).then_some(message),
        });
    }
    Ok(Suite { path: s.path.clone(), cases })
}

/// The results table.
fn table(suites: &[Suite]) -> String {
    let w = suites.iter().map(|s| s.path.display().to_string().chars().count()).max().unwrap_or(8).max(8);
    let mut t = String::new();
    let _ = writeln!(t, "{:<w$}  {:<30}  {:<44}  result", "scenario", "nominal", "randomized");
    for s in suites {
        let case = |n: &str| s.cases.iter().find(|c| c.name == n).map_or("-".to_string(), |c| c.summary.clone());
        let ok = s.cases.iter().all(|c| c.failure.is_none());
        let _ = writeln!(
            t,
            "{:<w$}  {:<30}  {:<44}  {}",
            s.path.display(),
            case("nominal"),
            case("randomized"),
            if ok { "PASS" } else { "FAIL" }
        );
        for c in &s.cases {
            if let Some(f) = &c.failure {
                let _ = writeln!(t, "  {} {}: {f}", s.path.display(), c.name);
            }
        }
    }
    let failed = suites.iter().filter(|s| s.cases.iter().any(|c| c.failure.is_some())).count();
    let _ = writeln!(t, "{} of {} scenarios passed", suites.len() - failed, suites.len());
    t
}

/// XML attribute/text escaping.
fn xml(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Control characters are not allowed in XML 1.0.
            c if (c as u32) < 0x20 && !matches!(c, '\t' | '\n' | '\r') => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// The JUnit XML report: a `testsuite` per scenario, a `testcase` per run (nominal,
/// randomized), a `failure` with the message for each that failed.
fn junit(suites: &[Suite]) -> String {
    let tests: usize = suites.iter().map(|s| s.cases.len()).sum();
    let failures: usize = suites.iter().map(|s| s.cases.iter().filter(|c| c.failure.is_some()).count()).sum();
    let secs: f64 = suites.iter().flat_map(|s| s.cases.iter().map(|c| c.secs)).sum();
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        x,
        "<testsuites name=\"twin test\" tests=\"{tests}\" failures=\"{failures}\" errors=\"0\" time=\"{secs:.3}\">"
    );
    for s in suites {
        let name = xml(&s.path.display().to_string());
        let classname = xml(&s.path.file_stem().map_or_else(String::new, |n| n.to_string_lossy().into_owned()));
        let f = s.cases.iter().filter(|c| c.failure.is_some()).count();
        let t: f64 = s.cases.iter().map(|c| c.secs).sum();
        let _ = writeln!(
            x,
            "  <testsuite name=\"{name}\" tests=\"{}\" failures=\"{f}\" errors=\"0\" skipped=\"0\" time=\"{t:.3}\">",
            s.cases.len()
        );
        for c in &s.cases {
            let _ = write!(x, "    <testcase classname=\"{classname}\" name=\"{}\" time=\"{:.3}\"", c.name, c.secs);
            match &c.failure {
                None => x.push_str("/>\n"),
                Some(m) => {
                    let _ = writeln!(
                        x,
                        ">\n      <failure message=\"{}\" type=\"twin.{}\">{}</failure>\n    </testcase>",
                        xml(m),
                        c.name,
                        xml(m)
                    );
                }
            }
        }
        x.push_str("  </testsuite>\n");
    }
    x.push_str("</testsuites>\n");
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn junit_escapes_and_counts() {
        let suites = vec![Suite {
            path: PathBuf::from("a<b>.toml"),
            cases: vec![
                Case { name: "nominal", secs: 1.0, failure: None, summary: String::new() },
                Case { name: "randomized", secs: 2.0, failure: Some("x < 0.5 & \"y\"".into()), summary: String::new() },
            ],
        }];
        let x = junit(&suites);
        assert!(x.contains("tests=\"2\" failures=\"1\""), "{x}");
        assert!(x.contains("message=\"x &lt; 0.5 &amp; &quot;y&quot;\""), "{x}");
        assert!(x.contains("<testsuite name=\"a&lt;b&gt;.toml\""), "{x}");
    }
}
