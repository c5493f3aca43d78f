//! `twin randomize`: domain-randomized batch rollouts, and `twin randomize merge` for shards.
//! `--scenario FILE` takes the model, duration, controller and checks from a scenario file
//! (`twin_scenario`): its checks decide each episode's success. `--sweep NAME=FROM:TO:STEP`
//! runs one batch per level of a spec or scenario parameter (`randomize::sweep`) and reports
//! success against it.

use anyhow::Context as _;
use clap::{Args as ClapArgs, Subcommand};
use randomize::sweep::{LevelRow, Sweep, SweepManifest, Target};
use randomize::{Batch, EpisodeOptions, Layout, RunOptions, Shard, Spec};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;
use twin_core::robot::Robot;
use twin_scenario::Scenario;

/// Arguments of `twin randomize`.
#[derive(Debug, ClapArgs)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Args {
    #[command(subcommand)]
    pub merge: Option<MergeCommand>,

    /// Robot or scene model (MJCF or URDF); with --scenario, it replaces the scenario's
    /// `model`. Default: the scenario's, else the shipped humanoid.
    pub model: Option<PathBuf>,

    /// Number of episodes of the whole batch (all shards together).
    #[arg(long, default_value_t = 100)]
    pub episodes: u64,

    /// Simulated seconds per episode [default: 5, or the scenario's].
    #[arg(long)]
    pub duration: Option<f64>,

    /// Scenario file (TOML): model, physics options (armature, friction), duration, controller
    /// and its parameters; its checks decide each episode's success. Its scripted pushes act
    /// in every episode, besides the randomization spec's random ones.
    #[arg(long, value_name = "SCENARIO.toml")]
    pub scenario: Option<PathBuf>,

    /// Master seed: each episode's random stream derives from (seed, episode index).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,

    /// Worker threads (0: every core). Results do not depend on it.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,

    /// Randomization spec (TOML). Without it, the default spec (see --print-config).
    #[arg(long)]
    pub config: Option<PathBuf>,

    /// Print the default randomization spec as TOML and exit.
    #[arg(long)]
    pub print_config: bool,

    /// Output folder: episodes.csv, summary.json, spec.toml, worst/.
    #[arg(long)]
    pub out: Option<PathBuf>,

    /// Run only shard K of N (1-based), e.g. 3/8; merge the outputs with `twin randomize merge`.
    #[arg(long)]
    pub shard: Option<String>,

    /// Re-simulate the K worst episodes and write their trajectories to OUT/worst/: CSV, MCAP
    /// (the topics of `twin sim`) and, with the rerun feature, .rrd.
    #[arg(long, default_value_t = 0)]
    pub record_worst: usize,

    /// With a controller outside twin (a scenario's `controller = "ros"`), do not run the first
    /// episode a second time to check that the node's answers are reproducible (by default it
    /// is run again and a difference is reported with the node's likely pattern).
    #[arg(long)]
    pub no_repeat_check: bool,

    /// Controller driving the robot: pd-hold (alias hold: hold the home pose), passive (no
    /// torque) or walk (stand and balance; with a scenario, walk as it says) [default:
    /// pd-hold, or the scenario's].
    #[arg(long)]
    pub controller: Option<super::ControllerName>,

    /// A fall: base below this fraction of its initial height.
    #[arg(long, default_value_t = 0.6)]
    pub fall_height_fraction: f64,

    /// A fall: base tilted more than this from upright, radians.
    #[arg(long, default_value_t = 1.0)]
    pub fall_tilt: f64,

    /// Success against a parameter: one batch of --episodes per level FROM, FROM+STEP, … TO of
    /// a randomization term (fixed to the level, e.g. push.speed_mps=0:0.6:0.1) or a scenario
    /// key (e.g. terrain.difficulty=0:1:0.2). Prints success with its 95 % interval per level;
    /// with --out, OUT/level-NN/ per level and OUT/sweep.csv, OUT/sweep.svg.
    #[arg(long, value_name = "NAME=FROM:TO:STEP")]
    pub sweep: Option<String>,

    /// The sweep reports the first level whose success rate is below this.
    #[arg(long, default_value_t = randomize::sweep::DEFAULT_THRESHOLD)]
    pub sweep_threshold: f64,
}

