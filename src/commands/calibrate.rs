//! `twin calibrate noise --log still.mcap --update ROBOT.urdf`: sensor noise from a log of the
//! robot standing still, written into the URDF's Gazebo IMU `<noise>` tags.

use anyhow::Context;
use std::path::PathBuf;
use sysid::noise::{NoiseOptions, calibrate_noise, imu_noise_updates};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub what: What,
}

#[derive(Debug, clap::Subcommand)]
pub enum What {
    /// IMU white-noise density, bias instability and bias random walk (overlapping Allan
    /// deviation per axis), encoder σ and quantization, from a log of the robot standing still.
    Noise(NoiseArgs),
}

#[derive(Debug, clap::Args)]
pub struct NoiseArgs {
    /// The still log: a ROS 2 bag (rosbag2 folder or `.mcap`) with sensor_msgs/msg/Imu
    /// (every Imu topic is measured) and/or sensor_msgs/msg/JointState.
    #[arg(long, value_name = "LOG")]
    pub log: PathBuf,
    /// The robot's URDF: its Gazebo IMU sensors' <noise> tags are rewritten (only those
    /// numbers change; original kept as ROBOT.urdf.bak). Without it, nothing is written.
    #[arg(long, value_name = "ROBOT.urdf")]
    pub update: Option<PathBuf>,
    /// Only this Imu topic (default: all).
    #[arg(long, value_name = "T")]
    pub imu_topic: Option<String>,
    /// JointState topic of the encoders (default: auto-detected).
    #[arg(long, value_name = "T")]
    pub joint_topic: Option<String>,
    /// Largest averaging time τ, s (default: a quarter of the log; the log must be ≥ 4·τ).
    #[arg(long, value_name = "S")]
    pub tau_max: Option<f64>,
    /// Shortest log accepted, s.
    #[arg(long, value_name = "S", default_value_t = 60.0)]
    pub min_duration: f64,
    /// A gyro axis whose 1-s mean departs from its resting value by more moved, rad/s.
    #[arg(long, value_name = "RAD_S", default_value_t = 0.02)]
    pub gyro_motion: f64,
    /// Same for an accelerometer axis, m/s².
    #[arg(long, value_name = "M_S2", default_value_t = 0.1)]
    pub accel_motion: f64,
    /// Same for a joint position, rad or m.
    #[arg(long, value_name = "RAD", default_value_t = 0.002)]
    pub encoder_motion: f64,
    /// Write an SVG plot of the Allan deviations with their bands and fitted models.
    #[arg(long, value_name = "allan.svg")]
    pub plot: Option<PathBuf>,
    /// Write a `twin randomize` spec fragment (TOML) with the measured noise.
    #[arg(long, value_name = "noise.toml")]
    pub spec: Option<PathBuf>,
    /// Write the Allan deviation curves (data, confidence band, fit) to a rerun recording:
    /// log10 σ against a timeline `log10_tau_milli` = 1000·log10 τ.
    #[arg(long, value_name = "allan.rrd")]
    pub rerun: Option<PathBuf>,
    /// Write the full report (Allan curves, fits, encoders) as JSON.
    #[arg(long, value_name = "noise.json")]
    pub report: Option<PathBuf>,
    /// Print the diff of the URDF instead of writing it.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.what {
        What::Noise(a) => noise(a),
    }
}

fn noise(args: NoiseArgs) -> anyhow::Result<()> {
    let opts = NoiseOptions {
        tau_max_secs: args.tau_max,
        min_duration_secs: args.min_duration,
        gyro_motion_rad_s: args.gyro_motion,
        accel_motion_mps2: args.accel_motion,
        encoder_motion: args.encoder_motion,
        ..Default::default()
    };
    let mut inputs = vec![args.log.as_path()];
    inputs.extend(args.update.as_deref());
    twin_core::fsio::check_outputs(
        &[
            ("--report", args.report.as_deref()),
            ("--plot", args.plot.as_deref()),
            ("--rerun", args.rerun.as_deref()),
            ("--spec", args.spec.as_deref()),
        ],
        &inputs,
    )?;
    let fail = || match &args.update {
        Some(u) => format!("noise calibration failed; {} was not changed", u.display()),
        None => "noise calibration failed".to_string(),
    };
    let (report, warnings) =
        calibrate_noise(&args.log, args.imu_topic.as_deref(), args.joint_topic.as_deref(), &opts).with_context(fail)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    print!("{}", report.table());
    if let Some(p) = &args.report {
        super::write_output(p, &report.to_json(), "report")?;
    }
    if let Some(p) = &args.plot {
        super::write_output(p, &report.svg(), "Allan deviation plot")?;
    }
    if let Some(p) = &args.rerun {
        write_allan_rrd(p, &report)?;
        eprintln!("Allan deviation recording written to {}", p.display());
    }
    if let Some(p) = &args.spec {
        super::write_output(p, &report.spec_fragment(), "randomization spec fragment")?;
    }
    let Some(urdf) = &args.update else { return Ok(()) };
    if report.imus.is_empty() {
        eprintln!("no IMU in the log: {} unchanged (encoder noise goes to the spec fragment)", urdf.display());
        return Ok(());
    }
    let mut notes = Vec::new();
    let outcome = sysid::writeback::update_file_with(urdf, args.dry_run, |text| {
        let (updates, w) = imu_noise_updates(urdf, text, &report.imus)?;
        notes = w;
        sysid::writeback::rewrite_imu_noise(urdf, text, &updates)
    })
    .with_context(|| format!("{} was not changed", urdf.display()))?;
    for n in notes {
        eprintln!("warning: {n}");
    }
    if args.dry_run {
        println!("\n--dry-run: {} would change as follows:\n{}", urdf.display(), outcome.diff);
    } else if let Some(backup) = &outcome.backup {
        eprintln!(
            "updated the IMU <noise> of {} ({} IMU(s)); original kept as {}",
            urdf.display(),
            report.imus.len(),
            backup.display()
        );
    }
    Ok(())
}

#[cfg(feature = "rerun")]
fn write_allan_rrd(path: &std::path::Path, report: &sysid::noise::NoiseReport) -> anyhow::Result<()> {
    Ok(twin_core::viz::write_curves(path, "twin_allan", "log10_tau_milli", 1000.0, &report.allan_curves())?)
}

#[cfg(not(feature = "rerun"))]
fn write_allan_rrd(_path: &std::path::Path, _report: &sysid::noise::NoiseReport) -> anyhow::Result<()> {
    Err(twin_core::sim::record::rerun_unavailable().into())
}
