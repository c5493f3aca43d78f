//! One episode: draw, reset, roll out under a controller with noise, latency and pushes, and
//! measure.

use crate::draw::{Draw, Layout, episode_rng};
use crate::error::{Error, Result};
use rand::Rng;
use rand_distr::StandardNormal;
use std::sync::Arc;
use twin_core::control::{Actuation, Controller, Observation, base_body};
use twin_core::mj::{Data, JointType, Model, ObjType};

/// How an episode runs and when it ends early.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeOptions {
    /// Simulated time per episode, seconds. (default: 5.0)
    pub duration_secs: f64,
    /// The robot has fallen when its base is lower than this fraction of its initial height.
    /// (default: 0.6)
    pub fall_height_fraction: f64,
    /// The robot has fallen when its base tilts more than this from upright, radians.
    /// (default: 1.0, about 57°)
    pub fall_tilt_rad: f64,
    /// Controller name, one of `twin_core::control::CONTROLLERS`. (default: `pd-hold`)
    pub controller: String,
}

impl Default for EpisodeOptions {
    fn default() -> Self {
        EpisodeOptions {
            duration_secs: 5.0,
            fall_height_fraction: 0.6,
            fall_tilt_rad: 1.0,
            controller: "pd-hold".into(),
        }
    }
}

/// Everything fixed across the episodes of a batch.
pub struct Batch {
    /// The nominal model; each episode edits a copy.
    pub nominal: Arc<Model>,
    /// The spec bound to the nominal model.
    pub layout: Layout,
    /// Episode options.
    pub options: EpisodeOptions,
    /// Master seed.
    pub seed: u64,
    feet: Vec<usize>,
    geom_foot: Vec<i32>,
    base: Option<usize>,
}

impl Batch {
    /// Prepares a batch: finds the floating base and the feet (bodies named `*foot*`, else
    /// `*ankle*`, else the bodies whose geoms are lowest in the home pose).
    ///
    /// # Errors
    /// [`Error::Core`] if the controller name is unknown or MuJoCo fails.
    pub fn new(nominal: Arc<Model>, layout: Layout, options: EpisodeOptions, seed: u64) -> Result<Batch> {
        twin_core::control::by_name(&options.controller, &nominal)?;
        if !(options.duration_secs > 0.0 && options.duration_secs.is_finite()) {
            return Err(Error::Options(format!(
                "the episode duration must be a positive number of seconds, got {}",
                options.duration_secs
            )));
        }
        let base = base_body(&nominal);
        let feet = find_feet(&nominal, &layout.home_qpos)?;
        let mut geom_foot = vec![-1; nominal.ngeom()];
        for (g, slot) in geom_foot.iter_mut().enumerate() {
            let body = nominal.geom_bodyid()[g] as usize;
            if let Some(k) = feet.iter().position(|&f| f == body) {
                *slot = k as i32;
            }
        }
        Ok(Batch { nominal, layout, options, seed, feet, geom_foot, base })
    }

    /// Names of the bodies counted as feet.
    pub fn feet(&self) -> Vec<String> {
        self.feet.iter().map(|&b| self.nominal.name(ObjType::Body, b).to_string()).collect()
    }

    /// Number of simulation steps of a full episode.
    pub fn steps_per_episode(&self) -> u64 {
        (self.options.duration_secs / self.nominal.timestep_secs()).round() as u64
    }
}

fn find_feet(model: &Model, home_qpos: &[f64]) -> Result<Vec<usize>> {
    let named = |needle: &str| -> Vec<usize> {
        (1..model.nbody())
            .filter(|&b| model.name(ObjType::Body, b).to_lowercase().contains(needle))
            .filter(|&b| model.geom_bodyid().iter().any(|&gb| gb as usize == b))
            .collect()
    };
    let feet = named("foot");
    if !feet.is_empty() {
        return Ok(feet);
    }
    let feet = named("ankle");
    if !feet.is_empty() {
        return Ok(feet);
    }
    // Lowest bodies: those with a geom within 1 cm of the lowest robot point at home.
    let mut data = Data::new(Arc::new(model.try_clone()?))?;
    data.qpos_mut().copy_from_slice(home_qpos);
    data.forward()?;
    let lowest = twin_core::control::lowest_robot_point_z(model, &data);
    let mut feet = Vec::new();
    for g in 0..model.ngeom() {
        let body = model.geom_bodyid()[g] as usize;
        if body == 0 || feet.contains(&body) {
            continue;
        }
        let z = data.geom_xpos()[g][2] - model.geom_rbound()[g];
        if z <= lowest + 0.01 {
            feet.push(body);
        }
    }
    Ok(feet)
}

