//! `twin sim [MODEL] --duration S --controller pd-hold|passive|replay|walk …`: runs the twin
//! under a controller of twin's registry (`twin_controllers::registry::by_name_with`) and records ROS 2
//! topics (MCAP) and a rerun recording, stamped in simulation time. `--scenario FILE` runs a
//! scenario (`twin_scenario`): its model, controller, pushes and checks, printing the gait
//! metrics and each check as PASS/FAIL; `--controller walk` alone runs the default scenario.
//! `--ros` puts the run on the ROS 2 graph (`twin_bridges::live`): the bridge publishes what the
//! recorder writes and its commands drive the robot.
//!
//! [`run`] reads in steps: the [`Plan`] (scenario and command line merged, checked, outputs
//! checked before any work), the robot, the controller, the [`Outputs`] (recording; with
//! `--ros` the live bridge, a sink of the recording whose controller replaces the registry's),
//! the simulation (`twin_core::sim::simulate_with`, seeded by `--seed`), the printed report and
//! the scenario's verdicts.

use anyhow::{Context, bail};
use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use twin_controllers::registry::ControllerOptions;
use twin_core::control::{Controller, JointTrajectory};
use twin_core::engine::{Disturbance, Observer};
use twin_core::log::{Compression, WriterOptions};
use twin_core::robot::Robot;
use twin_core::sim::{self, RecordOptions, Recording, SimOptions};
use twin_scenario::Scenario;

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
    pub controller: Option<super::ControllerName>,
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
    /// Seed of the run's random stream: the sensor noise and biases the controller observes
    /// (and the recording and the live bridge publish), random disturbances [default: the
    /// scenario's, or 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Rate of /joint_states, /odom, contacts and commands, Hz (every step if the timestep is
    /// longer) [default: 500; with --ros --lockstep, the control rate].
    #[arg(long)]
    pub rate: Option<f64>,
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
    /// /<robot>/joint_commands (Float64MultiArray), /<robot>/joint_trajectory and
    /// /<robot>/joint_command (JointState by joint name).
    #[arg(long)]
    pub ros: bool,
    /// With --ros: simulated seconds per wall second (1.0 = real time), or `max`.
    #[arg(long, default_value = "1.0", value_name = "FACTOR|max")]
    pub rtf: String,
    /// With --ros: wait for the controller to join, run the first control period under hold,
    /// then wait for exactly one command per period (deterministic, however slow the
    /// controller; see the README).
    #[arg(long)]
    pub lockstep: bool,
    /// With --lockstep: longest wait for a command, seconds.
    #[arg(long, default_value_t = 10.0, value_name = "SECS")]
    pub lockstep_timeout: f64,
    /// With --lockstep: longest wait, before time starts, for the controller's command
    /// publisher to join, seconds.
    #[arg(long, default_value_t = 30.0, value_name = "SECS")]
    pub join_timeout: f64,
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
    /// With --ros --controller walk: simulated seconds without a Twist on /cmd_vel (which
    /// steers the walker: linear.x forward, linear.y left, angular.z yaw rate) before it
    /// stops and stands.
    #[arg(long, default_value_t = 0.5, value_name = "SECS")]
    pub cmd_vel_timeout: f64,
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
    /// With --foxglove (no --ros): wait up to this long for a Foxglove client to subscribe.
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

