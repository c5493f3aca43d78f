//! The one rollout engine: every simulation twin runs (`twin sim`, each `twin randomize`
//! episode, `twin check`'s steps) is a configuration of [`Engine::run`].
//!
//! Each step runs the same fixed phases:
//!
//! 1. **sensors**: the observation the controller gets: the state and `sensordata` of this
//!    instant (`mj_step1` computes positions, velocities and position/velocity sensors before
//!    the controller runs, so an IMU's orientation and rate match `qpos`), corrupted by the
//!    [`SensorModel`] (white noise, constant bias, bias processes) and delayed by its latency
//!    (a ring of past observations). Acceleration-stage sensors (accelerometers, force sensors)
//!    hold the previous step's values. Models on the RK4 integrator, which can't be split,
//!    step with `mj_step` and their controllers see all sensors one step old. This is twin's
//!    one sensor model: observers get the same observation ([`StepView::observation`]), so a
//!    recording, the live bridge and every sink publish exactly what the controller received;
//! 2. **controller**: [`Controller::compute`] writes the command, which is scaled
//!    ([`Episode::command_scale`]), checked for saturation and applied ([`Actuation::apply`]);
//! 3. **disturbances**: each [`Disturbance`] acts on the state (pushes, pinned bases);
//! 4. **physics**: the rest of the step (`mj_step2`; `mj_step` on RK4);
//! 5. **observers**: each [`Observer`] sees the step ([`StepView`]) in order and may end the
//!    rollout ([`Flow`]). Fall and divergence detection, metrics ([`Metric`]), verdicts
//!    ([`Check`]) and recorders are observers;
//! 6. **controller's say**: [`Controller::proceed`] may end the rollout (a live bridge told to
//!    stop) or abort it with an error (a lockstep peer that stopped answering).
//!
//! Random numbers (sensor noise and biases, disturbances) come from one stream given to
//! [`Engine::run`], drawn in this fixed order (at the start: each bias process's turn-on and
//! initial values; per step: the bias processes' drives, then each noisy entry's white noise in
//! entry order, `qpos` before `sensordata`, then the disturbances), so a rollout is a pure
//! function of its inputs and seed.
//!
//! ```no_run
//! use std::sync::Arc;
//! use rand::SeedableRng;
//! use twin_core::control::{PdHold, PdHoldOptions};
//! use twin_core::engine::{Engine, Episode, observers::Divergence};
//! use twin_core::robot::Robot;
//!
//! let robot = Robot::load("models/humanoid.urdf")?;
//! let mut controller = PdHold::new(&robot.model, PdHoldOptions::default());
//! let mut divergence = Divergence::default();
//! let episode = Episode { steps: 1000, ..Episode::default() };
//! let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
//! let outcome = Engine::new().run(&robot.model, &episode, &mut controller, &mut [], &mut [&mut divergence], &mut rng)?;
//! println!("{} steps", outcome.steps);
//! # Ok::<(), twin_core::Error>(())
//! ```

pub mod disturb;
pub mod observers;
pub mod replay;

pub use crate::control::{Actuation, Controller, Observation};
pub use crate::convert::ImuBias as BiasModel;

use crate::error::{Error, Result};
use crate::mj::{Data, Integrator, Model};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::sync::Arc;

/// What an observer wants after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Go on.
    Continue,
    /// End the rollout after this step; the remaining observers still see it.
    EndAfterStep,
    /// End the rollout now; the remaining observers do not see this step (e.g. a diverged
    /// state that would poison their numbers).
    EndNow,
}

