//! Running a twin under a controller (`twin sim`) and recording what it does: ROS 2 MCAP
//! topics and rerun recordings, all stamped in simulation time ([`record`]).
//!
//! ```no_run
//! use twin_core::control::{Controller, PdHold, PdHoldOptions};
//! use twin_core::sim::{self, RecordOptions, Recording, SimOptions};
//!
//! let robot = twin_core::robot::Robot::load("models/humanoid.urdf")?;
//! let mut controller = PdHold::new(&robot.model, PdHoldOptions::default());
//! let options = RecordOptions { mcap: Some("run.mcap".into()), ..RecordOptions::default() };
//! let mut recording = Recording::new(&robot, &options)?;
//! let report = sim::simulate(&robot, &mut controller, &SimOptions::default(), Some(&mut recording), &mut |_| {})?;
//! let summary = recording.finish()?;
//! println!("{} steps, {} messages", report.steps, summary.messages());
//! # Ok::<(), twin_core::Error>(())
//! ```

pub mod record;

#[cfg(feature = "rerun")]
pub use record::RerunSink;
pub use record::{McapSink, RecordOptions, RecordSummary, Recording, SensorCost};

pub use crate::robot::Robot;

use crate::control::Controller;
use crate::engine::{Disturbance, Engine, Episode, Flow, Observer, StepView, observers::Divergence};
use crate::error::{Error, Result};
use crate::mj::Model;
use rand::SeedableRng;

/// How long and how to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Simulated time, seconds (default: 5.0).
    pub duration_secs: f64,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions { duration_secs: 5.0 }
    }
}

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct SimReport {
    /// Steps taken.
    pub steps: u64,
    /// Simulated time, seconds.
    pub sim_secs: f64,
    /// Wall time of the stepping loop (recording included), seconds.
    pub wall_secs: f64,
    /// Wall time spent inside [`Recording::record`], seconds.
    pub record_secs: f64,
    /// CPU time of the simulating thread during the loop, seconds (Linux; `None` elsewhere):
    /// unlike wall time, not inflated by waiting for a core on a busy machine, and without the
    /// MCAP writer thread's work.
    pub loop_cpu_secs: Option<f64>,
}

/// CPU time of the calling thread, seconds, from `/proc/thread-self/schedstat` (Linux).
fn thread_cpu_secs() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let nanos: u64 = text.split_whitespace().next()?.parse().ok()?;
    Some(nanos as f64 * 1e-9)
}

impl SimReport {
    /// Simulated seconds per wall second.
    pub fn real_time_factor(&self) -> f64 {
        if self.wall_secs > 0.0 { self.sim_secs / self.wall_secs } else { f64::INFINITY }
    }
}

/// Number of steps for `duration_secs` at the model's timestep (at least one).
pub fn steps_for(model: &Model, duration_secs: f64) -> u64 {
    ((duration_secs / model.timestep_secs()).round() as u64).max(1)
}

/// Times the recording inside the loop and reports progress: the sim's own observer.
struct Timing<'a> {
    recording: Option<&'a mut Recording>,
    record_secs: f64,
    report_every: u64,
    steps: u64,
    progress: &'a mut dyn FnMut(f64),
}

impl Observer for Timing<'_> {
    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        if let Some(rec) = self.recording.as_deref_mut() {
            let t = std::time::Instant::now();
            let flow = rec.observe(step)?;
            self.record_secs += t.elapsed().as_secs_f64();
            if flow != Flow::Continue {
                return Ok(flow);
            }
        }
        if step.index.is_multiple_of(self.report_every) {
            (self.progress)(step.index as f64 / self.steps as f64);
        }
        Ok(Flow::Continue)
    }
}

/// Runs `controller` on `robot` from its home pose ([`crate::control::reset_to_home`]) for
/// `options.duration_secs` on the rollout engine ([`crate::engine`]), recording into
/// `recording` when given. `progress` is called with the fraction done now and then.
///
/// The recording gets, per step, the state at the step's start time t (positions,
/// velocities, the command) with the body poses, sensors, contacts and actuator forces of the
/// same instant, so every message stamped t describes one instant.
///
/// # Errors
/// [`Error::MuJoCo`] if MuJoCo raises or the simulation diverges; [`Error::Trajectory`] and
/// others from the controller's reset; recording errors.
pub fn simulate(
    robot: &Robot,
    controller: &mut dyn Controller,
    options: &SimOptions,
    recording: Option<&mut Recording>,
    progress: &mut dyn FnMut(f64),
) -> Result<SimReport> {
    simulate_with(robot, controller, options, recording, progress, &mut [], &mut [])
}

/// [`simulate`] with extra `disturbances` (e.g. a scenario's pushes) and `observers` (e.g.
/// gait metrics, checks), which see every step after the divergence check and the recording.
///
/// # Errors
/// As [`simulate`]; errors of the disturbances and observers.
pub fn simulate_with(
    robot: &Robot,
    controller: &mut dyn Controller,
    options: &SimOptions,
    recording: Option<&mut Recording>,
    progress: &mut dyn FnMut(f64),
    disturbances: &mut [&mut dyn Disturbance],
    observers: &mut [&mut dyn Observer],
) -> Result<SimReport> {
    let model = &robot.model;
    let steps = steps_for(model, options.duration_secs);
    let episode = Episode { steps, ..Episode::default() };
    let mut divergence = Divergence::default();
    let mut timing = Timing { recording, record_secs: 0.0, report_every: (steps / 100).max(1), steps, progress };
    // No sensor noise or random disturbances here: the stream is not drawn from.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let cpu_started = thread_cpu_secs();
    let started = std::time::Instant::now();
    let mut all: Vec<&mut dyn Observer> = vec![&mut divergence, &mut timing];
    all.extend(observers.iter_mut().map(|o| &mut **o as &mut dyn Observer));
    let outcome = Engine::new().run(model, &episode, controller, disturbances, &mut all, &mut rng)?;
    drop(all);
    let wall_secs = started.elapsed().as_secs_f64();
    let loop_cpu_secs = cpu_started.zip(thread_cpu_secs()).map(|(a, b)| b - a);
    if let Some(e) = outcome.physics_error {
        return Err(e);
    }
    if let (Some(reason), Some(t)) = (&divergence.reason, divergence.time_secs) {
        return Err(Error::MuJoCo {
            call: "mj_step",
            message: format!("the simulation diverged at t = {t:.3} s: {reason}"),
        });
    }
    (timing.progress)(1.0);
    Ok(SimReport {
        steps: outcome.steps,
        sim_secs: outcome.sim_secs,
        wall_secs,
        record_secs: timing.record_secs,
        loop_cpu_secs,
    })
}
