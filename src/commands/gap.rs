//! `twin gap --log real.mcap ROBOT.urdf`: the reality gap: the logged efforts replayed on the
//! twin open loop from the logged state (re-synchronized every `--resync` seconds), per-joint
//! position, velocity and torque error against the log.

use anyhow::Context;
use std::path::PathBuf;
use sysid::gap::{GapOptions, measure_gap};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The robot's URDF (the twin).
    #[arg(value_name = "ROBOT.urdf")]
    pub urdf: PathBuf,
    /// The real robot's log: a ROS 2 bag with sensor_msgs/msg/JointState (position, velocity,
    /// effort), or a CSV as `twin sysid` reads.
    #[arg(long, value_name = "LOG")]
    pub log: PathBuf,
    /// Joint-state topic (default: auto-detected).
    #[arg(long, value_name = "T")]
    pub topic: Option<String>,
    /// Re-synchronize the twin to the logged state every this many seconds.
    #[arg(long, default_value_t = 1.0, value_name = "SECS")]
    pub resync: f64,
    /// Armature of every joint of the twin, kg·m² (URDF has none; `twin sysid` reports it).
    #[arg(long, default_value_t = 0.0, value_name = "KGM2")]
    pub armature: f64,
    /// Refuse a log that lacks some of the robot's joints (default: hold them at their home
    /// position, with a warning).
    #[arg(long)]
    pub strict: bool,
    /// Write the report as JSON.
    #[arg(long, value_name = "gap.json")]
    pub report: Option<PathBuf>,
    /// Plot logged and twin joint positions (SVG).
    #[arg(long, value_name = "gap.svg")]
    pub plot: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    super::check_range("--resync", args.resync, 1e-3, super::MAX_SIM_SECS, "s")?;
    super::check_range("--armature", args.armature, 0.0, 1e6, "kg·m²")?;
    twin_core::fsio::check_outputs(
        &[("--report", args.report.as_deref()), ("--plot", args.plot.as_deref())],
        &[args.urdf.as_path(), args.log.as_path()],
    )?;
    let log = super::sysid::read_log(&args.log, args.topic.as_deref(), None)?;
    let opts = GapOptions { resync_secs: args.resync, armature: args.armature, strict: args.strict };
    let report = measure_gap(&args.urdf, &log, &opts)
        .with_context(|| format!("no gap measured for {} on {}", args.urdf.display(), args.log.display()))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    print!("{}", report.table());
    if let Some(p) = &args.report {
        super::write_output(p, &report.to_json(), "report")?;
    }
    if let Some(p) = &args.plot {
        super::write_output(p, &report.svg(), "plot")?;
    }
    Ok(())
}
