//! The twin on a live ROS 2 graph (`twin sim --ros`): a DDS bridge in pure Rust (rustdds), no
//! ROS install.
//!
//! [`start`] gives two halves that plug into the one simulation loop ([`twin_core::sim::simulate`]):
//! - a [`LiveSink`], a [`Sink`] of the recording ([`twin_core::sim::Recording::with_sinks`]): every
//!   topic the recorder writes (`/joint_states`, the IMUs, `/odom`, `/tf`, `/tf_static`,
//!   `/contacts/<body>`, a controller's diagnostics) is published as CDR;
//! - a [`LiveController`], the [`Controller`](twin_core::control::Controller) of the run: it
//!   publishes `/clock` at each control period, takes `Float64MultiArray` commands on
//!   `/<robot>/joint_commands`, `JointTrajectory` on `/<robot>/joint_trajectory` and
//!   `JointState` commands by joint name on `/<robot>/joint_command` (the convention of
//!   `topic_based_ros2_control`), turns them into actuator commands with the loops and gains
//!   twin's own controllers use ([`command`]), paces the run (real time × factor, as fast as
//!   possible, or lockstep); `/clock` and the commands it received are its own topics
//!   ([`Controller::topics`]), recorded byte for byte.
//!
//! What the bridge publishes is what the recorder writes, and the recorder writes the
//! observation the engine gave the controller ([`twin_core::engine`]'s one sensor model): a node
//! on the graph sees exactly what an in-process controller sees.
//!
//! ROS naming: topic `/x` is DDS topic `rt/x`, type `pkg/msg/T` is `pkg::msg::dds_::T_`. QoS:
//! reliable + volatile (keep last 100; matches rclpy/rclcpp defaults and best-effort sensor
//! subscriptions); `/tf_static` and `/robot_description` reliable + transient-local. A writer
//! never blocks the simulation.
//!
//! Lockstep ([`Pacing::Lockstep`]), the protocol:
//! 1. **join**: before time starts, the twin says `/clock` = 0 (again every 200 ms) and waits,
//!    at most [`LiveOptions::join_timeout_secs`], until the controller's command publisher has
//!    matched one of its command readers (a command written before that match would be lost:
//!    DDS does not keep volatile samples for readers it has not met), then up to 2 s more for
//!    a reader of `/joint_states` (so the controller gets the first state). A node's `/clock`
//!    subscription can match a moment after its publisher (discovery runs each way on its
//!    own); one that matched after the last `/clock` = 0 first hears period 1's time;
//! 2. **period 0** runs without waiting, under hold (the home pose): a `use_sim_time` timer
//!    fires when simulation time has advanced by its period, so it can only fire once `/clock`
//!    moves past 0;
//! 3. **each later period k** (t_k = k·P): every state message stamped before t_k is
//!    delivered first: acknowledged by each reliable reader that has matched (rustdds
//!    `wait_for_acknowledgments`, at most the lockstep timeout; [`outbox`]); a best-effort
//!    reader (`qos_profile_sensor_data`) cannot acknowledge and gets its sample before `/clock`
//!    only in the writing order. Then the twin publishes `/clock` = t_k, takes exactly the next
//!    command in arrival order (waiting at most [`LiveOptions::lockstep_timeout_secs`]) and
//!    applies it over [t_k, t_k + P). A rejected command counts as the period's command (the
//!    last good one is held), so the run stays deterministic. Until the run's first command,
//!    a state message goes out again (with `/clock`, every 200 ms) when a reader of its topic
//!    appears that discovery had not seen when it went out ([`outbox`]): a node that subscribes
//!    late still gets its first state.
//! 4. **flood**: just before each later period's `/clock`, every command still queued is taken:
//!    the first stays for that period, the others (commands beyond one per period) are dropped
//!    and counted; above [`LiveOptions::flood_commands_per_period`] on average over
//!    [`LiveOptions::flood_window_secs`] the run fails, naming the topic and the rate
//!    ([`flood`]). A node that sends one command per period has no surplus: the commands
//!    applied are the same with or without the count.
//!
//! In lockstep the state topics come once per period (the CLI sets their rate to the control
//! rate), stamped t_k and published during period k. A timer-driven node ticks at `/clock` =
//! t_k with the state of t_(k−1); a node that answers each `/joint_states` answers the state of
//! t_k during period k, and twin applies that answer from t_(k+1). Either way a command acts
//! one period after the state it answers (the one-period delay), and the k-th command a node
//! sends is applied in period k: the run is a function of the node's answers alone, however
//! long they take. Topics are not ordered against each other in DDS; the bridge waits for the
//! reliable readers' acknowledgments of the state before it writes the `/clock` that follows
//! it, and writes a best-effort reader's sample before that `/clock` from the same thread.
//! A node's executor (rclpy, rclcpp) takes one message of a subscription per turn: with one
//! message per topic and period, a single-threaded executor has taken period k's state by the
//! time its timer fires on `/clock` k (the `/clock` subscription comes first in its turn); a
//! topic sent several times per period (an IMU faster than the control rate) would not be.
//!
//! Services ([`simulation`]): pause, resume, step, reset and quit through the
//! `simulation_interfaces` services `/twin/get_simulation_state`, `/twin/set_simulation_state`,
//! `/twin/step_simulation` and `/twin/reset_simulation`, and Gazebo Classic's `std_srvs/srv/Empty`
//! `/pause_physics`, `/unpause_physics`, `/reset_simulation` and `/reset_world`. Requests are taken at each control
//! period's start (after its `/clock`), and at every step while paused. While paused the
//! simulation waits (no steps, no `/clock`); after a resume, real-time pacing starts again
//! from the current simulated time (no catching up). A reset acts through [`ResetOnRequest`](twin_core::engine::disturb::ResetOnRequest), the
//! run's disturbance: the state at the start comes back at the next step. In lockstep, a
//! `StepSimulation` that crosses a control period's start waits for that period's command, as
//! any step does.
//!
//! Steering a walker ([`LiveController::drive_walker`], `twin sim --ros --controller walk`):
//! the run's controller is twin's walker, and `geometry_msgs/Twist` on `/cmd_vel`
//! ([`twin_core::topics::CMD_VEL_TOPIC`]) sets its velocity target (linear.x forward, linear.y
//! left, angular.z yaw rate; [`twin_controllers::walk::Walker::steer`]: clamped to what its steps allow,
//! with a warning, and reached at its acceleration limits). In lockstep a Twist is the
//! period's command (one per `/clock` period, as for joint commands); in the real-time modes
//! the newest one wins. A Twist with a non-finite component is rejected. No Twist for
//! [`LiveOptions::cmd_vel_timeout_secs`] of simulated time (a mobile base's `cmd_vel_timeout`)
//! stops the walker: it finishes its step and stands; the next Twist steers again. Before the
//! first Twist the walker keeps its own command (the scenario's; standing by default).
//!
//! Silent controller (real-time modes): the last command is held; after
//! [`LiveOptions::silence_timeout_secs`] of wall time without a good command, the joints hold
//! the pose they are in (PD, the hold gains) until commands come back.

pub mod command;
pub mod dds;
pub mod flood;
pub mod loopback;
pub mod outbox;
pub mod service;
pub mod simulation;

pub use command::{CommandInterface, Commander};
pub use loopback::Loopback;

use dds::{Node, RawCdr, RawReader, RawWriter, TopicQos};
use simulation::{Call, Gazebo, Outcome, SimulationServices, result, scope, state};
use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use twin_controllers::walk::{Command as WalkCommand, Walker};
use twin_core::control::{Controller, Observation};
use twin_core::engine::disturb::ResetOnRequest;
use twin_core::error::{Error, Result};
use twin_core::log::cdr::{CdrReader, CdrWriter};
use twin_core::log::{Clock, Float64MultiArray, JointState, JointTrajectory, RosMessage, RosString, Twist};
use twin_core::mj::Model;
use twin_core::robot::Robot;
use twin_core::topics::{Qos, Sink, TopicInfo, TopicKind, TypedMessage};

