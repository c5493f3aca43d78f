//! `twin sysid --log LOG --update ROBOT.urdf`: identify link inertias and joint friction from a
//! log and write them into the URDF (only those numbers change).

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use sysid::{Base, JointLog, RobotModel, SysidOptions};
use twin_core::fsio;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BaseArg {
    /// Robot bolted down or hung on a gantry.
    Fixed,
    /// Free-floating base: base motion from nav_msgs/msg/Odometry (--odom-topic), contact
    /// wrenches from every geometry_msgs/msg/WrenchStamped topic whose header.frame_id is a link
    /// (force/torque in that link's frame, torque about its origin).
    Floating,
}

#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
    /// Another identification than inertias (`twin sysid friction --log sweeps.mcap`).
    #[command(subcommand)]
    pub mode: Option<Mode>,
    /// The log: a ROS 2 bag (rosbag2 folder or `.mcap`) with `sensor_msgs/msg/JointState`
    /// (position, velocity, effort), or a CSV file with columns `time_sec`, then
    /// `<joint>/position`, `<joint>/velocity` (optional), `<joint>/effort` per joint.
    #[arg(long, value_name = "LOG", required = true)]
    pub log: Option<PathBuf>,
    /// The robot's URDF: the model identified and the file updated (original kept as
    /// ROBOT.urdf.bak).
    #[arg(long, value_name = "ROBOT.urdf", required = true)]
    pub update: Option<PathBuf>,
    /// Joint-state topic to read from an MCAP log (default: auto-detected).
    #[arg(long, value_name = "T")]
    pub topic: Option<String>,
    /// Print the diff of the URDF instead of writing it.
    #[arg(long)]
    pub dry_run: bool,
    /// Write the full report as JSON.
    #[arg(long, value_name = "sysid.json")]
    pub report: Option<PathBuf>,
    /// A held-out log: print per-joint torque NRMSE before and after on it (default: the last
    /// --held-out fraction of LOG is held out).
    #[arg(long, value_name = "OTHER")]
    pub validate: Option<PathBuf>,
    /// Fraction of the log (its end) held out from fitting and from choosing the cut-off and
    /// friction model, to score the URDF before, the fit and --compare models on; the fit
    /// written back is then refitted on the whole log. 0 turns it off.
    #[arg(long, value_name = "F", default_value_t = 0.3)]
    pub held_out: f64,
    /// Write the fit of the first part (the one the held-out table scores) instead of refitting
    /// on the whole log.
    #[arg(long)]
    pub no_refit: bool,
    /// Another model of the robot (a URDF, with its own `<twin_sysid>` friction block if any)
    /// to score on the held-out data beside the URDF before and the fit (repeatable).
    #[arg(long, value_name = "OTHER.urdf")]
    pub compare: Vec<PathBuf>,
    /// Scale from the logged effort to joint torque (N·m or N), for drives that publish motor
    /// current or motor-side torque: one number for every joint, or JOINT=SCALE pairs
    /// (comma separated).
    #[arg(long, value_name = "S|J=S,…", value_delimiter = ',')]
    pub effort_scale: Vec<String>,
    /// Also write a MuJoCo model (MJCF) with the identified values, armature included.
    #[arg(long, value_name = "OUT.xml")]
    pub mjcf: Option<PathBuf>,
    /// Refuse (exit with an error) when the log is under-exciting instead of warning.
    #[arg(long)]
    pub strict: bool,
    /// How the robot's base was held while logging.
    #[arg(long, value_enum, default_value_t = BaseArg::Fixed)]
    pub base: BaseArg,
    /// Odometry topic of the base motion for --base floating (pose in the world frame, twist
    /// in the base frame, REP-105).
    #[arg(long, value_name = "T", default_value = "/odom")]
    pub odom_topic: String,
    /// Low-pass cut-off in Hz (default: chosen by time-blocked cross-validation among 4–25 Hz).
    #[arg(long, value_name = "HZ")]
    pub cutoff_hz: Option<f64>,
    /// Butterworth filter order.
    #[arg(long, default_value_t = 4, value_name = "N")]
    pub filter_order: usize,
    /// Identify a constant torque offset per joint as well (sensor bias); with this or
    /// --coulomb-smoothing the friction model is given, not chosen by cross-validation.
    #[arg(long)]
    pub offset: bool,
    /// Smooth Coulomb friction as tanh(velocity / EPS) instead of sign(velocity) with a dead
    /// zone (EPS in rad/s or m/s).
    #[arg(long, value_name = "EPS")]
    pub coulomb_smoothing: Option<f64>,
}