/// One step as observers see it. `time_secs`, `qpos`, `qvel` and `command` describe the
/// instant t at the start of the step; `data` is the state after the physics step: its
/// `qpos`/`qvel`/`time` are at t + dt, while its derived quantities (body poses, sensors,
/// contacts, actuator forces) come from the forward pass at t, so they match `qpos`/`qvel`.
#[derive(Clone, Copy)]
pub struct StepView<'a> {
    /// Step index, from 0.
    pub index: u64,
    /// Time at the start of the step, seconds.
    pub time_secs: f64,
    /// Simulated time after the step, seconds (`(index + 1) · dt`).
    pub sim_secs: f64,
    /// Timestep, seconds.
    pub dt_secs: f64,
    /// Joint positions at `time_secs` (len `nq`).
    pub qpos: &'a [f64],
    /// Joint velocities at `time_secs` (len `nv`).
    pub qvel: &'a [f64],
    /// The observation the controller received for this step (noise, bias and latency of the
    /// [`SensorModel`] included): what recorders publish.
    pub observation: Observation<'a>,
    /// The command applied during the step (after scaling).
    pub command: &'a [f64],
    /// Whether some command entry was at a finite limit.
    pub saturated: bool,
    /// Where the command went.
    pub actuation: Actuation,
    /// The simulation after the step (see above).
    pub data: &'a Data,
    /// The rollout's controller (e.g. for its diagnostics, [`Controller::diagnostics`]).
    pub controller: &'a dyn Controller,
}

/// Watches a rollout: fall and divergence detection, metrics, checks, recorders.
pub trait Observer {
    /// Called once the initial state is set (positions, velocities and derived quantities at
    /// time 0), before the first step. `model` is this rollout's model.
    ///
    /// # Errors
    /// When the observer can't watch this model.
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        Ok(())
    }

    /// Called after every physics step.
    ///
    /// # Errors
    /// Ends the rollout with this error (e.g. a recorder that can't write).
    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow>;
}

/// One measured number.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// What it is.
    pub name: String,
    /// Its value.
    pub value: f64,
    /// Its unit.
    pub unit: &'static str,
}

impl Measurement {
    /// A measurement.
    pub fn new(name: impl Into<String>, value: f64, unit: &'static str) -> Measurement {
        Measurement { name: name.into(), value, unit }
    }
}

/// An observer that measures something over a rollout.
pub trait Metric: Observer {
    /// The measurements so far.
    fn measurements(&self) -> Vec<Measurement>;
}

/// A verdict: PASS or FAIL, with the numbers it rests on.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// What was checked.
    pub name: String,
    /// Whether it passed.
    pub passed: bool,
    /// The numbers behind the verdict.
    pub metrics: Vec<Measurement>,
    /// Extra lines (per-joint failures, what was skipped).
    pub details: Vec<String>,
    /// The likely cause when it failed.
    pub cause: Option<String>,
}

/// An observer that gives a verdict on a rollout (`Send`: batches make them per worker thread).
pub trait Check: Observer + Send {
    /// Name of the check (column and report label).
    fn name(&self) -> &str;

    /// The verdict on the rollout so far (called after it ends).
    fn verdict(&self) -> Verdict;
}

/// Acts on the simulation between the controller and the physics step.
pub trait Disturbance: Send {
    /// Called once the initial state is set, before the first step.
    ///
    /// # Errors
    /// When the disturbance can't act on this model.
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        Ok(())
    }

    /// Acts on `data` (velocities, applied forces) before the physics step; random draws
    /// come from `rng`, the rollout's stream.
    fn apply(&mut self, data: &mut Data, rng: &mut ChaCha8Rng);
}

/// How the controller's observation differs from the simulation: noise, bias, latency.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SensorModel {
    /// White-noise standard deviation per `qpos` entry (len `nq`, or empty: none).
    pub qpos_noise_std: Vec<f64>,
    /// White-noise standard deviation per `sensordata` entry (len `nsensordata`, or empty).
    pub sensor_noise_std: Vec<f64>,
    /// Constant bias per `sensordata` entry (len `nsensordata`, or empty).
    pub sensor_bias: Vec<f64>,
    /// Random bias processes: `(sensordata entry, model)`, e.g. an IMU's gyroscope and
    /// accelerometer axes from the URDF's Gazebo `<noise>` tags (Gazebo's turn-on bias, a
    /// first-order Gauss–Markov bias, twin's extra random walk; see [`BiasModel`]), advanced
    /// exactly over each step. (default: none)
    pub bias_processes: Vec<(usize, BiasModel)>,
    /// The controller sees the observation of this many steps ago.
    pub latency_steps: usize,
}