/// How simulated time relates to wall time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// Simulated seconds per wall second (1.0: real time).
    RealTime(f64),
    /// As fast as possible.
    Max,
    /// One command per control period, however long it takes (bounded by
    /// [`LiveOptions::lockstep_timeout_secs`]).
    Lockstep,
}

/// Options of the live bridge.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct LiveOptions {
    /// DDS domain (the CLI reads `ROS_DOMAIN_ID`) (default: 0).
    pub domain_id: u16,
    /// Address of the only interface DDS uses: discovery, multicast and advertised locators
    /// (default: 127.0.0.1, loopback only: unicast discovery to 127.0.0.1, no multicast).
    #[default(IpAddr::V4(std::net::Ipv4Addr::LOCALHOST))]
    pub interface: IpAddr,
    /// Control rate: `/clock` and command periods, Hz (default: 100, the workflow's gait
    /// controller).
    #[default(100.0)]
    pub control_rate_hz: f64,
    /// Meaning of `Float64MultiArray` commands (default: position).
    #[default(CommandInterface::Position)]
    pub command_interface: CommandInterface,
    /// Pacing (default: real time).
    #[default(Pacing::RealTime(1.0))]
    pub pacing: Pacing,
    /// Wall time without a good command after which the joints hold their current pose, s
    /// (default: 0.5).
    #[default(0.5)]
    pub silence_timeout_secs: f64,
    /// Longest wait for a command in lockstep, wall s (default: 10).
    #[default(10.0)]
    pub lockstep_timeout_secs: f64,
    /// Lockstep: longest wait for the controller's command publisher before time starts, wall
    /// s (default: 30: a Python node with rclpy takes a few seconds to start and discover).
    #[default(30.0)]
    pub join_timeout_secs: f64,
    /// Steering a walker: simulated time without a Twist on `/cmd_vel` after which it stops
    /// and stands, s (default: 0.5, as `diff_drive_controller`'s `cmd_vel_timeout`).
    #[default(0.5)]
    pub cmd_vel_timeout_secs: f64,
    /// Lockstep: commands beyond the one each control period uses, averaged over
    /// [`LiveOptions::flood_window_secs`], above which the run fails as a flood (default: 10;
    /// a well-behaved node sends none beyond, a timer twice as fast as the control rate one).
    #[default(10.0)]
    pub flood_commands_per_period: f64,
    /// Lockstep: the window of that average, simulated s (default: 1).
    #[default(1.0)]
    pub flood_window_secs: f64,
}

/// In lockstep, how often `/clock` is said again while twin waits for a command.
const CLOCK_RESEND: Duration = Duration::from_millis(200);

/// A message the controller half exchanged (`/clock` sent, a command received), waiting for
/// the recording: topic index in [`LiveController::topics`], simulation time, CDR bytes.
struct ExchangedMessage {
    topic: usize,
    log_time_nanos: u64,
    cdr: Vec<u8>,
}

/// Messages exchanged by the controller half, waiting for the recording.
type Exchanged = Mutex<Vec<ExchangedMessage>>;

/// The controller half's topics, in [`LiveController::topics`] order.
const CLOCK: usize = 0;
const COMMANDS: usize = 1;
const TRAJECTORY: usize = 2;
const BY_NAME: usize = 3;
const CMD_VEL: usize = 4;
/// The walker's own topics follow the bridge's.
const WALKER_TOPICS: usize = 5;

/// Lockstep join: how long the twin waits for a `/joint_states` reader once the command
/// publisher has matched.
const STATE_READER_GRACE: Duration = Duration::from_secs(2);

/// Publishes the recorder's topics (a [`Sink`]).
pub struct LiveSink {
    node: Arc<Node>,
    writers: HashMap<String, Arc<RawWriter>>,
    /// Writer of each topic id.
    by_id: twin_core::topics::ById<String>,
    /// Topics the bridge exchanges itself (`/clock`, its command inputs): recorded, never
    /// published again.
    own: Vec<String>,
    cdr: CdrWriter,
    /// Failed writes (a reader that vanished mid-write), counted, not fatal.
    write_failures: u64,
    /// The `/joint_states` writer, shared with the controller half, which asks it for matched
    /// readers before time starts (lockstep join).
    state_writer: SharedWriter,
    /// The stream writers and what they sent, shared with the controller half ([`outbox`]).
    outbox: SharedOutbox,
}

/// The [`outbox::Outbox`] the two halves share.
type SharedOutbox = Arc<Mutex<outbox::Outbox>>;

/// A writer the sink creates and the controller half watches.
type SharedWriter = Arc<Mutex<Option<Arc<RawWriter>>>>;

impl Sink for LiveSink {
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool> {
        // The recorder's own per-step command stream is not published: the bridge's
        // `/<robot>/joint_commands` is the controller's input.
        if topic.kind == TopicKind::Commands || self.own.contains(&topic.name) {
            return Ok(false);
        }
        if !self.writers.contains_key(&topic.name) {
            let qos = TopicQos::of(topic.qos);
            let w = Arc::new(self.node.writer(&topic.name, topic.type_name, qos)?);
            if matches!(qos, TopicQos::Stream { .. })
                && let Ok(mut o) = self.outbox.lock()
            {
                o.add(&topic.name, w.clone());
            }
            if topic.kind == TopicKind::JointStates
                && let Ok(mut s) = self.state_writer.lock()
            {
                *s = Some(w.clone());
            }
            self.writers.insert(topic.name.clone(), w);
        }
        self.by_id.set(id, topic.name.clone());
        Ok(true)
    }

    fn write(&mut self, id: usize, _topic: &TopicInfo, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        if let Some(name) = self.by_id.get(id)
            && let Some(w) = self.writers.get(name)
        {
            let cdr = message.to_cdr(&mut self.cdr).to_vec();
            if let Ok(mut o) = self.outbox.lock() {
                o.sent(name, log_time_nanos, &cdr);
            }
            if w.write(RawCdr(cdr), None).is_err() {
                self.write_failures += 1;
            }
        }
        Ok(())
    }
}

/// Statistics of a live run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LiveStats {
    /// Control periods run.
    pub periods: u64,
    /// Commands applied (`Float64MultiArray`, trajectories, Twists).
    pub commands_applied: u64,
    /// Commands rejected (wrong length, NaN, undecodable, bad trajectory).
    pub commands_rejected: u64,
    /// Times the joints switched to the safe hold after a silent controller.
    pub safe_holds: u64,
    /// Wall seconds from the first to the last control period.
    pub wall_secs: f64,
    /// Simulated seconds over the same span.
    pub sim_secs: f64,
    /// Lateness of each period's start against its real-time target, µs (real-time pacing).
    pub jitter_micros: Vec<f64>,
    /// Lockstep: wall time from publishing `/clock` to having the command, µs.
    pub round_trip_micros: Vec<f64>,
    /// Service calls answered.
    pub service_calls: u64,
    /// Resets done through `/twin/reset_simulation` (or a stop).
    pub resets: u64,
    /// Lockstep: wall seconds from the start until the controller's command publisher matched.
    pub join_secs: Option<f64>,
    /// Twists on `/cmd_vel` cut to what the walker's steps allow.
    pub cmd_vel_clamped: u64,
    /// Stops of the walker after [`LiveOptions::cmd_vel_timeout_secs`] without a Twist.
    pub cmd_vel_timeouts: u64,
    /// Lockstep: periods whose command was already there before their `/clock` went out (a
    /// node that answers a state message in its subscription callback), not after it (a node
    /// that computes on `/clock`, a timer on simulation time).
    pub commands_before_clock: u64,
}