#[derive(Debug, clap::Subcommand)]
pub enum Mode {
    /// Joint friction curves (Coulomb + viscous + Stribeck) from constant-velocity sweeps:
    /// each joint moved forth and back at a series of constant speeds.
    Friction(FrictionArgs),
    /// Each drive's command delay, position-loop gains and armature from a log of the commands
    /// the drives received and the joint states (`twin sysid actuator --log LOG --update ROBOT.urdf`).
    Actuator(super::sysid_actuator::ActuatorArgs),
}

#[derive(Debug, clap::Args)]
pub struct FrictionArgs {
    /// The sweep log (ROS 2 bag with sensor_msgs/msg/JointState, or CSV as for `twin sysid`).
    #[arg(long, value_name = "LOG")]
    pub log: PathBuf,
    /// Write the Coulomb (`friction`) and viscous (`damping`) parts into this URDF's
    /// `<dynamics>` (original kept as ROBOT.urdf.bak).
    #[arg(long, value_name = "ROBOT.urdf")]
    pub update: Option<PathBuf>,
    /// Joint-state topic to read from an MCAP log (default: auto-detected).
    #[arg(long, value_name = "T")]
    pub topic: Option<String>,
    /// Only these joints (comma separated; default: every joint with a sweep).
    #[arg(long, value_name = "J1,J2", value_delimiter = ',')]
    pub joints: Vec<String>,
    /// Shortest constant-velocity segment, s.
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub min_segment: f64,
    /// Write an SVG plot of each joint's curve over the data.
    #[arg(long, value_name = "friction.svg")]
    pub plot: Option<PathBuf>,
    /// Write the full report as JSON.
    #[arg(long, value_name = "friction.json")]
    pub report: Option<PathBuf>,
    /// Print the diff of the URDF instead of writing it.
    #[arg(long)]
    pub dry_run: bool,
}

fn friction(args: FrictionArgs) -> anyhow::Result<()> {
    if !(args.min_segment > 0.0 && args.min_segment.is_finite()) {
        bail!("--min-segment must be a positive duration in seconds, got {}", args.min_segment);
    }
    let opts = sysid::friction::FrictionOptions {
        min_segment_secs: args.min_segment,
        joints: args.joints.clone(),
        ..Default::default()
    };
    let mut inputs = vec![args.log.as_path()];
    inputs.extend(args.update.as_deref());
    fsio::check_outputs(&[("--report", args.report.as_deref()), ("--plot", args.plot.as_deref())], &inputs)?;
    let log = read_log(&args.log, args.topic.as_deref(), None)?;
    let report = sysid::friction::identify_friction(&log, &opts).with_context(|| match &args.update {
        Some(u) => format!("friction identification failed; {} was not changed", u.display()),
        None => "friction identification failed".into(),
    })?;
    print!("{}\n{}", report.segments_text(), report.table());
    if let Some(path) = &args.report {
        super::write_output(path, &report.to_json(), "report")?;
    }
    if let Some(path) = &args.plot {
        super::write_output(path, &report.svg(), "friction curves plot")?;
    }
    if let Some(urdf) = &args.update {
        let joints = report.joint_updates();
        let outcome = sysid::writeback::update_urdf_file(urdf, &[], &joints, args.dry_run)
            .with_context(|| format!("{} was not changed", urdf.display()))?;
        if args.dry_run {
            println!("\n--dry-run: {} would change as follows:\n{}", urdf.display(), outcome.diff);
        } else if let Some(backup) = &outcome.backup {
            eprintln!(
                "updated <dynamics> of {} joint(s) in {} (Coulomb → friction, viscous → damping); original kept as {}",
                joints.len(),
                urdf.display(),
                backup.display()
            );
        }
    }
    Ok(())
}

