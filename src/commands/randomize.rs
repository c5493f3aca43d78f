//! `twin randomize`: domain-randomized batch rollouts, and `twin randomize merge` for shards.

use anyhow::Context as _;
use clap::{Args as ClapArgs, Subcommand};
use randomize::{Batch, EpisodeOptions, Layout, RunOptions, Shard, Spec};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use twin_core::robot::Robot;

/// Arguments of `twin randomize`.
#[derive(Debug, ClapArgs)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Args {
    #[command(subcommand)]
    pub merge: Option<MergeCommand>,

    /// Robot or scene model (MJCF or URDF). Default: the shipped humanoid.
    pub model: Option<PathBuf>,

    /// Number of episodes of the whole batch (all shards together).
    #[arg(long, default_value_t = 100)]
    pub episodes: u64,

    /// Simulated seconds per episode.
    #[arg(long, default_value_t = 5.0)]
    pub duration: f64,

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

    /// Controller driving the robot: pd-hold (alias hold: hold the home pose) or passive (no
    /// torque).
    #[arg(long, default_value = "pd-hold")]
    pub controller: String,

    /// A fall: base below this fraction of its initial height.
    #[arg(long, default_value_t = 0.6)]
    pub fall_height_fraction: f64,

    /// A fall: base tilted more than this from upright, radians.
    #[arg(long, default_value_t = 1.0)]
    pub fall_tilt: f64,
}

/// `twin randomize merge`.
#[derive(Debug, Subcommand)]
pub enum MergeCommand {
    /// Combine the outputs of shards 1/N … N/N into the summary one machine would print.
    Merge {
        /// Output folders of the shards (each with episodes.csv and summary.json).
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Write the merged episodes.csv and summary.json here.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// Runs `twin randomize`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(MergeCommand::Merge { dirs, out }) = args.merge {
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
    let model_path = args.model.unwrap_or_else(super::default_model);
    let robot = Robot::load(&model_path)?;
    let model = robot.model.clone();
    let spec = match &args.config {
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
    let bound = if args.config.is_some() {
        Layout::new(&spec, &model).map(|l| (l, Vec::new()))
    } else {
        Layout::new_skipping_missing(&spec, &model)
    };
    let (layout, skipped) = bound.map_err(|e| match (&args.config, e) {
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
    let options = EpisodeOptions {
        duration_secs: args.duration,
        fall_height_fraction: args.fall_height_fraction,
        fall_tilt_rad: args.fall_tilt,
        controller: args.controller.clone(),
    };
    let batch = Batch::from_robot(robot, layout, options, args.seed)?;
    let run_info = randomize::run_info(&batch, &model_path.display().to_string(), &spec, args.episodes, shard);
    let run_options = RunOptions {
        episodes: args.episodes,
        threads: args.threads,
        shard,
        out_dir: args.out.clone(),
        record_worst: args.record_worst,
    };
    let requested = (0..args.episodes).filter(|&i| shard.is_none_or(|s| s.contains(i))).count() as u64;

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while finishing still ends the process the usual way.
        let _ = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\nstopping: finishing the episodes in flight (Ctrl-C again to abort)");
        });
    }
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
    let report = randomize::run_batch(&batch, run_info, &run_options, &stop, &|| {
        if let Some(b) = &bar {
            b.inc(1);
        }
    })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let secs = started.elapsed().as_secs_f64();
    print!("{}", report.summary.to_text(report.requested));
    eprintln!(
        "\n{} episodes in {:.1} s ({:.1} episodes/s, {:.0} steps/s){}",
        report.summary.episodes,
        secs,
        report.summary.episodes as f64 / secs.max(1e-9),
        report.simulated_steps as f64 / secs.max(1e-9),
        shard.map_or_else(String::new, |s| format!(", shard {s}"))
    );
    if let Some(out) = &args.out {
        eprintln!("wrote {}", out.display());
        if !report.worst.is_empty() {
            eprintln!(
                "worst episodes {:?}: trajectories ({}) in {}",
                report.worst,
                if cfg!(feature = "rerun") { ".csv, .mcap, .rrd" } else { ".csv, .mcap" },
                out.join("worst").display()
            );
        }
    }
    if report.interrupted {
        eprintln!("interrupted: {} of {} episodes finished", report.summary.episodes, requested);
    }
    Ok(())
}
