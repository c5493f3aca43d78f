//! `twin sim [MODEL] --duration S --controller pd-hold|passive|replay|walk …`: runs the twin
//! under a controller of twin's registry (`twin_core::control::by_name_with`) and records ROS 2
//! topics (MCAP) and a rerun recording, stamped in simulation time. `--scenario FILE` runs a
//! scenario (`twin_core::scenario`): its model, controller, pushes and checks, printing the gait
//! metrics and each check as PASS/FAIL; `--controller walk` alone runs the default scenario.

use anyhow::{Context, bail};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use twin_core::control::{Controller, ControllerOptions, JointTrajectory};
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
    /// Topic of the trajectory log: sensor_msgs/JointState, or trajectory_msgs/JointTrajectory
    /// (as `twin excite` writes on /joint_trajectory).
    #[arg(long, default_value = "/joint_states")]
    pub trajectory_topic: String,
    /// Simulate the full Stribeck friction curves of this `twin sysid friction --report` JSON
    /// on their joints, per step (replacing those joints' URDF friction and damping).
    #[arg(long, value_name = "friction.json")]
    pub friction_fit: Option<PathBuf>,
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
    /// Record only these topics (comma-separated; `/contacts/*` for every contact topic). The
    /// controller's own topics (the walker's `/walk/*`) may be named and are always recorded.
    #[arg(long, value_delimiter = ',', value_name = "TOPIC,...")]
    pub topics: Option<Vec<String>>,
    /// Join the ROS 2 graph (domain `ROS_DOMAIN_ID`): publish /clock, /joint_states, the IMUs,
    /// /odom, /tf, /tf_static, contacts and /robot_description, and take commands on
    /// /<robot>/joint_commands (Float64MultiArray) and /<robot>/joint_trajectory.
    #[arg(long)]
    pub ros: bool,
    /// With --ros: simulated seconds per wall second (1.0 = real time), or `max`.
    #[arg(long, default_value = "1.0", value_name = "FACTOR|max")]
    pub rtf: String,
    /// With --ros: wait for exactly one command per control period (deterministic, however
    /// slow the controller).
    #[arg(long)]
    pub lockstep: bool,
    /// With --lockstep: longest wait for a command, seconds.
    #[arg(long, default_value_t = 10.0, value_name = "SECS")]
    pub lockstep_timeout: f64,
    /// With --ros: control rate (/clock and command periods), Hz.
    #[arg(long, default_value_t = 100.0, value_name = "HZ")]
    pub control_rate: f64,
    /// With --ros: what the numbers of /<robot>/joint_commands are.
    #[arg(long, value_enum, default_value_t = InterfaceKind::Position)]
    pub command_interface: InterfaceKind,
    /// With --ros: the only network interface DDS uses: `lo` (loopback only, unicast discovery
    /// to 127.0.0.1, no multicast) or an IPv4/IPv6 address of this machine.
    #[arg(long, default_value = "lo", value_name = "lo|IP")]
    pub ros_interface: String,
    /// With --ros (real-time modes): seconds without a good command before the joints hold
    /// their current pose.
    #[arg(long, default_value_t = 0.5, value_name = "SECS")]
    pub silence_timeout: f64,
    /// Serve the run to Foxglove/Lichtblick over WebSocket at PORT (loopback) or ADDR:PORT:
    /// every topic live (CDR), /robot_description and its package:// meshes, the
    /// /twin/pause, /twin/resume, /twin/step and /twin/reset services, and joint position
    /// commands published by a client. Paced at --rtf unless --ros paces the run.
    #[arg(long, value_name = "[ADDR:]PORT")]
    pub foxglove: Option<String>,
    /// Serve the run to Unity's ROS-TCP-Connector (the ROS-TCP-Endpoint protocol, ROS 2 CDR)
    /// at PORT (loopback; 10000 when no port is given) or ADDR:PORT: Unity subscribes to
    /// /joint_states and the other topics and publishes joint position commands.
    #[arg(long, value_name = "[ADDR:]PORT", num_args = 0..=1, default_missing_value = "10000")]
    pub unity: Option<String>,
    /// With --ros: wait up to this long for a subscriber on /clock before starting, seconds.
    #[arg(long, default_value_t = 0.0, value_name = "SECS")]
    pub wait_for_subscriber: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InterfaceKind {
    /// Joint positions, rad (m): PD servo with the hold gains.
    Position,
    /// Joint velocities, rad/s (m/s).
    Velocity,
    /// Joint efforts, N·m (N).
    Effort,
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
    twin_core::fsio::check_outputs(
        &[("--record", args.record.as_deref()), ("--rerun", args.rerun.as_deref())],
        &inputs,
    )?;
    if (args.rerun.is_some() || args.connect.is_some()) && !cfg!(feature = "rerun") {
        return Err(twin_core::sim::record::rerun_unavailable().into());
    }
    let path = model_path.clone();
    let robot = match &scenario {
        Some(s) => s.robot(&path)?,
        None => Robot::load(&path)?,
    };
    let mut stribeck = args.friction_fit.as_deref().map(|file| stribeck_curves(file, &robot)).transpose()?;
    let robot = match &stribeck {
        Some(f) => robot.with_model(std::sync::Arc::new(f.model_without_joint_friction(&robot.model)?))?,
        None => robot,
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
    let grasp = scenario.as_ref().map(|s| s.grasp.clone()).unwrap_or_default();
    let controller_options = ControllerOptions { trajectory, walk, grasp, ..ControllerOptions::default() };
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
        controller_topics: controller.topics().into_iter().map(|t| t.name).collect(),
        ..RecordOptions::default()
    };
    // From here on, Ctrl-C (or SIGTERM) ends the run after the current step: recordings are
    // closed, the summary printed, and twin exits with status 130; a second one aborts.
    twin_core::fsio::cooperate();
    let mut stop = twin_core::engine::observers::StopFlag::new(twin_core::fsio::interrupt_flag());
    let recording_wanted = options.mcap.is_some() || options.rrd.is_some() || options.connect.is_some();
    let mut viewer = viewer_start(&args, &robot)?;
    if let Some(v) = &viewer
        && !args.ros
    {
        controller = v.wrap(controller, &robot.model);
    }
    #[cfg(feature = "ros")]
    let live = if args.ros { Some(live::start(&args, &robot)?) } else { None };
    #[cfg(not(feature = "ros"))]
    if args.ros {
        return Err(
            twin_core::Error::FeatureMissing { feature: "ros", what: "--ros (the live ROS 2 bridge)".into() }.into()
        );
    }
    #[cfg(feature = "ros")]
    let (mut recording, mut live_controller) = match live {
        Some((sink, controller)) => {
            let options = RecordOptions {
                command_topic: Some(twin_core::live::actuator_topic(&robot)),
                controller_topics: controller.topics().into_iter().map(|t| t.name).collect(),
                ..options
            };
            let mut sinks: Vec<Box<dyn twin_core::topics::Sink>> = vec![Box::new(sink)];
            sinks.extend(viewer.iter().flat_map(|v| v.sinks()));
            (Some(Recording::with_sinks(&robot, &options, sinks)?), Some(controller))
        }
        None => match &viewer {
            Some(v) => (Some(Recording::with_sinks(&robot, &options, v.sinks())?), None),
            None => (if recording_wanted { Some(Recording::new(&robot, &options)?) } else { None }, None),
        },
    };
    #[cfg(not(feature = "ros"))]
    let mut recording = if recording_wanted { Some(Recording::new(&robot, &options)?) } else { None };
    #[cfg(feature = "ros")]
    if let Some(c) = &live_controller {
        live::announce(&args, &robot, c)?;
        if args.wait_for_subscriber > 0.0
            && !c.wait_for_subscriber(std::time::Duration::from_secs_f64(args.wait_for_subscriber))
        {
            bail!("no subscriber on /clock within {} s (--wait-for-subscriber)", args.wait_for_subscriber);
        }
    }
    #[cfg(feature = "ros")]
    let mut live_reset = live_controller.as_ref().map(|c| c.reset_disturbance());
    #[cfg(feature = "ros")]
    let controller: &mut dyn Controller = match live_controller.as_mut() {
        Some(c) => c,
        None => controller.as_mut(),
    };
    #[cfg(not(feature = "ros"))]
    let controller: &mut dyn Controller = controller.as_mut();

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
    let mut viewer_reset = viewer.as_ref().map(|v| v.reset_disturbance());
    let mut disturbances: Vec<&mut dyn Disturbance> = pushes.iter_mut().map(|p| p as &mut dyn Disturbance).collect();
    #[cfg(feature = "ros")]
    disturbances.extend(live_reset.iter_mut().map(|r| r as &mut dyn Disturbance));
    if let Some(f) = stribeck.as_mut() {
        disturbances.push(f);
    }
    disturbances.extend(viewer_reset.iter_mut().map(|r| r.as_mut() as &mut dyn Disturbance));
    let mut observers: Vec<&mut dyn Observer> = check.iter_mut().map(|c| c as &mut dyn Observer).collect();
    observers.push(&mut stop);
    observers.extend(viewer.as_mut().map(|v| v.observer()));
    let report = sim::simulate_with(
        &robot,
        controller,
        &SimOptions { duration_secs: duration },
        recording.as_mut(),
        &mut progress,
        &mut disturbances,
        &mut observers,
    )?;
    drop(observers);
    let controller_name = controller.name();
    let controller_report = controller.report();
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    #[cfg(feature = "ros")]
    let live_stats = live_controller.as_ref().map(|c| c.stats().clone());
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
        controller_name,
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
    #[cfg(feature = "ros")]
    if let Some(stats) = live_stats {
        live::report(&mut out, &stats)?;
    }
    if let Some(v) = &viewer {
        v.report(&mut out)?;
    }
    for line in &controller_report {
        writeln!(out, "{line}")?;
    }
    // A live run also ends on the flag, through its controller.
    let interrupted = twin_core::fsio::interrupted();
    if interrupted {
        writeln!(out, "stopped by Ctrl-C at {:.3} s of {duration} s simulated", report.sim_secs)?;
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
        if failed > 0 && !interrupted {
            bail!("{failed} of {} checks of {} failed", verdicts.len(), s.path.display());
        }
    }
    if interrupted {
        out.flush()?;
        return Err(super::Interrupted(format!(
            "simulated {:.3} of {duration} s; the recordings are closed and readable",
            report.sim_secs
        ))
        .into());
    }
    Ok(())
}

