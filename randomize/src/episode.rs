//! One episode: draw, then one rollout of `twin_core::engine` under the batch's controller
//! with the draw's sensor noise, bias, latency and pushes; fall and divergence detection,
//! metrics and the batch's checks are the engine's observers.

use crate::draw::{Draw, Layout, episode_rng};
use crate::error::{Error, Result};
use std::sync::Arc;
use twin_core::control::Controller;
use twin_core::engine::disturb::Push;
use twin_core::engine::observers::{Divergence, Energy, Fall, FallOptions, Saturation, Touchdowns};
use twin_core::engine::{Check, Disturbance, Engine, Episode, Flow, Observer, SensorModel, StepView, Verdict};
use twin_core::mj::Model;
use twin_core::robot::Robot;

/// Makes a batch's controller for a worker thread: any [`Controller`], including ones written
/// outside twin. Called once per worker with the nominal robot; [`Controller::reset`] then
/// starts each episode on that episode's model.
pub type ControllerFactory = dyn Fn(&Robot) -> twin_core::Result<Box<dyn Controller>> + Send + Sync;

/// Makes the scripted disturbances of one episode on that episode's model (e.g. a scenario's
/// pushes), applied besides the spec's random ones.
pub type DisturbanceFactory = dyn Fn(&Model) -> Vec<Box<dyn Disturbance>> + Send + Sync;

/// Makes a batch's checks for a worker thread (see [`ControllerFactory`]); each check's
/// verdict is part of every episode's result, and a failed check fails the episode.
pub type CheckFactory = dyn Fn(&Robot) -> twin_core::Result<Vec<Box<dyn Check>>> + Send + Sync;

/// Makes a batch's controller together with the checks that watch it, for a worker thread: an
/// external controller ([`twin_bridges::external`]) comes with the check that publishes the
/// robot's state to its process and judges its health, so a controller that crashes or hangs
/// fails its episode, not the batch.
pub type DriverFactory = dyn Fn(&Robot) -> twin_core::Result<(Box<dyn Controller>, Vec<Box<dyn Check>>)> + Send + Sync;

/// How an episode runs and when it ends early.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct EpisodeOptions {
    /// Simulated time per episode, seconds. (default: 5.0)
    #[default(5.0)]
    pub duration_secs: f64,
    /// The robot has fallen when its base is lower than this fraction of its initial height.
    /// (default: 0.6)
    #[default(0.6)]
    pub fall_height_fraction: f64,
    /// The robot has fallen when its base tilts more than this from upright, radians.
    /// (default: 1.0, about 57°)
    #[default(1.0)]
    pub fall_tilt_rad: f64,
    /// Controller name, one of `twin_controllers::registry::CONTROLLERS`, used unless the batch is
    /// given a controller factory ([`Batch::with_controller`]). (default: `pd-hold`)
    #[default("pd-hold")]
    pub controller: String,
}

/// Everything fixed across the episodes of a batch.
pub struct Batch {
    /// The nominal model; each episode edits a copy.
    pub nominal: Arc<Model>,
    /// The nominal robot (its model is [`Batch::nominal`]).
    pub robot: Robot,
    /// The spec bound to the nominal model.
    pub layout: Layout,
    /// Episode options.
    pub options: EpisodeOptions,
    /// Master seed.
    pub seed: u64,
    controller: Arc<ControllerFactory>,
    controller_name: String,
    checks: Option<Arc<CheckFactory>>,
    disturbances: Option<Arc<DisturbanceFactory>>,
    /// A controller with its own checks, instead of `controller` (see [`DriverFactory`]), and
    /// the verdicts of those checks before any episode (their CSV columns).
    driver: Option<(Arc<DriverFactory>, Vec<Verdict>)>,
    terrain: Option<twin_core::terrain::TerrainOptions>,
}

impl Batch {
    /// Prepares a batch on a bare model (the robot as the model holds it: see
    /// `twin_core::robot::Robot::from_parts`).
    ///
    /// # Errors
    /// As [`Batch::from_robot`].
    pub fn new(nominal: Arc<Model>, layout: Layout, options: EpisodeOptions, seed: u64) -> Result<Batch> {
        let robot = Robot::from_parts(nominal, std::path::Path::new("robot"), None)?;
        Batch::from_robot(robot, layout, options, seed)
    }