/// `twin randomize merge`.
#[derive(Debug, Subcommand)]
pub enum MergeCommand {
    /// Combine the outputs of shards 1/N … N/N into the summary one machine would print.
    Merge {
        /// Output folders of the shards (each with shard.json, and episodes.csv and summary.json
        /// once finished).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Write the merged episodes.csv and summary.json here.
        #[arg(long, conflicts_with = "status")]
        out: Option<PathBuf>,
        /// Only report each shard's finished/total episodes (works while they run); merge nothing.
        #[arg(long)]
        status: bool,
    },
}

/// Runs `twin randomize`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(MergeCommand::Merge { dirs, out, status }) = args.merge {
        if status {
            print!("{}", randomize::merge::status_text(&randomize::merge::status(&dirs)?));
            return Ok(());
        }
        if let Some(out) = &out {
            // Never write the merge into one of the shards it reads.
            let shards: Vec<&std::path::Path> = dirs.iter().map(PathBuf::as_path).collect();
            twin_core::fsio::check_output_dir(out, &shards)?;
        }
        if SweepManifest::read(&dirs[0])?.is_some() {
            let (manifest, rows) = randomize::sweep::merge(&dirs, out.as_deref())?;
            print!("{}", randomize::sweep::to_text(&manifest.sweep.name, &rows, manifest.threshold));
            if let Some(out) = out {
                eprintln!("wrote {}", out.display());
            }
            return Ok(());
        }
        let merged = randomize::merge(&dirs, out.as_deref())?;
        print!("{}", merged.summary.to_text(merged.run.episodes));
        if let Some(out) = out {
            eprintln!("wrote {}", out.display());
        }
        return Ok(());
    }
    if args.print_config {
        println!(
            "# Default randomization spec of `twin randomize`: each entry draws x from `dist` and\n\
             # combines it with the nominal value by `mode` (scale: v·x, add: v + x, absolute: x).\n\
             # Entries left out are not randomized. Edit and pass with --config FILE.\n"
        );
        print!("{}", Spec::default_spec().to_toml());
        return Ok(());
    }
    let shard: Option<Shard> = args.shard.as_deref().map(str::parse).transpose()?;
    if args.record_worst > 0 && args.out.is_none() {
        anyhow::bail!("--record-worst needs --out DIR to write the trajectories to");
    }
    if args.episodes == 0 {
        anyhow::bail!("--episodes must be a whole number from 1 to {}, got 0", u64::MAX);
    }
    let scenario = args.scenario.as_deref().map(Scenario::load).transpose()?;
    if let Some(out) = &args.out {
        let mut inputs: Vec<&Path> = args.model.iter().map(PathBuf::as_path).collect();
        inputs.extend(args.config.as_deref());
        inputs.extend(args.scenario.as_deref());
        twin_core::fsio::check_output_dir(out, &inputs)?;
    }
    // Ctrl-C (or SIGTERM) ends the run after the episodes in flight; a second one aborts.
    twin_core::fsio::cooperate();
    let Some(sweep) = &args.sweep else {
        return run_one(&args, scenario, None, args.out.as_deref(), shard).map(|_| ());
    };
    let sweep: Sweep = sweep.parse()?;
    if !(0.0..=1.0).contains(&args.sweep_threshold) {
        anyhow::bail!("--sweep-threshold must be within [0, 1], got {}", args.sweep_threshold);
    }
    let manifest = SweepManifest { sweep: sweep.clone(), threshold: args.sweep_threshold };
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        manifest.write(out)?;
    }
    let mut rows = Vec::new();
    for (i, &level) in sweep.levels.iter().enumerate() {
        println!("== {} = {level} ({} of {})", sweep.name, i + 1, sweep.levels.len());
        let out = args.out.as_deref().map(|o| Sweep::level_dir(o, i));
        let Some(summary) = run_one(&args, scenario.clone(), Some((&sweep, level)), out.as_deref(), shard)? else {
            return Err(super::Interrupted(format!("the sweep stopped at {} = {level}", sweep.name)).into());
        };
        rows.push(LevelRow::new(level, &summary));
        println!();
    }
    print!("{}", randomize::sweep::to_text(&sweep.name, &rows, args.sweep_threshold));
    if let Some(out) = &args.out {
        if shard.is_some() {
            eprintln!(
                "wrote shard {} of each level in {}: `twin randomize merge --out DIR` with the other shards' folders writes sweep.csv and sweep.svg",
                shard.map_or_else(String::new, |s| s.to_string()),
                out.display()
            );
        } else {
            randomize::sweep::write_outputs(out, &manifest, &rows)?;
            eprintln!("wrote {} (sweep.csv, sweep.svg, level-NN/)", out.display());
        }
    }
    Ok(())
}