/// Per-episode results: the metrics and the drawn parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeResult {
    /// Episode index in the batch.
    pub index: u64,
    /// Whether the base fell (height or tilt threshold crossed).
    pub fell: bool,
    /// Simulated time of the fall, seconds.
    pub fall_time_secs: Option<f64>,
    /// The simulation diverged (NaN, MuJoCo's bad-qacc/qpos/qvel warning, or a MuJoCo error).
    pub unstable: bool,
    /// Why it is unstable (MuJoCo's message or the warning), empty otherwise.
    pub unstable_reason: String,
    /// Simulated time, seconds (less than the duration after a fall or divergence).
    pub sim_secs: f64,
    /// Horizontal distance of the base from its start, metres.
    pub distance_m: f64,
    /// `distance_m / sim_secs`, m/s.
    pub avg_speed_mps: f64,
    /// Foot touch-downs (a foot's contact with the ground starting).
    pub steps_taken: u64,
    /// Largest tilt of the base from upright, radians.
    pub max_tilt_rad: f64,
    /// Time with at least one command at its limit, seconds.
    pub saturation_secs: f64,
    /// Actuator work ∫ Σ|τ·q̇| dt, joules.
    pub energy_j: f64,
    /// Drawn parameters, one per layout column.
    pub params: Vec<f64>,
}

impl EpisodeResult {
    /// Neither fell nor diverged.
    pub fn success(&self) -> bool {
        !self.fell && !self.unstable
    }
}

/// One recorded trajectory (for `--record-worst`): a row per step.
#[derive(Debug, Clone, Default)]
pub struct Trajectory {
    /// Column names: time, base position and tilt, qpos entries, command entries.
    pub columns: Vec<String>,
    /// One row per step.
    pub rows: Vec<Vec<f64>>,
}

/// Per-thread state: one `Data` reused across episodes (moved onto each episode's model), the
/// controller and scratch buffers.
pub struct Worker {
    data: Option<Data>,
    controller: Box<dyn Controller>,
    history: Vec<f64>,
    command: Vec<f64>,
}

impl Worker {
    /// A worker for `batch`.
    ///
    /// # Errors
    /// [`Error::Core`] for an unknown controller.
    pub fn new(batch: &Batch) -> Result<Worker> {
        Ok(Worker {
            data: None,
            controller: twin_core::control::by_name(&batch.options.controller, &batch.nominal)?,
            history: Vec::new(),
            command: Vec::new(),
        })
    }

    /// Runs episode `index` of `batch`; with `trajectory`, records every step.
    ///
    /// A MuJoCo error or divergence during the episode is a result (`unstable`), not an
    /// error.
    ///
    /// # Errors
    /// [`Error::Apply`] if the drawn parameters can't be applied, [`Error::Core`] if MuJoCo
    /// fails outside the rollout (copying, resetting).
    pub fn run(&mut self, batch: &Batch, index: u64, trajectory: Option<&mut Trajectory>) -> Result<EpisodeResult> {
        self.run_recorded(batch, index, trajectory, None)
    }

    /// [`Worker::run`], also recording every step into `recording` (MCAP topics / rerun, see
    /// `twin_core::sim::record`). The recording reads the simulation after each step: joint
    /// states stamped with the new time, body poses, sensors and contact forces from that
    /// step's forward pass (one step, `dt`, earlier). Recording does not change the episode.
    ///
    /// # Errors
    /// As [`Worker::run`]; write errors of the recording.
    pub fn run_recorded(
        &mut self,
        batch: &Batch,
        index: u64,
        trajectory: Option<&mut Trajectory>,
        recording: Option<&mut twin_core::sim::Recording>,
    ) -> Result<EpisodeResult> {
        let mut param_rng = episode_rng(batch.seed, index, 0);
        let draw = batch.layout.draw(&batch.nominal, index, &mut param_rng)?;
        self.rollout(batch, index, draw, trajectory, recording)
    }

