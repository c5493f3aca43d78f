//! The external controller as a [`Controller`] of the rollout engine, and the check that
//! publishes the robot's state to it and gives the verdict on its health.

use super::process::{ControllerProcess, DomainLease, Stopped};
use super::{Interface, Restart, RosOptions};
use crate::live::Loopback;
use crate::live::{self, CommandInterface, LiveController, LiveOptions, LiveSink, Pacing};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use twin_core::control::{Controller, Observation, PdHold, PdHoldOptions};
use twin_core::engine::{Check, Flow, Measurement, Observer, StepView, Verdict};
use twin_core::error::{Error, Result};
use twin_core::mj::{Data, Model};
use twin_core::robot::Robot;
use twin_core::sim::{RecordOptions, Recording};
use twin_core::topics::{Sink, TopicInfo, TypedMessage};

/// How often the join says in the log what it still waits for.
const JOIN_NOTE_EVERY: Duration = Duration::from_secs(1);

/// After discovery saw the node's readers, how long their set must stay the same before the
/// first state goes out (see [`ExternalController::start_process`]).
const JOIN_SETTLE: Duration = Duration::from_millis(150);

/// While the join waits for the node's state readers, how often the episode's start time is
/// said again on `/clock`.
const CLOCK_REPEAT: Duration = Duration::from_millis(100);

/// The bridge's sink, shared by the recordings of successive episodes (its DDS writers stay
/// matched to the process).
struct SharedSink(Arc<Mutex<LiveSink>>);

impl Sink for SharedSink {
    fn add_topic(&mut self, id: usize, topic: &TopicInfo) -> Result<bool> {
        self.0.lock().map_err(|_| poisoned())?.add_topic(id, topic)
    }

    fn write(&mut self, id: usize, topic: &TopicInfo, log_time_nanos: u64, message: &TypedMessage<'_>) -> Result<()> {
        self.0.lock().map_err(|_| poisoned())?.write(id, topic, log_time_nanos, message)
    }
}

fn poisoned() -> Error {
    Error::Live { message: "the live bridge's state was poisoned by a panic on another thread".into() }
}

/// What the controller and its check share: this episode's state publisher and verdict.
#[derive(Default)]
struct Shared {
    /// Publishes the robot's topics (`/joint_states`, IMUs, `/tf`…) to the process.
    recording: Option<Recording>,
    /// Why the controller failed this episode (`<kind>: <details>`).
    failure: Option<String>,
    /// Wall seconds from the process's start to its having joined, this episode.
    join_secs: Option<f64>,
    /// Commands applied this episode.
    commands: u64,
    /// Control periods this episode.
    periods: u64,
    /// Commands this episode that came before their period's `/clock`
    /// ([`live::LiveStats::commands_before_clock`]).
    before_clock: u64,
}

/// A user's ROS 2 node driving the twin (see the [module docs](super)).
pub struct ExternalController {
    options: RosOptions,
    folder: PathBuf,
    log: PathBuf,
    env: Vec<(String, String)>,
    lease: DomainLease,
    _profile_dir: tempfile::TempDir,
    inner: LiveController,
    sink: Arc<Mutex<LiveSink>>,
    robot: Robot,
    shared: Arc<Mutex<Shared>>,
    process: Option<ControllerProcess>,
    hold: PdHold,
    step: u64,
    steps_per_period: u64,
    /// Steps held at the start of every episode: one control period (see
    /// [`ExternalController::compute`]).
    hold_steps: u64,
    /// Episodes started on this controller.
    runs: u64,
    stop: &'static AtomicBool,
    failed: bool,
    time_secs: f64,
    /// Wall seconds spent starting processes and waiting for them to join, and how many.
    startup: (f64, u64),
    /// Wall seconds spent stopping processes.
    stopping_secs: f64,
    /// The bridge's periods, commands applied and commands before `/clock` at this episode's reset.
    stats_at_reset: (u64, u64, u64),
}

