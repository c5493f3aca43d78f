//! External controllers: a user's own ROS 2 node that twin starts, drives in lockstep and
//! stops (`controller = "ros"` in a scenario file, with a `[ros]` table: [`RosOptions`]).
//!
//! Data flow, per run (one `twin sim --scenario`, or one `twin randomize` worker):
//! 1. twin takes a DDS domain id that no other twin run on this machine holds
//!    ([`process::DomainLease`]), writes the loopback-only Fast DDS and Cyclone DDS profiles and
//!    puts `ROS_DOMAIN_ID`, `FASTDDS_DEFAULT_PROFILES_FILE`, `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`,
//!    an empty `ROS_STATIC_PEERS` and `CYCLONEDDS_URI` into the process's environment
//!    ([`crate::live::Loopback`], the same settings the tests give their nodes);
//! 2. joins that domain with the live bridge ([`crate::live`], lockstep, loopback) and starts
//!    `command` with `sh -c` in the scenario file's folder, in a process group of its own, its
//!    stdout and stderr appended to a log ([`process::ControllerProcess`]);
//! 3. waits, at most `join_timeout_secs`, until the process has joined: DDS discovery has seen
//!    its reader of `/clock` and its command publisher (the discovery database,
//!    [`crate::live::dds::Node::readers_of`]: rustdds 0.15 has no publication-matched status
//!    and drops match events); then says the episode's start time on `/clock` (acknowledged;
//!    time does not advance, so a timer fires nothing) and waits for its readers of the
//!    `subscribes` topics (default `/joint_states`), made at its start or in its first `/clock`
//!    callback, saying in the log each second which it still waits for; then until its readers
//!    of twin's state topics have not changed for 150 ms (an IMU reader made just after);
//! 4. holds the start pose for the first control period (PD with the hold gains, as
//!    `pd-hold`; the state goes out once per period on every state topic, an IMU included),
//!    then runs in lockstep: the state acknowledged, `/clock` = t, exactly one command per
//!    control period, waiting at most `period_timeout_secs` for it ([`crate::live`]); a missing
//!    command's cause names what twin had sent, to which of the node's readers, and whether
//!    they acknowledged it;
//! 5. stops it: SIGINT, then SIGTERM, then SIGKILL to its process group, each after
//!    `stop_timeout_secs` — per episode (`restart = "episode"`, the default) or at the end
//!    (`restart = "never"`: one process per worker, the simulation reset under it; twin then
//!    says the jump back in time on `/clock` alone for `reset_settle_secs`, because ROS
//!    nodes keep only the latest `/clock` message and would otherwise miss the jump).
//!
//! What goes wrong with the process — it exits, never joins, stops answering — fails that
//! run with the reason (the `controller` check's cause, [`ControllerHealth`]), never the batch.

pub mod process;

#[cfg(feature = "ros")]
mod controller;

#[cfg(feature = "ros")]
pub use controller::{ControllerHealth, ExternalController, external};

/// When a `twin randomize` worker starts its controller process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Restart {
    /// A fresh process for every episode (deterministic whatever the thread count).
    Episode,
    /// One process per worker, kept across episodes: the simulation is reset under it and
    /// `/clock` starts again from the first control period (a jump back in time). Cheaper; only
    /// deterministic for a controller that keeps no state across such a jump.
    Never,
}

/// What the numbers of the controller's `Float64MultiArray` commands are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interface {
    /// Joint positions, rad (m): the PD servo with the hold gains.
    Position,
    /// Joint velocities, rad/s (m/s).
    Velocity,
    /// Joint efforts, N·m (N).
    Effort,
}