    /// Prepares a batch on `robot` (its feet, from the kinematic tree and the geometry, count
    /// touch-downs), driven by the controller named in `options`.
    ///
    /// # Errors
    /// [`Error::Core`] if the controller name is unknown; [`Error::Options`] for a duration
    /// that is not a positive number of seconds.
    pub fn from_robot(robot: Robot, layout: Layout, options: EpisodeOptions, seed: u64) -> Result<Batch> {
        if !(options.duration_secs > 0.0 && options.duration_secs.is_finite()) {
            return Err(Error::Options(format!(
                "the episode duration must be a positive number of seconds, got {}",
                options.duration_secs
            )));
        }
        let name = options.controller.clone();
        let factory: Arc<ControllerFactory> =
            Arc::new(move |r: &Robot| twin_controllers::registry::by_name(&name, &r.model));
        let batch = Batch {
            nominal: robot.model.clone(),
            robot,
            layout,
            controller_name: options.controller.clone(),
            options,
            seed,
            controller: factory,
            checks: None,
            disturbances: None,
            driver: None,
            terrain: None,
        };
        let factory = batch.controller.clone();
        batch.with_controller_factory(factory)
    }

    /// The batch driven by controllers from `factory` (one per worker thread) instead of the
    /// named one.
    ///
    /// # Errors
    /// The factory's error for the nominal robot.
    pub fn with_controller(
        self,
        factory: impl Fn(&Robot) -> twin_core::Result<Box<dyn Controller>> + Send + Sync + 'static,
    ) -> Result<Batch> {
        self.with_controller_factory(Arc::new(factory))
    }

    fn with_controller_factory(mut self, factory: Arc<ControllerFactory>) -> Result<Batch> {
        // Made once here so a bad controller fails the batch before any episode runs.
        self.controller_name = factory(&self.robot)?.name().to_string();
        self.options.controller = self.controller_name.clone();
        self.controller = factory;
        Ok(self)
    }

    /// The batch driven by controllers that come with checks of their own, from `factory` (one
    /// pair per worker thread), instead of the named controller.
    ///
    /// # Errors
    /// The factory's error for the nominal robot.
    pub fn with_driver(
        mut self,
        factory: impl Fn(&Robot) -> twin_core::Result<(Box<dyn Controller>, Vec<Box<dyn Check>>)> + Send + Sync + 'static,
    ) -> Result<Batch> {
        // Made once here so a bad controller fails the batch before any episode runs.
        let (controller, checks) = factory(&self.robot)?;
        self.controller_name = controller.name().to_string();
        self.options.controller = self.controller_name.clone();
        let verdicts = checks.iter().map(|c| c.verdict()).collect();
        drop((controller, checks));
        self.driver = Some((Arc::new(factory), verdicts));
        Ok(self)
    }

    /// The batch with checks from `factory` (one set per worker thread).
    ///
    /// # Errors
    /// The factory's error for the nominal robot.
    pub fn with_checks(
        mut self,
        factory: impl Fn(&Robot) -> twin_core::Result<Vec<Box<dyn Check>>> + Send + Sync + 'static,
    ) -> Result<Batch> {
        factory(&self.robot)?;
        self.checks = Some(Arc::new(factory));
        Ok(self)
    }

    /// The batch with scripted disturbances from `factory` in every episode (made per episode
    /// on its model), besides the spec's random pushes.
    pub fn with_disturbances(
        mut self,
        factory: impl Fn(&Model) -> Vec<Box<dyn Disturbance>> + Send + Sync + 'static,
    ) -> Batch {
        self.disturbances = Some(Arc::new(factory));
        self
    }

    /// The batch on a new terrain per episode: `terrain` (the nominal model's, as
    /// `twin_scenario::Scenario::robot` built it) with its seed drawn from (its seed, the
    /// master seed, the episode index), written into the episode's model, the robot seated on
    /// it. Only the kinds with random parts (rough ground, obstacles) change.
    pub fn with_terrain(mut self, terrain: twin_core::terrain::TerrainOptions) -> Batch {
        self.terrain = matches!(terrain.kind.as_str(), "rough" | "obstacles").then_some(terrain);
        self
    }

    /// The batch run as `scenario` says (`twin randomize --scenario`): the scenario's
    /// controller, with its options, on each worker; its checks deciding each episode's success;
    /// its scripted pushes besides the spec's random ones; a new terrain per episode
    /// ([`Batch::with_terrain`]). The nominal robot should be `scenario.robot(..)` (its armature,
    /// friction and terrain).
    ///
    /// # Errors
    /// The scenario's controller or check error for the nominal robot.
    pub fn with_scenario(self, scenario: Arc<twin_scenario::Scenario>) -> Result<Batch> {
        let logs = std::env::temp_dir().join("twin-controller-logs");
        self.with_scenario_logs(scenario, &logs)
    }

