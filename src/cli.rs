//! Command-line interface (clap derive). Each subcommand's arguments live next to its command
//! module; this file lists them and dispatches a parsed command to its module's `run`.

use crate::commands;
use clap::{Parser, Subcommand};

/// Digital twin of a legged or armed robot, simulated with MuJoCo.
#[derive(Debug, Parser)]
#[command(name = "twin", version = crate::commands::VERSION_LINE.as_str(), about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Print a model's bodies, joints, actuators, sensors and total mass.
    Info(crate::commands::info::Args),
    /// Convert a URDF (+ Gazebo tags, transmissions, ros2_control) into a MuJoCo MJCF with
    /// actuators and sensors.
    Convert(crate::commands::convert::Args),
    /// Validate a model step by step: physics, sensors, control, integration speed.
    Check(crate::commands::check::Args),
    /// Inspect ROS 2 MCAP logs (`twin log info FILE`) and find why the robot fell (`twin log
    /// analyze FILE`).
    Log(crate::commands::log::Args),
    /// Domain-randomized batch rollouts: how often and how the robot fails.
    Randomize(Box<crate::commands::randomize::Args>),
    /// Identify link inertias and joint friction from a log and update the URDF.
    Sysid(crate::commands::sysid::Args),
    /// Run the twin under a built-in controller and record ROS 2 topics (MCAP) and a rerun
    /// recording, stamped in simulation time.
    Sim(Box<crate::commands::sim::Args>),
    /// Turn a robot's ROS 2 log into a rerun recording: the robot animated from its joint
    /// states, joint and IMU time series.
    View(crate::commands::view::Args),
    /// Calibrate the twin's sensors from real logs (`twin calibrate noise --log still.mcap`).
    Calibrate(crate::commands::calibrate::Args),
    /// Design an excitation trajectory for `twin sysid` within the robot's limits (CSV and a
    /// ROS 2 JointTrajectory bag that `twin sim --controller replay` plays).
    Excite(crate::commands::excite::Args),
    /// Measure the reality gap: replay a real log's efforts on the twin open loop and compare
    /// joint positions, velocities and torques.
    Gap(crate::commands::gap::Args),
    /// Test controllers for CI: each scenario nominal and randomized, its checks and a
    /// threshold on the success rate; a table, JUnit XML, exit 0 only when all pass.
    Test(crate::commands::test::Args),
}

impl Cli {
    /// Runs the parsed subcommand.
    pub fn run(self) -> anyhow::Result<()> {
        match self.command {
            Command::Info(args) => commands::info::run(args),
            Command::Convert(args) => commands::convert::run(args),
            Command::Check(args) => commands::check::run(args),
            Command::Log(args) => commands::log::run(args),
            Command::Randomize(args) => commands::randomize::run(*args),
            Command::Sysid(args) => commands::sysid::run(args),
            Command::Sim(args) => commands::sim::run(*args),
            Command::View(args) => commands::view::run(args),
            Command::Calibrate(args) => commands::calibrate::run(args),
            Command::Excite(args) => commands::excite::run(args),
            Command::Gap(args) => commands::gap::run(args),
            Command::Test(args) => commands::test::run(args),
        }
    }
}
