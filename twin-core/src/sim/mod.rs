//! Running a twin under a controller (`twin sim`) and recording what it does: ROS 2 MCAP
//! topics and rerun recordings, all stamped in simulation time ([`record`]).
//!
//! [`simulate_with`] runs the one rollout engine ([`crate::engine`]) with the robot's sensor
//! model ([`sensor_model`]: its sensors' white noise and its IMUs' bias processes) seeded by
//! [`SimOptions::seed`]; the recorder writes the observation the controller received, so what
//! is recorded or published live is what the controller saw.
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
use crate::engine::{Disturbance, Engine, Episode, Flow, Observer, SensorModel, StepView, observers::Divergence};
use crate::error::{Error, Result};
use crate::mj::Model;
use rand::SeedableRng;

/// How long and how to simulate.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct SimOptions {
    /// Simulated time, seconds (default: 5.0).
    #[default(5.0)]
    pub duration_secs: f64,
    /// Seed of the run's one random stream: sensor noise and biases, random disturbances
    /// (default: 0).
    pub seed: u64,
}

/// The sensor model of `robot` as its files describe it: the white noise of each sensor
/// (MuJoCo's `noise`, which the URDF converter sets from the Gazebo `<noise>` tags of an IMU)
/// on its `sensordata` entries, and each IMU's gyroscope and accelerometer bias processes
/// (turn-on, Gauss–Markov, random walk) on its axes. No latency, no encoder noise.
pub fn sensor_model(robot: &Robot) -> SensorModel {
    let model = &robot.model;
    let mut sensor_noise_std = vec![0.0; model.nsensordata()];
    for (s, &noise) in model.sensor_noise().iter().enumerate() {
        let adr = model.sensor_adr()[s] as usize;
        for k in 0..model.sensor_dim()[s] as usize {
            sensor_noise_std[adr + k] = noise;
        }
    }
    let mut bias_processes = Vec::new();
    for imu in &robot.imus {
        bias_processes.extend((0..3).map(|axis| (imu.gyro_adr + axis, imu.meta.gyro_bias)));
        bias_processes.extend((0..3).map(|axis| (imu.accel_adr + axis, imu.meta.accel_bias)));
    }
    SensorModel { sensor_noise_std, bias_processes, ..SensorModel::default() }
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
    let episode = Episode { steps, sensors: sensor_model(robot), ..Episode::default() };
    let mut divergence = Divergence::default();
    let mut timing = Timing { recording, record_secs: 0.0, report_every: (steps / 100).max(1), steps, progress };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
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
        return Err(Error::Mj(twin_mj::Error::MuJoCo {
            call: "mj_step",
            message: format!("the simulation diverged at t = {t:.3} s: {reason}"),
        }));
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{Observation, PdHold, PdHoldOptions};
    use crate::log::{Imu, JointState, Log, ReadOptions};

    /// An observation as kept: qpos, qvel, sensordata.
    type Seen = (Vec<f64>, Vec<f64>, Vec<f64>);

    /// pd-hold that keeps every observation it is given, by time (ns).
    struct Watching {
        hold: PdHold,
        seen: std::collections::HashMap<u64, Seen>,
    }

    impl Controller for Watching {
        fn name(&self) -> &'static str {
            "watching"
        }
        fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
            self.hold.reset(model, observation)
        }
        fn compute(&mut self, model: &Model, o: &Observation<'_>, command: &mut [f64]) {
            let t = (o.time_secs * 1e9).round() as u64;
            self.seen.insert(t, (o.qpos.to_vec(), o.qvel.to_vec(), o.sensordata.to_vec()));
            self.hold.compute(model, o, command);
        }
    }

    fn read<T: crate::log::RosMessage>(path: &std::path::Path, topic: &str) -> Vec<(u64, T)> {
        Log::open(path, ReadOptions { strict: true }).unwrap().read_typed::<T>(topic).unwrap().0
    }

    /// Runs the humanoid (its IMU has white noise) under [`Watching`] for 0.2 s with `seed`,
    /// recording; returns what the controller saw and the recorded /joint_states and IMU.
    #[allow(clippy::type_complexity)]
    fn observed_and_recorded(seed: u64) -> (Robot, Watching, Vec<(u64, JointState)>, Vec<(u64, Imu)>) {
        let robot = Robot::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mcap = dir.path().join("run.mcap");
        let options = RecordOptions { mcap: Some(mcap.clone()), ..RecordOptions::default() };
        let mut recording = Recording::new(&robot, &options).unwrap();
        let mut watching =
            Watching { hold: PdHold::new(&robot.model, PdHoldOptions::default()), seen: Default::default() };
        let sim = SimOptions { duration_secs: 0.2, seed };
        simulate(&robot, &mut watching, &sim, Some(&mut recording), &mut |_| {}).unwrap();
        recording.finish().unwrap();
        let imu_topic = robot.imus[0].topic().to_string();
        let (js, imu) = (read::<JointState>(&mcap, "/joint_states"), read::<Imu>(&mcap, &imu_topic));
        (robot, watching, js, imu)
    }

    #[test]
    fn recorded_joint_states_and_imu_are_the_controllers_observation_bit_for_bit() {
        let (robot, watching, js, imu) = observed_and_recorded(1);
        let model = &robot.model;
        assert_eq!(js.len(), 100);
        assert_eq!(imu.len(), 40);
        for (t, m) in &js {
            let (qpos, qvel, _) = &watching.seen[t];
            for (k, name) in m.name.iter().enumerate() {
                let j = model.id(crate::mj::ObjType::Joint, name).unwrap();
                let (adr, dof) = (model.jnt_qposadr()[j] as usize, model.jnt_dofadr()[j] as usize);
                assert_eq!(m.position[k].to_bits(), qpos[adr].to_bits(), "{name} at {t} ns");
                assert_eq!(m.velocity[k].to_bits(), qvel[dof].to_bits(), "{name} at {t} ns");
            }
        }
        let i = &robot.imus[0];
        assert!(i.meta.gyro_noise_std > 0.0 && i.meta.accel_noise_std > 0.0, "the humanoid's IMU is noisy");
        let mut noise = 0.0f64;
        for (t, m) in &imu {
            let (_, _, s) = &watching.seen[t];
            for a in 0..3 {
                assert_eq!(m.angular_velocity[a].to_bits(), s[i.gyro_adr + a].to_bits(), "gyro {a} at {t} ns");
                assert_eq!(m.linear_acceleration[a].to_bits(), s[i.accel_adr + a].to_bits(), "accel {a} at {t} ns");
            }
            let q = i.quat_adr.unwrap();
            assert_eq!(m.orientation_xyzw, [s[q + 1], s[q + 2], s[q + 3], s[q]]);
            noise = noise.max(m.angular_velocity[0].abs());
        }
        // The observation is noisy (the robot stands still: the gyro reads noise alone).
        assert!(noise > 1e-4, "largest gyro x reading {noise} rad/s");

        // Another seed, other noise; the seed is the whole story: the same seed, the same run.
        let (_, _, _, imu2) = observed_and_recorded(2);
        assert!(imu.iter().zip(&imu2).any(|(a, b)| a.1.angular_velocity != b.1.angular_velocity));
        let (_, _, js1, imu1) = observed_and_recorded(1);
        assert!(js1 == js && imu1 == imu);
    }

    #[test]
    fn the_engine_draws_imu_bias_processes_once_and_advances_them() {
        let robot = Robot::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap();
        let mut sensors = sensor_model(&robot);
        // A turn-on bias of 0.1 rad/s (sign drawn) on each gyro axis, nothing dynamic: every
        // gyro reading is the true rate + ±0.1 + white noise.
        for (_, b) in sensors.bias_processes.iter_mut().take(3) {
            b.mean = 0.1;
        }
        let steps = 50;
        let episode = Episode { steps, sensors, ..Episode::default() };
        let mut watching =
            Watching { hold: PdHold::new(&robot.model, PdHoldOptions::default()), seen: Default::default() };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        Engine::new().run(&robot.model, &episode, &mut watching, &mut [], &mut [], &mut rng).unwrap();
        let gyro = robot.imus[0].gyro_adr;
        let sigma = robot.imus[0].meta.gyro_noise_std;
        let mean: Vec<f64> = (0..3)
            .map(|a| watching.seen.values().map(|(_, _, s)| s[gyro + a]).sum::<f64>() / watching.seen.len() as f64)
            .collect();
        for m in mean {
            // ±0.1, within 5 σ/√n of it (the robot barely moves under pd-hold).
            assert!((m.abs() - 0.1).abs() < 5.0 * sigma / (steps as f64).sqrt() + 0.01, "mean gyro {m}");
        }
    }
}