/// A scenario's `[ros]` table: the external controller and its bounds.
///
/// ```toml
/// controller = "ros"
/// [ros]
/// command = "python3 controllers/hold_pose.py --ros-args -p use_sim_time:=true"
/// command_interface = "position"   # position | velocity | effort
/// control_rate_hz = 100.0          # /clock and command periods
/// join_timeout_secs = 30.0         # longest wait for the process to join the graph
/// period_timeout_secs = 5.0        # longest wait for one period's command
/// stop_timeout_secs = 2.0          # wait after each of SIGINT, SIGTERM (then SIGKILL)
/// restart = "episode"              # episode | never (twin randomize)
/// reset_settle_secs = 0.1          # restart = "never": the jump back on /clock, alone, this long
/// subscribes = ["/joint_states"]   # topics the process must subscribe to before time starts
/// flood_commands_per_period = 10.0 # commands beyond one per period, averaged over
/// flood_window_secs = 1.0          #   this much simulated time, that fail the episode
/// ```
#[derive(Debug, Clone, PartialEq, serde::Deserialize, smart_default::SmartDefault)]
#[serde(deny_unknown_fields, default)]
pub struct RosOptions {
    /// The command line, run with `sh -c` in the scenario file's folder (so `$VARIABLES` and
    /// relative paths work). Required ([`RosOptions::validate`] refuses an empty one).
    pub command: String,
    /// Meaning of the `Float64MultiArray` commands on `/<robot>/joint_commands` (default:
    /// position).
    #[default(Interface::Position)]
    pub command_interface: Interface,
    /// Control rate: `/clock` and command periods, Hz (default: 100).
    #[serde(alias = "control_rate")]
    #[default(100.0)]
    pub control_rate_hz: f64,
    /// Longest wait for the process to join the ROS graph, wall seconds (default: 30).
    #[default(30.0)]
    pub join_timeout_secs: f64,
    /// Longest wait for one control period's command, wall seconds (default: 5).
    #[default(5.0)]
    pub period_timeout_secs: f64,
    /// Wait after SIGINT and again after SIGTERM before the next signal, wall seconds
    /// (default: 2).
    #[default(2.0)]
    pub stop_timeout_secs: f64,
    /// When `twin randomize` starts a new process (default: every episode).
    #[default(Restart::Episode)]
    pub restart: Restart,
    /// Under a kept process (`restart = "never"`), how long twin says the jump back in time on
    /// `/clock` (again every 10 ms) before the first lockstep period, wall seconds (default:
    /// 0.1). rclpy's and rclcpp's `/clock` subscriptions keep only the latest message (depth
    /// 1, best effort): a node busy with the last episode's messages that gets the jump and
    /// the first period's time together keeps the second alone, reads it as the jump, and its
    /// sim-time timer waits one more period, so no command comes.
    #[default(0.1)]
    pub reset_settle_secs: f64,
    /// Topics (besides `/clock`) the process must subscribe to before simulated time starts,
    /// at its start or in its callback of the start time on `/clock`, so that it misses none of
    /// their messages (default: `["/joint_states"]`). A node that subscribes only later (in
    /// another callback, after time has started) leaves its topic out: its first state is sent
    /// again when its reader appears, until its first command.
    #[default(vec!["/joint_states".into()])]
    pub subscribes: Vec<String>,
    /// Commands beyond one per control period, averaged over `flood_window_secs`, above which
    /// the episode fails as a flood (default: 10). Twin takes one command per period; the
    /// others still queued when the next period opens are dropped and counted
    /// ([`crate::live::flood`]). A node with one command per `/clock` period sends none beyond;
    /// a timer at twice the control rate sends 1.
    #[default(10.0)]
    pub flood_commands_per_period: f64,
    /// The window of that average, simulated seconds (default: 1).
    #[default(1.0)]
    pub flood_window_secs: f64,
}

impl RosOptions {
    /// Checks the values: `Err((key, message))`.
    ///
    /// # Errors
    /// The first key out of range.
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        if self.command.trim().is_empty() {
            return Err(("command", "must be a command line (e.g. \"python3 my_controller.py\")".into()));
        }
        twin_core::bounds::positive([
            ("control_rate_hz", self.control_rate_hz),
            ("join_timeout_secs", self.join_timeout_secs),
            ("period_timeout_secs", self.period_timeout_secs),
            ("stop_timeout_secs", self.stop_timeout_secs),
            ("reset_settle_secs", self.reset_settle_secs),
            ("flood_window_secs", self.flood_window_secs),
        ])?;
        twin_core::bounds::non_negative([("flood_commands_per_period", self.flood_commands_per_period)])?;
        if let Some(t) = self.subscribes.iter().find(|t| !t.starts_with('/')) {
            return Err(("subscribes", format!("topic {t:?} must start with `/`")));
        }
        Ok(())
    }
}