/// The health of an external controller as a [`Check`] (named `controller`): it also
/// publishes the robot's state to the process each step. Fails when the process exited, never
/// joined or stopped answering, with that reason as its cause.
pub struct ControllerHealth {
    shared: Arc<Mutex<Shared>>,
    tracking: twin_core::tracking::Tracking,
}

/// An external controller for `robot` as `options` say, its process started in `folder` (the
/// scenario file's) with its output appended to `log`; with the check that publishes the
/// state to it and judges its health. Takes a domain id of its own and joins it; the process
/// starts at the first episode's reset.
///
/// # Errors
/// [`Error::Live`] when the bridge can't start or a `subscribes` topic is not one the robot
/// publishes; [`Error::File`] for the profile or the log.
pub fn external(
    robot: &Robot,
    options: &RosOptions,
    folder: &Path,
    log: &Path,
) -> Result<(ExternalController, ControllerHealth)> {
    options.validate().map_err(|(key, m)| Error::Live { message: format!("[ros] {key} {m}") })?;
    let lease = DomainLease::acquire()?;
    let profile_dir = tempfile::Builder::new()
        .prefix("twin-ros-")
        .tempdir()
        .map_err(|source| Error::io(std::env::temp_dir(), source))?;
    let env = Loopback::write(profile_dir.path(), lease.id())?.environment();
    let live_options = LiveOptions {
        domain_id: lease.id(),
        interface: std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST),
        control_rate_hz: options.control_rate_hz,
        command_interface: match options.command_interface {
            Interface::Position => CommandInterface::Position,
            Interface::Velocity => CommandInterface::Velocity,
            Interface::Effort => CommandInterface::Effort,
        },
        pacing: Pacing::Lockstep,
        silence_timeout_secs: options.period_timeout_secs,
        lockstep_timeout_secs: options.period_timeout_secs,
        join_timeout_secs: options.join_timeout_secs,
        flood_commands_per_period: options.flood_commands_per_period,
        flood_window_secs: options.flood_window_secs,
        ..LiveOptions::default()
    };
    let stop = twin_core::fsio::interrupt_flag();
    let warnings = log.to_path_buf();
    let warn = Box::new(move |m: &str| {
        if let Ok(mut f) = std::fs::File::options().create(true).append(true).open(&warnings) {
            let _ = writeln!(f, "--- twin warning: {m}");
        }
    });
    let (sink, mut inner) = live::start(robot, &live_options, stop, warn)?;
    // The topics it said it reads, and the joint states every controller reads.
    let mut reads = options.subscribes.clone();
    if !reads.iter().any(|t| t == "/joint_states") {
        reads.push("/joint_states".into());
    }
    inner.set_reads(reads);
    // The process's join and the first period's hold are done here, per episode.
    inner.mark_joined();
    let shared = Arc::new(Mutex::new(Shared::default()));
    let controller = ExternalController {
        options: options.clone(),
        folder: folder.to_path_buf(),
        log: log.to_path_buf(),
        env,
        lease,
        _profile_dir: profile_dir,
        steps_per_period: inner.steps_per_period(),
        inner,
        sink: Arc::new(Mutex::new(sink)),
        robot: robot.clone(),
        shared: shared.clone(),
        process: None,
        hold: PdHold::new(&robot.model, PdHoldOptions::default()),
        step: 0,
        hold_steps: 0,
        runs: 0,
        stop,
        failed: false,
        time_secs: 0.0,
        startup: (0.0, 0),
        stopping_secs: 0.0,
        stats_at_reset: (0, 0, 0),
    };
    // The state publisher now, so that its writers exist for the process to match.
    controller.new_recording()?;
    {
        let sink = controller.sink.lock().map_err(|_| poisoned())?;
        if let Some(t) = options.subscribes.iter().find(|t| !sink.publishes(t)) {
            return Err(Error::Live {
                message: format!(
                    "[ros] subscribes: twin publishes no topic {t} for {}; its topics: `twin sim --ros` prints them",
                    robot.name
                ),
            });
        }
    }
    Ok((controller, ControllerHealth { shared, tracking: twin_core::tracking::Tracking::new() }))
}