/// `--foxglove`, `--unity`: the servers, their hook and sinks (see `super::viewers`); paced at
/// `--rtf` unless `--ros` paces the run.
#[cfg(feature = "ros")]
fn viewer_start(args: &Args, robot: &Robot) -> anyhow::Result<Option<super::viewers::Viewers>> {
    if args.foxglove.is_none() && args.unity.is_none() {
        return Ok(None);
    }
    let foxglove = args.foxglove.as_deref().map(|a| super::viewers::parse_addr("--foxglove", a)).transpose()?;
    let unity = args.unity.as_deref().map(|a| super::viewers::parse_addr("--unity", a)).transpose()?;
    let rtf = if args.ros || args.rtf.eq_ignore_ascii_case("max") {
        None
    } else {
        match args.rtf.parse::<f64>() {
            Ok(f) if f > 0.0 && f.is_finite() => Some(f),
            _ => bail!("--rtf must be a positive real-time factor (1.0 = real time) or `max` (got {:?})", args.rtf),
        }
    };
    Ok(Some(super::viewers::start(foxglove, unity, robot, rtf)?))
}

#[cfg(not(feature = "ros"))]
fn viewer_start(args: &Args, _robot: &Robot) -> anyhow::Result<Option<super::viewers::Viewers>> {
    if args.foxglove.is_some() || args.unity.is_some() {
        return Err(super::viewers::unavailable());
    }
    Ok(None)
}