    /// [`Batch::with_scenario`], an external controller's process output going to
    /// `logs/worker-<k>.log` (one log per worker, each process start marked in it).
    ///
    /// # Errors
    /// As [`Batch::with_scenario`].
    pub fn with_scenario_logs(self, scenario: Arc<twin_scenario::Scenario>, logs: &std::path::Path) -> Result<Batch> {
        let (for_checks, for_pushes) = (scenario.clone(), scenario.clone());
        let batch = match scenario.terrain.clone() {
            Some(t) => self.with_terrain(t),
            None => self,
        };
        let batch = if scenario.is_external() {
            batch.with_external(&scenario, logs)?
        } else {
            batch.with_controller(move |r| scenario.controller(&r.model))?
        };
        Ok(batch
            .with_checks(move |r| {
                let check: Box<dyn Check> = Box::new(for_checks.check(&r.model)?);
                Ok(vec![check])
            })?
            .with_disturbances(move |m| {
                for_pushes.disturbances(m).into_iter().map(|d| Box::new(d) as Box<dyn Disturbance>).collect()
            }))
    }

    /// The scenario's external controller ([`twin_bridges::external`]) on each worker: a domain,
    /// a bridge and a process of its own.
    #[cfg(feature = "ros")]
    fn with_external(self, scenario: &twin_scenario::Scenario, logs: &std::path::Path) -> Result<Batch> {
        let Some(options) = scenario.ros.clone() else {
            return Err(Error::Options(format!(
                "{}: controller = \"ros\" needs a [ros] table",
                scenario.path.display()
            )));
        };
        let folder = scenario.folder();
        let logs = logs.to_path_buf();
        let workers = std::sync::atomic::AtomicU64::new(0);
        self.with_driver(move |r| {
            let k = workers.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let log = logs.join(format!("worker-{k}.log"));
            let (controller, health) = twin_bridges::external::external(r, &options, &folder, &log)?;
            Ok((Box::new(controller) as Box<dyn Controller>, vec![Box::new(health) as Box<dyn Check>]))
        })
    }

    #[cfg(not(feature = "ros"))]
    fn with_external(self, _scenario: &twin_scenario::Scenario, _logs: &std::path::Path) -> Result<Batch> {
        Err(twin_core::Error::FeatureMissing {
            feature: "ros",
            what: "controller = \"ros\" (your ROS 2 node through the live bridge)".into(),
        }
        .into())
    }

    /// Name of the controller.
    pub fn controller_name(&self) -> &str {
        &self.controller_name
    }

    /// The verdicts of the batch's checks before any episode (empty without checks): their
    /// names and the measurements each one reports, which are the CSV's check columns.
    ///
    /// # Errors
    /// The check factory's error.
    pub fn check_verdicts(&self) -> Result<Vec<Verdict>> {
        let mut verdicts = self.driver.as_ref().map(|(_, v)| v.clone()).unwrap_or_default();
        if let Some(f) = &self.checks {
            verdicts.extend(f(&self.robot)?.iter().map(|c| c.verdict()));
        }
        Ok(verdicts)
    }

    /// Names of the bodies counted as feet.
    pub fn feet(&self) -> Vec<String> {
        self.robot.body_names(&self.robot.feet)
    }

    /// Number of simulation steps of a full episode.
    pub fn steps_per_episode(&self) -> u64 {
        (self.options.duration_secs / self.nominal.timestep_secs()).round() as u64
    }
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
    /// Foot touch-downs (a foot's contact with the ground starting after at least
    /// [`twin_core::engine::observers::TOUCHDOWN_MIN_AIR_SECS`] in the air).
    pub steps_taken: u64,
    /// Largest tilt of the base from upright, radians.
    pub max_tilt_rad: f64,
    /// Time with at least one command at its limit, seconds.
    pub saturation_secs: f64,
    /// Actuator work ∫ Σ|τ·q̇| dt, joules.
    pub energy_j: f64,
    /// Drawn parameters, one per layout column.
    pub params: Vec<f64>,
    /// Verdicts of the batch's checks (empty without checks), in check order.
    pub checks: Vec<Verdict>,
}

impl EpisodeResult {
    /// Neither fell nor diverged, and every check passed.
    pub fn success(&self) -> bool {
        !self.fell && !self.unstable && self.checks.iter().all(|c| c.passed)
    }