impl SensorModel {
    fn noisy_sensors(&self) -> bool {
        self.sensor_noise_std.iter().any(|&s| s > 0.0)
            || self.sensor_bias.iter().any(|&b| b != 0.0)
            || self.bias_processes.iter().any(|(_, b)| BiasState::acts(b))
    }
}

/// One entry's bias process (see [`SensorModel::bias_processes`]).
#[derive(Debug, Clone)]
struct BiasState {
    entry: usize,
    model: BiasModel,
    turn_on: f64,
    markov: f64,
    walk: f64,
}

impl BiasState {
    /// Whether `model` makes any bias at all.
    fn acts(model: &BiasModel) -> bool {
        model.mean != 0.0 || model.stddev != 0.0 || model.dynamic_stddev > 0.0 || model.random_walk > 0.0
    }

    /// The process at time 0: its turn-on bias drawn (Gazebo: `mean + stddev·w`, added or
    /// subtracted with equal probability) and the Gauss–Markov part in its stationary
    /// distribution (`σ_b·√(τ/2)`), so statistics hold from t = 0.
    fn start(entry: usize, model: BiasModel, rng: &mut ChaCha8Rng) -> BiasState {
        let mut turn_on = 0.0;
        if model.mean != 0.0 || model.stddev != 0.0 {
            let magnitude = model.mean + model.stddev * rng.sample::<f64, _>(StandardNormal);
            turn_on = if rng.random_bool(0.5) { magnitude } else { -magnitude };
        }
        let tau = model.dynamic_correlation_time_secs;
        let markov = if model.dynamic_stddev > 0.0 && tau > 0.0 {
            model.dynamic_stddev * (tau / 2.0).sqrt() * rng.sample::<f64, _>(StandardNormal)
        } else {
            0.0
        };
        BiasState { entry, model, turn_on, markov, walk: 0.0 }
    }

    /// Advances the process by `dt_secs`, exactly (no Euler error at any rate).
    fn advance(&mut self, dt_secs: f64, rng: &mut ChaCha8Rng) {
        let (sigma, tau) = (self.model.dynamic_stddev, self.model.dynamic_correlation_time_secs);
        if sigma > 0.0 {
            if tau > 0.0 {
                // b' = φ·b + σ_b·√(τ/2·(1 − φ²))·w, φ = e^(−Δt/τ).
                let phi = (-dt_secs / tau).exp();
                let drive = sigma * (tau / 2.0 * -(-2.0 * dt_secs / tau).exp_m1()).sqrt();
                self.markov = phi * self.markov + drive * rng.sample::<f64, _>(StandardNormal);
            } else {
                self.markov += sigma * dt_secs.sqrt() * rng.sample::<f64, _>(StandardNormal);
            }
        }
        if self.model.random_walk > 0.0 {
            self.walk += self.model.random_walk * dt_secs.sqrt() * rng.sample::<f64, _>(StandardNormal);
        }
    }

    fn value(&self) -> f64 {
        self.turn_on + self.markov + self.walk
    }
}

/// One rollout's configuration.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Episode {
    /// Initial joint positions (len `nq`); `None`: the home pose
    /// ([`crate::control::reset_to_home`]). The controller may adjust them
    /// ([`Controller::initial_qpos`]). (default: `None`)
    pub initial_qpos: Option<Vec<f64>>,
    /// Physics steps to run (fewer when an observer ends the rollout). (default: 0)
    pub steps: u64,
    /// The sensor model. (default: exact observations)
    pub sensors: SensorModel,
    /// Factor on each command entry (len of the command, or empty: none). (default: none)
    pub command_scale: Vec<f64>,
}

/// How a rollout ended.
#[derive(Debug)]
pub struct Outcome {
    /// Physics steps completed.
    pub steps: u64,
    /// Simulated time completed, seconds (`steps · dt`).
    pub sim_secs: f64,
    /// Index of the observer that ended the rollout, if one did.
    pub ended_by: Option<usize>,
    /// The physics step failed (MuJoCo raised an error): the rollout stopped there.
    pub physics_error: Option<Error>,
}