impl LiveStats {
    /// Measured real-time factor: simulated seconds per wall second.
    pub fn real_time_factor(&self) -> f64 {
        if self.wall_secs > 0.0 { self.sim_secs / self.wall_secs } else { f64::INFINITY }
    }
}

/// The p-th percentile (0–100) of `values` (nearest rank), `None` if empty.
pub fn percentile(values: &[f64], p: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * v.len() as f64).ceil().max(1.0) as usize;
    Some(v[rank.min(v.len()) - 1])
}

/// The run's controller: commands in, `/clock` out, pacing (see the module docs).
pub struct LiveController {
    options: LiveOptions,
    commander: Commander,
    clock: RawWriter,
    commands: RawReader,
    trajectories: RawReader,
    /// `JointState` commands by joint name.
    by_name: RawReader,
    /// `Twist` on `/cmd_vel`: the walker's velocity target.
    twist: RawReader,
    /// The walker it runs instead of the joint commander ([`LiveController::drive_walker`]),
    /// whether it must start over at the next step (a reset), and when the last Twist came
    /// (simulated s; `None`: none yet, or timed out).
    walker: Option<Box<Walker>>,
    walker_reset: bool,
    last_twist_secs: Option<f64>,
    /// The sink's `/joint_states` writer (lockstep join).
    state_writer: SharedWriter,
    /// The participant (what discovery has seen).
    node: Arc<Node>,
    /// The sink's stream writers and what they sent ([`outbox`]).
    outbox: SharedOutbox,
    /// Lockstep: no command has come yet in this run (its first period's state is sent again
    /// to readers that appear late, [`outbox::Outbox::resend_to_late_readers`]).
    awaiting_first: bool,
    /// The state topics the node reads, and, when a command did not come, what twin had sent
    /// before that `/clock` and which of them had not reached the node
    /// ([`LiveController::missing_command`]).
    reads: Vec<String>,
    missing: Option<(String, Vec<String>)>,
    poll: rustdds::mio1::Poll,
    events: rustdds::mio1::Events,
    exchanged: Exchanged,
    command_topic: String,
    trajectory_topic: String,
    by_name_topic: String,
    steps_per_period: u64,
    step: u64,
    started: Option<(Instant, f64)>,
    last_good: Instant,
    stop: &'static std::sync::atomic::AtomicBool,
    failure: Option<Error>,
    log: Box<dyn FnMut(&str) + Send>,
    stats: LiveStats,
    /// Scratch buffers for the last observation (trajectory start, safe hold).
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    clock_cdr: CdrWriter,
    /// The `simulation_interfaces` services and what they set.
    services: SimulationServices,
    paused: bool,
    /// A `StepSimulation` in progress: its request and the steps still to take.
    stepping: Option<(usize, service::RequestId, u64)>,
    /// Set by a reset, taken by [`ResetOnRequest`](twin_core::engine::disturb::ResetOnRequest) at the next step.
    reset_requested: Arc<AtomicBool>,
    /// `SetSimulationState(QUITTING)` ends the run after this step.
    quit: bool,
    dt_secs: f64,
    /// Simulated time at the end of the step being taken, s.
    step_end_secs: f64,
    /// Lockstep: the surplus of commands over one per period ([`flood`]).
    flood: flood::FloodWatch,
    /// Lockstep: the command kept for the next period when the surplus was taken (its input
    /// topic index and bytes).
    held: Option<(usize, RawCdr)>,
    /// Why the run failed as a flood, if it did.
    flooded: Option<String>,
}

/// Topic of the commands (`/<robot>/joint_commands`).
pub fn command_topic(robot: &Robot) -> String {
    format!("/{}/joint_commands", robot.name)
}

/// Topic of trajectory commands (`/<robot>/joint_trajectory`).
pub fn trajectory_topic(robot: &Robot) -> String {
    format!("/{}/joint_trajectory", robot.name)
}

/// Topic of `JointState` commands by joint name (`/<robot>/joint_command`): what
/// `topic_based_ros2_control`'s `joint_commands_topic` is set to.
pub fn by_name_topic(robot: &Robot) -> String {
    format!("/{}/joint_command", robot.name)
}

/// Topic the recorder writes its per-step actuator command to in a live run (the usual
/// `/<robot>/joint_commands` is the bridge's input).
pub fn actuator_topic(robot: &Robot) -> String {
    format!("/{}/actuator_commands", robot.name)
}

/// Joins the ROS 2 graph for `robot`: publishes `/robot_description` (the robot's file, when
/// it is a URDF) and returns the two halves. `log` gets warnings (rejected commands, safe
/// holds); `stop` ends the run when set (Ctrl-C).
///
/// # Errors
/// [`Error::Live`] when DDS can't start or an option is out of range.
pub fn start(
    robot: &Robot,
    options: &LiveOptions,
    stop: &'static std::sync::atomic::AtomicBool,
    log: Box<dyn FnMut(&str) + Send>,
) -> Result<(LiveSink, LiveController)> {
    if !(options.control_rate_hz > 0.0 && options.control_rate_hz.is_finite()) {
        return Err(Error::Live {
            message: format!("control rate must be positive (got {} Hz)", options.control_rate_hz),
        });
    }
    if let Pacing::RealTime(f) = options.pacing
        && !(f > 0.0 && f.is_finite())
    {
        return Err(Error::Live {
            message: format!("real-time factor must be positive (got {f}); use max for no pacing"),
        });
    }
    if !(options.flood_commands_per_period >= 0.0 && options.flood_commands_per_period.is_finite()) {
        return Err(Error::Live {
            message: format!(
                "flood limit must be a number of commands per period ≥ 0 (got {})",
                options.flood_commands_per_period
            ),
        });
    }
    if !(options.flood_window_secs > 0.0 && options.flood_window_secs.is_finite()) {
        return Err(Error::Live {
            message: format!("flood window must be a positive number of seconds (got {})", options.flood_window_secs),
        });
    }
    let node = Arc::new(Node::new(options.domain_id, options.interface)?);
    let exchanged: Exchanged = Mutex::default();
    let command_topic = command_topic(robot);
    let trajectory_topic = trajectory_topic(robot);
    let by_name_topic = by_name_topic(robot);

    let text = std::fs::read_to_string(&robot.path).unwrap_or_default();
    let mut sink = LiveSink {
        node: node.clone(),
        writers: HashMap::new(),
        by_id: Default::default(),
        own: vec![
            "/clock".into(),
            command_topic.clone(),
            trajectory_topic.clone(),
            by_name_topic.clone(),
            twin_core::topics::CMD_VEL_TOPIC.into(),
        ],
        cdr: CdrWriter::new(),
        write_failures: 0,
        state_writer: SharedWriter::default(),
        outbox: Arc::new(Mutex::new(outbox::Outbox::new(node.clone()))),
    };
    if let Ok(mut o) = sink.outbox.lock() {
        o.set_lockstep(options.pacing == Pacing::Lockstep);
    }
    if twin_core::urdf::is_urdf(&text) {
        let w = node.writer("/robot_description", RosString::TYPE_NAME, TopicQos::Latched)?;
        let mut cdr = CdrWriter::new();
        RosString { data: text }.encode(&mut cdr);
        w.write(RawCdr(cdr.bytes().to_vec()), None)
            .map_err(|e| Error::Live { message: format!("publishing /robot_description: {e}") })?;
        sink.writers.insert("/robot_description".into(), Arc::new(w));
    }

    let clock = node.writer("/clock", Clock::TYPE_NAME, TopicQos::Stream { depth: 100 })?;
    let mut commands = node.reader(&command_topic, Float64MultiArray::TYPE_NAME, 1000)?;
    let mut trajectories = node.reader(&trajectory_topic, JointTrajectory::TYPE_NAME, 10)?;
    let mut by_name = node.reader(&by_name_topic, JointState::TYPE_NAME, 1000)?;
    let mut twist = node.reader(twin_core::topics::CMD_VEL_TOPIC, Twist::TYPE_NAME, 1000)?;
    let mut services = SimulationServices::new(&node)?;
    let poll = rustdds::mio1::Poll::new().map_err(|e| Error::Live { message: format!("creating a poller: {e}") })?;
    {
        use rustdds::mio1::{Interest, Token};
        let watch = |e: std::io::Error| Error::Live { message: format!("watching the command readers: {e}") };
        poll.registry()
            .register(&mut commands, Token(0), Interest::READABLE)
            .and_then(|()| poll.registry().register(&mut trajectories, Token(1), Interest::READABLE))
            .and_then(|()| poll.registry().register(&mut by_name, Token(2), Interest::READABLE))
            .and_then(|()| poll.registry().register(&mut twist, Token(3), Interest::READABLE))
            .map_err(watch)?;
        for (k, r) in services.readers_mut().enumerate() {
            poll.registry().register(r, Token(4 + k), Interest::READABLE).map_err(watch)?;
        }
    }
    let model: &Model = &robot.model;
    let dt = model.timestep_secs();
    let steps_per_period = ((1.0 / options.control_rate_hz) / dt).round().max(1.0) as u64;
    let controller = LiveController {
        options: options.clone(),
        commander: Commander::new(model, options.command_interface),
        clock,
        commands,
        trajectories,
        by_name,
        twist,
        walker: None,
        walker_reset: false,
        last_twist_secs: None,
        state_writer: sink.state_writer.clone(),
        node: node.clone(),
        outbox: sink.outbox.clone(),
        awaiting_first: true,
        reads: vec!["/joint_states".into()],
        missing: None,
        poll,
        events: rustdds::mio1::Events::with_capacity(16),
        exchanged,
        command_topic,
        trajectory_topic,
        by_name_topic,
        steps_per_period,
        step: 0,
        started: None,
        last_good: Instant::now(),
        stop,
        failure: None,
        log,
        stats: LiveStats::default(),
        qpos: vec![0.0; model.nq()],
        qvel: vec![0.0; model.nv()],
        clock_cdr: CdrWriter::new(),
        services,
        paused: false,
        stepping: None,
        reset_requested: Arc::default(),
        quit: false,
        dt_secs: dt,
        step_end_secs: 0.0,
        flood: flood::FloodWatch::new(
            options.flood_commands_per_period,
            options.flood_window_secs,
            steps_per_period as f64 * dt,
        ),
        held: None,
        flooded: None,
    };
    Ok((sink, controller))
}

