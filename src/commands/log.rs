//! `twin log info FILE`: topics, types, counts, rates, time span and gaps of a ROS 2 MCAP log
//! (a `.mcap` file or a rosbag2 folder), with what was lost if the file is damaged.
//! `twin log analyze FILE [--model ROBOT] [--plot DIR] [--json FILE]`: why the robot fell
//! (`twin_diagnose`): fall onset and direction, CoM and capture point against the
//! support polygon, slip, what changed first, commanded vs actual, and a diagnosis.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};
use twin_core::log::{Log, LogInfo, ReadOptions};
use twin_diagnose::{AnalyzeOptions, CommandKind};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: LogCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum LogCommand {
    /// List topics, types, message counts, rates, time span and the largest gap per topic.
    Info {
        /// A `.mcap` file or a rosbag2 folder (metadata.yaml + .mcap).
        file: PathBuf,
        /// Fail on a damaged file instead of reading what is intact.
        #[arg(long)]
        strict: bool,
    },
    /// Why the robot fell: fall onset and direction, CoM and capture point against the support
    /// polygon (with --model), slip, what changed first, commanded vs actual per joint, and a
    /// diagnosis in troubleshooting terms.
    Analyze(Box<AnalyzeArgs>),
}

#[derive(Debug, clap::Args)]
pub struct AnalyzeArgs {
    /// A `.mcap` file or a rosbag2 folder (metadata.yaml + .mcap).
    pub file: PathBuf,
    /// The robot (URDF or MJCF): CoM, capture point, support polygon, slip, joint limits and
    /// what its actuators' commands are.
    #[arg(long, value_name = "ROBOT")]
    pub model: Option<PathBuf>,
    /// Write SVG plots of the window (window.svg, tracking.svg) into this folder.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Write the report as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// The sensor_msgs/JointState topic.
    #[arg(long, default_value = "/joint_states")]
    pub joint_states: String,
    /// The sensor_msgs/Imu topic [default: the first Imu topic].
    #[arg(long)]
    pub imu: Option<String>,
    /// The nav_msgs/Odometry topic (base pose) [default: the first Odometry topic].
    #[arg(long)]
    pub odom: Option<String>,
    /// The joint command topic: std_msgs/Float64MultiArray, or trajectory_msgs/JointTrajectory
    /// (positions by joint name, interpolated in time) [default: the Float64MultiArray topic
    /// ending in joint_commands, else the JointTrajectory topic ending in joint_trajectory].
    #[arg(long)]
    pub commands: Option<String>,
    /// What the commands are [default: the model's actuators', else the JointState field they
    /// match best].
    #[arg(long, value_enum)]
    pub command_interface: Option<CommandInterfaceArg>,
    /// Seconds of sensor window before the onset.
    #[arg(long, default_value_t = 1.0)]
    pub window: f64,
    /// Fail on a damaged file instead of reading what is intact.
    #[arg(long)]
    pub strict: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CommandInterfaceArg {
    /// Joint positions, rad (m).
    Position,
    /// Joint velocities, rad/s (m/s).
    Velocity,
    /// Joint efforts, N·m (N).
    Effort,
}

/// Runs `twin log analyze` and writes its outputs; returns the report text (printed by the
/// caller). Also used by `twin randomize --record-worst`.
pub fn analyze(args: &AnalyzeArgs) -> anyhow::Result<String> {
    super::check_range("--window", args.window, 1e-3, 3600.0, "s")?;
    let log = Log::open(&args.file, ReadOptions { strict: args.strict })?;
    let robot = args
        .model
        .as_deref()
        .map(|m| twin_core::robot::Robot::load(m).with_context(|| format!("loading --model {}", m.display())))
        .transpose()?;
    let options = AnalyzeOptions {
        joint_states_topic: args.joint_states.clone(),
        imu_topic: args.imu.clone(),
        odom_topic: args.odom.clone(),
        command_topic: args.commands.clone(),
        command_kind: args.command_interface.map(|k| match k {
            CommandInterfaceArg::Position => CommandKind::Position,
            CommandInterfaceArg::Velocity => CommandKind::Velocity,
            CommandInterfaceArg::Effort => CommandKind::Effort,
        }),
        window_secs: args.window,
        ..AnalyzeOptions::default()
    };
    let analysis = twin_diagnose::analyze(&log, robot.as_ref(), &options)
        .with_context(|| format!("analysing {}", args.file.display()))?;
    for w in &analysis.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(dir) = &args.plot {
        write_plots(dir, &analysis)?;
    }
    if let Some(path) = &args.json {
        super::write_output(path, &analysis.to_json(), "analysis (JSON)")?;
    }
    Ok(analysis.to_text())
}

fn write_plots(dir: &Path, analysis: &twin_diagnose::Analysis) -> anyhow::Result<()> {
    if dir.exists() && !dir.is_dir() {
        anyhow::bail!("--plot {}: not a folder; give a folder for the SVG plots", dir.display());
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating --plot folder {}", dir.display()))?;
    let plots = analysis.plots();
    if plots.is_empty() {
        eprintln!("no plots: the log has no base pose, IMU, contacts or commands to draw");
    }
    for (name, svg) in plots {
        super::write_output(&dir.join(name), &svg, "plot")?;
    }
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        LogCommand::Info { file, strict } => {
            let log = Log::open(&file, ReadOptions { strict })?;
            let info = log.info().with_context(|| format!("reading {}", file.display()))?;
            for w in info.read.warnings() {
                eprintln!("warning: {w}");
            }
            let mut out = std::io::stdout().lock();
            write_info(&mut out, &log, &info)?;
            Ok(())
        }
        LogCommand::Analyze(a) => {
            let text = analyze(&a)?;
            std::io::stdout().lock().write_all(text.as_bytes())?;
            Ok(())
        }
    }
}

fn secs(nanos: u64) -> f64 {
    nanos as f64 * 1e-9
}

fn write_info(out: &mut impl Write, log: &Log, info: &LogInfo) -> std::io::Result<()> {
    writeln!(out, "log: {}", log.path().display())?;
    for f in log.files() {
        if f != log.path() {
            writeln!(out, "  file: {}", f.display())?;
        }
    }
    writeln!(
        out,
        "profile: {} · library: {}",
        if info.profile.is_empty() { "-" } else { &info.profile },
        if info.library.is_empty() { "-" } else { &info.library }
    )?;
    writeln!(
        out,
        "messages: {} · start {:.6} s · end {:.6} s · duration {:.3} s",
        info.message_count,
        secs(info.start_nanos),
        secs(info.end_nanos),
        info.duration_secs()
    )?;
    let damaged = info.read.damage().count();
    if damaged > 0 {
        writeln!(out, "damage: {damaged} finding(s), see warnings")?;
    }
    writeln!(
        out,
        "\n  {:<32} {:<34} {:>5} {:>9} {:>10} {:>12} {:>14}",
        "topic", "type", "enc", "count", "rate_hz", "max_gap_s", "gap_ends_at_s"
    )?;
    for t in &info.topics {
        writeln!(
            out,
            "  {:<32} {:<34} {:>5} {:>9} {:>10.2} {:>12.4} {:>14.6}",
            t.topic,
            t.type_name,
            t.encoding,
            t.count,
            t.rate_hz(),
            secs(t.largest_gap_nanos),
            secs(t.largest_gap_end_nanos)
        )?;
        if t.out_of_order > 0 {
            writeln!(out, "    {} messages with log time before the previous one", t.out_of_order)?;
        }
        if t.channels > 1 {
            writeln!(out, "    {} channels (publishers) on this topic", t.channels)?;
        }
    }
    Ok(())
}