    /// Names of the checks that failed.
    pub fn failed_checks(&self) -> Vec<&str> {
        self.checks.iter().filter(|c| !c.passed).map(|c| c.name.as_str()).collect()
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

/// Fills a [`Trajectory`]: one row per step, at the step's start time t.
struct TrajectoryRows<'a> {
    trajectory: &'a mut Trajectory,
    base: Option<usize>,
}

impl Observer for TrajectoryRows<'_> {
    fn start(&mut self, model: &Model, _data: &twin_core::mj::Data) -> twin_core::Result<()> {
        let nu = twin_core::control::Actuation::of(model).len(model);
        self.trajectory.columns = ["time_secs", "base_x_m", "base_y_m", "base_z_m", "tilt_rad"]
            .iter()
            .map(|s| s.to_string())
            .chain((0..model.nq()).map(|i| format!("qpos[{i}]")))
            .chain((0..nu).map(|i| format!("command[{i}]")))
            .collect();
        self.trajectory.rows.clear();
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        let data = step.data;
        let p = self.base.map_or([0.0; 3], |b| data.xpos()[b]);
        let tilt = self.base.map_or(0.0, |b| Fall::tilt_rad(data, b));
        let mut row = vec![step.time_secs, p[0], p[1], p[2], tilt];
        row.extend_from_slice(step.qpos);
        row.extend_from_slice(step.command);
        self.trajectory.rows.push(row);
        Ok(Flow::Continue)
    }
}

/// Episode `index`'s terrain: `terrain` with a seed from (its seed, the master seed, the
/// index), written into the draw's model, the robot's start raised or lowered by as much as the
/// ground under its feet differs from the nominal terrain's.
fn episode_terrain(
    batch: &Batch,
    terrain: &twin_core::terrain::TerrainOptions,
    index: u64,
    draw: &mut Draw,
) -> Result<()> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(terrain.seed ^ batch.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(index);
    let options = twin_core::terrain::TerrainOptions { seed: rng.random(), ..terrain.clone() };
    let geometry = options.build();
    draw.model = geometry.write_into(&draw.model)?;
    let lift = twin_core::terrain::seat_lift(&draw.model, &batch.layout.home_qpos, &geometry, &batch.robot.feet)?;
    if let Some(free) = draw.model.free_joint()
        && lift.abs() > 1e-9
    {
        draw.init_qpos[free.qpos_adr + 2] += lift;
    }
    Ok(())
}

/// Per-thread state: the rollout engine (one `Data` reused across episodes), the controller,
/// the checks and the touch-down counter.
pub struct Worker {
    engine: Engine,
    controller: Box<dyn Controller>,
    checks: Vec<Box<dyn Check>>,
    touchdowns: Touchdowns,
}

impl Worker {
    /// A worker for `batch`.
    ///
    /// # Errors
    /// [`Error::Core`] from the controller or check factory.
    pub fn new(batch: &Batch) -> Result<Worker> {
        let (controller, mut checks) = match &batch.driver {
            Some((f, _)) => f(&batch.robot)?,
            None => ((batch.controller)(&batch.robot)?, Vec::new()),
        };
        if let Some(f) = &batch.checks {
            checks.extend(f(&batch.robot)?);
        }
        Ok(Worker {
            engine: Engine::new(),
            controller,
            checks,
            touchdowns: Touchdowns::new(&batch.nominal, &batch.robot.feet),
        })
    }

    /// The simulation as the last episode left it.
    pub fn data(&self) -> Option<&twin_core::mj::Data> {
        self.engine.data()
    }

    /// Runs episode `index` of `batch`; with `trajectory`, records every step.
    ///
    /// A MuJoCo error or divergence during the episode is a result (`unstable`), not an
    /// error.
    ///
    /// # Errors
    /// [`Error::Apply`] if the drawn parameters can't be applied, [`Error::Episode`] if the
    /// controller or MuJoCo fails on the episode's robot (resetting it, a controller's error).
    pub fn run(&mut self, batch: &Batch, index: u64, trajectory: Option<&mut Trajectory>) -> Result<EpisodeResult> {
        self.run_recorded(batch, index, trajectory, None)
    }