/// Per-thread scratch for rollouts: one `Data` reused across rollouts (moved onto each
/// rollout's model), the observation ring, the command.
#[derive(Debug, Default)]
pub struct Engine {
    data: Option<Data>,
    history: Vec<f64>,
    command: Vec<f64>,
    qpos_t: Vec<f64>,
    qvel_t: Vec<f64>,
}

impl Engine {
    /// An engine with no `Data` yet.
    pub fn new() -> Engine {
        Engine::default()
    }

    /// The simulation as the last rollout left it.
    pub fn data(&self) -> Option<&Data> {
        self.data.as_ref()
    }

    /// The simulation as the last rollout left it, taken out of the engine (e.g. to examine it
    /// further; the next rollout makes a new one).
    pub fn take_data(&mut self) -> Option<Data> {
        self.data.take()
    }

    /// Runs `episode` on `model` under `controller`, with `disturbances` and `observers`, random
    /// numbers from `rng` (see the module docs for the step order).
    ///
    /// A MuJoCo error during a step ends the rollout and is reported in
    /// [`Outcome::physics_error`], not as an error.
    ///
    /// # Errors
    /// [`Error::MuJoCo`] when the initial state can't be set; errors of the controller's
    /// reset, of disturbances' and observers' `start`, and of observers.
    pub fn run(
        &mut self,
        model: &Arc<Model>,
        episode: &Episode,
        controller: &mut dyn Controller,
        disturbances: &mut [&mut dyn Disturbance],
        observers: &mut [&mut dyn Observer],
        rng: &mut ChaCha8Rng,
    ) -> Result<Outcome> {
        let data = match self.data.as_mut() {
            Some(d) => {
                d.set_model(model.clone())?;
                d
            }
            None => self.data.insert(Data::new(model.clone())?),
        };
        match &episode.initial_qpos {
            Some(q) => {
                data.qpos_mut().copy_from_slice(q);
                data.forward()?;
            }
            None => crate::control::reset_to_home(data)?,
        }
        // Only a controller that moves the start pays for a second forward pass.
        self.qpos_t.clear();
        self.qpos_t.extend_from_slice(data.qpos());
        controller.initial_qpos(model, data.qpos_mut());
        if data.qpos() != self.qpos_t.as_slice() {
            data.forward()?;
        }

        let (nq, nv, ns) = (model.nq(), model.nv(), model.nsensordata());
        let sensors = &episode.sensors;
        let obs_len = nq + nv + ns;
        let depth = sensors.latency_steps + 1;
        let noisy_s = sensors.noisy_sensors();
        // The entries that draw noise, in index order (the draws' order): the loops below then
        // skip the noiseless ones without testing each entry every step.
        let noisy = |deviations: &[f64], len: usize| -> Vec<(usize, f64)> {
            deviations.iter().copied().take(len).enumerate().filter(|&(_, s)| s > 0.0).collect()
        };
        let (qpos_noise, sensor_noise) = (noisy(&sensors.qpos_noise_std, nq), noisy(&sensors.sensor_noise_std, ns));
        // The bias of every `sensordata` entry (zero past the spec's).
        let bias: Vec<f64> = (0..ns).map(|k| sensors.sensor_bias.get(k).copied().unwrap_or(0.0)).collect();
        let mut processes: Vec<BiasState> = sensors
            .bias_processes
            .iter()
            .filter(|(k, b)| *k < ns && BiasState::acts(b))
            .map(|&(k, b)| BiasState::start(k, b, rng))
            .collect();
        let dt = model.timestep_secs();
        // `advance`: time moved by one step since the last capture (the bias processes go on).
        let mut capture = |data: &Data, history: &mut [f64], slot: usize, rng: &mut ChaCha8Rng, advance: bool| {
            let o = &mut history[slot * obs_len..(slot + 1) * obs_len];
            o[..nq].copy_from_slice(data.qpos());
            o[nq..nq + nv].copy_from_slice(data.qvel());
            o[nq + nv..].copy_from_slice(data.sensordata());
            if advance {
                for p in &mut processes {
                    p.advance(dt, rng);
                }
            }
            for &(k, s) in &qpos_noise {
                o[k] += s * rng.sample::<f64, _>(StandardNormal);
            }
            if noisy_s {
                let o = &mut o[nq + nv..];
                for (v, b) in o.iter_mut().zip(&bias) {
                    *v += b;
                }
                for p in &processes {
                    o[p.entry] += p.value();
                }
                for &(k, s) in &sensor_noise {
                    o[k] += s * rng.sample::<f64, _>(StandardNormal);
                }
            }
        };
        // The observations, a ring of `depth` (one slot when exact: the copy is what observers
        // get, as acceleration-stage sensors change in the physics step). The whole delay line
        // starts with the initial observation.
        self.history.clear();
        self.history.resize(obs_len * depth, 0.0);
        for slot in 0..depth {
            capture(data, &mut self.history, slot, rng, false);
        }
        controller.reset(model, &slot_observation(&self.history, 0, (nq, nv, ns), data.time_secs()))?;

        let actuation = Actuation::of(model);
        let limits = actuation.limits(model);
        self.command.clear();
        self.command.resize(actuation.len(model), 0.0);
        self.qpos_t.resize(nq, 0.0);
        self.qvel_t.clear();
        self.qvel_t.resize(nv, 0.0);

        for d in disturbances.iter_mut() {
            d.start(model, data)?;
        }
        for o in observers.iter_mut() {
            o.start(model, data)?;
        }

        // RK4 can't be split into mj_step1/mj_step2 (mj_step2 would integrate with Euler).
        let split = model.integrator() != Integrator::Rk4;
        let mut outcome = Outcome { steps: 0, sim_secs: 0.0, ended_by: None, physics_error: None };
        let mut oldest = 0usize;
        for step in 0..episode.steps {
            // 1. Positions, velocities and sensors of this instant (the initial state's are
            // current already).
            if split && step > 0 {
                if let Err(e) = data.step1() {
                    outcome.physics_error = Some(e.into());
                    break;
                }
                // The newest observation replaces the oldest; the next oldest is one further.
                capture(data, &mut self.history, oldest, rng, true);
                oldest = (oldest + 1) % depth;
            }
            // 2. The controller sees the observation captured `latency_steps` steps ago.
            let time_secs = data.time_secs();
            let observation = slot_observation(&self.history, oldest * obs_len, (nq, nv, ns), time_secs);
            controller.compute(model, &observation, &mut self.command);
            // (Entries past `command_scale` keep their value: `c · 1` is `c`.)
            for (c, &k) in self.command.iter_mut().zip(&episode.command_scale) {
                *c *= k;
            }
            // Without short-circuits, so that the loop runs branch-free over the entries.
            let saturated = self.command.iter().zip(&limits).fold(false, |any, (&c, &[lo, hi])| {
                any | (((c <= lo) & lo.is_finite()) | ((c >= hi) & hi.is_finite())) & (lo != hi)
            });
            actuation.apply(data, &self.command);
            // 3.
            self.qpos_t.copy_from_slice(data.qpos());
            self.qvel_t.copy_from_slice(data.qvel());
            for d in disturbances.iter_mut() {
                d.apply(data, rng);
            }
            // 4. A disturbance that moved the state (a kick of the base's velocity, a pinned base)
            // makes the physics start from the moved state: its position and velocity stages
            // run again, as `mj_step` would run them.
            if differs(data.qpos(), &self.qpos_t) || differs(data.qvel(), &self.qvel_t) {
                self.qpos_t.copy_from_slice(data.qpos());
                self.qvel_t.copy_from_slice(data.qvel());
                if split && let Err(e) = data.step1() {
                    outcome.physics_error = Some(e.into());
                    break;
                }
            }
            let stepped = if split { data.step2() } else { data.step() };
            if let Err(e) = stepped {
                outcome.physics_error = Some(e.into());
                break;
            }
            outcome.steps = step + 1;
            outcome.sim_secs = (step + 1) as f64 * dt;
            // 5. The observation the controller got is still in the ring (the next capture is
            // after the observers).
            let observation = slot_observation(&self.history, oldest * obs_len, (nq, nv, ns), time_secs);
            let view = StepView {
                index: step,
                time_secs,
                sim_secs: outcome.sim_secs,
                dt_secs: dt,
                qpos: &self.qpos_t,
                qvel: &self.qvel_t,
                observation,
                command: &self.command,
                saturated,
                actuation,
                data,
                controller: &*controller,
            };
            let mut end = false;
            for (k, o) in observers.iter_mut().enumerate() {
                match o.observe(&view)? {
                    Flow::Continue => {}
                    Flow::EndAfterStep => {
                        end = true;
                        outcome.ended_by.get_or_insert(k);
                    }
                    Flow::EndNow => {
                        end = true;
                        outcome.ended_by.get_or_insert(k);
                        break;
                    }
                }
            }
            // 6. A controller may end the run (a live bridge told to stop) or abort it.
            if end || !controller.proceed()? {
                break;
            }
            if !split {
                // The newest observation replaces the oldest; the next oldest is one further.
                capture(data, &mut self.history, oldest, rng, true);
                oldest = (oldest + 1) % depth;
            }
        }
        Ok(outcome)
    }
}