/// What [`run_periods`] did.
#[derive(Debug, Clone)]
pub struct PeriodsRun {
    /// The simulation's report.
    pub report: twin_core::sim::SimReport,
    /// The bridge's statistics.
    pub stats: LiveStats,
    /// What was recorded and published.
    pub summary: twin_core::sim::RecordSummary,
}

/// Runs `periods` control periods of `robot` against an external controller on the ROS 2
/// graph: the bridge ([`start`]) with `options` (give [`Pacing::Lockstep`] for a deterministic
/// run, and [`Loopback::live_options`] for loopback only), the recorder with `record` (its MCAP
/// and rerun outputs, if any, and the bridge as a sink), `sim` for the seed (its duration is
/// `periods` control periods). `stop` ends the run early; `log` gets the bridge's warnings.
///
/// # Errors
/// As [`start`] and [`twin_core::sim::simulate_with`]: DDS, a controller that never joins or stops
/// answering in lockstep, recording errors.
pub fn run_periods(
    robot: &Robot,
    options: &LiveOptions,
    periods: u64,
    record: &twin_core::sim::RecordOptions,
    sim: &twin_core::sim::SimOptions,
    stop: &'static AtomicBool,
    log: Box<dyn FnMut(&str) + Send>,
) -> Result<PeriodsRun> {
    let (sink, mut controller) = start(robot, options, stop, log)?;
    let record = twin_core::sim::RecordOptions {
        command_topic: Some(actuator_topic(robot)),
        controller_topics: Controller::topics(&controller).into_iter().map(|t| t.name).collect(),
        ..record.clone()
    };
    let mut recording = twin_core::sim::Recording::with_sinks(robot, &record, vec![Box::new(sink)])?;
    let mut reset = controller.reset_disturbance();
    let period_secs = controller.steps_per_period() as f64 * robot.model.timestep_secs();
    let sim = twin_core::sim::SimOptions { duration_secs: periods as f64 * period_secs, ..sim.clone() };
    let report = twin_core::sim::simulate_with(
        robot,
        &mut controller,
        &sim,
        Some(&mut recording),
        &mut |_| {},
        &mut [&mut reset],
        &mut [],
    )?;
    let stats = controller.stats().clone();
    let summary = recording.finish()?;
    Ok(PeriodsRun { report, stats, summary })
}

impl LiveSink {
    /// Writes that failed (counted, not fatal).
    pub fn write_failures(&self) -> u64 {
        self.write_failures
    }
}

impl LiveController {
    /// Runs `walker` as the run's controller, steered by `geometry_msgs/Twist` on `/cmd_vel`
    /// (see the module docs), instead of taking joint commands. Call before the recording is
    /// opened: the walker's topics join the bridge's ([`Controller::topics`]).
    pub fn drive_walker(&mut self, walker: Walker) {
        self.walker = Some(Box::new(walker));
    }

    /// The walker it drives, if any.
    pub fn walker(&self) -> Option<&Walker> {
        self.walker.as_deref()
    }

    /// The commanded joints, in `Float64MultiArray` order.
    pub fn joint_names(&self) -> &[String] {
        self.commander.joint_names()
    }

    /// Simulation steps per control period.
    pub fn steps_per_period(&self) -> u64 {
        self.steps_per_period
    }

    /// The statistics so far.
    pub fn stats(&self) -> &LiveStats {
        &self.stats
    }

    /// The run's reset disturbance: give it to the simulation loop with the others
    /// ([`twin_core::sim::simulate_with`]); without it a reset only brings the command back to
    /// holding the home pose.
    pub fn reset_disturbance(&self) -> ResetOnRequest {
        ResetOnRequest::new(self.reset_requested.clone())
    }

    /// Answers every waiting service call (see [`simulation`]).
    fn serve(&mut self, model: &Model, t_secs: f64) {
        while let Some(next) = self.services.next_call() {
            let (k, id, call) = match next {
                Ok(c) => c,
                Err(why) => {
                    self.warn(format!("service call refused: {why}"));
                    continue;
                }
            };
            let outcome = self.call(model, t_secs, k, id, call);
            self.stats.service_calls += 1;
            if let Some(outcome) = outcome {
                // A std_srvs/Empty reply can't say it: a warning does.
                if simulation::SERVICES[k].1 == simulation::EMPTY && outcome.code != result::OK {
                    self.warn(format!("{}: not done: {}", simulation::SERVICES[k].0, outcome.message));
                }
                let current = if self.paused { state::PAUSED } else { state::PLAYING };
                if let Err(e) = self.services.answer(k, &id, current, &outcome) {
                    self.warn(e.to_string());
                }
            }
        }
    }

