//! `twin excite ROBOT.urdf`: design an excitation trajectory for `twin sysid` (finite Fourier
//! series, optimized for the base regressor's condition number within the robot's limits and
//! free of self-collision), written as CSV and as a ROS 2 `JointTrajectory` bag.

use anyhow::Context;
use std::path::PathBuf;
use sysid::excite::{Criterion, ExciteOptions, design};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CriterionArg {
    /// Condition number of the base regressor.
    Cond,
    /// log det of the column-scaled base regressor's information matrix.
    Logdet,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The robot's URDF.
    #[arg(value_name = "ROBOT.urdf")]
    pub urdf: PathBuf,
    /// Joints to excite (comma-separated; default: every revolute and prismatic joint). The
    /// others hold still at 0 (clamped into their range).
    #[arg(long, value_delimiter = ',', value_name = "J1,J2,…")]
    pub joints: Vec<String>,
    /// Output CSV `time_sec,<joint>,<joint>_vel,…` (one period).
    #[arg(long, default_value = "excite.csv", value_name = "FILE.csv")]
    pub csv: PathBuf,
    /// Output ROS 2 bag with one trajectory_msgs/msg/JointTrajectory on --topic.
    #[arg(long, default_value = "excite.mcap", value_name = "FILE.mcap")]
    pub bag: PathBuf,
    /// Topic of the JointTrajectory message.
    #[arg(long, default_value = "/joint_trajectory", value_name = "T")]
    pub topic: String,
    /// Sample rate of the written trajectory, Hz.
    #[arg(long, default_value_t = 100.0, value_name = "HZ")]
    pub rate: f64,
    /// Harmonics per joint of the designed trajectory.
    #[arg(long, default_value_t = 15, value_name = "N")]
    pub harmonics: usize,
    /// Harmonics per joint of the 20 random trajectories the design starts from and is compared
    /// with (at most --harmonics).
    #[arg(long, default_value_t = 5, value_name = "N")]
    pub baseline_harmonics: usize,
    /// Fundamental frequency, Hz (the trajectory's period is its inverse).
    #[arg(long, default_value_t = 0.1, value_name = "HZ")]
    pub base_frequency: f64,
    /// Acceleration limit of every joint, rad/s² (URDF has none).
    #[arg(long, default_value_t = 10.0, value_name = "A")]
    pub max_acceleration: f64,
    /// Velocity limit of joints whose URDF <limit> has none, rad/s.
    #[arg(long, value_name = "V")]
    pub max_velocity: Option<f64>,
    /// Fraction of the URDF velocity limits used.
    #[arg(long, default_value_t = 0.8, value_name = "F")]
    pub velocity_fraction: f64,
    /// Fraction of the URDF effort limits the inverse-dynamics torque may reach.
    #[arg(long, default_value_t = 0.8, value_name = "F")]
    pub effort_fraction: f64,
    /// Distance kept from each end of a joint's range, rad.
    #[arg(long, default_value_t = 0.05, value_name = "RAD")]
    pub margin: f64,
    /// Do not check self-collision.
    #[arg(long)]
    pub no_collision_check: bool,
    /// What to minimize.
    #[arg(long, value_enum, default_value_t = CriterionArg::Cond)]
    pub criterion: CriterionArg,
    /// Searches started from the best random trajectories (fewer: a quicker design).
    #[arg(long, default_value_t = 3, value_name = "N")]
    pub starts: usize,
    /// Quasi-Newton iterations per search stage.
    #[arg(long, default_value_t = 150, value_name = "N")]
    pub iterations: usize,
    /// Seed of the random trajectories the search starts from.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write the full report (trajectory coefficients, limits, conditions) as JSON.
    #[arg(long, value_name = "excite.json")]
    pub report: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    super::check_range("--rate", args.rate, 1.0, super::MAX_RATE_HZ, "Hz")?;
    let opts = ExciteOptions {
        joints: args.joints.clone(),
        harmonics: args.harmonics,
        baseline_harmonics: args.baseline_harmonics,
        base_frequency_hz: args.base_frequency,
        position_margin: args.margin,
        velocity_fraction: args.velocity_fraction,
        default_velocity_limit: args.max_velocity,
        max_acceleration: args.max_acceleration,
        effort_fraction: args.effort_fraction,
        self_collision: !args.no_collision_check,
        criterion: match args.criterion {
            CriterionArg::Cond => Criterion::Condition,
            CriterionArg::Logdet => Criterion::LogDet,
        },
        seed: args.seed,
        starts: args.starts,
        max_iterations: args.iterations,
        ..ExciteOptions::default()
    };
    twin_core::fsio::check_outputs(
        &[
            ("--csv", Some(args.csv.as_path())),
            ("--bag", Some(args.bag.as_path())),
            ("--report", args.report.as_deref()),
        ],
        &[args.urdf.as_path()],
    )?;
    let report =
        design(&args.urdf, &opts).with_context(|| format!("no excitation trajectory for {}", args.urdf.display()))?;
    print!("{}", report.table());
    let traj = &report.trajectory;
    twin_core::fsio::write_atomic(&args.csv, traj.to_csv(args.rate).as_bytes(), twin_core::fsio::Backup::None)?;
    traj.write_mcap(&args.bag, &args.topic, args.rate)?;
    if let Some(p) = &args.report {
        super::write_output(p, &report.to_json(), "report")?;
    }
    eprintln!(
        "trajectory written to {} and {} (topic {}); play it on the twin with\n  twin sim {} --controller replay \
         --trajectory {} --trajectory-topic {} --duration {:.1}",
        args.csv.display(),
        args.bag.display(),
        args.topic,
        args.urdf.display(),
        args.bag.display(),
        args.topic,
        traj.period_secs()
    );
    Ok(())
}
