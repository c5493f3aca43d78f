//! `twin sysid actuator --log LOG --update ROBOT.urdf`: each drive's command delay,
//! position-loop gains and armature from the commands the drives received and what the joints
//! did, written into the URDF's `<twin_actuator>` and `<twin_sysid>` blocks (see
//! `sysid::actuator`).

use anyhow::Context;
use std::path::PathBuf;
use sysid::actuator::{CommandLog, DriveOptions, DriveReport, identify_drives, rewrite_drives};
use twin_core::fsio;

#[derive(Debug, clap::Args)]
pub struct ActuatorArgs {
    /// The log: a ROS 2 bag with the joint states (`sensor_msgs/msg/JointState`) and the
    /// drives' commands (`std_msgs/msg/Float64MultiArray`, as a ros2_control forward command
    /// controller receives them).
    #[arg(long, value_name = "LOG")]
    pub log: PathBuf,
    /// The robot's URDF: its rigid-body model is the one the fit uses, and its `<twin_actuator>`
    /// (delay, gains) and `<twin_sysid>` (armature) blocks are updated (original kept as a
    /// numbered .bak; every other byte kept).
    #[arg(long, value_name = "ROBOT.urdf")]
    pub update: PathBuf,
    /// Joint-state topic (default: auto-detected).
    #[arg(long, value_name = "T")]
    pub topic: Option<String>,
    /// The commands' topic (default: the log's only Float64MultiArray topic).
    #[arg(long, value_name = "T")]
    pub command_topic: Option<String>,
    /// The joints of each command, in order (comma separated; default: the URDF's joints with
    /// an actuator, in URDF order).
    #[arg(long, value_name = "J1,J2", value_delimiter = ',')]
    pub command_joints: Vec<String>,
    /// Longest delay searched, seconds.
    #[arg(long, value_name = "S", default_value_t = 0.03)]
    pub max_delay: f64,
    /// Fraction of the log (its end) held out and scored by replaying its commands on the twin
    /// before and after; 0 turns it off.
    #[arg(long, value_name = "F", default_value_t = 0.3)]
    pub held_out: f64,
    /// Write the full report as JSON.
    #[arg(long, value_name = "actuator.json")]
    pub report: Option<PathBuf>,
    /// Print the diff of the URDF instead of writing it.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(args: ActuatorArgs) -> anyhow::Result<()> {
    if !(args.max_delay > 0.0 && args.max_delay <= 1.0) {
        anyhow::bail!("--max-delay must be in (0, 1] s, got {}", args.max_delay);
    }
    if !(0.0..0.9).contains(&args.held_out) {
        anyhow::bail!("--held-out must be in [0, 0.9), got {}", args.held_out);
    }
    fsio::check_outputs(&[("--report", args.report.as_deref())], &[args.log.as_path(), args.update.as_path()])?;
    let joints = if args.command_joints.is_empty() {
        let robot = sysid::model::load_urdf_robot(&args.update, false)
            .with_context(|| format!("loading {}", args.update.display()))?;
        robot
            .actuators
            .iter()
            .filter_map(|a| a.joint)
            .map(|j| robot.model.name(twin_core::mj::ObjType::Joint, j).to_string())
            .collect()
    } else {
        args.command_joints.clone()
    };
    let states = super::sysid::read_log(&args.log, args.topic.as_deref(), None)?;
    let commands = CommandLog::read_mcap(&args.log, args.command_topic.as_deref(), &joints)?;
    let opts = DriveOptions { max_delay_secs: args.max_delay, held_out: args.held_out, ..DriveOptions::default() };
    let report = identify_drives(&args.update, &states, &commands, &opts)
        .with_context(|| format!("drive identification failed; {} was not changed", args.update.display()))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    print!("{}", table(&report));
    if let Some(path) = &args.report {
        super::write_output(path, &report.to_json(), "report")?;
    }
    let outcome = sysid::writeback::update_file_with(&args.update, args.dry_run, |text| {
        rewrite_drives(&args.update, text, &report.joints)
    })
    .with_context(|| format!("{} was not changed", args.update.display()))?;
    if args.dry_run {
        println!("\n--dry-run: {} would change as follows:\n{}", args.update.display(), outcome.diff);
    } else if let Some(backup) = &outcome.backup {
        eprintln!(
            "updated the drives of {} joint(s) in {} (<twin_actuator>: delay, kp, kd; <twin_sysid>: armature); original kept as {}",
            report.joints.len(),
            args.update.display(),
            backup.display()
        );
    }
    Ok(())
}

/// Per joint: the drive fitted on the whole log with 95 % intervals, then the held-out replay.
fn table(r: &DriveReport) -> String {
    use std::fmt::Write as _;
    let mut s = format!("drives from {} and {}:\n", r.states, r.commands);
    let _ = writeln!(
        s,
        "  {:<20} {:<9} {:>22} {:>26} {:>22} {:>26}",
        "joint", "interface", "delay ms [95 %]", "kp [95 %]", "kd [95 %]", "armature [95 %]"
    );
    let e = |v: &sysid::actuator::Estimate, scale: f64, digits: usize| {
        format!("{:.digits$} [{:.digits$}, {:.digits$}]", v.value * scale, v.ci95[0] * scale, v.ci95[1] * scale)
    };
    for j in &r.joints {
        let _ = writeln!(
            s,
            "  {:<20} {:<9} {:>22} {:>26} {:>22} {:>26}",
            j.joint,
            j.interface,
            e(&j.delay_secs, 1e3, 2),
            e(&j.kp, 1.0, 2),
            e(&j.kd, 1.0, 3),
            e(&j.armature, 1.0, 4)
        );
    }
    if !r.held_out.is_empty() {
        let _ = writeln!(
            s,
            "held-out replay ({:.1} s, commands replayed on the twin): RMS position error, fit without the held-out part",
            r.held_out_secs
        );
        let _ = writeln!(s, "  {:<20} {:>12} {:>12} {:>8}", "joint", "before", "after", "ratio");
        for h in &r.held_out {
            let _ = writeln!(
                s,
                "  {:<20} {:>12.5} {:>12.5} {:>8.3}",
                h.joint,
                h.before_rms,
                h.after_rms,
                h.after_rms / h.before_rms
            );
        }
    }
    s
}