    /// Does `call`; the reply, or `None` when it comes later (a step in progress).
    fn call(&mut self, model: &Model, t_secs: f64, k: usize, id: service::RequestId, call: Call) -> Option<Outcome> {
        Some(match call {
            Call::GetState => Outcome::ok(),
            Call::SetState(target) if self.stepping.is_some() && target != state::QUITTING => Outcome::new(
                result::INCORRECT_STATE,
                "a StepSimulation is in progress; set the state when it has replied",
            ),
            Call::SetState(state::PAUSED) if self.paused => {
                Outcome::new(result::ALREADY_IN_TARGET_STATE, "already paused")
            }
            Call::SetState(state::PAUSED) => {
                self.paused = true;
                Outcome::ok()
            }
            Call::SetState(state::PLAYING) if !self.paused => {
                Outcome::new(result::ALREADY_IN_TARGET_STATE, "already playing")
            }
            Call::SetState(state::PLAYING) => {
                self.resume(t_secs);
                Outcome::ok()
            }
            Call::SetState(state::STOPPED) => {
                self.paused = true;
                self.reset(model, t_secs);
                Outcome::ok()
            }
            Call::SetState(state::QUITTING) => {
                self.quit = true;
                Outcome::ok()
            }
            Call::SetState(other) => Outcome::new(
                result::INCORRECT_TRANSITION,
                format!("twin sets STOPPED (0), PLAYING (1), PAUSED (2) or QUITTING (3), not {other}"),
            ),
            Call::Step(_) if !self.paused => Outcome::new(
                result::OPERATION_FAILED,
                "StepSimulation needs a paused simulation: pause it first (SetSimulationState PAUSED)",
            ),
            Call::Step(_) if self.stepping.is_some() => {
                Outcome::new(result::OPERATION_FAILED, "a StepSimulation is already in progress")
            }
            Call::Step(0) => Outcome::ok(),
            Call::Step(n) => {
                self.stepping = Some((k, id, n));
                return None;
            }
            Call::Reset(s) if s != scope::DEFAULT && s & scope::TIME != 0 => Outcome::new(
                result::FEATURE_UNSUPPORTED,
                "twin does not reset simulation time (/clock and recordings stay monotonic); use SCOPE_STATE (2)",
            ),
            Call::Reset(s) if s == scope::DEFAULT || s & scope::STATE != 0 => {
                self.reset(model, t_secs);
                Outcome::ok()
            }
            Call::Reset(_) => Outcome::new(result::OK, "twin spawns nothing: nothing to remove"),
            Call::Gazebo(Gazebo::Pause | Gazebo::Unpause) if self.stepping.is_some() => Outcome::new(
                result::INCORRECT_STATE,
                "a StepSimulation is in progress: pause/unpause when it has replied",
            ),
            Call::Gazebo(Gazebo::Pause) => {
                self.paused = true;
                Outcome::ok()
            }
            Call::Gazebo(Gazebo::Unpause) => {
                if self.paused {
                    self.resume(t_secs);
                }
                Outcome::ok()
            }
            Call::Gazebo(Gazebo::ResetSimulation | Gazebo::ResetWorld) => {
                self.reset(model, t_secs);
                Outcome::ok()
            }
        })
    }

    fn resume(&mut self, t_secs: f64) {
        self.paused = false;
        // Pacing goes on from now: the paused wall time is not caught up.
        if let (Pacing::RealTime(factor), Some((_, sim0))) = (self.options.pacing, self.started) {
            let now = Instant::now();
            let behind = Duration::from_secs_f64(((t_secs - sim0) / factor).max(0.0));
            self.started = Some((now.checked_sub(behind).unwrap_or(now), sim0));
        }
        self.last_good = Instant::now();
    }

    fn reset(&mut self, model: &Model, t_secs: f64) {
        self.reset_requested.store(true, Ordering::Relaxed);
        self.commander = Commander::new(model, self.options.command_interface);
        self.walker_reset = self.walker.is_some();
        self.stats.resets += 1;
        self.warn(format!(
            "reset_simulation: the robot's state goes back to its start at the next step (t = {t_secs:.3} s); \
             holding the home pose until the next command"
        ));
    }

    /// Waits, answering service calls, while paused (and not stepping).
    fn wait_while_paused(&mut self, model: &Model, t_secs: f64) {
        while self.paused && self.stepping.is_none() && !self.quit && !self.stop.load(Ordering::Relaxed) {
            let _ = self.poll.poll(&mut self.events, Some(Duration::from_millis(20)));
            self.serve(model, t_secs);
        }
    }

    /// After a step: counts a `StepSimulation` down and replies when it is done, saying the
    /// time reached on `/clock` first (real-time modes; lockstep says it each period).
    fn stepped(&mut self) {
        let Some((k, id, left)) = self.stepping.as_mut() else { return };
        *left -= 1;
        if *left > 0 {
            return;
        }
        let (k, id) = (*k, *id);
        self.stepping = None;
        if self.options.pacing != Pacing::Lockstep {
            let t_nanos = (self.step_end_secs * 1e9).round().max(0.0) as u64;
            self.publish_clock(t_nanos);
        }
        if let Err(e) = self.services.answer(k, &id, state::PAUSED, &Outcome::ok()) {
            self.warn(e.to_string());
        }
    }

    /// Publishes and records `/clock` = `t_nanos`.
    fn publish_clock(&mut self, t_nanos: u64) {
        self.clock_cdr.reset();
        Clock { clock_nanos: t_nanos as i64 }.encode(&mut self.clock_cdr);
        let bytes = self.clock_cdr.bytes().to_vec();
        let _ = self.clock.write(RawCdr(bytes.clone()), None);
        self.record(CLOCK, t_nanos, bytes);
    }