/// One batch (one sweep level with `level`): prints its summary; returns it, or `None` when a
/// stop request ended it early.
fn run_one(
    args: &Args,
    scenario: Option<Scenario>,
    level: Option<(&Sweep, f64)>,
    out: Option<&Path>,
    shard: Option<Shard>,
) -> anyhow::Result<Option<randomize::Summary>> {
    // A scenario key swept: the scenario file with that key at the level.
    let target = level.map(|(sweep, _)| sweep.target(&Spec::default_spec()));
    let scenario = match (&target, level, scenario) {
        (Some(Target::Scenario(key)), Some((_, value)), Some(s)) => {
            let text = twin_core::fsio::read_to_string(&s.path)?;
            let text = randomize::sweep::scenario_text_at(&text, key, value)?;
            Some(Scenario::parse(&s.path, &text).with_context(|| format!("--sweep {key} = {value}"))?)
        }
        (Some(Target::Scenario(key)), _, None) => {
            anyhow::bail!("--sweep {key}: not a randomization term, and there is no --scenario whose key it could be")
        }
        (_, _, s) => s,
    };
    // MODEL replaces the scenario's `model` (as in `twin sim`): the robot simulated is the one
    // the summary names.
    let scenario = scenario.map(|mut s| {
        if args.model.is_some() {
            s.model = args.model.clone();
        }
        s
    });
    let duration = args.duration.or(scenario.as_ref().map(|s| s.duration_secs)).unwrap_or(5.0);
    super::check_range("--duration", duration, super::MIN_SECS, super::MAX_SIM_SECS, "s")?;
    super::check_range("--fall-tilt", args.fall_tilt, 0.0, std::f64::consts::PI, "rad")?;
    super::check_range("--fall-height-fraction", args.fall_height_fraction, 0.0, 1.0, "")?;
    let model_path = args
        .model
        .clone()
        .or_else(|| scenario.as_ref().and_then(|s| s.model.clone()))
        .unwrap_or_else(super::default_model);
    if let Some(out) = out {
        twin_core::fsio::check_output_dir(out, &[model_path.as_path()])?;
    }
    // A scenario's physics options (armature, friction) are part of the nominal model: every
    // episode's draw starts from it.
    let robot = match &scenario {
        Some(s) => s.robot(&model_path)?,
        None => Robot::load(&model_path)?,
    };
    let model = robot.model.clone();
    let controller = args
        .controller
        .map(|c| c.name().to_string())
        .or_else(|| scenario.as_ref().map(|s| s.controller.clone()))
        .unwrap_or("pd-hold".into());
    // The walker's options for this robot, derived once from the nominal model (every episode's
    // walker gets the same): a scenario's, or with none the defaults.
    let scenario = match scenario {
        Some(mut s) if controller == "walk" => {
            s.controller = controller.clone();
            s.fit_walk(&model)?;
            Some(s)
        }
        s => s,
    };
    let walk_alone = (controller == "walk" && scenario.is_none())
        .then(|| twin_controllers::walk::WalkOptions::default().for_robot(&model, &|_| false))
        .transpose()?;
    // Without --config, a scenario's own spec (e.g. the grasp scenario's cup and camera draws).
    let config = args.config.clone().or_else(|| scenario.as_ref().and_then(|s| s.randomize.clone()));
    let mut spec = match &config {
        Some(path) => Spec::from_file(path)?,
        None => {
            let mut spec = Spec::default_spec();
            if robot.base.is_none() {
                spec.push = None;
                eprintln!(
                    "note: {} has no floating base (free joint): the default spec's pushes are \
                     left out",
                    model_path.display()
                );
            }
            spec
        }
    };
    if let (Some(Target::Spec(key)), Some((_, value))) = (&target, level) {
        spec = randomize::sweep::spec_at(&spec, key, value)?;
    }
    // A drawn command delay needs every actuator's history buffer to span it: the robot is
    // converted again with buffers for the longest delay the term can draw (same physics).
    let (robot, model) = match spec.delay_buffer_secs(&model) {
        Some(secs) => {
            let robot = match &scenario {
                Some(s) => s.robot_with_delay_buffer(&model_path, secs)?,
                None => Robot::load_with(
                    &model_path,
                    &twin_core::convert::ConvertOptions { delay_buffer_secs: secs, ..Default::default() },
                )?,
            };
            let model = robot.model.clone();
            (robot, model)
        }
        None => (robot, model),
    };
    let bound = if config.is_some() {
        Layout::new(&spec, &model).map(|l| (l, Vec::new()))
    } else {
        Layout::new_skipping_missing(&spec, &model)
    };
    let (layout, skipped) = bound.map_err(|e| match (&config, e) {
        // Binding errors name the spec file the user wrote.
        (Some(path), randomize::Error::Spec { key, message, .. }) => randomize::Error::Spec {
            path: Some(path.clone()),
            key,
            message: format!("{message} (model {})", model_path.display()),
        },
        (_, e) => e,
    })?;
    if !skipped.is_empty() {
        eprintln!(
            "note: {} lacks what the default spec's {} apply to: left out",
            model_path.display(),
            skipped.join(", ")
        );
    }
    let external = controller == twin_scenario::EXTERNAL_CONTROLLER;
    let options = EpisodeOptions {
        duration_secs: duration,
        fall_height_fraction: args.fall_height_fraction,
        fall_tilt_rad: args.fall_tilt,
        // An external controller comes with the scenario, the walker with the options derived
        // for this robot (below): the batch starts on pd-hold, which they replace, so that no
        // walker is built on its default options (the shipped humanoid's steps, which another
        // robot's legs may not reach).
        controller: if external || controller == "walk" { "pd-hold".into() } else { controller.clone() },
    };
    if external && scenario.is_none() {
        anyhow::bail!("--controller ros needs --scenario FILE with a [ros] table (the command that starts your node)");
    }
    // The nominal robot, for `twin log analyze` of the worst episodes' recordings.
    let nominal = (args.record_worst > 0).then(|| robot.clone());
    let mut batch = Batch::from_robot(robot, layout, options, args.seed)?;
    if let Some(walk) = walk_alone {
        batch = batch.with_controller(move |r| {
            Ok(Box::new(twin_controllers::walk::Walker::new(&r.model, walk.clone())?)
                as Box<dyn twin_core::control::Controller>)
        })?;
    }
    if let Some(mut s) = scenario {
        // The scenario's walker (its options, the --controller override) on each worker, its
        // checks, and its scripted pushes besides the spec's random ones.
        s.controller = controller;
        // An external controller's output: OUT/controller_logs/worker-<k>.log.
        let logs = match &args.out {
            Some(out) => out.join("controller_logs"),
            None => std::env::temp_dir().join(format!("twin-controller-logs-{}", std::process::id())),
        };
        if s.is_external() {
            eprintln!(
                "external controller `{}`: its output goes to {}",
                s.ros.as_ref().map_or("", |r| &r.command),
                logs.display()
            );
        }
        batch = batch.with_scenario_logs(std::sync::Arc::new(s), &logs)?;
    }
    // A sweep level names its parameter with the model, so its outputs say which level they are.
    let label = match level {
        Some((sweep, value)) => format!("{} [{} = {value}]", model_path.display(), sweep.name),
        None => model_path.display().to_string(),
    };
    let run_info = randomize::run_info(&batch, &label, &spec, args.episodes, shard);
    let run_options = RunOptions {
        episodes: args.episodes,
        threads: args.threads,
        shard,
        out_dir: out.map(Path::to_path_buf),
        record_worst: args.record_worst,
        repeat_first: external && !args.no_repeat_check,
    };
    let requested = (0..args.episodes).filter(|&i| shard.is_none_or(|s| s.contains(i))).count() as u64;
    // A shard records what it runs before its first episode (for merge and --status); a shard
    // already finished in its folder by this binary is not run again.
    if let Some(out) = out {
        let cwd = std::env::current_dir().context("current folder")?;
        if let Some(manifest) =
            randomize::ShardManifest::new(&run_info, &super::VERSION_LINE, std::env::args().collect(), cwd)
            && let randomize::ShardStart::AlreadyDone(done) = randomize::merge::start_shard(out, &manifest)?
        {
            print!("{}", done.summary.to_text(requested));
            eprintln!(
                "shard {} is already complete in {} (same batch, same twin): nothing to do",
                manifest.shard,
                out.display()
            );
            return Ok(Some(done.summary));
        }
    }

    let stop = twin_core::fsio::interrupt_flag();
    let bar = if std::io::stderr().is_terminal() {
        let bar = indicatif::ProgressBar::new(requested);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} episodes  {per_sec}  ETA {eta}")
                .context("progress bar template")?,
        );
        Some(bar)
    } else {
        None
    };
    let started = Instant::now();
    let report = randomize::run_batch(&batch, run_info, &run_options, stop, &|| {
        if let Some(b) = &bar {
            b.inc(1);
        }
    })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let secs = started.elapsed().as_secs_f64();
    print!("{}", report.summary.to_text(report.requested));
    match &report.repeat {
        Some(r) if !r.reproducible() => println!("warning: {}", r.explain()),
        Some(r) => eprintln!("{}", r.explain()),
        None => {}
    }
    eprintln!(
        "\n{} episodes in {:.1} s ({:.1} episodes/s, {:.0} steps/s){}",
        report.summary.outcomes.episodes,
        secs,
        report.summary.outcomes.episodes as f64 / secs.max(1e-9),
        report.simulated_steps as f64 / secs.max(1e-9),
        shard.map_or_else(String::new, |s| format!(", shard {s}"))
    );
    if let Some(out) = out {
        eprintln!("wrote {}", out.display());
        if !report.worst.is_empty() {
            eprintln!(
                "worst episodes {:?}: trajectories ({}) in {}",
                report.worst,
                if cfg!(feature = "rerun") { ".csv, .mcap, .rrd" } else { ".csv, .mcap" },
                out.join("worst").display()
            );
            if let Some(robot) = &nominal {
                let fall = twin_core::engine::observers::FallOptions {
                    height_fraction: args.fall_height_fraction,
                    tilt_rad: args.fall_tilt,
                };
                analyze_worst(&out.join("worst"), &report.worst, robot, fall)?;
            }
        }
    }
    if report.interrupted {
        if level.is_some() {
            return Ok(None);
        }
        return Err(super::Interrupted(format!(
            "{} of {} episodes finished",
            report.summary.outcomes.episodes, requested
        ))
        .into());
    }
    Ok(Some(report.summary))
}