pub(crate) fn read_log(path: &Path, topic: Option<&str>, odom_topic: Option<&str>) -> anyhow::Result<JointLog> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "csv" if odom_topic.is_some() => bail!(
            "{}: --base floating needs the base motion (nav_msgs/msg/Odometry) and contact wrenches, which a \
             CSV log cannot carry; record a ROS 2 bag",
            path.display()
        ),
        _ if (ext == "mcap" || path.is_dir()) && odom_topic.is_some() => {
            let (log, warnings) = JointLog::read_mcap_floating(path, topic, odom_topic.unwrap_or("/odom"))?;
            for w in warnings {
                eprintln!("warning: {w}");
            }
            Ok(log)
        }
        "csv" => {
            if topic.is_some() {
                eprintln!("warning: --topic is ignored for CSV logs");
            }
            Ok(JointLog::read_csv(path)?)
        }
        _ if ext == "mcap" || path.is_dir() => {
            let (log, warnings) = JointLog::read_mcap(path, topic)?;
            for w in warnings {
                eprintln!("warning: {w}");
            }
            Ok(log)
        }
        _ => bail!(
            "{}: unknown log format (expected a ROS 2 bag: a rosbag2 folder or a .mcap file with \
             sensor_msgs/msg/JointState, or a .csv with columns time_sec, <joint>/position, \
             <joint>/velocity, <joint>/effort)",
            path.display()
        ),
    }
}