    /// Waits up to `timeout` for a subscriber on `/clock` (a peer that joined the graph).
    pub fn wait_for_subscriber(&self, timeout: Duration) -> bool {
        use rustdds::StatusEvented;
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            while let Some(status) = self.clock.try_recv_status() {
                if let rustdds::DataWriterStatus::PublicationMatched { current, .. } = status
                    && current.count() > 0
                {
                    return true;
                }
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    fn warn(&mut self, message: String) {
        (self.log)(&message);
    }

    fn record(&self, topic: usize, t_nanos: u64, cdr: Vec<u8>) {
        if let Ok(mut q) = self.exchanged.lock() {
            q.push(ExchangedMessage { topic, log_time_nanos: t_nanos, cdr });
        }
    }

    /// Applies one received `Float64MultiArray` (or rejects it). Returns whether it was good.
    fn take_command(&mut self, raw: RawCdr, t_nanos: u64) -> bool {
        let decoded = CdrReader::new(&raw.0).and_then(|mut r| Float64MultiArray::decode(&mut r));
        let verdict = match &decoded {
            Ok(m) => self.commander.check(m),
            Err(e) => Err(format!("not a Float64MultiArray: {}", e.message)),
        };
        self.record(COMMANDS, t_nanos, raw.0);
        match (verdict, decoded) {
            (Ok(()), Ok(m)) => {
                self.commander.set_direct(&m);
                self.settle(Ok(()), |b| b.command_topic.clone(), t_nanos)
            }
            (Err(why), _) => self.settle(Err(why), |b| b.command_topic.clone(), t_nanos),
            (Ok(()), Err(_)) => false,
        }
    }

    /// Counts a command as applied (and the bridge as fed now), or rejects it with the reason on
    /// the topic `topic` names (called only then); returns whether it was applied.
    fn settle(
        &mut self,
        verdict: std::result::Result<(), String>,
        topic: impl FnOnce(&Self) -> String,
        t_nanos: u64,
    ) -> bool {
        match verdict {
            Ok(()) => {
                self.stats.commands_applied += 1;
                self.last_good = Instant::now();
                true
            }
            Err(why) => {
                self.reject(&topic(self), t_nanos, &why);
                false
            }
        }
    }

    fn take_trajectory(&mut self, raw: RawCdr, t_nanos: u64) {
        let decoded = CdrReader::new(&raw.0).and_then(|mut r| JointTrajectory::decode(&mut r));
        self.record(TRAJECTORY, t_nanos, raw.0);
        let now = t_nanos as f64 * 1e-9;
        let verdict = match decoded {
            Ok(t) => self.commander.set_trajectory(&t, now, &self.qpos),
            Err(e) => Err(format!("not a JointTrajectory: {}", e.message)),
        };
        self.settle(verdict, |b| b.trajectory_topic.clone(), t_nanos);
    }

    fn reject(&mut self, topic: &str, t_nanos: u64, why: &str) {
        self.stats.commands_rejected += 1;
        let n = self.stats.commands_rejected;
        // A flood of bad commands must not flood the terminal: the first ten, then every 1000th.
        if n <= 10 || n.is_multiple_of(1000) {
            self.warn(format!(
                "rejected command #{n} on {topic} at t = {:.3} s: {why}; holding the last good command",
                t_nanos as f64 * 1e-9
            ));
        }
    }

    /// Applies one received `JointState` command by joint name (or rejects it).
    fn take_by_name(&mut self, raw: RawCdr, t_nanos: u64) {
        let decoded = CdrReader::new(&raw.0).and_then(|mut r| JointState::decode(&mut r));
        self.record(BY_NAME, t_nanos, raw.0);
        let verdict = match decoded {
            Ok(m) => self.commander.set_by_name(&m, &self.qpos),
            Err(e) => Err(format!("not a JointState: {}", e.message)),
        };
        self.settle(verdict, |b| b.by_name_topic.clone(), t_nanos);
    }

    /// Applies one received `Twist` to the walker (or rejects it).
    fn take_twist(&mut self, raw: RawCdr, t_nanos: u64) {
        let decoded = CdrReader::new(&raw.0).and_then(|mut r| Twist::decode(&mut r));
        self.record(CMD_VEL, t_nanos, raw.0);
        let t_secs = t_nanos as f64 * 1e-9;
        let target = match decoded {
            Ok(m) if m.linear.iter().chain(&m.angular).all(|v| v.is_finite()) => {
                WalkCommand { vx: m.linear[0], vy: m.linear[1], yaw_rate: m.angular[2] }
            }
            Ok(m) => {
                return self.reject(twin_core::topics::CMD_VEL_TOPIC, t_nanos, &format!("not finite: {m:?}"));
            }
            Err(e) => {
                return self.reject(twin_core::topics::CMD_VEL_TOPIC, t_nanos, &format!("not a Twist: {}", e.message));
            }
        };
        let Some(walker) = self.walker.as_mut() else {
            return self.reject(
                twin_core::topics::CMD_VEL_TOPIC,
                t_nanos,
                "no walker runs (twin sim --ros --controller walk)",
            );
        };
        if walker.steer(target) {
            self.stats.cmd_vel_clamped += 1;
            let n = self.stats.cmd_vel_clamped;
            let b = walker.options().command_bounds();
            if n <= 10 || n.is_multiple_of(1000) {
                self.warn(format!(
                    "/cmd_vel #{n} at t = {t_secs:.3} s asks (vx {}, vy {}, yaw rate {}), beyond what the walker's \
                     steps allow (|vx| ≤ {:.3} m/s, |vy| ≤ {:.3} m/s, |yaw rate| ≤ {:.3} rad/s: max_step_length, \
                     max_step_lateral, max_step_yaw over step_period): clamped",
                    target.vx, target.vy, target.yaw_rate, b.vx_mps, b.vy_mps, b.yaw_rate_radps
                ));
            }
        }
        self.last_twist_secs = Some(t_secs);
        self.stats.commands_applied += 1;
        self.last_good = Instant::now();
    }

    /// Steering a walker: stops it when no Twist came for the timeout (simulated time).
    fn check_cmd_vel_timeout(&mut self, t_secs: f64) {
        let Some(last) = self.last_twist_secs else { return };
        if t_secs - last <= self.options.cmd_vel_timeout_secs {
            return;
        }
        if let Some(walker) = self.walker.as_mut() {
            walker.steer(WalkCommand::default());
        }
        self.last_twist_secs = None;
        self.stats.cmd_vel_timeouts += 1;
        self.warn(format!(
            "no Twist on {} for {} s at t = {t_secs:.3} s: the walker stops and stands",
            twin_core::topics::CMD_VEL_TOPIC,
            self.options.cmd_vel_timeout_secs
        ));
    }

    /// Takes every queued trajectory and command (real-time modes; the last good one wins).
    fn drain(&mut self, t_nanos: u64) {
        while let Ok(Some(s)) = self.twist.take_next_sample() {
            self.take_twist(s.into_value(), t_nanos);
        }
        while let Ok(Some(s)) = self.trajectories.take_next_sample() {
            self.take_trajectory(s.into_value(), t_nanos);
        }
        while let Ok(Some(s)) = self.by_name.take_next_sample() {
            self.take_by_name(s.into_value(), t_nanos);
        }
        while let Ok(Some(s)) = self.commands.take_next_sample() {
            self.take_command(s.into_value(), t_nanos);
        }
    }

    /// Lockstep, just before a period's `/clock`: takes every queued command, keeps the first
    /// (in [`LiveController::take_one`]'s order) for the period that `/clock` opens, drops
    /// the others (the surplus) and counts them ([`flood`]). A flood fails the run.
    fn take_surplus(&mut self, t_secs: f64) -> Result<()> {
        const ORDER: [usize; flood::INPUTS] = [TRAJECTORY, BY_NAME, COMMANDS, CMD_VEL];
        let mut surplus = [0u64; flood::INPUTS];
        for (slot, input) in ORDER.into_iter().enumerate() {
            loop {
                let reader = match input {
                    TRAJECTORY => &mut self.trajectories,
                    BY_NAME => &mut self.by_name,
                    COMMANDS => &mut self.commands,
                    _ => &mut self.twist,
                };
                let Ok(Some(sample)) = reader.take_next_sample() else { break };
                if self.held.is_none() {
                    self.held = Some((input, sample.into_value()));
                    self.stats.commands_before_clock += 1;
                } else {
                    surplus[slot] += 1;
                }
            }
        }
        let Some(f) = self.flood.push(surplus) else { return Ok(()) };
        let topic = match ORDER[f.input] {
            TRAJECTORY => self.trajectory_topic.clone(),
            BY_NAME => self.by_name_topic.clone(),
            COMMANDS => self.command_topic.clone(),
            _ => twin_core::topics::CMD_VEL_TOPIC.to_string(),
        };
        let why = format!(
            "{} commands beyond one per control period in the last {} periods before t = {t_secs:.3} s, most on {topic} \
             ({:.2} per period, {:.0} per simulated second); the limit is {} per period averaged over {} s \
             (flood_commands_per_period); is the controller publishing on a wall-time loop instead of once per /clock period?",
            f.surplus,
            f.window_periods,
            f.per_period,
            f.per_sim_sec,
            self.options.flood_commands_per_period,
            self.options.flood_window_secs
        );
        self.flooded = Some(why.clone());
        Err(Error::Live { message: format!("lockstep: the controller floods: {why}") })
    }

    /// Why the run failed as a flood of commands ([`flood`]), if it did.
    pub fn flood(&self) -> Option<&str> {
        self.flooded.as_deref()
    }

    /// Takes the next command of any kind, if one is queued; whether one was.
    fn take_one(&mut self, t_nanos: u64) -> bool {
        if let Some((input, raw)) = self.held.take() {
            match input {
                TRAJECTORY => self.take_trajectory(raw, t_nanos),
                BY_NAME => self.take_by_name(raw, t_nanos),
                COMMANDS => {
                    self.take_command(raw, t_nanos);
                }
                _ => self.take_twist(raw, t_nanos),
            }
        } else if let Ok(Some(s)) = self.trajectories.take_next_sample() {
            self.take_trajectory(s.into_value(), t_nanos);
        } else if let Ok(Some(s)) = self.by_name.take_next_sample() {
            self.take_by_name(s.into_value(), t_nanos);
        } else if let Ok(Some(s)) = self.commands.take_next_sample() {
            self.take_command(s.into_value(), t_nanos);
        } else if let Ok(Some(s)) = self.twist.take_next_sample() {
            self.take_twist(s.into_value(), t_nanos);
        } else {
            return false;
        }
        true
    }

    /// Lockstep, before time starts: waits until a command publisher has matched one of the
    /// command readers (at most [`LiveOptions::join_timeout_secs`]), then up to
    /// [`STATE_READER_GRACE`] for a `/joint_states` reader, saying `/clock` = 0 now and then.
    fn join(&mut self) -> Result<()> {
        use rustdds::StatusEvented;
        let started = Instant::now();
        let deadline = started + Duration::from_secs_f64(self.options.join_timeout_secs);
        let mut resend = started;
        let matched = |r: &RawReader, count: &mut i32| {
            while let Some(status) = r.try_recv_status() {
                if let rustdds::DataReaderStatus::SubscriptionMatched { current, .. } = status {
                    *count = current.count();
                }
            }
            *count > 0
        };
        let (mut a, mut b, mut c, mut d) = (0, 0, 0, 0);
        loop {
            let now = Instant::now();
            if now >= resend {
                let _ = self.clock.write(RawCdr(self.clock_cdr.bytes().to_vec()), None);
                resend = now + CLOCK_RESEND;
            }
            // (Each reader's status is drained every time: no short-circuit.)
            let any = matched(&self.commands, &mut a)
                | matched(&self.trajectories, &mut b)
                | matched(&self.by_name, &mut c)
                | matched(&self.twist, &mut d);
            if any {
                break;
            }
            if self.stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            if now >= deadline {
                return Err(Error::Live {
                    message: format!(
                        "lockstep: no controller joined within {} s: nothing published on {}, {}, {} or {} in domain {} (ROS_DOMAIN_ID); is it running, on the same domain \
                         and interface (loopback: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)?",
                        self.options.join_timeout_secs,
                        self.command_topic,
                        self.trajectory_topic,
                        self.by_name_topic,
                        twin_core::topics::CMD_VEL_TOPIC,
                        self.options.domain_id
                    ),
                });
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let joined = started.elapsed();
        let writer = self.state_writer.lock().ok().and_then(|w| w.clone());
        let mut readers = 0;
        let grace = Instant::now() + STATE_READER_GRACE;
        if let Some(w) = writer {
            while Instant::now() < grace {
                while let Some(status) = w.try_recv_status() {
                    if let rustdds::DataWriterStatus::PublicationMatched { current, .. } = status {
                        readers = current.count();
                    }
                }
                if readers > 0 {
                    break;
                }
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        self.stats.join_secs = Some(joined.as_secs_f64());
        if readers == 0 {
            self.warn(format!(
                "lockstep: the controller joined after {:.2} s but nothing reads /joint_states (waited {} s more); starting",
                joined.as_secs_f64(),
                STATE_READER_GRACE.as_secs()
            ));
        }
        Ok(())
    }

    /// Lockstep: exactly one command (a trajectory also counts), waiting at most the timeout.
    fn wait_one(&mut self, t_nanos: u64) -> Result<()> {
        let published = Instant::now();
        let deadline = published + Duration::from_secs_f64(self.options.lockstep_timeout_secs);
        let mut resend = published + CLOCK_RESEND;
        loop {
            if self.take_one(t_nanos) {
                self.first_command_came(t_nanos);
                break;
            }
            let now = Instant::now();
            if now >= deadline {
                let sent = self.sent_before_clock(&self.reads);
                let missed = self.reads.iter().filter(|t| self.reached(t) != Some(true)).cloned().collect();
                self.missing = Some((sent.clone(), missed));
                return Err(Error::Live {
                    message: format!(
                        "lockstep: no command on {} (nor {}, {}, {}) within {} s after /clock = {:.3} s (command {} \
                         of the run); what twin sent before that /clock: {sent}; is the controller still running in \
                         domain {} (ROS_DOMAIN_ID), sending one command per /clock period? (--lockstep-timeout \
                         sets the wait)",
                        self.command_topic,
                        self.trajectory_topic,
                        self.by_name_topic,
                        twin_core::topics::CMD_VEL_TOPIC,
                        self.options.lockstep_timeout_secs,
                        t_nanos as f64 * 1e-9,
                        self.stats.periods,
                        self.options.domain_id
                    ),
                });
            }
            if self.stop.load(std::sync::atomic::Ordering::Relaxed) {
                return Ok(());
            }
            // A reader that matched while the first /clock was on its way may have missed it
            // (volatile): say the time again now and then. A use_sim_time node sees the same
            // time twice, which fires nothing.
            if now >= resend {
                // Before the run's first command, the state that went out before a reader of
                // its topic appeared goes out again (then /clock, in the period's order).
                if self.awaiting_first {
                    self.resend_to_late_readers(t_nanos);
                }
                let _ = self.clock.write(RawCdr(self.clock_cdr.bytes().to_vec()), None);
                resend = now + CLOCK_RESEND;
            }
            // Readiness is edge-triggered and samples may already be queued: poll briefly, then
            // look again either way.
            let wait = (deadline - now).min(Duration::from_millis(20));
            let _ = self.poll.poll(&mut self.events, Some(wait));
        }
        self.stats.round_trip_micros.push(published.elapsed().as_secs_f64() * 1e6);
        Ok(())
    }

    fn period_start(&mut self, observation: &Observation<'_>) -> Result<()> {
        let t_secs = observation.time_secs;
        let t_nanos = (t_secs * 1e9).round().max(0.0) as u64;
        self.qpos.copy_from_slice(observation.qpos);
        self.qvel.copy_from_slice(observation.qvel);
        let first = self.started.is_none();
        if first && self.options.pacing == Pacing::Lockstep {
            self.publish_clock(t_nanos);
            self.join()?;
        }
        let now = Instant::now();
        let (wall0, sim0) = *self.started.get_or_insert((now, t_secs));
        if let Pacing::RealTime(factor) = self.options.pacing {
            let target = wall0 + Duration::from_secs_f64((t_secs - sim0) / factor);
            if target > now {
                std::thread::sleep(target - now);
            }
            let late = Instant::now().saturating_duration_since(target);
            if self.stats.periods > 0 {
                self.stats.jitter_micros.push(late.as_secs_f64() * 1e6);
            }
        }
        // Lockstep: the surplus over one command per period, before the period opens.
        if !first && self.options.pacing == Pacing::Lockstep {
            self.take_surplus(t_secs)?;
        }
        // Lockstep: the state stamped before t is delivered (acknowledged by every reliable
        // reader), then /clock = t ([`outbox`]).
        if !first && self.options.pacing == Pacing::Lockstep {
            self.deliver(t_secs)?;
        }
        if !first || self.options.pacing != Pacing::Lockstep {
            self.publish_clock(t_nanos);
        }
        match self.options.pacing {
            // The first period runs under hold (see the module docs).
            Pacing::Lockstep if first => {}
            Pacing::Lockstep => self.wait_one(t_nanos)?,
            _ => {
                self.drain(t_nanos);
                let silent = self.last_good.elapsed().as_secs_f64() > self.options.silence_timeout_secs;
                if silent && !self.commander.holding() {
                    self.commander.hold_current(&self.qpos);
                    self.stats.safe_holds += 1;
                    let msg = format!(
                        "no good command for {} s at t = {t_secs:.3} s: holding the current pose",
                        self.options.silence_timeout_secs
                    );
                    self.warn(msg);
                }
            }
        }
        if self.walker.is_some() {
            self.check_cmd_vel_timeout(t_secs);
        }
        self.stats.periods += 1;
        self.stats.wall_secs = Instant::now().duration_since(wall0).as_secs_f64();
        self.stats.sim_secs = t_secs - sim0;
        Ok(())
    }
}

impl Controller for LiveController {
    fn name(&self) -> &'static str {
        "ros"
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        self.commander = Commander::new(model, self.options.command_interface);
        self.step = 0;
        self.begin_run(true);
        self.flood.reset();
        self.flooded = None;
        if let Some(w) = self.walker.as_mut() {
            w.reset(model, observation)?;
        }
        Ok(())
    }

    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        let boundary = self.step.is_multiple_of(self.steps_per_period);
        if boundary
            && self.failure.is_none()
            && let Err(e) = self.period_start(observation)
        {
            self.failure = Some(e);
        }
        if boundary || self.paused {
            self.serve(model, observation.time_secs);
            self.wait_while_paused(model, observation.time_secs);
        }
        self.step_end_secs = observation.time_secs + self.dt_secs;
        self.step += 1;
        if let Some(walker) = self.walker.as_mut() {
            if std::mem::take(&mut self.walker_reset)
                && let Err(e) = walker.reset(model, observation)
            {
                self.failure.get_or_insert(e);
            }
            walker.compute(model, observation, command);
            return;
        }
        self.commander.compute(observation.time_secs, observation.qpos, observation.qvel, command);
    }

    fn proceed(&mut self) -> Result<bool> {
        if let Some(e) = self.failure.take() {
            return Err(e);
        }
        self.stepped();
        Ok(!self.quit && !self.stop.load(Ordering::Relaxed))
    }

    /// `/clock` as sent and the commands as received (CDR bytes as they were, rejected ones
    /// included), for the recording.
    fn topics(&self) -> Vec<TopicInfo> {
        let topic = |name: &str, type_name, rate_hz, k| TopicInfo {
            name: name.to_string(),
            type_name,
            rate_hz,
            frame_id: String::new(),
            qos: Qos::STREAM,
            kind: TopicKind::Controller(k),
        };
        vec![
            topic("/clock", Clock::TYPE_NAME, Some(self.options.control_rate_hz), CLOCK),
            topic(&self.command_topic, Float64MultiArray::TYPE_NAME, None, COMMANDS),
            topic(&self.trajectory_topic, JointTrajectory::TYPE_NAME, None, TRAJECTORY),
            topic(&self.by_name_topic, JointState::TYPE_NAME, None, BY_NAME),
            topic(twin_core::topics::CMD_VEL_TOPIC, Twist::TYPE_NAME, None, CMD_VEL),
        ]
        .into_iter()
        .chain(self.walker.iter().flat_map(|w| w.topics()).map(|t| TopicInfo {
            kind: match t.kind {
                TopicKind::Controller(k) => TopicKind::Controller(WALKER_TOPICS + k),
                other => other,
            },
            ..t
        }))
        .collect()
    }

    fn diagnostics(&self, emit: &mut dyn FnMut(usize, u64, TypedMessage<'_>)) {
        if let Ok(mut q) = self.exchanged.lock() {
            for m in q.drain(..) {
                emit(m.topic, m.log_time_nanos, TypedMessage::Cdr(&m.cdr));
            }
        }
        if let Some(w) = &self.walker {
            w.diagnostics(&mut |k, t, m| emit(WALKER_TOPICS + k, t, m));
        }
    }
}

impl Drop for LiveController {
    /// A `StepSimulation` cut short by the end of the run still gets its answer.
    fn drop(&mut self) {
        if let Some((k, id, left)) = self.stepping.take() {
            let why = format!("the run ended with {left} steps still to take");
            let _ = self.services.answer(k, &id, state::PAUSED, &Outcome::new(result::OPERATION_FAILED, why));
        }
    }
}

/// Who has joined: for [`crate::external`], which starts a controller process and waits until
/// it has subscribed and published before simulated time starts.
impl LiveController {
    /// The cumulative numbers of subscriptions matched on `/clock`, of publications matched on
    /// the command topic (`Float64MultiArray`) and on the trajectory topic since the bridge
    /// started, as the latest match events say (`None`: no event since the last call). Takes
    /// the writer's and readers' status events.
    pub fn match_totals(&mut self) -> [Option<i32>; 3] {
        use rustdds::StatusEvented;
        let mut out = [None; 3];
        while let Some(status) = self.clock.try_recv_status() {
            if let rustdds::DataWriterStatus::PublicationMatched { total, .. } = status {
                out[0] = Some(total.count());
            }
        }
        for (k, reader) in [&self.commands, &self.trajectories].into_iter().enumerate() {
            while let Some(status) = reader.try_recv_status() {
                if let rustdds::DataReaderStatus::SubscriptionMatched { total, .. } = status {
                    out[k + 1] = Some(total.count());
                }
            }
        }
        out
    }

    /// The position targets of the command in force ([`Commander::position_targets`]).
    pub fn position_targets(&self, emit: &mut dyn FnMut(usize, f64)) {
        self.commander.position_targets(emit);
    }

    /// Says that the caller ([`crate::external`], which starts the controller itself) has waited
    /// for it to join and has held the first control period: lockstep then asks for a command
    /// from the bridge's first period on (no join, no period under hold here).
    pub fn mark_joined(&mut self) {
        if self.started.is_none() {
            self.started = Some((Instant::now(), 0.0));
        }
    }

    /// Publishes `/clock` = `t_secs` outside the lockstep periods (not recorded: a fresh
    /// process gets the same time from the join, unrecorded too): after a reset under a running
    /// controller, so that its sim-time timers start again from there.
    pub fn announce_time(&mut self, t_secs: f64) {
        self.clock_cdr.reset();
        Clock { clock_nanos: (t_secs * 1e9).round().max(0.0) as i64 }.encode(&mut self.clock_cdr);
        self.repeat_time();
    }

    /// Says the last `/clock` again (not recorded again: a node sees the same time, which
    /// fires nothing).
    pub fn repeat_time(&mut self) {
        let _ = self.clock.write(RawCdr(self.clock_cdr.bytes().to_vec()), None);
    }

    /// Drops every command waiting in the readers (a new episode must not start on a command
    /// meant for the last one).
    pub fn discard_pending(&mut self) {
        self.held = None;
        while let Ok(Some(_)) = self.commands.take_next_sample() {}
        while let Ok(Some(_)) = self.trajectories.take_next_sample() {}
        while let Ok(Some(_)) = self.by_name.take_next_sample() {}
    }
}

impl LiveSink {
    /// The cumulative number of subscriptions matched on `topic`'s writer, as its latest match
    /// event says (`None`: no writer for it, or no event since the last call).
    pub fn subscription_total(&mut self, topic: &str) -> Option<i32> {
        use rustdds::StatusEvented;
        let w = self.writers.get(topic)?;
        let mut last = None;
        while let Some(status) = w.try_recv_status() {
            if let rustdds::DataWriterStatus::PublicationMatched { total, .. } = status {
                last = Some(total.count());
            }
        }
        last
    }

    /// Whether the sink has a writer for `topic` (it offered it).
    pub fn publishes(&self, topic: &str) -> bool {
        self.writers.contains_key(topic)
    }
}
