//! `twin view LOG.mcap [--model robot.urdf] -o log.rrd [--connect URL]`: a robot's ROS 2 bag as
//! a rerun recording, the robot animated from `/joint_states` (and `/odom` when present), joint
//! and IMU time series as scalars: RViz and PlotJuggler in one file.
//! `twin view LOG --foxglove [ADDR:]PORT`: plays the log to Foxglove/Lichtblick over WebSocket
//! instead (its CDR topics with their schemas, at the log's pace).

use anyhow::bail;
use std::path::PathBuf;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The log: a `.mcap` file or a rosbag2 folder.
    pub log: PathBuf,
    /// Robot model (URDF or MJCF) whose joints the log names. Default: the shipped humanoid.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Write the recording to this `.rrd` file.
    #[arg(short = 'o', long = "output", value_name = "LOG.rrd")]
    pub output: Option<PathBuf>,
    /// Stream to a running rerun viewer instead (e.g. rerun+http://127.0.0.1:9876/proxy).
    #[arg(long, value_name = "URL")]
    pub connect: Option<String>,
    /// JointState topic that animates the robot.
    #[arg(long, default_value = "/joint_states")]
    pub topic: String,
    /// Odometry topic that moves the floating base (used when present).
    #[arg(long, default_value = "/odom")]
    pub odom_topic: String,
    /// Posed frames per second of log time.
    #[arg(long, default_value_t = 50.0)]
    pub fps: f64,
    /// Fail on a damaged log instead of showing what is intact.
    #[arg(long)]
    pub strict: bool,
    /// Play the log to Foxglove/Lichtblick over WebSocket at PORT (loopback) or ADDR:PORT,
    /// once a client subscribes (see --wait), at --rate × its pace.
    #[arg(long, value_name = "[ADDR:]PORT")]
    pub foxglove: Option<String>,
    /// With --foxglove: playback speed (1.0 = the log's pace).
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// With --foxglove: longest wait for a client's subscription before playing, seconds.
    #[arg(long, default_value_t = 30.0, value_name = "SECS")]
    pub wait: f64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(addr) = &args.foxglove {
        super::check_range("--rate", args.rate, 1e-3, 1e3, "")?;
        super::check_range("--wait", args.wait, 0.0, 3600.0, "s")?;
        let _addr = super::viewers::parse_addr("--foxglove", addr)?;
        #[cfg(feature = "ros")]
        return super::viewers::play(&args.log, args.model.as_deref(), _addr, args.rate, args.wait, args.strict);
        #[cfg(not(feature = "ros"))]
        return Err(super::viewers::unavailable());
    }
    if args.output.is_none() && args.connect.is_none() {
        bail!(
            "give -o LOG.rrd to write a recording, --connect URL to stream to a rerun viewer, or --foxglove PORT to \
             play it to Foxglove"
        );
    }
    super::check_range("--fps", args.fps, 1e-3, super::MAX_FPS, "frames per second")?;
    if let Some(out) = &args.output {
        let model = args.model.clone().unwrap_or_else(super::default_model);
        twin_core::fsio::check_output(out, &[args.log.as_path(), model.as_path()])?;
    }
    run_view(args)
}

#[cfg(not(feature = "rerun"))]
fn run_view(_args: Args) -> anyhow::Result<()> {
    Err(twin_core::sim::record::rerun_unavailable().into())
}

#[cfg(feature = "rerun")]
fn run_view(args: Args) -> anyhow::Result<()> {
    use anyhow::Context;
    use std::io::Write;
    use twin_core::log::{Log, ReadOptions};
    use twin_core::viz::{Recorder, ViewOptions, record_log};

    let log = Log::open(&args.log, ReadOptions { strict: args.strict })?;
    let model_path = args.model.clone().unwrap_or_else(super::default_model);
    let robot = twin_core::robot::Robot::load(&model_path)?;
    let recorder = match (&args.output, &args.connect) {
        (_, Some(url)) => Recorder::to_viewer(&robot.model, "twin", url)?,
        (Some(path), None) => Recorder::to_file(&robot.model, "twin", path)?,
        (None, None) => unreachable!("checked in run"),
    };
    let options = ViewOptions {
        joint_states_topic: args.topic.clone(),
        odom_topic: args.odom_topic.clone(),
        pose_rate_hz: args.fps,
        stop: Some(twin_core::fsio::interrupt_flag()),
    };
    // Ctrl-C (or SIGTERM) stops after the current frame: the recording is closed, the summary
    // printed, and twin exits with status 130; a second one aborts.
    twin_core::fsio::cooperate();
    let mut out = std::io::stdout().lock();
    let summary =
        record_log(&robot, &log, &options, &recorder).with_context(|| format!("reading {}", args.log.display()))?;
    recorder.finish()?;
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    if summary.joints_matched.is_empty() && !summary.interrupted {
        bail!(
            "none of the log's joints ({}) is a joint of {}; pass the robot's model with --model",
            summary.joints_unknown.join(", "),
            model_path.display()
        );
    }
    if !summary.joints_unknown.is_empty() {
        eprintln!(
            "warning: {} log joints are not in {} (plotted, not animated): {}",
            summary.joints_unknown.len(),
            model_path.display(),
            summary.joints_unknown.join(", ")
        );
    }
    writeln!(
        out,
        "{}: {:.3} s of log, {} frames, {} joints animated, base {}, {} IMU topics, {} scalars",
        args.log.display(),
        summary.duration_secs,
        summary.frames,
        summary.joints_matched.len(),
        if summary.odom_messages > 0 {
            format!("from {} ({} messages)", args.odom_topic, summary.odom_messages)
        } else {
            "at its home pose".into()
        },
        summary.imu_topics.len(),
        summary.scalars
    )?;
    match (&args.output, &args.connect) {
        (_, Some(url)) => writeln!(out, "streamed to {url}")?,
        (Some(path), None) => {
            let bytes = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
            writeln!(out, "{}: {bytes} bytes", path.display())?;
        }
        (None, None) => {}
    }
    if summary.interrupted {
        out.flush()?;
        let shown_secs = summary.frames.saturating_sub(1) as f64 / args.fps;
        return Err(super::Interrupted(format!(
            "{} frames recorded, up to {shown_secs:.3} s of the {:.3} s log; the recording is closed and readable",
            summary.frames, summary.duration_secs
        ))
        .into());
    }
    Ok(())
}
