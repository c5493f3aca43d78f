//! `twin sim [MODEL] --duration S --controller pd-hold|passive|replay|walk …`: runs the twin
//! under a controller of twin's registry (`twin_core::control::by_name_with`) and records ROS 2
//! topics (MCAP) and a rerun recording, stamped in simulation time. `--scenario FILE` runs a
//! scenario (`twin_core::scenario`): its model, controller, pushes and checks, printing the gait
//! metrics and each check as PASS/FAIL; `--controller walk` alone runs the default scenario.

use anyhow::{Context, bail};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use twin_core::control::{ControllerOptions, JointTrajectory};
use twin_core::engine::{Disturbance, Observer};
use twin_core::log::{Compression, WriterOptions};
use twin_core::robot::Robot;
use twin_core::scenario::Scenario;
use twin_core::sim::{self, RecordOptions, Recording, SimOptions};

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
    /// Controller: pd-hold (alias hold: PD hold of the home pose), passive (no torque),
    /// replay (track --trajectory with PD and velocity feed-forward) or walk (model-based
    /// walking at --vx/--vy/--yaw-rate; stands and balances at zero velocity; prints gait
    /// metrics) [default: pd-hold, or the scenario's].
    #[arg(long)]
    pub controller: Option<String>,
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
    let mut scenario = args.scenario.as_deref().map(Scenario::load).transpose()?;
    let controller_name =
        args.controller.clone().or_else(|| scenario.as_ref().map(|s| s.controller.clone())).unwrap_or("pd-hold".into());
    let duration = args.duration.or(scenario.as_ref().map(|s| s.duration_secs)).unwrap_or(5.0);
    super::check_range("--duration", duration, super::MIN_SECS, super::MAX_SIM_SECS, "s")?;
    super::check_range("--rate", args.rate, 1e-3, super::MAX_RATE_HZ, "Hz")?;
    super::check_range("--tf-rate", args.tf_rate, 1e-3, super::MAX_RATE_HZ, "Hz")?;
    let walking = controller_name == "walk";
    if !walking && (args.vx.is_some() || args.vy.is_some() || args.yaw_rate.is_some()) {
        bail!("--vx, --vy and --yaw-rate are for --controller walk");
    }
    // Walking runs a scenario: the given file, or the defaults with the command-line model and
    // velocity.
    if scenario.is_none() && walking {
        let defaults = format!("duration = {duration:?}\ncontroller = \"walk\"\n");
        scenario = Some(Scenario::parse(std::path::Path::new("<command line>"), &defaults)?);
    }
    if let Some(s) = scenario.as_mut() {
        s.walk.vx = args.vx.unwrap_or(s.walk.vx);
        s.walk.vy = args.vy.unwrap_or(s.walk.vy);
        s.walk.yaw_rate = args.yaw_rate.unwrap_or(s.walk.yaw_rate);
        s.walk.validate().map_err(|(key, m)| anyhow::anyhow!("walking option `{key}` {m}"))?;
        if args.model.is_some() {
            s.model = args.model.clone();
        }
    }
    // Outputs are checked before any work: not a folder or device, not an input.
    let model_path = scenario
        .as_ref()
        .and_then(|s| s.model.clone())
        .or_else(|| args.model.clone())
        .unwrap_or_else(super::default_model);
    let mut inputs = vec![model_path.as_path()];
    inputs.extend(args.trajectory.as_deref());
    inputs.extend(args.scenario.as_deref());
    for out in [&args.record, &args.rerun].into_iter().flatten() {
        twin_core::fsio::check_output(out, &inputs)?;
    }
    if let (Some(a), Some(b)) = (&args.record, &args.rerun)
        && twin_core::fsio::check_output(a, &[b.as_path()]).is_err()
    {
        bail!("--record and --rerun name the same file {}", a.display());
    }
    if (args.rerun.is_some() || args.connect.is_some()) && !cfg!(feature = "rerun") {
        return Err(twin_core::sim::record::rerun_unavailable().into());
    }
    let path = model_path.clone();
    let robot = match &scenario {
        Some(s) => s.robot(&path)?,
        None => Robot::load(&path)?,
    };
    let trajectory = match (&args.trajectory, controller_name.as_str()) {
        (Some(file), "replay") => Some(JointTrajectory::load(file, &args.trajectory_topic)?),
        (Some(_), _) => bail!("--trajectory is for --controller replay"),
        (None, "replay") => {
            bail!("--controller replay needs --trajectory LOG_OR_CSV (a ROS 2 log or a CSV time_sec,<joint>,…)")
        }
        (None, _) => None,
    };
    let walk = scenario.as_ref().map(|s| s.walk.clone()).unwrap_or_default();
    let controller_options = ControllerOptions { trajectory, walk, ..ControllerOptions::default() };
    let mut controller = twin_core::control::by_name_with(&controller_name, &robot.model, &controller_options)?;
    // A scenario's pushes and its gait metrics and checks.
    let mut pushes = scenario.as_ref().map(|s| s.disturbances(&robot.model)).unwrap_or_default();
    let mut check = scenario.as_ref().map(|s| s.check(&robot.model)).transpose()?;
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
    let mut disturbances: Vec<&mut dyn Disturbance> = pushes.iter_mut().map(|p| p as &mut dyn Disturbance).collect();
    let mut observers: Vec<&mut dyn Observer> = check.iter_mut().map(|c| c as &mut dyn Observer).collect();
    let report = sim::simulate_with(
        &robot,
        controller.as_mut(),
        &SimOptions { duration_secs: duration },
        recording.as_mut(),
        &mut progress,
        &mut disturbances,
        &mut observers,
    )?;
    drop(observers);
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
    if let (Some(c), Some(s)) = (&check, &scenario) {
        writeln!(out, "{}", c.metrics.summary())?;
        let verdicts = c.verdicts();
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