/// Parses `--effort-scale`: one number for all joints, or `JOINT=SCALE` pairs.
fn effort_scales(specs: &[String], joints: &[String]) -> anyhow::Result<Vec<(usize, f64)>> {
    let parse = |v: &str| -> anyhow::Result<f64> {
        match v.trim().parse::<f64>() {
            Ok(x) if x.is_finite() && x != 0.0 => Ok(x),
            _ => bail!("--effort-scale: \"{v}\" is not a finite, non-zero number"),
        }
    };
    match specs {
        [] => Ok(Vec::new()),
        [one] if !one.contains('=') => {
            let s = parse(one)?;
            Ok((0..joints.len()).map(|j| (j, s)).collect())
        }
        pairs => pairs
            .iter()
            .map(|p| {
                let (name, v) = p.split_once('=').with_context(|| {
                    format!("--effort-scale: \"{p}\" is not JOINT=SCALE (or give one number for all)")
                })?;
                let j = joints.iter().position(|n| n == name.trim()).with_context(|| {
                    format!(
                        "--effort-scale: joint \"{}\" is not in the log (which has {})",
                        name.trim(),
                        joints.join(", ")
                    )
                })?;
                Ok((j, parse(v)?))
            })
            .collect(),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let args = match args.mode {
        Some(Mode::Friction(f)) => return friction(f),
        Some(Mode::Actuator(a)) => return super::sysid_actuator::run(a),
        None => args,
    };
    let (Some(log_path), Some(update)) = (args.log.clone(), args.update.clone()) else {
        bail!("twin sysid needs --log LOG and --update ROBOT.urdf");
    };
    if let Some(eps) = args.coulomb_smoothing
        && !(eps > 0.0 && eps.is_finite())
    {
        bail!("--coulomb-smoothing must be a positive velocity, got {eps}");
    }
    if !(0.0..0.9).contains(&args.held_out) {
        bail!("--held-out must be a fraction in [0, 0.9), got {}", args.held_out);
    }
    let opts = SysidOptions {
        condition: sysid::condition::ConditionOptions {
            cutoff_hz: args.cutoff_hz,
            filter_order: args.filter_order,
            ..Default::default()
        },
        friction: sysid::regressor::FrictionModel {
            offset: args.offset,
            coulomb_smoothing: args.coulomb_smoothing,
            asymmetry: false,
        },
        strict: args.strict,
        base: match args.base {
            BaseArg::Fixed => Base::Fixed,
            BaseArg::Floating => Base::Floating,
        },
        ..Default::default()
    };
    // Every output is checked before any work: not a folder or device, not an input.
    let mut inputs: Vec<&Path> = vec![log_path.as_path()];
    inputs.extend(args.validate.as_deref());
    inputs.extend(args.compare.iter().map(PathBuf::as_path));
    fsio::check_input(&log_path, fsio::InputKind::FileOrDir)?;
    if let Some(v) = &args.validate {
        fsio::check_input(v, fsio::InputKind::FileOrDir)?;
    }
    for c in &args.compare {
        fsio::check_input(c, fsio::InputKind::File)?;
    }
    let urdf_target = fsio::check_output(&update, &inputs)?;
    inputs.push(update.as_path());
    let mut targets =
        fsio::check_outputs(&[("--report", args.report.as_deref()), ("--mjcf", args.mjcf.as_deref())], &inputs)?
            .into_iter();
    let (report_target, mjcf_target) = (targets.next().flatten(), targets.next().flatten());
    let odom = (opts.base == Base::Floating).then_some(args.odom_topic.as_str());
    let mut log = read_log(&log_path, args.topic.as_deref(), odom)?;
    let mut held_out = args.validate.as_deref().map(|p| read_log(p, args.topic.as_deref(), odom)).transpose()?;
    let scales = effort_scales(&args.effort_scale, &log.joint_names)?;
    let mut notes = Vec::new();
    if !scales.is_empty() {
        let scale_log = |l: &mut JointLog| {
            for &(j, s) in &scales {
                if let Some(k) = l.joint_index(&log.joint_names[j].clone()) {
                    l.effort[k].iter_mut().for_each(|e| *e *= s);
                }
            }
        };
        if let Some(h) = held_out.as_mut() {
            scale_log(h);
        }
        let names = log.joint_names.clone();
        for &(j, s) in &scales {
            let k = j;
            log.effort[k].iter_mut().for_each(|e| *e *= s);
            notes.push(format!(
                "effort of joint \"{}\" multiplied by {s} (--effort-scale) to give joint torque",
                names[j]
            ));
        }
    }
    let (robot, held) = match opts.base {
        Base::Fixed => {
            let h = sysid::hold::from_urdf_holding(&update, &log.joint_names, args.strict)
                .with_context(|| format!("loading the robot {}", update.display()))?;
            (h.robot.clone(), h.warning())
        }
        Base::Floating => (
            RobotModel::from_urdf_floating(&update)
                .with_context(|| format!("loading the robot {}", update.display()))?,
            None,
        ),
    };
    if let Some(w) = &held {
        eprintln!("warning: {w}");
    }
    let started = std::time::Instant::now();
    // Fit part and held-out part: --validate's log, or the end of LOG.
    let default_split = held_out.is_none() && args.held_out > 0.0 && opts.base == Base::Fixed;
    let (fit_log, held_label) = if default_split {
        let cut = 1.0 - args.held_out;
        held_out = Some(sysid::select::time_slice(&log, cut, 1.0));
        (
            sysid::select::time_slice(&log, 0.0, cut),
            format!("the last {:.0} % of {}", 100.0 * args.held_out, log_path.display()),
        )
    } else {
        (log.clone(), args.validate.as_ref().map(|p| p.display().to_string()).unwrap_or_default())
    };
    // Cut-off and friction model from the data unless given.
    let sel = sysid::select::SelectOptions {
        choose_cutoff: args.cutoff_hz.is_none(),
        choose_friction: !args.offset && args.coulomb_smoothing.is_none(),
        ..Default::default()
    };
    let (opts, selection) = if opts.base == Base::Fixed && (sel.choose_cutoff || sel.choose_friction) {
        let s =
            sysid::select::select(&robot, &fit_log, &opts, &sel).context("choosing the cut-off and friction model")?;
        (s.options, s.candidates)
    } else {
        (opts, Vec::new())
    };
    let fit = sysid::identify(&robot, &fit_log, &opts).context("identification failed; the URDF was not changed")?;
    let fit_secs = started.elapsed().as_secs_f64();
    let mut held_table = None;
    let mut validation = None;
    let mut held_warning = None;
    if let Some(other) = &held_out {
        if opts.base == Base::Fixed {
            let effort_cutoff_hz = selection
                .iter()
                .map(|c| c.cutoff_hz)
                .fold(opts.condition.cutoff_hz.unwrap_or(0.0), f64::max)
                .max(opts.condition.cutoff_hz.unwrap_or(0.0));
            let mut score_opts = opts.clone();
            score_opts.condition.effort_cutoff_hz = Some(effort_cutoff_hz);
            let update_text = fsio::read_to_string(&update)?;
            let block = sysid::extension::read_block(&update, &update_text)?;
            let mut models = vec![
                sysid::select::ScoredModel::of_urdf(&robot, &block),
                sysid::select::ScoredModel::of_identification(&robot, &fit),
            ];
            let mut names = vec!["URDF before".to_string(), "twin fit".to_string()];
            let mut others = Vec::new();
            for c in &args.compare {
                let h = sysid::hold::from_urdf_holding(c, &log.joint_names, false)
                    .with_context(|| format!("loading --compare {}", c.display()))?;
                let text = fsio::read_to_string(c)?;
                others.push((h.robot, sysid::extension::read_block(c, &text)?));
                names.push(c.display().to_string());
            }
            for (r, b) in &others {
                models.push(sysid::select::ScoredModel::of_urdf(r, b));
            }
            let nrmse = match sysid::select::models_nrmse(&robot, other, &score_opts, &models) {
                Ok(n) => n,
                // A held-out part the user did not choose that cannot be scored (too short for
                // the filter, say) is a warning; a --validate log that cannot is an error.
                Err(e) if default_split => {
                    held_warning = Some(format!("the models were not scored on {held_label}: {e}"));
                    Vec::new()
                }
                Err(e) => return Err(anyhow::Error::new(e).context(format!("scoring the models on {held_label}"))),
            };
            if !nrmse.is_empty() && !default_split {
                // A held-out log of the user's: also the before/after table of earlier versions.
                validation = Some(before_after(&robot, &nrmse));
            }
            held_table = (!nrmse.is_empty()).then(|| sysid::report::HeldOutTable {
                log: held_label.clone(),
                effort_cutoff_hz,
                models: names,
                joints: robot.joints.iter().map(|j| j.name.clone()).collect(),
                nrmse,
            });
        } else {
            let nrmse = sysid::validate(&robot, other, &opts, &[&fit.before, &fit.after])
                .with_context(|| format!("validating on {held_label}"))?;
            validation = Some(before_after(&robot, &nrmse));
        }
    }
    // The fit written back: on the whole log with the chosen settings (the held-out scores are
    // of the fit on the first part).
    let mut ident = if default_split && !args.no_refit {
        sysid::identify(&robot, &log, &opts).context("identification failed; the URDF was not changed")?
    } else {
        fit
    };
    ident.report.selection = selection;
    ident.report.held_out = held_table;
    ident.report.warnings.splice(0..0, held.into_iter().chain(notes).chain(held_warning));
    if validation.is_some() {
        ident.report.validation_nrmse = validation;
        ident.report.validation_log = Some(held_label);
    }
    ident.report.wall_secs = started.elapsed().as_secs_f64();
    print!("{}", ident.report.table());
    eprintln!(
        "fit (selection included) on the first part took {fit_secs:.2} s; everything {:.2} s",
        ident.report.wall_secs
    );
    let (links, joints) = sysid::urdf_updates(&robot, &ident);
    let plan = sysid::writeback::plan_urdf_update(&update, &links, &joints)?;
    // The friction model beyond <dynamics> goes to the <twin_sysid> block.
    let comment = format!(
        "Identified from {} with a {:.1} Hz cut-off, friction model {}",
        log_path.display(),
        ident.report.cutoff_hz,
        ident.layout.friction.describe()
    );
    let new_text = sysid::extension::splice_block(
        &update,
        &plan.new,
        &sysid::extension::block_text(&ident.report.joint_friction, &comment),
    )?;
    if args.dry_run {
        println!(
            "\n--dry-run: {} would change as follows:\n{}",
            update.display(),
            sysid::writeback::unified_diff(&update, &plan.original, &new_text)
        );
    }
    // All outputs are staged and renamed only when every one was written: a failing --mjcf
    // leaves the URDF and the report untouched.
    let mut tx = fsio::Transaction::new();
    if let Some(target) = &report_target {
        tx.stage(target, ident.report.to_json().as_bytes(), fsio::Backup::None)?;
    }
    if let Some(target) = &mjcf_target {
        let text = sysid::mjcf::mjcf_text(&update, &robot, &ident, &links, &joints)
            .with_context(|| format!("writing {}", target.requested.display()))?;
        tx.stage(target, text.as_bytes(), fsio::Backup::None)?;
    }
    if !args.dry_run {
        tx.stage(&urdf_target, new_text.as_bytes(), fsio::Backup::Numbered)?;
        tx.expect_unchanged(plan.original.as_bytes());
    }
    let written = tx.commit()?;
    if let Some(path) = &args.report {
        eprintln!("report written to {}", path.display());
    }
    if let Some(backup) = written.iter().find(|w| w.path == update).and_then(|w| w.backup.as_ref()) {
        eprintln!(
            "updated {} ({} links, {} joints, <twin_sysid> friction block); original kept as {}",
            update.display(),
            links.len(),
            joints.len(),
            backup.display()
        );
    }
    if let Some(out) = &args.mjcf {
        eprintln!("MuJoCo model with the identified values (armature included) written to {}", out.display());
    }
    Ok(())
}

/// Per joint, the NRMSE before (`nrmse[0]`) and after (`nrmse[1]`) identification.
fn before_after(robot: &sysid::RobotModel, nrmse: &[Vec<f64>]) -> Vec<sysid::report::NrmseReport> {
    robot
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| sysid::report::NrmseReport {
            joint: joint.name.clone(),
            before: nrmse[0][j],
            after: nrmse[1][j],
        })
        .collect()
}