impl ExternalController {
    /// The DDS domain id of this controller's process.
    pub fn domain_id(&self) -> u16 {
        self.lease.id()
    }

    /// The log the process's output goes to.
    pub fn log(&self) -> &Path {
        &self.log
    }

    /// The live bridge's statistics (all episodes so far).
    pub fn live_stats(&self) -> &live::LiveStats {
        self.inner.stats()
    }

    /// Wall seconds spent starting processes until they joined (all episodes), and how many
    /// were started.
    pub fn startup(&self) -> (f64, u64) {
        self.startup
    }

    /// A fresh state publisher for an episode (its topics' schedules start at t = 0). Every
    /// state topic (joint states, IMUs, odometry, contacts, `/tf`) goes out at most once per
    /// control period, as with `twin sim --ros --lockstep`: a node's executor (rclpy, rclcpp)
    /// takes one message of a subscription per turn, so with several queued per period a timer
    /// fires between them and reads whichever it had taken by then: the runs of the same seed
    /// differed so (five `/joint_states` per 10 ms period at 500 Hz; two IMU samples at 200 Hz).
    /// An IMU slower than the control rate keeps its rate.
    fn new_recording(&self) -> Result<()> {
        let mut robot = self.robot.clone();
        for imu in &mut robot.imus {
            let rate = imu.meta.update_rate_hz.unwrap_or(self.options.control_rate_hz);
            imu.meta.update_rate_hz = Some(rate.min(self.options.control_rate_hz));
        }
        let options = RecordOptions {
            command_topic: Some(live::actuator_topic(&self.robot)),
            controller_topics: self.inner.topics().into_iter().map(|t| t.name).collect(),
            state_rate_hz: self.options.control_rate_hz,
            tf_rate_hz: self.options.control_rate_hz,
            ..RecordOptions::default()
        };
        let recording = Recording::with_sinks(&robot, &options, vec![Box::new(SharedSink(self.sink.clone()))])?;
        self.shared.lock().map_err(|_| poisoned())?.recording = Some(recording);
        Ok(())
    }

    fn note(&self, line: &str) {
        if let Ok(mut f) = std::fs::File::options().create(true).append(true).open(&self.log) {
            let _ = writeln!(f, "--- twin: {line}");
        }
    }

    fn fail(&mut self, why: String) {
        self.failed = true;
        self.note(&format!("episode failed: {why}"));
        if let Ok(mut s) = self.shared.lock() {
            s.failure.get_or_insert(why);
        }
    }

    fn stop_process(&mut self) {
        if let Some(mut p) = self.process.take() {
            let t = Instant::now();
            let how = p.stop(Duration::from_secs_f64(self.options.stop_timeout_secs));
            self.stopping_secs += t.elapsed().as_secs_f64();
            let how = match how {
                Stopped::Exited(status) => format!("it had exited ({status})"),
                Stopped::BySignal(s) => format!("it ended after {s}"),
            };
            self.note(&format!("stopped pid {}: {how}", p.pid()));
        }
    }