/// The `--ros` side of `twin sim`.
#[cfg(feature = "ros")]
mod live {
    use super::{Args, InterfaceKind};
    use anyhow::{Context, bail};
    use std::io::Write;
    use twin_core::live::{self as bridge, CommandInterface, LiveController, LiveOptions, LiveSink, LiveStats, Pacing};
    use twin_core::robot::Robot;

    /// `ROS_DOMAIN_ID` (0 when unset), checked.
    fn domain_id() -> anyhow::Result<u16> {
        match std::env::var("ROS_DOMAIN_ID") {
            Err(_) => Ok(0),
            Ok(v) if v.trim().is_empty() => Ok(0),
            Ok(v) => match v.trim().parse::<u16>() {
                Ok(d) if d <= 232 => Ok(d),
                _ => bail!("ROS_DOMAIN_ID={v:?} is not a DDS domain id (an integer 0..=232)"),
            },
        }
    }

    pub fn start(args: &Args, robot: &Robot) -> anyhow::Result<(LiveSink, LiveController)> {
        let pacing = if args.lockstep {
            Pacing::Lockstep
        } else if args.rtf.eq_ignore_ascii_case("max") {
            Pacing::Max
        } else {
            match args.rtf.parse::<f64>() {
                Ok(f) if f > 0.0 && f.is_finite() => Pacing::RealTime(f),
                _ => bail!("--rtf must be a positive real-time factor (1.0 = real time) or `max` (got {:?})", args.rtf),
            }
        };
        if !(args.lockstep_timeout > 0.0 && args.lockstep_timeout.is_finite()) {
            bail!("--lockstep-timeout must be a positive number of seconds (got {})", args.lockstep_timeout);
        }
        if !(args.silence_timeout > 0.0 && args.silence_timeout.is_finite()) {
            bail!("--silence-timeout must be a positive number of seconds (got {})", args.silence_timeout);
        }
        let interface = if args.ros_interface == "lo" {
            std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST)
        } else {
            args.ros_interface.parse().with_context(|| {
                format!(
                    "--ros-interface {:?}: give `lo` (loopback only) or an IP address of this machine's interface",
                    args.ros_interface
                )
            })?
        };
        let options = LiveOptions {
            domain_id: domain_id()?,
            interface,
            control_rate_hz: args.control_rate,
            command_interface: match args.command_interface {
                InterfaceKind::Position => CommandInterface::Position,
                InterfaceKind::Velocity => CommandInterface::Velocity,
                InterfaceKind::Effort => CommandInterface::Effort,
            },
            pacing,
            silence_timeout_secs: args.silence_timeout,
            lockstep_timeout_secs: args.lockstep_timeout,
        };
        // Ctrl-C ends the run cleanly (recordings closed); a second one aborts (twin's one
        // signal handler, installed by main).
        twin_core::fsio::cooperate();
        let stop = twin_core::fsio::interrupt_flag();
        let log = Box::new(|m: &str| eprintln!("warning: {m}"));
        Ok(bridge::start(robot, &options, stop, log)?)
    }

    pub fn announce(args: &Args, robot: &Robot, c: &LiveController) -> anyhow::Result<()> {
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "ROS 2 live: domain {}, interface {}, {} at {} Hz ({} steps per period), {}",
            domain_id()?,
            args.ros_interface,
            if args.lockstep { "lockstep".to_string() } else { format!("rtf {}", args.rtf) },
            args.control_rate,
            c.steps_per_period(),
            robot.name
        )?;
        writeln!(
            out,
            "commands: std_msgs/Float64MultiArray on {} ({}), trajectory_msgs/JointTrajectory on /{}/joint_trajectory",
            bridge::command_topic(robot),
            match args.command_interface {
                InterfaceKind::Position => "positions, rad",
                InterfaceKind::Velocity => "velocities, rad/s",
                InterfaceKind::Effort => "efforts, N·m",
            },
            robot.name
        )?;
        writeln!(out, "command order ({} joints): {}", c.joint_names().len(), c.joint_names().join(", "))?;
        let services: Vec<String> =
            bridge::simulation::SERVICES.iter().map(|(name, ty)| format!("{name} ({ty})")).collect();
        writeln!(out, "services: {}", services.join(", "))?;
        out.flush()?;
        Ok(())
    }

    pub fn report(out: &mut impl Write, s: &LiveStats) -> anyhow::Result<()> {
        writeln!(
            out,
            "live: {} control periods, {} commands applied, {} rejected, {} safe holds, {} service calls, {} resets; \
             measured real-time factor {:.4}",
            s.periods,
            s.commands_applied,
            s.commands_rejected,
            s.safe_holds,
            s.service_calls,
            s.resets,
            s.real_time_factor()
        )?;
        if let (Some(p50), Some(p99)) =
            (bridge::percentile(&s.jitter_micros, 50.0), bridge::percentile(&s.jitter_micros, 99.0))
        {
            writeln!(out, "period start lateness (jitter): p50 {p50:.0} µs, p99 {p99:.0} µs")?;
        }
        if let (Some(p50), Some(p99)) =
            (bridge::percentile(&s.round_trip_micros, 50.0), bridge::percentile(&s.round_trip_micros, 99.0))
        {
            writeln!(out, "lockstep round trip (/clock out to command in): p50 {p50:.0} µs, p99 {p99:.0} µs")?;
        }
        Ok(())
    }
}

/// The friction curves of a `twin sysid friction --report` JSON on `robot`'s joints.
fn stribeck_curves(
    file: &std::path::Path,
    robot: &Robot,
) -> anyhow::Result<twin_core::engine::disturb::StribeckFriction> {
    use twin_core::engine::disturb::{StribeckCurve, StribeckFriction};
    let mut curves = Vec::new();
    for (name, fit) in sysid::friction::read_fits(file)? {
        let curve = StribeckCurve {
            coulomb: fit.coulomb,
            breakaway: fit.breakaway,
            stribeck_velocity: fit.stribeck_velocity,
            exponent: fit.exponent,
            viscous: fit.viscous,
        };
        let Some(joint) = robot.joints.iter().find(|j| j.name == name) else {
            bail!(
                "{}: joint \"{name}\" is not a joint of {}; its joints: {}",
                file.display(),
                robot.path.display(),
                robot.joints.iter().map(|j| j.name.as_str()).collect::<Vec<_>>().join(", ")
            );
        };
        curves.push((joint.dof, curve));
    }
    Ok(StribeckFriction::new(curves))
}