/// `twin sim`, step by step: what to run ([`Plan`]), the robot, the controller, the outputs
/// (recording and the live bridge), the run, the report, the verdicts.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut plan = Plan::of(&args)?;
    let (robot, mut stribeck) = load_robot(&args, &plan)?;
    plan.fit_walk(&robot.model)?;
    // A scenario's own ROS 2 node (`controller = "ros"`): started, driven in lockstep, stopped.
    let external = plan.scenario.as_ref().filter(|s| s.is_external() && plan.controller == "ros");
    let (mut controller, mut health) = match external {
        Some(s) => {
            if args.ros {
                bail!("--ros is for driving the twin from a node you start; {} starts its own", s.path.display());
            }
            let (c, h) = external::start(s, &robot, args.record.as_deref())?;
            (c, Some(h))
        }
        None => {
            (twin_controllers::registry::by_name_with(&plan.controller, &robot.model, &plan.controller_options)?, None)
        }
    };
    // A scenario's pushes and its gait metrics and checks.
    let mut pushes = plan.scenario.as_ref().map(|s| s.disturbances(&robot.model)).unwrap_or_default();
    let mut check = plan.scenario.as_ref().map(|s| s.check(&robot.model)).transpose()?;
    // From here on, Ctrl-C (or SIGTERM) ends the run after the current step: recordings are
    // closed, the summary printed, and twin exits with status 130; a second one aborts.
    twin_core::fsio::cooperate();
    let mut viewer = viewer_start(&args, &robot)?;
    if let Some(v) = &viewer
        && !args.ros
    {
        controller = v.wrap(controller, &robot.model);
    }
    let viewer_sinks = viewer.as_ref().map(|v| v.sinks()).unwrap_or_default();
    let mut outputs = Outputs::open(&args, &plan, &robot, controller.as_ref(), viewer_sinks)?;
    let mut viewer_reset = viewer.as_ref().map(|v| v.reset_disturbance());
    if let Some(v) = &viewer
        && !args.ros
        && args.wait_for_subscriber > 0.0
    {
        v.wait_for_subscriber(args.wait_for_subscriber)?;
    }

    let mut stop = twin_core::engine::observers::StopFlag::new(twin_core::fsio::interrupt_flag());
    let mut disturbances: Vec<&mut dyn Disturbance> = pushes.iter_mut().map(|p| p as &mut dyn Disturbance).collect();
    if let Some(f) = stribeck.as_mut() {
        disturbances.push(f);
    }
    disturbances.extend(viewer_reset.iter_mut().map(|r| r.as_mut() as &mut dyn Disturbance));
    let mut observers: Vec<&mut dyn Observer> = health.iter_mut().map(|h| h.as_mut() as &mut dyn Observer).collect();
    observers.extend(check.iter_mut().map(|c| c as &mut dyn Observer));
    // Commanded vs actual joint positions, for every controller that says its targets.
    let mut tracking = twin_core::tracking::Tracking::new();
    observers.push(&mut tracking);
    observers.push(&mut stop);
    observers.extend(viewer.as_mut().map(|v| v.observer()));
    let (report, ran) = outputs.simulate(&robot, controller.as_mut(), &plan, &mut disturbances, &mut observers)?;
    drop(observers);
    let mut out = std::io::stdout().lock();
    outputs.print(&mut out, &plan, &robot, &report, &ran)?;
    writeln!(out, "{}", tracking.summary())?;

    if let Some(v) = &viewer {
        v.report(&mut out)?;
    }
    // A live run also ends on the flag, through its controller.
    let interrupted = twin_core::fsio::interrupted();
    if interrupted {
        writeln!(out, "stopped by Ctrl-C at {:.3} s of {} s simulated", report.sim_secs, plan.duration_secs)?;
    }
    if let Some(h) = &health
        && let Some(cause) = h.verdict().cause
    {
        writeln!(out, "FAIL controller: {cause}")?;
        out.flush()?;
        if !interrupted {
            bail!("the external controller failed: {cause}");
        }
    }
    if let (Some(c), Some(s)) = (&check, &plan.scenario) {
        print_verdicts(&mut out, c, s, interrupted)?;
    }
    if interrupted {
        out.flush()?;
        return Err(super::Interrupted(format!(
            "simulated {:.3} of {} s; the recordings are closed and readable",
            report.sim_secs, plan.duration_secs
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

/// What to run: the scenario (a file, or the defaults of `--controller walk`), the controller
/// and its options, the duration, the seed, the model file.
struct Plan {
    scenario: Option<Scenario>,
    controller: String,
    controller_options: ControllerOptions,
    duration_secs: f64,
    seed: u64,
    model_path: PathBuf,
    /// Rate of `/joint_states` and the other state topics, Hz.
    state_rate_hz: f64,
}

impl Plan {
    /// Reads the scenario, merges the command line over it, checks the numbers and the outputs
    /// (before any work: not a folder or device, not an input) and loads the trajectory.
    fn of(args: &Args) -> anyhow::Result<Plan> {
        let mut scenario = args.scenario.as_deref().map(Scenario::load).transpose()?;
        let controller = args
            .controller
            .map(|c| c.name().to_string())
            .or_else(|| scenario.as_ref().map(|s| s.controller.clone()))
            .unwrap_or("pd-hold".into());
        let duration_secs = args.duration.or(scenario.as_ref().map(|s| s.duration_secs)).unwrap_or(5.0);
        super::check_range("--duration", duration_secs, super::MIN_SECS, super::MAX_SIM_SECS, "s")?;
        // In lockstep the state comes once per control period (see twin_bridges::live).
        let state_rate_hz = args.rate.unwrap_or(if args.ros && args.lockstep { args.control_rate } else { 500.0 });
        super::check_range("--rate", state_rate_hz, 1e-3, super::MAX_RATE_HZ, "Hz")?;
        super::check_range("--tf-rate", args.tf_rate, 1e-3, super::MAX_RATE_HZ, "Hz")?;
        let walking = controller == "walk";
        if !walking && (args.vx.is_some() || args.vy.is_some() || args.yaw_rate.is_some()) {
            bail!("--vx, --vy and --yaw-rate are for --controller walk");
        }
        // Walking runs a scenario: the given file, or the defaults with the command-line model
        // and velocity.
        if scenario.is_none() && walking {
            scenario = Some(Scenario::defaults("walk", duration_secs));
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
        let trajectory = match (&args.trajectory, controller.as_str()) {
            (Some(file), "replay") => {
                let trajectory = JointTrajectory::load(file, &args.trajectory_topic)?;
                for w in &trajectory.warnings {
                    eprintln!("warning: {}: {w}", file.display());
                }
                Some(trajectory)
            }
            (Some(_), _) => bail!("--trajectory is for --controller replay"),
            (None, "replay") => {
                bail!("--controller replay needs --trajectory LOG_OR_CSV (a ROS 2 log or a CSV time_sec,<joint>,…)")
            }
            (None, _) => None,
        };
        let controller_options = ControllerOptions {
            trajectory,
            walk: scenario.as_ref().map(|s| s.walk.clone()).unwrap_or_default(),
            grasp: scenario.as_ref().map(|s| s.grasp.clone()).unwrap_or_default(),
            ..ControllerOptions::default()
        };
        // --seed wins over the scenario's.
        let seed = args.seed.or(scenario.as_ref().map(|s| s.seed)).unwrap_or(0);
        Ok(Plan { scenario, controller, controller_options, duration_secs, seed, model_path, state_rate_hz })
    }
}

impl Plan {
    /// The walker's options for the robot it drives: what the scenario and the command line
    /// leave unset derived from the robot ([`Scenario::fit_walk`]).
    fn fit_walk(&mut self, model: &twin_core::mj::Model) -> anyhow::Result<()> {
        if self.controller != "walk" {
            return Ok(());
        }
        if let Some(s) = self.scenario.as_mut() {
            s.controller = self.controller.clone();
            let before = s.walk.clone();
            s.fit_walk(model)?;
            self.controller_options.walk = s.walk.clone();
            // Say what was derived for this robot (nothing for the shipped humanoid).
            let changed = s.walk.changes_from(&before);
            if !changed.is_empty() {
                eprintln!("walker options derived from the robot: {}", changed.join(", "));
            }
        }
        Ok(())
    }
}

/// The robot to simulate, with the friction curves of `--friction-fit` (a disturbance of the
/// run) when given.
fn load_robot(
    args: &Args,
    plan: &Plan,
) -> anyhow::Result<(Robot, Option<twin_core::engine::disturb::StribeckFriction>)> {
    let path = &plan.model_path;
    let robot = match &plan.scenario {
        Some(s) => s.robot(path)?,
        None => Robot::load(path)?,
    };
    let stribeck = args.friction_fit.as_deref().map(|file| stribeck_curves(file, &robot)).transpose()?;
    let robot = match &stribeck {
        Some(f) => robot.with_model(std::sync::Arc::new(f.model_without_joint_friction(&robot.model)?))?,
        None => robot,
    };
    Ok((robot, stribeck))
}

/// Where the run goes: the recording (MCAP, rerun) and, with `--ros`, the live bridge (a sink
/// of the recording and the run's controller).
struct Outputs {
    recording: Option<Recording>,
    /// Whether the user asked for a file or viewer (the live bridge records too).
    recording_wanted: bool,
    live: Option<live::Live>,
}

/// What the run's controller said when it ended.
struct Ran {
    controller: &'static str,
    lines: Vec<String>,
}

impl Outputs {
    fn open(
        args: &Args,
        plan: &Plan,
        robot: &Robot,
        controller: &dyn Controller,
        viewer_sinks: Vec<Box<dyn twin_core::topics::Sink>>,
    ) -> anyhow::Result<Outputs> {
        let options = RecordOptions {
            mcap: args.record.clone(),
            rrd: args.rerun.clone(),
            connect: args.connect.clone(),
            state_rate_hz: plan.state_rate_hz,
            tf_rate_hz: args.tf_rate,
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
        let recording_wanted = options.mcap.is_some() || options.rrd.is_some() || options.connect.is_some();
        if recording_wanted || args.ros {
            for note in twin_core::sense::unrendered_cameras(robot) {
                eprintln!("note: {note}");
            }
        }
        if args.ros {
            // `--controller walk` on the graph: the walker runs, steered by `/cmd_vel`.
            let walker = (plan.controller == "walk")
                .then(|| twin_controllers::walk::Walker::new(&robot.model, plan.controller_options.walk.clone()))
                .transpose()?;
            let (live, recording) = live::Live::start(args, robot, options, viewer_sinks, walker)?;
            return Ok(Outputs { recording: Some(recording), recording_wanted, live: Some(live) });
        }
        let recording = if !viewer_sinks.is_empty() {
            Some(Recording::with_sinks(robot, &options, viewer_sinks)?)
        } else if recording_wanted {
            Some(Recording::new(robot, &options)?)
        } else {
            None
        };
        Ok(Outputs { recording, recording_wanted, live: None })
    }

    /// Runs the simulation with `controller` (or the live bridge's), a progress bar on a
    /// terminal, and closes the recording.
    fn simulate(
        &mut self,
        robot: &Robot,
        controller: &mut dyn Controller,
        plan: &Plan,
        disturbances: &mut [&mut dyn Disturbance],
        observers: &mut [&mut dyn Observer],
    ) -> anyhow::Result<(sim::SimReport, Ran)> {
        let bar = progress_bar()?;
        let mut progress = |f: f64| {
            if let Some(b) = &bar {
                b.set_position((f * 1000.0) as u64);
            }
        };
        let (controller, reset): (&mut dyn Controller, _) = match self.live.as_mut() {
            Some(l) => l.parts(),
            None => (controller, None),
        };
        let mut all: Vec<&mut dyn Disturbance> =
            disturbances.iter_mut().map(|d| &mut **d as &mut dyn Disturbance).collect();
        all.extend(reset);
        let options = SimOptions { duration_secs: plan.duration_secs, seed: plan.seed };
        let report = sim::simulate_with(
            robot,
            controller,
            &options,
            self.recording.as_mut(),
            &mut progress,
            &mut all,
            observers,
        )?;
        let ran = Ran { controller: controller.name(), lines: controller.report() };
        if let Some(b) = bar {
            b.finish_and_clear();
        }
        Ok((report, ran))
    }

    /// Closes the recording and prints what the run did.
    fn print(
        &mut self,
        out: &mut impl Write,
        plan: &Plan,
        robot: &Robot,
        report: &sim::SimReport,
        ran: &Ran,
    ) -> anyhow::Result<()> {
        let finishing = std::time::Instant::now();
        let summary = self.recording.take().map(Recording::finish).transpose()?;
        let finish_secs = finishing.elapsed().as_secs_f64();
        writeln!(
            out,
            "simulated {:.3} s of {} ({} steps of {} ms) with controller {} in {:.3} s wall: real-time factor {:.1}",
            report.sim_secs,
            plan.model_path.display(),
            report.steps,
            robot.model.timestep_secs() * 1e3,
            ran.controller,
            report.wall_secs,
            report.real_time_factor()
        )?;
        if let Some(cpu) = report.loop_cpu_secs {
            writeln!(out, "simulation thread CPU: {cpu:.3} s ({:.2} µs per step)", cpu * 1e6 / report.steps as f64)?;
        }
        if let Some(s) = summary {
            print_recording(out, &s, report, finish_secs, self.recording_wanted)?;
        }
        if let Some(l) = &self.live {
            l.report(out)?;
        }
        for line in &ran.lines {
            writeln!(out, "{line}")?;
        }
        Ok(())
    }
}

fn progress_bar() -> anyhow::Result<Option<indicatif::ProgressBar>> {
    if !std::io::stderr().is_terminal() {
        return Ok(None);
    }
    let bar = indicatif::ProgressBar::new(1000);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:40} {percent}% of the simulated time  ETA {eta}")
            .context("progress bar template")?,
    );
    Ok(Some(bar))
}

fn print_recording(
    out: &mut impl Write,
    s: &twin_core::sim::RecordSummary,
    report: &sim::SimReport,
    finish_secs: f64,
    recording_wanted: bool,
) -> anyhow::Result<()> {
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
    for c in &s.sensors {
        writeln!(
            out,
            "sensor {}: {} readings of {} rays at {} Hz, {:.2} ms each: {:.0} ms per simulated second",
            c.name,
            c.readings,
            c.rays,
            c.rate_hz,
            c.secs_per_reading * 1e3,
            c.secs_per_sim_sec() * 1e3
        )?;
        // The budget: real time on the core that casts the sensor's rays.
        if c.secs_per_sim_sec() > 1.0 {
            eprintln!(
                "warning: sensor {} alone keeps the run below real time: {:.1} ms a reading × {} Hz = {:.2} s per \
                 simulated second; lower its resolution or rate, or leave its topics out (--topics)",
                c.name,
                c.secs_per_reading * 1e3,
                c.rate_hz,
                c.secs_per_sim_sec()
            );
        }
    }
    Ok(())
}

/// Prints the scenario's gait metrics and verdicts; fails when a check failed (unless the run
/// was interrupted: its numbers are partial).
fn print_verdicts(
    out: &mut impl Write,
    check: &twin_scenario::ScenarioCheck,
    scenario: &Scenario,
    interrupted: bool,
) -> anyhow::Result<()> {
    writeln!(out, "{}", check.metrics.summary())?;
    let verdicts = check.verdicts();
    if !verdicts.is_empty() {
        writeln!(out, "checks of {}:", scenario.path.display())?;
        for v in &verdicts {
            writeln!(out, "  {v}")?;
        }
    }
    let failed = verdicts.iter().filter(|v| !v.passed).count();
    if failed > 0 && !interrupted {
        bail!("{failed} of {} checks of {} failed", verdicts.len(), scenario.path.display());
    }
    Ok(())
}

/// `controller = "ros"` in a scenario: the user's node as the controller
/// (`twin_bridges::external`).
mod external {
    use std::path::Path;
    use twin_core::control::Controller;
    use twin_core::engine::Check;
    use twin_core::robot::Robot;
    use twin_scenario::Scenario;

    /// The scenario's external controller and its health check; the process's output goes
    /// beside `record` (`<record>.controller.log`), or to `<scenario>.controller.log` in the
    /// current folder.
    #[cfg(feature = "ros")]
    pub fn start(
        s: &Scenario,
        robot: &Robot,
        record: Option<&Path>,
    ) -> anyhow::Result<(Box<dyn Controller>, Box<dyn Check>)> {
        let Some(options) = &s.ros else {
            anyhow::bail!("{}: controller = \"ros\" needs a [ros] table", s.path.display())
        };
        let stem = |p: &Path| p.file_stem().map_or_else(|| "run".into(), |n| n.to_string_lossy().into_owned());
        let log = match record {
            Some(r) => r.with_file_name(format!("{}.controller.log", stem(r))),
            None => Path::new(".").join(format!("{}.controller.log", stem(&s.path))),
        };
        let (c, h) = twin_bridges::external::external(robot, options, &s.folder(), &log)?;
        eprintln!(
            "external controller `{}` on ROS domain {}: its output goes to {}",
            options.command,
            c.domain_id(),
            log.display()
        );
        Ok((Box::new(c), Box::new(h)))
    }

    #[cfg(not(feature = "ros"))]
    pub fn start(_: &Scenario, _: &Robot, _: Option<&Path>) -> anyhow::Result<(Box<dyn Controller>, Box<dyn Check>)> {
        Err(twin_core::Error::FeatureMissing { feature: "ros", what: "controller = \"ros\" (your ROS 2 node)".into() }
            .into())
    }
}

/// The `--ros` side of `twin sim`: the live bridge's two halves, started, announced and
/// reported.
#[cfg(feature = "ros")]
mod live {
    use super::{Args, InterfaceKind};
    use anyhow::{Context, bail};
    use std::io::Write;
    use twin_bridges::live::{self as bridge, CommandInterface, LiveController, LiveOptions, Pacing};
    use twin_core::control::Controller;
    use twin_core::engine::Disturbance;
    use twin_core::robot::Robot;
    use twin_core::sim::{RecordOptions, Recording};

    /// The bridge of a run: its controller and its reset.
    pub struct Live {
        controller: LiveController,
        reset: twin_core::engine::disturb::ResetOnRequest,
    }

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

    fn positive(option: &str, value: f64) -> anyhow::Result<()> {
        if !(value > 0.0 && value.is_finite()) {
            bail!("{option} must be a positive number of seconds (got {value})");
        }
        Ok(())
    }

    fn options(args: &Args) -> anyhow::Result<LiveOptions> {
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
        positive("--lockstep-timeout", args.lockstep_timeout)?;
        positive("--join-timeout", args.join_timeout)?;
        positive("--silence-timeout", args.silence_timeout)?;
        positive("--cmd-vel-timeout", args.cmd_vel_timeout)?;
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
        Ok(LiveOptions {
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
            cmd_vel_timeout_secs: args.cmd_vel_timeout,
            lockstep_timeout_secs: args.lockstep_timeout,
            join_timeout_secs: args.join_timeout,
            ..LiveOptions::default()
        })
    }

    impl Live {
        /// Joins the graph, opens the recording with the bridge as a sink, announces the
        /// bridge, and waits for a subscriber when asked.
        pub fn start(
            args: &Args,
            robot: &Robot,
            record: RecordOptions,
            viewer_sinks: Vec<Box<dyn twin_core::topics::Sink>>,
            walker: Option<twin_controllers::walk::Walker>,
        ) -> anyhow::Result<(Live, Recording)> {
            let options = options(args)?;
            let stop = twin_core::fsio::interrupt_flag();
            let log = Box::new(|m: &str| eprintln!("warning: {m}"));
            let (sink, mut controller) = bridge::start(robot, &options, stop, log)?;
            if let Some(w) = walker {
                controller.drive_walker(w);
            }
            let record = RecordOptions {
                command_topic: Some(bridge::actuator_topic(robot)),
                controller_topics: controller.topics().into_iter().map(|t| t.name).collect(),
                ..record
            };
            let mut sinks: Vec<Box<dyn twin_core::topics::Sink>> = vec![Box::new(sink)];
            sinks.extend(viewer_sinks);
            let recording = Recording::with_sinks(robot, &record, sinks)?;
            announce(args, robot, &controller, options.domain_id)?;
            if args.wait_for_subscriber > 0.0
                && !controller.wait_for_subscriber(std::time::Duration::from_secs_f64(args.wait_for_subscriber))
            {
                bail!("no subscriber on /clock within {} s (--wait-for-subscriber)", args.wait_for_subscriber);
            }
            let reset = controller.reset_disturbance();
            Ok((Live { controller, reset }, recording))
        }

        /// The run's controller and its reset disturbance.
        pub fn parts(&mut self) -> (&mut dyn Controller, Option<&mut dyn Disturbance>) {
            (&mut self.controller, Some(&mut self.reset))
        }

        pub fn report(&self, out: &mut impl Write) -> anyhow::Result<()> {
            let s = self.controller.stats();
            writeln!(
                out,
                "live: {} control periods, {} commands applied, {} rejected, {} safe holds, {} service calls, {} \
                 resets; measured real-time factor {:.4}",
                s.periods,
                s.commands_applied,
                s.commands_rejected,
                s.safe_holds,
                s.service_calls,
                s.resets,
                s.real_time_factor()
            )?;
            if self.controller.walker().is_some() {
                writeln!(
                    out,
                    "walker steered by {}: {} Twists clamped to what its steps allow, {} stops for lack of one",
                    twin_core::topics::CMD_VEL_TOPIC,
                    s.cmd_vel_clamped,
                    s.cmd_vel_timeouts,
                )?;
            }
            if let Some(j) = s.join_secs {
                writeln!(out, "lockstep: the controller joined after {j:.2} s")?;
            }
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

    fn announce(args: &Args, robot: &Robot, c: &LiveController, domain: u16) -> anyhow::Result<()> {
        let mut out = std::io::stdout().lock();
        writeln!(
            out,
            "ROS 2 live: domain {domain}, interface {}, {} at {} Hz ({} steps per period), {}",
            args.ros_interface,
            if args.lockstep { "lockstep".to_string() } else { format!("rtf {}", args.rtf) },
            args.control_rate,
            c.steps_per_period(),
            robot.name
        )?;
        writeln!(
            out,
            "commands: std_msgs/Float64MultiArray on {} ({}), trajectory_msgs/JointTrajectory on {}, \
             sensor_msgs/JointState by joint name on {}",
            bridge::command_topic(robot),
            match args.command_interface {
                InterfaceKind::Position => "positions, rad",
                InterfaceKind::Velocity => "velocities, rad/s",
                InterfaceKind::Effort => "efforts, N·m",
            },
            bridge::trajectory_topic(robot),
            bridge::by_name_topic(robot)
        )?;
        writeln!(out, "command order ({} joints): {}", c.joint_names().len(), c.joint_names().join(", "))?;
        let services: Vec<String> =
            bridge::simulation::SERVICES.iter().map(|(name, ty)| format!("{name} ({ty})")).collect();
        writeln!(out, "services: {}", services.join(", "))?;
        out.flush()?;
        Ok(())
    }
}

/// Without the `ros` feature: `--ros` says the build lacks it.
#[cfg(not(feature = "ros"))]
mod live {
    use super::Args;
    use twin_core::control::Controller;
    use twin_core::engine::Disturbance;
    use twin_core::sim::Recording;

    /// No bridge in this build: never made.
    pub enum Live {}

    impl Live {
        /// Refused before any of the bridge's parts (robot, options, sinks, walker) is used.
        pub fn start<R, O, S, W>(_: &Args, _: R, _: O, _: S, _: W) -> anyhow::Result<(Live, Recording)> {
            Err(twin_core::Error::FeatureMissing { feature: "ros", what: "--ros (the live ROS 2 bridge)".into() }
                .into())
        }

        pub fn parts(&mut self) -> (&mut dyn Controller, Option<&mut dyn Disturbance>) {
            match *self {}
        }

        pub fn report(&self, _: &mut impl std::io::Write) -> anyhow::Result<()> {
            match *self {}
        }
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