    /// Starts the process and waits, bounded, until it has joined, in two phases, each
    /// against the DDS discovery database ([`crate::live::LiveController::readers_of`], not
    /// match events, which rustdds 0.15 drops; only endpoints discovery had not seen before the
    /// process started count):
    /// 1. a reader of `/clock` and a writer of a command topic;
    /// 2. then `/clock` = `start_secs` (the episode's start, acknowledged by the `/clock`
    ///    readers: a timer fires nothing on it, time does not advance) and a reader of each
    ///    `subscribes` topic. A node that subscribes to its state in its first `/clock` callback
    ///    does so now, before time starts, like one that subscribed at its start.
    ///
    /// Then the set of its readers of twin's state topics must not change for `JOIN_SETTLE`
    /// (an IMU reader made a moment after the one waited for). It notes in the log which topics
    /// it still waits for, once a second. A failure is the episode's.
    fn start_process(&mut self, start_secs: f64) -> Result<()> {
        let started = Instant::now();
        let note = format!("run {} on domain {}", self.runs, self.lease.id());
        let subscribes: Vec<String> = self.options.subscribes.iter().filter(|t| *t != "/clock").cloned().collect();
        let commands: Vec<String> = self.inner.command_topics().iter().map(|t| t.to_string()).collect();
        // Endpoints of an earlier process may stay in the discovery database until its leave
        // is heard: only new ones count.
        let before: Vec<_> = std::iter::once("/clock")
            .chain(subscribes.iter().map(String::as_str))
            .flat_map(|t| self.inner.readers_of(t))
            .chain(commands.iter().flat_map(|t| self.inner.writers_of(t)))
            .collect();
        let mut process = ControllerProcess::start(&self.options.command, &self.folder, &self.env, &self.log, &note)?;
        let mut outcome = self.wait_for(&mut process, started, &before, &["/clock".to_string()], &commands, false);
        if outcome.is_none() {
            self.inner.announce_time_delivered(start_secs, Duration::from_secs(1));
            outcome = self.wait_for(&mut process, started, &before, &subscribes, &[], true);
        }
        if outcome.is_none() {
            // The node creates its other readers (an IMU's) about when those waited for, and
            // each one's own side matches twin's writer when twin's announcement of it reaches
            // the node: wait until the set of its readers of twin's state topics has not changed
            // for JOIN_SETTLE before the first state goes out (a reader that appears later gets
            // the first state again, [`crate::live::outbox`]).
            let join = Duration::from_secs_f64(self.options.join_timeout_secs);
            let mut readers = self.inner.state_readers();
            let mut stable = Instant::now();
            while stable.elapsed() < JOIN_SETTLE && started.elapsed() < join {
                std::thread::sleep(Duration::from_millis(5));
                let now = self.inner.state_readers();
                if now != readers {
                    readers = now;
                    stable = Instant::now();
                }
            }
            // The start time once more, acknowledged, just before the first state: a /clock
            // reader that discovery had listed but that matched twin's writer only after the
            // sayings above (load) has it before the first state (a node that answers states
            // once it has seen a /clock lost 1 of 200 episodes without this).
            self.inner.announce_time_delivered(start_secs, Duration::from_secs(1));
        }
        self.process = Some(process);
        self.startup.0 += started.elapsed().as_secs_f64();
        self.startup.1 += 1;
        if let Ok(mut s) = self.shared.lock() {
            s.join_secs = Some(started.elapsed().as_secs_f64());
        }
        if let Some(why) = outcome {
            self.fail(why);
        }
        Ok(())
    }