    fn rollout(
        &mut self,
        batch: &Batch,
        index: u64,
        draw: Draw,
        mut trajectory: Option<&mut Trajectory>,
        mut recording: Option<&mut twin_core::sim::Recording>,
    ) -> Result<EpisodeResult> {
        let Draw {
            values,
            model,
            sensor_noise_std,
            sensor_bias,
            qpos_noise_std,
            latency_steps,
            init_qpos,
            push_interval_secs,
            push_speed_mps,
            command_scale,
        } = draw;
        let model = Arc::new(model);
        let data = match self.data.as_mut() {
            Some(d) => {
                d.set_model(model.clone())?;
                d
            }
            None => self.data.insert(Data::new(model.clone())?),
        };
        data.qpos_mut().copy_from_slice(&init_qpos);
        data.forward()?;
        let mut rng = episode_rng(batch.seed, index, 1);
        let (nq, nv, ns) = (model.nq(), model.nv(), model.nsensordata());
        let obs_len = nq + nv + ns;
        let depth = latency_steps + 1;
        self.history.clear();
        self.history.resize(obs_len * depth, 0.0);
        let noisy_q = qpos_noise_std.iter().any(|&s| s > 0.0);
        let noisy_s = sensor_noise_std.iter().any(|&s| s > 0.0) || sensor_bias.iter().any(|&b| b != 0.0);
        let actuation = Actuation::of(&model);
        let limits = actuation.limits(&model);
        self.command.clear();
        self.command.resize(actuation.len(&model), 0.0);
        let free_adr = batch.base.map(|b| {
            let j = (0..model.njnt())
                .find(|&j| model.jnt_bodyid()[j] as usize == b && model.joint_type(j) == JointType::Free)
                .expect("base body has a free joint");
            model.jnt_dofadr()[j] as usize
        });
        let dt = model.timestep_secs();
        let steps = batch.steps_per_episode();
        let base_xy0 = batch.base.map(|b| data.xpos()[b]);
        let fall_z = base_xy0.map(|p| p[2] * batch.options.fall_height_fraction);

        // Writes the current (noisy) observation into history slot `slot`.
        let capture = |data: &Data, history: &mut [f64], slot: usize, rng: &mut rand_chacha::ChaCha8Rng| {
            let o = &mut history[slot * obs_len..(slot + 1) * obs_len];
            o[..nq].copy_from_slice(data.qpos());
            o[nq..nq + nv].copy_from_slice(data.qvel());
            o[nq + nv..].copy_from_slice(data.sensordata());
            if noisy_q {
                for (q, &s) in o[..nq].iter_mut().zip(&qpos_noise_std) {
                    if s > 0.0 {
                        *q += s * rng.sample::<f64, _>(StandardNormal);
                    }
                }
            }
            if noisy_s {
                for ((v, &s), &b) in o[nq + nv..].iter_mut().zip(&sensor_noise_std).zip(&sensor_bias) {
                    *v += b;
                    if s > 0.0 {
                        *v += s * rng.sample::<f64, _>(StandardNormal);
                    }
                }
            }
        };
        // Fill the whole delay line with the initial observation.
        for slot in 0..depth {
            capture(data, &mut self.history, slot, &mut rng);
        }
        {
            let o = &self.history[..obs_len];
            let obs = Observation {
                time_secs: data.time_secs(),
                qpos: &o[..nq],
                qvel: &o[nq..nq + nv],
                sensordata: &o[nq + nv..],
            };
            self.controller.reset(&model, &obs)?;
        }
        if let Some(t) = trajectory.as_deref_mut() {
            t.columns = ["time_secs", "base_x_m", "base_y_m", "base_z_m", "tilt_rad"]
                .iter()
                .map(|s| s.to_string())
                .chain((0..nq).map(|i| format!("qpos[{i}]")))
                .chain((0..self.command.len()).map(|i| format!("command[{i}]")))
                .collect();
            t.rows.clear();
        }

        let mut result = EpisodeResult {
            index,
            fell: false,
            fall_time_secs: None,
            unstable: false,
            unstable_reason: String::new(),
            sim_secs: 0.0,
            distance_m: 0.0,
            avg_speed_mps: 0.0,
            steps_taken: 0,
            max_tilt_rad: 0.0,
            saturation_secs: 0.0,
            energy_j: 0.0,
            params: values,
        };
        let mut foot_down: Vec<bool> = vec![false; batch.feet.len()];
        let mut foot_now: Vec<bool> = vec![false; batch.feet.len()];
        let mark_contacts = |data: &Data, now: &mut [bool]| {
            now.fill(false);
            for [g1, g2] in data.contact_geoms() {
                if g1 < 0 || g2 < 0 {
                    continue;
                }
                let (b1, b2) = (model.geom_bodyid()[g1 as usize], model.geom_bodyid()[g2 as usize]);
                let (f1, f2) = (batch.geom_foot[g1 as usize], batch.geom_foot[g2 as usize]);
                if f1 >= 0 && b2 == 0 {
                    now[f1 as usize] = true;
                }
                if f2 >= 0 && b1 == 0 {
                    now[f2 as usize] = true;
                }
            }
        };
        mark_contacts(data, &mut foot_down);
        let mut next_push = push_interval_secs;
        let total_mass = model.total_mass_kg();
        let mut push_force = [0.0; 2];
        let mut push_until = f64::NEG_INFINITY;
        let mut oldest = 0usize;

        for step in 0..steps {
            // The controller sees the observation captured `latency_steps` steps ago.
            {
                let o = &self.history[oldest * obs_len..(oldest + 1) * obs_len];
                let obs = Observation {
                    time_secs: data.time_secs(),
                    qpos: &o[..nq],
                    qvel: &o[nq..nq + nv],
                    sensordata: &o[nq + nv..],
                };
                self.controller.compute(&model, &obs, &mut self.command);
            }
            let mut saturated = false;
            for ((c, &[lo, hi]), &k) in self.command.iter_mut().zip(&limits).zip(&command_scale) {
                *c *= k;
                if (*c <= lo && lo.is_finite()) || (*c >= hi && hi.is_finite()) {
                    saturated = saturated || lo != hi;
                }
            }
            actuation.apply(data, &self.command);
            if let (Some(t), Some(adr)) = (next_push, free_adr)
                && data.time_secs() + 0.5 * dt >= t
            {
                let angle = rng.random::<f64>() * std::f64::consts::TAU;
                let (dx, dy) = (push_speed_mps * angle.cos(), push_speed_mps * angle.sin());
                match batch.layout.push_body {
                    None => {
                        data.qvel_mut()[adr] += dx;
                        data.qvel_mut()[adr + 1] += dy;
                    }
                    Some((_, duration)) => {
                        push_force = [dx * total_mass / duration, dy * total_mass / duration];
                        push_until = data.time_secs() + duration;
                    }
                }
                next_push = Some(t + push_interval_secs.unwrap_or(f64::INFINITY));
            }
            if let Some((body, _)) = batch.layout.push_body {
                let active = data.time_secs() + 0.5 * dt < push_until;
                let f = &mut data.xfrc_applied_mut()[body];
                (f[0], f[1]) = if active { (push_force[0], push_force[1]) } else { (0.0, 0.0) };
            }
            if let Err(e) = data.step() {
                result.unstable = true;
                result.unstable_reason = e.to_string();
                break;
            }
            result.sim_secs = (step + 1) as f64 * dt;
            if data.diverged() || data.qpos().iter().any(|q| !q.is_finite()) {
                result.unstable = true;
                let (_, text) = twin_core::mj::thread_warnings();
                result.unstable_reason = if data.diverged() {
                    format!("MuJoCo reset a diverged simulation: {text}")
                } else {
                    "non-finite joint positions".into()
                };
                break;
            }
            if saturated {
                result.saturation_secs += dt;
            }
            let power: f64 = match actuation {
                Actuation::Ctrl => data.qfrc_actuator().iter().zip(data.qvel()).map(|(t, v)| (t * v).abs()).sum(),
                Actuation::Qfrc => data.qfrc_applied().iter().zip(data.qvel()).map(|(t, v)| (t * v).abs()).sum(),
            };
            result.energy_j += power * dt;
            mark_contacts(data, &mut foot_now);
            for (down, &now) in foot_down.iter_mut().zip(&foot_now) {
                if now && !*down {
                    result.steps_taken += 1;
                }
                *down = now;
            }
            if let Some(b) = batch.base {
                let z_axis_z = data.xmat()[b][8].clamp(-1.0, 1.0);
                let tilt = z_axis_z.acos();
                result.max_tilt_rad = result.max_tilt_rad.max(tilt);
                let z = data.xpos()[b][2];
                if tilt > batch.options.fall_tilt_rad || fall_z.is_some_and(|f| z < f) {
                    result.fell = true;
                    result.fall_time_secs = Some(result.sim_secs);
                }
            }
            if let Some(rec) = recording.as_deref_mut() {
                let sample = twin_core::sim::StepSample {
                    time_secs: data.time_secs(),
                    qpos: data.qpos(),
                    qvel: data.qvel(),
                    command: &self.command,
                };
                rec.record(&sample, data)?;
            }
            if let Some(t) = trajectory.as_deref_mut() {
                let p = batch.base.map_or([0.0; 3], |b| data.xpos()[b]);
                let tilt = batch.base.map_or(0.0, |b| data.xmat()[b][8].clamp(-1.0, 1.0).acos());
                let mut row = vec![data.time_secs(), p[0], p[1], p[2], tilt];
                row.extend_from_slice(data.qpos());
                row.extend_from_slice(&self.command);
                t.rows.push(row);
            }
            if result.fell {
                break;
            }
            // Newest observation replaces the oldest; the next oldest is one slot further.
            capture(data, &mut self.history, oldest, &mut rng);
            oldest = (oldest + 1) % depth;
        }
        if let (Some(b), Some(p0)) = (batch.base, base_xy0) {
            let p = data.xpos()[b];
            result.distance_m = ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2)).sqrt();
            if !result.distance_m.is_finite() {
                result.distance_m = 0.0;
            }
        }
        if result.sim_secs > 0.0 {
            result.avg_speed_mps = result.distance_m / result.sim_secs;
        }
        Ok(result)
    }
}