/// `twin log analyze` of each worst episode's recording (`worst_<i>.mcap`): the report as
/// `worst_<i>.analysis.txt` and `.json`, the plots in `worst_<i>_plots/`, and its first finding
/// on stderr.
fn analyze_worst(
    dir: &std::path::Path,
    worst: &[u64],
    robot: &Robot,
    fall: twin_core::engine::observers::FallOptions,
) -> anyhow::Result<()> {
    let options = twin_diagnose::AnalyzeOptions { fall, ..Default::default() };
    for &i in worst {
        let mcap = dir.join(format!("worst_{i:06}.mcap"));
        let log = twin_core::log::Log::open(&mcap, twin_core::log::ReadOptions::default())?;
        let analysis = twin_diagnose::analyze(&log, Some(robot), &options)
            .with_context(|| format!("analysing {}", mcap.display()))?;
        twin_core::fsio::write_atomic(
            &dir.join(format!("worst_{i:06}.analysis.txt")),
            analysis.to_text().as_bytes(),
            twin_core::fsio::Backup::None,
        )?;
        twin_core::fsio::write_atomic(
            &dir.join(format!("worst_{i:06}.analysis.json")),
            analysis.to_json().as_bytes(),
            twin_core::fsio::Backup::None,
        )?;
        let plots = dir.join(format!("worst_{i:06}_plots"));
        std::fs::create_dir_all(&plots).with_context(|| format!("creating {}", plots.display()))?;
        for (name, svg) in analysis.plots() {
            twin_core::fsio::write_atomic(&plots.join(name), svg.as_bytes(), twin_core::fsio::Backup::None)?;
        }
        if let Some(d) = analysis.diagnosis.first() {
            eprintln!("episode {i}: {} ({})", d.cause, d.evidence);
        }
    }
    eprintln!("analyses (twin log analyze): worst_<i>.analysis.txt/.json and worst_<i>_plots/ in {}", dir.display());
    Ok(())
}