    /// Waits, bounded by `join_timeout_secs` from `started`, until discovery has a reader of each
    /// of `readers` and (when `writers` is not empty) a writer of one of `writers` that are not
    /// in `before`; `None` when it has, else why not (the episode's failure). With `say_time`,
    /// the last `/clock` is said again every [`CLOCK_REPEAT`] meanwhile (a `/clock` reader that
    /// discovery had seen may have matched twin's writer only after the first saying).
    fn wait_for(
        &mut self,
        process: &mut ControllerProcess,
        started: Instant,
        before: &[crate::live::dds::SeenEndpoint],
        readers: &[String],
        writers: &[String],
        say_time: bool,
    ) -> Option<String> {
        let join = Duration::from_secs_f64(self.options.join_timeout_secs);
        let mut said = Instant::now();
        let mut time_said = Instant::now();
        loop {
            if say_time && time_said.elapsed() >= CLOCK_REPEAT {
                self.inner.repeat_time();
                time_said = Instant::now();
            }
            let fresh = |seen: Vec<crate::live::dds::SeenEndpoint>| seen.iter().any(|e| !before.contains(e));
            let missing: Vec<&str> =
                readers.iter().filter(|t| !fresh(self.inner.readers_of(t))).map(String::as_str).collect();
            let publishing = writers.is_empty() || writers.iter().any(|t| fresh(self.inner.writers_of(t)));
            self.inner.watch_readers();
            if publishing && missing.is_empty() {
                return None;
            }
            if let Some(status) = process.exited() {
                return Some(format!(
                    "exited before joining: {status}, before it joined the graph (see {})",
                    self.log.display()
                ));
            }
            if self.stop.load(Ordering::Relaxed) {
                return Some("interrupted: stopped by Ctrl-C while it was joining".into());
            }
            let lacks = || {
                let mut lacks = Vec::new();
                if missing.contains(&"/clock") {
                    lacks.push("subscribed to /clock (is use_sim_time set?)".to_string());
                }
                let others: Vec<&str> = missing.iter().copied().filter(|t| *t != "/clock").collect();
                if !others.is_empty() {
                    lacks.push(format!("subscribed to {}", others.join(", ")));
                }
                if !publishing {
                    lacks.push(format!(
                        "published on {} or /{}/joint_trajectory",
                        live::command_topic(&self.robot),
                        self.robot.name
                    ));
                }
                lacks.join(", nor ")
            };
            if started.elapsed() >= join {
                return Some(format!(
                    "never joined: within {} s (join_timeout_secs) on domain {} it had not {} (see {})",
                    self.options.join_timeout_secs,
                    self.lease.id(),
                    lacks(),
                    self.log.display()
                ));
            }
            if said.elapsed() >= JOIN_NOTE_EVERY {
                said = Instant::now();
                self.note(&format!(
                    "join: {:.1} s after the start, waiting for the process to have {}",
                    started.elapsed().as_secs_f64(),
                    lacks()
                ));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Says `t_secs` (the episode's start) on `/clock` after a reset under a kept process (a
    /// jump back in time), and again every 10 ms for `reset_settle_secs` of wall time before
    /// the episode starts and the first lockstep period says the next time. ROS nodes subscribe to `/clock` keeping only the latest message
    /// (depth 1): had the next time come while the node was still busy with the last
    /// episode's messages, it would have replaced the jump, the node's timer would have taken
    /// *it* for the jump (rcl: fire one period after a backward jump) and skipped the period
    /// twin waits a command for. Said again, the same time changes nothing for the node. Wall
    /// time only: the simulation does not move meanwhile, so the run stays deterministic.
    fn announce_jump(&mut self, t_secs: f64) {
        let until = Instant::now() + Duration::from_secs_f64(self.options.reset_settle_secs);
        self.inner.announce_time(t_secs);
        loop {
            std::thread::sleep(Duration::from_millis(10).min(until.saturating_duration_since(Instant::now())));
            self.inner.repeat_time();
            let now = Instant::now();
            if now >= until || self.stop.load(Ordering::Relaxed) {
                break;
            }
        }
    }

    /// Why a period had no command (the bridge's error `e`), naming what twin sent the node
    /// before that period's `/clock` and whether its readers were there for it, before blaming
    /// the process.
    fn no_command(&self, e: &Error) -> String {
        let message = e.to_string();
        if message.contains("not acknowledged") {
            return format!("state not delivered: {message} (see {})", self.log.display());
        }
        let (sent, missed) = self.inner.missing_command().cloned().unwrap_or_default();
        let blame = if missed.is_empty() {
            "every reader it had of them was there and acknowledged it: the process hangs, stopped publishing or \
             waits for something else"
                .to_string()
        } else {
            format!(
                "the node never received the last {} (no reader of it was there when it went out, or it did not \
                 acknowledge): a join that missed its readers, not necessarily the process",
                missed.join(", ")
            )
        };
        format!(
            "no command: none within {} s (period_timeout_secs) after /clock = {:.3} s; twin had sent {sent}; {blame} \
             (see {})",
            self.options.period_timeout_secs,
            self.time_secs,
            self.log.display()
        )
    }

    /// Why the process can't go on, if it has exited.
    fn exit_reason(&mut self) -> Option<String> {
        let status = self.process.as_mut()?.exited()?;
        Some(format!("exited: {status} at t = {:.3} s (see {})", self.time_secs, self.log.display()))
    }
}

impl Controller for ExternalController {
    fn name(&self) -> &'static str {
        "ros"
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        self.runs += 1;
        self.failed = false;
        self.step = 0;
        self.time_secs = observation.time_secs;
        {
            let mut s = self.shared.lock().map_err(|_| poisoned())?;
            s.failure = None;
            s.join_secs = None;
        }
        self.hold.reset(model, observation)?;
        let alive = self.process.as_mut().is_some_and(|p| p.exited().is_none());
        let fresh = self.options.restart == Restart::Episode || !alive;
        if fresh {
            self.stop_process();
        }
        self.inner.discard_pending();
        self.inner.reset(model, observation)?;
        self.inner.begin_run(!fresh);
        if self.runs > 1 {
            self.new_recording()?;
        }
        let stats = self.inner.stats();
        self.stats_at_reset = (stats.periods, stats.commands_applied, stats.commands_before_clock);
        self.hold_steps = self.steps_per_period;
        if fresh {
            // The episode's start time goes out on /clock during the join (unrecorded, as under
            // a kept process): a node that answers states once it has seen a /clock answers the
            // first one too, one that subscribes on it has by the time the first state goes out.
            self.start_process(observation.time_secs)?;
        } else {
            self.note(&format!("run {}: the same process, the simulation reset under it", self.runs));
            self.announce_jump(observation.time_secs);
        }
        Ok(())
    }

    /// The first control period holds the start pose while the state goes out; then the
    /// process commands, one command per period. A kept process (`restart = "never"`) was
    /// told the episode's start time at the reset, alone for `reset_settle_secs`
    /// ([`ExternalController::announce_jump`]): its sim-time timers saw time jump back (rcl
    /// then fires them one period after the jump), so they fire at the first lockstep period
    /// as a fresh process's do, and every episode runs the same periods whichever process it
    /// got (the same `episodes.csv` whatever the thread count).
    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        self.time_secs = observation.time_secs;
        if self.failed || self.step < self.hold_steps {
            self.hold.compute(model, observation, command);
            self.step += 1;
            return;
        }
        if (self.step - self.hold_steps).is_multiple_of(self.steps_per_period)
            && let Some(why) = self.exit_reason()
        {
            self.fail(why);
            self.hold.compute(model, observation, command);
            return;
        }
        self.inner.compute(model, observation, command);
        self.step += 1;
    }

    fn proceed(&mut self) -> Result<bool> {
        let go = if self.failed {
            false
        } else {
            match self.inner.proceed() {
                Ok(go) => go,
                Err(e) => {
                    let flood = self.inner.flood().map(|f| format!("flood: {f}"));
                    let why = flood.or_else(|| self.exit_reason()).unwrap_or_else(|| self.no_command(&e));
                    self.fail(why);
                    false
                }
            }
        };
        if let Ok(mut s) = self.shared.lock() {
            let stats = self.inner.stats();
            s.periods = stats.periods - self.stats_at_reset.0;
            s.commands = stats.commands_applied - self.stats_at_reset.1;
            s.before_clock = stats.commands_before_clock - self.stats_at_reset.2;
        }
        Ok(go)
    }

    fn report(&self) -> Vec<String> {
        let s = self.inner.stats();
        let mut lines = vec![format!(
            "external controller `{}`: domain {}, {} process start(s) ({:.3} s to join on average), \
             {} control periods, {} commands applied, {} rejected; its output: {}",
            self.options.command,
            self.lease.id(),
            self.startup.1,
            self.startup.0 / self.startup.1.max(1) as f64,
            s.periods,
            s.commands_applied,
            s.commands_rejected,
            self.log.display()
        )];
        if let (Some(p50), Some(p99)) =
            (live::percentile(&s.round_trip_micros, 50.0), live::percentile(&s.round_trip_micros, 99.0))
        {
            lines.push(format!("lockstep round trip (/clock out to command in): p50 {p50:.0} µs, p99 {p99:.0} µs"));
        }
        if let Ok(sh) = self.shared.lock()
            && let Some(f) = &sh.failure
        {
            lines.push(format!("controller failed: {f}"));
        }
        lines
    }

    fn topics(&self) -> Vec<TopicInfo> {
        self.inner.topics()
    }

    fn diagnostics(&self, emit: &mut dyn FnMut(usize, u64, TypedMessage<'_>)) {
        self.inner.diagnostics(emit);
    }

    fn position_targets(&self, emit: &mut dyn FnMut(usize, f64)) {
        if self.failed || self.step <= self.hold_steps {
            self.hold.position_targets(emit);
        } else {
            self.inner.position_targets(emit);
        }
    }
}

impl Drop for ExternalController {
    /// Never leaves the process behind.
    fn drop(&mut self) {
        self.stop_process();
    }
}

impl Observer for ControllerHealth {
    fn start(&mut self, model: &Model, data: &Data) -> Result<()> {
        self.tracking.start(model, data)?;
        let mut s = self.shared.lock().map_err(|_| poisoned())?;
        match s.recording.as_mut() {
            Some(r) => r.start(model, data),
            None => Ok(()),
        }
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        self.tracking.observe(step)?;
        let mut s = self.shared.lock().map_err(|_| poisoned())?;
        if let Some(r) = s.recording.as_mut() {
            r.record(step)?;
        }
        Ok(Flow::Continue)
    }
}

impl Check for ControllerHealth {
    fn name(&self) -> &str {
        "controller"
    }

    fn verdict(&self) -> Verdict {
        let tracking = self.tracking.summary();
        let (failure, join, periods, commands, before_clock) = match self.shared.lock() {
            Ok(s) => (s.failure.clone(), s.join_secs.unwrap_or(0.0), s.periods, s.commands, s.before_clock),
            Err(_) => (Some("internal: poisoned".into()), 0.0, 0, 0, 0),
        };
        Verdict {
            name: "controller".into(),
            passed: failure.is_none(),
            metrics: [
                Measurement::new("commands", commands as f64, ""),
                Measurement::new("periods", periods as f64, ""),
                // Commands per simulated second.
                Measurement::new("command_rate", commands as f64 / tracking.sim_secs.max(1e-12), "Hz"),
            ]
            .into_iter()
            .chain(tracking.measurements())
            .collect(),
            details: vec![format!("joined in {join:.3} s wall"), pattern(commands, before_clock), tracking.to_string()],
            cause: failure,
        }
    }
}

/// What the command timing says of the node's pattern, and what would make that pattern's
/// output depend on more than the states twin sent (quoted when a run differs when run again).
fn pattern(commands: u64, before_clock: u64) -> String {
    if commands == 0 {
        return "no command: nothing to say of how the node computes".into();
    }
    if before_clock * 2 > commands {
        format!(
            "{before_clock} of {commands} commands came before their period's /clock: the node answers a state message \
             in its subscription callback (runs differ when what it uses of its other topics, the IMU or another state \
             topic, depends on which callback its executor ran first, or when it uses the wall clock: compute from \
             the answered message alone, or on /clock with a timer on simulation time reading the latest of each topic)"
        )
    } else {
        format!(
            "{} of {commands} commands came after their period's /clock: the node computes on /clock, a timer on \
             simulation time (twin delivers a period's states before its /clock; runs differ when the node's callbacks \
             run at the same time, a MultiThreadedExecutor with a ReentrantCallbackGroup, and the timer reads a state \
             being taken: use a SingleThreadedExecutor or one MutuallyExclusiveCallbackGroup; or when it uses the \
             wall clock, time.time() or a timer not on simulation time)",
            commands - before_clock
        )
    }
}