    /// [`Worker::run`], also showing every step to `recording`: a recorder (MCAP topics / rerun,
    /// `twin_core::sim::Recording`, stamped with each step's start time) or any other observer
    /// (e.g. `twin_core::engine::replay::InputLog`), after the fall and divergence detection and
    /// the metrics. Recording does not change the episode.
    ///
    /// # Errors
    /// As [`Worker::run`]; the recording's errors (e.g. a write that failed).
    pub fn run_recorded(
        &mut self,
        batch: &Batch,
        index: u64,
        trajectory: Option<&mut Trajectory>,
        recording: Option<&mut dyn Observer>,
    ) -> Result<EpisodeResult> {
        let mut param_rng = episode_rng(batch.seed, index, 0);
        let mut draw = batch.layout.draw(&batch.nominal, index, &mut param_rng)?;
        if let Some(t) = &batch.terrain {
            episode_terrain(batch, t, index, &mut draw)?;
        }
        self.rollout(batch, index, draw, trajectory, recording)
    }

    fn rollout(
        &mut self,
        batch: &Batch,
        index: u64,
        draw: Draw,
        trajectory: Option<&mut Trajectory>,
        recording: Option<&mut dyn Observer>,
    ) -> Result<EpisodeResult> {
        let model = Arc::new(draw.model);
        let episode = Episode {
            initial_qpos: Some(draw.init_qpos),
            steps: batch.steps_per_episode(),
            // The robot's IMU bias processes (twin's one sensor model, `twin_core::sim::sensor_model`)
            // with the drawn white noise, bias and latency.
            sensors: SensorModel {
                qpos_noise_std: draw.qpos_noise_std,
                sensor_noise_std: draw.sensor_noise_std,
                sensor_bias: draw.sensor_bias,
                bias_processes: twin_core::sim::sensor_model(&batch.robot).bias_processes,
                latency_steps: draw.latency_steps,
            },
            command_scale: draw.command_scale,
        };
        let mut push =
            draw.push_interval_secs.map(|every| Push::new(every, draw.push_speed_mps, batch.layout.push_body));
        let mut scripted = batch.disturbances.as_ref().map_or_else(Vec::new, |f| f(&model));
        let mut disturbances: Vec<&mut dyn Disturbance> = Vec::new();
        if let Some(p) = push.as_mut() {
            disturbances.push(p);
        }
        for d in scripted.iter_mut() {
            disturbances.push(d.as_mut());
        }
        let mut divergence = Divergence::default();
        let mut saturation = Saturation::default();
        let mut energy = Energy::default();
        let fall_options =
            FallOptions { height_fraction: batch.options.fall_height_fraction, tilt_rad: batch.options.fall_tilt_rad };
        let mut fall = Fall::new(fall_options);
        let mut rows = trajectory.map(|t| TrajectoryRows { trajectory: t, base: batch.robot.base_body() });
        let mut observers: Vec<&mut dyn Observer> =
            vec![&mut divergence, &mut saturation, &mut energy, &mut self.touchdowns, &mut fall];
        if let Some(r) = recording {
            observers.push(r);
        }
        if let Some(r) = rows.as_mut() {
            observers.push(r);
        }
        for c in self.checks.iter_mut() {
            observers.push(c.as_mut());
        }
        let mut rng = episode_rng(batch.seed, index, 1);
        let outcome = self
            .engine
            .run(&model, &episode, self.controller.as_mut(), &mut disturbances, &mut observers, &mut rng)
            .map_err(|source| Error::Episode { episode: index, seed: batch.seed, source: Box::new(source) })?;
        drop(observers);

        let (unstable, unstable_reason) = match (&outcome.physics_error, &divergence.reason) {
            (Some(e), _) => (true, e.to_string()),
            (None, Some(reason)) => (true, reason.clone()),
            (None, None) => (false, String::new()),
        };
        let mut distance_m = 0.0;
        if let (Some(b), Some(p0), Some(data)) = (batch.robot.base_body(), fall.start_pos, self.engine.data()) {
            let p = data.xpos()[b];
            distance_m = ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2)).sqrt();
            if !distance_m.is_finite() {
                distance_m = 0.0;
            }
        }
        let sim_secs = outcome.sim_secs;
        Ok(EpisodeResult {
            index,
            fell: fall.fell(),
            fall_time_secs: fall.fall_time_secs,
            unstable,
            unstable_reason,
            sim_secs,
            distance_m,
            avg_speed_mps: if sim_secs > 0.0 { distance_m / sim_secs } else { 0.0 },
            steps_taken: self.touchdowns.count,
            max_tilt_rad: fall.max_tilt_rad,
            saturation_secs: saturation.secs,
            energy_j: energy.joules,
            params: draw.values,
            checks: self.checks.iter().map(|c| c.verdict()).collect::<Vec<Verdict>>(),
        })
    }
}