/// `a != b` for slices of one length, without stopping at the first difference: a loop the
/// compiler vectorizes, where the slices' `!=` compares one pair at a time.
fn differs(a: &[f64], b: &[f64]) -> bool {
    a.len() != b.len() || a.iter().zip(b).fold(false, |any, (x, y)| any | (x != y))
}

/// The observation stored at `start` of `history`: `qpos`, `qvel`, `sensordata` back to back.
fn slot_observation(
    history: &[f64],
    start: usize,
    (nq, nv, ns): (usize, usize, usize),
    time_secs: f64,
) -> Observation<'_> {
    let o = &history[start..start + nq + nv + ns];
    Observation { time_secs, qpos: &o[..nq], qvel: &o[nq..nq + nv], sensordata: &o[nq + nv..] }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Records each observation's `qpos` and `sensordata`; commands nothing.
    #[derive(Default)]
    struct Recorder {
        seen: Vec<(Vec<f64>, Vec<f64>)>,
    }

    impl Controller for Recorder {
        fn name(&self) -> &'static str {
            "recorder"
        }
        fn compute(&mut self, _model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
            command.fill(0.0);
            self.seen.push((observation.qpos.to_vec(), observation.sensordata.to_vec()));
        }
    }

    /// Noise goes on the entries with a deviation, drawn in entry order from the rollout's
    /// stream; a bias acts even without a noise list. The robot rests at zero (no gravity, no
    /// command), so the observation is the corruption alone.
    #[test]
    fn sensor_noise_and_bias_act_on_their_entries_only() {
        let xml = r#"<mujoco><option gravity="0 0 0"/><worldbody><body>
            <joint name="a" axis="0 0 1"/><geom type="sphere" size="0.1" mass="1"/>
            <body><joint name="b" axis="0 1 0"/><geom type="sphere" size="0.1" mass="1"/></body>
            </body></worldbody><sensor><jointpos joint="a"/><jointpos joint="b"/></sensor></mujoco>"#;
        let model = Arc::new(Model::from_xml_str(xml).unwrap());
        let sensors = SensorModel {
            qpos_noise_std: vec![0.0, 0.1],
            sensor_noise_std: Vec::new(),
            sensor_bias: vec![0.5, -0.25],
            ..SensorModel::default()
        };
        let episode = Episode { steps: 20, sensors, ..Episode::default() };
        let mut recorder = Recorder::default();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        Engine::new().run(&model, &episode, &mut recorder, &mut [], &mut [], &mut rng).unwrap();
        let mut draws = ChaCha8Rng::seed_from_u64(7);
        assert_eq!(recorder.seen.len(), 20);
        for (qpos, sensordata) in &recorder.seen {
            assert_eq!(qpos[0], 0.0);
            assert_eq!(qpos[1], 0.1 * draws.sample::<f64, _>(StandardNormal));
            assert_eq!(sensordata, &[0.5, -0.25]);
        }
    }
}
