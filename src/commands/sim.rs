//! `twin sim [MODEL] --duration S --controller hold|replay …`: runs the twin under a built-in
//! controller and records ROS 2 topics (MCAP) and a rerun recording, stamped in simulation time.

use anyhow::{Context, bail};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use twin_core::control::{Controller, JointTrajectory, PdHold, PdHoldOptions, Replay, ReplayOptions};
use twin_core::log::{Compression, WriterOptions};
use twin_core::sim::{self, RecordOptions, Recording, SimOptions};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerKind {
    /// PD hold of the nominal pose (keyframe `home`).
    Hold,
    /// Track a joint trajectory (`--trajectory`) with PD and velocity feed-forward.
    Replay,
    /// Model-based walking (LIPM preview control + DCM feedback) at `--vx/--vy/--yaw-rate`;
    /// stands and balances at zero velocity. Prints gait metrics at the end.
    Walk,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CompressionKind {
    /// zstd level 1.
    Zstd,
    /// LZ4 (cheaper, larger files).
    Lz4,
    /// None.
    None,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Robot model: URDF (converted by twin) or MJCF. Default: the shipped humanoid.
    pub model: Option<PathBuf>,
    /// Simulated time, seconds [default: 5, or the scenario's].
    #[arg(long)]
    pub duration: Option<f64>,
    /// Built-in controller [default: hold, or the scenario's].
    #[arg(long, value_enum)]
    pub controller: Option<ControllerKind>,
    /// Scenario file (TOML: model, physics options, controller and parameters, duration, pushes,
    /// checks); prints each check as PASS/FAIL and fails when one fails.
    #[arg(long, value_name = "SCENARIO.toml")]
    pub scenario: Option<PathBuf>,
    /// Forward velocity command of `--controller walk`, m/s.
    #[arg(long, allow_negative_numbers = true)]
    pub vx: Option<f64>,
    /// Leftward velocity command of `--controller walk`, m/s.
    #[arg(long, allow_negative_numbers = true)]
    pub vy: Option<f64>,
    /// Yaw-rate command of `--controller walk`, rad/s.
    #[arg(long, allow_negative_numbers = true)]
    pub yaw_rate: Option<f64>,
    /// Trajectory for `--controller replay`: a ROS 2 log (.mcap or rosbag2 folder) with a
    /// JointState topic, or a CSV `time_sec,<joint>,…`.
    #[arg(long, value_name = "LOG_OR_CSV")]
    pub trajectory: Option<PathBuf>,
    /// JointState topic of the trajectory log.
    #[arg(long, default_value = "/joint_states")]
    pub trajectory_topic: String,
    /// Write the ROS 2 topics to this MCAP file.
    #[arg(long, value_name = "RUN.mcap")]
    pub record: Option<PathBuf>,
    /// Write a rerun recording to this .rrd file.
    #[arg(long, value_name = "RUN.rrd")]
    pub rerun: Option<PathBuf>,
    /// Stream the rerun recording to a running viewer (e.g. rerun+http://127.0.0.1:9876/proxy).
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Rate of /joint_states, /odom, contacts and commands, Hz (every step if the timestep is
    /// longer).
    #[arg(long, default_value_t = 500.0)]
    pub rate: f64,
    /// Rate of /tf, Hz.
    #[arg(long, default_value_t = 100.0)]
    pub tf_rate: f64,
    /// MCAP chunk compression.
    #[arg(long, value_enum, default_value_t = CompressionKind::Zstd)]
    pub compression: CompressionKind,
    /// Compress and write the MCAP on the simulation thread instead of a writer thread.
    #[arg(long)]
    pub inline_writer: bool,
    /// Record only these topics (comma-separated; `/contacts/*` for every contact topic).
    #[arg(long, value_delimiter = ',', value_name = "TOPIC,...")]
    pub topics: Option<Vec<String>>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scenario = match &args.scenario {
        Some(file) => Some(twin_core::scenario::Scenario::load(file)?),
        None => None,
    };
    let kind = match (args.controller, &scenario) {
        (Some(k), _) => k,
        (None, Some(s)) => match s.controller.as_str() {
            "walk" => ControllerKind::Walk,
            "pd-hold" => ControllerKind::Hold,
            other => bail!("{}: controller \"{other}\" can't run under twin sim (walk or pd-hold)", s.path.display()),
        },
        (None, None) => ControllerKind::Hold,
    };
    let duration = args.duration.or(scenario.as_ref().map(|s| s.duration_secs)).unwrap_or(5.0);
    if !(duration > 0.0 && duration.is_finite()) {
        bail!("--duration must be a positive number of seconds (got {duration})");
    }
    if kind != ControllerKind::Walk && (args.vx.is_some() || args.vy.is_some() || args.yaw_rate.is_some()) {
        bail!("--vx, --vy and --yaw-rate are for --controller walk");
    }
    if !(args.rate > 0.0 && args.tf_rate > 0.0) {
        bail!("--rate and --tf-rate must be positive (Hz)");
    }
    if (args.rerun.is_some() || args.connect.is_some()) && !cfg!(feature = "rerun") {
        return Err(twin_core::sim::record::rerun_unavailable().into());
    }
    // Walking runs a scenario: the given file, or the defaults with the command-line model and
    // velocity.
    let scenario = match (scenario, kind) {
        (Some(s), _) => Some(s),
        (None, ControllerKind::Walk) => Some(twin_core::scenario::Scenario::parse(
            std::path::Path::new("<command line>"),
            &format!("duration = {duration:?}\ncontroller = \"walk\"\n"),
        )?),
        (None, _) => None,
    };
    let mut scenario = scenario;
    if let Some(s) = scenario.as_mut() {
        s.walk.vx = args.vx.unwrap_or(s.walk.vx);
        s.walk.vy = args.vy.unwrap_or(s.walk.vy);
        s.walk.yaw_rate = args.yaw_rate.unwrap_or(s.walk.yaw_rate);
        s.walk.validate().map_err(|(key, m)| anyhow::anyhow!("walking option `{key}` {m}"))?;
        if args.model.is_some() {
            s.model = args.model.clone();
        }
    }
    let path = match &scenario {
        Some(s) => s.model.clone().unwrap_or_else(super::default_model),
        None => args.model.clone().unwrap_or_else(super::default_model),
    };
    let robot = match &scenario {
        Some(s) => s.robot(&path),
        None => sim::load_robot(&path),
    }
    .with_context(|| format!("loading {}", path.display()))?;
    let mut controller: Box<dyn Controller> = match kind {
        ControllerKind::Hold => {
            if args.trajectory.is_some() {
                bail!("--trajectory is for --controller replay");
            }
            Box::new(PdHold::new(&robot.model, PdHoldOptions::default()))
        }
        ControllerKind::Replay => {
            let Some(file) = &args.trajectory else {
                bail!("--controller replay needs --trajectory LOG_OR_CSV (a ROS 2 log or a CSV time_sec,<joint>,…)");
            };
            let trajectory = JointTrajectory::load(file, &args.trajectory_topic)?;
            Box::new(Replay::new(&robot.model, trajectory, ReplayOptions::default())?)
        }
        ControllerKind::Walk => {
            let s = scenario.as_ref().context("walking runs a scenario")?;
            Box::new(twin_core::walk::Walker::new(&robot.model, s.walk.clone())?)
        }
    };
    let mut hook = match &scenario {
        Some(s) => Some(s.hook(&robot.model)?),
        None => None,
    };
    let options = RecordOptions {
        mcap: args.record.clone(),
        rrd: args.rerun.clone(),
        connect: args.connect.clone(),
        state_rate_hz: args.rate,
        tf_rate_hz: args.tf_rate,
        seed: scenario.as_ref().map_or(args.seed, |s| if args.seed != 0 { args.seed } else { s.seed }),
        writer: WriterOptions {
            compression: match args.compression {
                CompressionKind::Zstd => Compression::Zstd(1),
                CompressionKind::Lz4 => Compression::Lz4,
                CompressionKind::None => Compression::None,
            },
            background: !args.inline_writer,
            ..WriterOptions::default()
        },
        topics: args.topics.clone(),
        ..RecordOptions::default()
    };
    let recording_wanted = options.mcap.is_some() || options.rrd.is_some() || options.connect.is_some();
    let mut recording = if recording_wanted { Some(Recording::new(&robot, &options)?) } else { None };

    let bar = if std::io::stderr().is_terminal() {
        let bar = indicatif::ProgressBar::new(1000);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {percent}% of the simulated time  ETA {eta}")
                .context("progress bar template")?,
        );
        Some(bar)
    } else {
        None
    };
    let mut progress = |f: f64| {
        if let Some(b) = &bar {
            b.set_position((f * 1000.0) as u64);
        }
    };
    let sim_options = SimOptions { duration_secs: duration };
    let report = match hook.as_mut() {
        Some(h) => sim::simulate_with(&robot, controller.as_mut(), &sim_options, recording.as_mut(), &mut progress, h)?,
        None => sim::simulate(&robot, controller.as_mut(), &sim_options, recording.as_mut(), &mut progress)?,
    };
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let finishing = std::time::Instant::now();
    let summary = match recording {
        Some(r) => Some(r.finish()?),
        None => None,
    };
    let finish_secs = finishing.elapsed().as_secs_f64();
    let mut out = std::io::stdout().lock();

    writeln!(
        out,
        "simulated {:.3} s of {} ({} steps of {} ms) with controller {} in {:.3} s wall: real-time factor {:.1}",
        report.sim_secs,
        path.display(),
        report.steps,
        robot.model.timestep_secs() * 1e3,
        controller.name(),
        report.wall_secs,
        report.real_time_factor()
    )?;
    if let Some(cpu) = report.loop_cpu_secs {
        writeln!(out, "simulation thread CPU: {cpu:.3} s ({:.2} µs per step)", cpu * 1e6 / report.steps as f64)?;
    }
    if let Some(s) = summary {
        if recording_wanted {
            writeln!(
                out,
                "recording: {:.3} s inside the loop ({:.1} % of the loop, {:.2} µs per step), {:.3} s to close",
                report.record_secs,
                100.0 * report.record_secs / report.wall_secs.max(1e-12),
                report.record_secs * 1e6 / report.steps as f64,
                finish_secs
            )?;
        }
        if let Some((file, w)) = &s.mcap {
            writeln!(out, "{}: {} messages, {} chunks, {} bytes", file.display(), w.messages, w.chunks, w.bytes)?;
            if w.queue_full_waits > 0 {
                writeln!(
                    out,
                    "  the simulation waited {} times for the MCAP writer thread (no free core, or slow disk)",
                    w.queue_full_waits
                )?;
            }
            let width = s.topics.iter().map(|(t, _)| t.len()).max().unwrap_or(0);
            for (topic, n) in &s.topics {
                writeln!(out, "  {topic:<width$}  {n}")?;
            }
        }
        if let Some((file, bytes)) = &s.rrd {
            writeln!(out, "{}: {bytes} bytes", file.display())?;
        }
    }
    if let (Some(h), Some(s)) = (&hook, &scenario) {
        let summary = h.metrics.summary();
        writeln!(out, "{summary}")?;
        let verdicts = s.evaluate(&summary);
        if !verdicts.is_empty() {
            writeln!(out, "checks of {}:", s.path.display())?;
            for v in &verdicts {
                writeln!(out, "  {v}")?;
            }
        }
        let failed = verdicts.iter().filter(|v| !v.passed).count();
        if failed > 0 {
            bail!("{failed} of {} checks of {} failed", verdicts.len(), s.path.display());
        }
    }
    Ok(())
}
