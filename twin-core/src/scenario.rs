//! Scenario files: a small TOML naming the model, physics options, controller and its
//! parameters, duration, disturbances (pushes) and checks with thresholds. `twin sim
//! --scenario FILE` runs one and prints each check as PASS/FAIL with its numbers.
//!
//! ```toml
//! model = "../models/humanoid.urdf"  # relative to this file; default: the shipped humanoid
//! duration = 40.0                    # simulated seconds
//! controller = "walk"                # walk | pd-hold | passive
//! armature = 0.01                    # joint armature, kg·m² (default: walk::WALK_ARMATURE)
//! # friction = 0.8                   # sliding friction of every geom (default: the model's)
//!
//! [walk]                             # walk::WalkOptions, by field name
//! vx = 0.3
//!
//! [[push]]                           # a force on a body (default: the floating base)
//! time = 5.0
//! duration = 0.1
//! force = [0.0, 80.0, 0.0]           # N, world frame
//!
//! [checks]                           # each present threshold is a PASS/FAIL line
//! falls = 0
//! min_forward = 10.0
//! ```
//!
//! Grasping scenarios (`controller = "grasp"`, see `scenarios/grasp.toml`) add a world, the
//! contact model, where the cup starts, the grasper's options and the grasp checks:
//!
//! ```toml
//! world = "../models/table_cup.world" # composed with the robot (relative to this file)
//! impratio = 10.0                     # elliptic friction cones with this impratio
//!
//! randomize = "grasp_randomize.toml"  # spec of `twin randomize --scenario` (without --config)
//!
//! [cup]                               # where the cup starts: x y on the table, world, m
//! position = [0.38, -0.12]
//!
//! [grasp]                             # grasp::GraspOptions, by field name
//! grip_force_n = 8.0
//!
//! [checks]
//! min_lift_m = 0.1
//! min_hold_secs = 2.0
//! ```
//!
//! Walking scenarios may put the robot on terrain (see [`crate::terrain`] for every kind and
//! key); the robot starts seated on it:
//!
//! ```toml
//! [terrain]                           # terrain::TerrainOptions, by field name
//! kind = "slope"                      # flat | rough | slope | steps | stairs | obstacles | gaps
//! slope_deg = 5.0
//! difficulty = 1.0                    # 0: flat … 1: the parameters as written
//! ```
//!
//! Unknown keys, wrong types and impossible values are errors naming the file, the line and the
//! key.
//!
//! On the rollout engine ([`crate::engine`]) a scenario is a controller
//! ([`Scenario::controller`]), disturbances ([`Scenario::disturbances`]: its pushes) and an
//! observer that measures the gait and checks it ([`Scenario::check`], a
//! [`crate::engine::Check`]); `twin sim` and `twin randomize` run the same pieces.

use crate::control::{Controller, ControllerOptions};
use crate::engine::disturb::TimedForce;
use crate::engine::{Check, Flow, Measurement, Observer, StepView};
use crate::error::{Error, Result};
use crate::mj::{Data, JointType, Model, ObjType};
use crate::robot::Robot;
use crate::walk::{GaitMetrics, GaitSummary, GaitTargets, WALK_ARMATURE, WalkOptions};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A push: a constant force on a body for a while.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Push {
    /// Start, simulated seconds.
    pub time: f64,
    /// Duration, seconds (default: 0.1).
    #[serde(default = "default_push_secs")]
    pub duration: f64,
    /// Force, world frame, N.
    pub force: [f64; 3],
    /// Body pushed (default: the floating base).
    #[serde(default)]
    pub body: Option<String>,
}

fn default_push_secs() -> f64 {
    0.1
}

/// Thresholds on [`GaitSummary`]; each one present is checked.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checks {
    /// Most falls allowed (0 or 1 in a single run).
    pub falls: Option<u32>,
    /// Least displacement along the initial heading, m.
    pub min_forward: Option<f64>,
    /// Largest lateral drift (absolute), m.
    pub max_lateral_drift: Option<f64>,
    /// Largest net displacement, m (standing).
    pub max_distance: Option<f64>,
    /// Least average speed, m/s.
    pub min_average_speed: Option<f64>,
    /// Largest foot slide in one stance, m.
    pub max_slip: Option<f64>,
    /// Largest mean foot slide per stance, m.
    pub max_mean_slip: Option<f64>,
    /// Largest RMS velocity-tracking error, m/s.
    pub max_velocity_error: Option<f64>,
    /// Least heading change, degrees (signed as the command: a negative threshold asks for at
    /// least that much turning right).
    pub min_turn_deg: Option<f64>,
    /// Least number of steps.
    pub min_steps: Option<u64>,
    /// Largest RMS step-length error, m.
    pub max_step_length_error: Option<f64>,
    /// Largest cost of transport.
    pub max_cost_of_transport: Option<f64>,
    /// Grasp: least clearance between the arms and the rest of the robot, and no robot contact
    /// with the world other than feet and gripper–cup, m (0: touching fails).
    pub min_clearance_m: Option<f64>,
    /// Grasp: largest finger–cup normal force of one finger, N.
    pub max_grip_force_n: Option<f64>,
    /// Grasp: least mean finger–cup normal force of each finger while the cup is held up, N.
    pub min_grip_force_n: Option<f64>,
    /// Grasp: largest cup displacement in the grasp frame after the lift started (the grasp
    /// frame, once at the cup, rose 1 cm), m.
    pub max_slip_m: Option<f64>,
    /// Grasp: largest cup tilt in the grasp frame after the lift started, degrees.
    pub max_tilt_deg: Option<f64>,
    /// Grasp: least margin of the CoM's ground projection inside the support polygon, m.
    pub min_com_margin_m: Option<f64>,
    /// Grasp: least cup height above its start, held for `min_hold_secs` at the end of the
    /// run, m.
    pub min_lift_m: Option<f64>,
    /// Grasp: how long the cup must stay lifted at the end of the run, s (default with
    /// `min_lift_m`: 2).
    pub min_hold_secs: Option<f64>,
}

impl Checks {
    /// Whether any grasp threshold is set (a [`crate::grasp::GraspCheck`] then runs).
    pub fn has_grasp(&self) -> bool {
        self.min_clearance_m.is_some()
            || self.max_grip_force_n.is_some()
            || self.min_grip_force_n.is_some()
            || self.max_slip_m.is_some()
            || self.max_tilt_deg.is_some()
            || self.min_com_margin_m.is_some()
            || self.min_lift_m.is_some()
            || self.min_hold_secs.is_some()
    }
}

/// Where a scene object (the cup) starts.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// The object's body (default: `cup`).
    #[serde(default = "default_cup")]
    pub body: String,
    /// Its x y, world frame, m (height and orientation: the world file's).
    pub position: [f64; 2],
}

fn default_cup() -> String {
    "cup".into()
}

/// One check's verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// Check name (its key).
    pub name: &'static str,
    /// Measured value.
    pub value: f64,
    /// `<=` or `>=`.
    pub op: &'static str,
    /// Threshold.
    pub threshold: f64,
    /// Whether it passed.
    pub passed: bool,
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {:<22} {:.4} {} {}",
            if self.passed { "PASS" } else { "FAIL" },
            self.name,
            self.value,
            self.op,
            self.threshold
        )
    }
}

#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    model: Option<PathBuf>,
    duration: f64,
    #[serde(default)]
    seed: u64,
    #[serde(default = "default_controller")]
    controller: String,
    armature: Option<f64>,
    friction: Option<f64>,
    #[serde(default)]
    walk: WalkOptions,
    #[serde(default)]
    push: Vec<Push>,
    #[serde(default)]
    checks: Checks,
    world: Option<PathBuf>,
    impratio: Option<f64>,
    cup: Option<Placement>,
    #[serde(default)]
    grasp: crate::grasp::GraspOptions,
    randomize: Option<PathBuf>,
    terrain: Option<crate::terrain::TerrainOptions>,
}

fn default_controller() -> String {
    "walk".into()
}

/// A loaded scenario (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The file.
    pub path: PathBuf,
    /// Model file, resolved against the scenario's folder (`None`: the caller's default).
    pub model: Option<PathBuf>,
    /// Simulated seconds.
    pub duration_secs: f64,
    /// Seed (sensor noise of recordings).
    pub seed: u64,
    /// Controller name.
    pub controller: String,
    /// Joint armature given to every hinge/slide joint with less, kg·m².
    pub armature: f64,
    /// Sliding friction of every geom, if set.
    pub friction: Option<f64>,
    /// Walking options.
    pub walk: WalkOptions,
    /// Pushes.
    pub pushes: Vec<Push>,
    /// Checks.
    pub checks: Checks,
    /// World composed with the robot, resolved against the scenario's folder.
    pub world: Option<PathBuf>,
    /// Elliptic friction cones with this impratio, if set.
    pub impratio: Option<f64>,
    /// Where the cup starts, if moved.
    pub cup: Option<Placement>,
    /// Grasping options.
    pub grasp: crate::grasp::GraspOptions,
    /// The randomization spec `twin randomize --scenario` uses without `--config`, resolved
    /// against the scenario's folder.
    pub randomize: Option<PathBuf>,
    /// The ground, if not the flat floor.
    pub terrain: Option<crate::terrain::TerrainOptions>,
}

/// 1-based line of byte `offset` in `text`.
fn line_at(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

/// Line of `key = …` in table `section` (`None`: top level), 1-based.
fn line_of_key(text: &str, section: Option<&str>, key: &str) -> Option<usize> {
    let mut current: Option<String> = None;
    for (i, line) in text.lines().enumerate() {
        let l = line.trim();
        if l.starts_with('[') {
            current = Some(l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
            continue;
        }
        if current.as_deref() == section
            && let Some((k, _)) = l.split_once('=')
            && k.trim() == key
        {
            return Some(i + 1);
        }
    }
    None
}

impl Scenario {
    /// Reads and checks `path`.
    ///
    /// # Errors
    /// [`Error::Io`] if it can't be read; [`Error::Scenario`] naming the line and key for
    /// unknown keys, wrong types and impossible values.
    pub fn load(path: impl AsRef<Path>) -> Result<Scenario> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        Scenario::parse(path, &text)
    }

    /// Parses `text` as the scenario file `path`.
    ///
    /// # Errors
    /// As [`Scenario::load`].
    pub fn parse(path: &Path, text: &str) -> Result<Scenario> {
        let file: File = toml::from_str(text).map_err(|e| {
            let line = e.span().map(|s| line_at(text, s.start));
            let key = line
                .and_then(|l| text.lines().nth(l - 1))
                .and_then(|l| l.split_once('='))
                .map(|(k, _)| k.trim().to_string());
            Error::Scenario { path: path.to_path_buf(), line, key, message: e.message().trim().to_string() }
        })?;
        let bad = |section: Option<&str>, key: &str, message: String| Error::Scenario {
            path: path.to_path_buf(),
            line: line_of_key(text, section, key),
            key: Some(match section {
                Some(s) => format!("{s}.{key}"),
                None => key.to_string(),
            }),
            message,
        };
        if !(file.duration > 0.0 && file.duration.is_finite()) {
            return Err(bad(None, "duration", format!("must be a positive number of seconds (got {})", file.duration)));
        }
        if !crate::control::CONTROLLERS.contains(&file.controller.as_str()) {
            return Err(bad(
                None,
                "controller",
                format!(
                    "unknown controller \"{}\" (available: {})",
                    file.controller,
                    crate::control::CONTROLLERS.join(", ")
                ),
            ));
        }
        if let Some(a) = file.armature
            && !(a >= 0.0 && a.is_finite())
        {
            return Err(bad(None, "armature", format!("must be a non-negative number of kg·m² (got {a})")));
        }
        if let Some(f) = file.friction
            && !(f >= 0.0 && f.is_finite())
        {
            return Err(bad(None, "friction", format!("must be a non-negative coefficient (got {f})")));
        }
        file.walk.validate().map_err(|(key, m)| bad(Some("walk"), key, m))?;
        file.grasp.validate().map_err(|(key, m)| bad(Some("grasp"), key, m))?;
        if let Some(t) = &file.terrain {
            t.validate().map_err(|(key, m)| bad(Some("terrain"), key, m))?;
            if file.world.is_some() && t.kind != "flat" {
                return Err(bad(None, "world", "a scenario has either a world or a [terrain], not both".into()));
            }
        }
        if let Some(r) = file.impratio
            && !(r > 0.0 && r.is_finite())
        {
            return Err(bad(None, "impratio", format!("must be a positive number (got {r})")));
        }
        if let Some(c) = &file.cup
            && !c.position.iter().all(|v| v.is_finite())
        {
            return Err(bad(Some("cup"), "position", "must be two finite numbers (x, y in metres)".into()));
        }
        for (i, p) in file.push.iter().enumerate() {
            if !(p.time >= 0.0 && p.duration > 0.0 && p.force.iter().all(|f| f.is_finite())) {
                return Err(Error::Scenario {
                    path: path.to_path_buf(),
                    line: None,
                    key: Some(format!("push[{i}]")),
                    message: "a push needs time ≥ 0, duration > 0 and a finite force".into(),
                });
            }
        }
        let resolve = |m: PathBuf| if m.is_absolute() { m } else { path.parent().unwrap_or(Path::new(".")).join(m) };
        let model = file.model.map(resolve);
        let world = file.world.map(resolve);
        let randomize = file.randomize.map(resolve);
        Ok(Scenario {
            path: path.to_path_buf(),
            model,
            duration_secs: file.duration,
            seed: file.seed,
            controller: file.controller,
            armature: file.armature.unwrap_or(WALK_ARMATURE),
            friction: file.friction,
            walk: file.walk,
            pushes: file.push,
            checks: file.checks,
            world,
            impratio: file.impratio,
            cup: file.cup,
            grasp: file.grasp,
            randomize,
            terrain: file.terrain,
        })
    }

    /// Loads the scenario's robot (`default_model` when it names none) with its physics
    /// options applied.
    ///
    /// # Errors
    /// As [`Robot::load`]; [`Error::Scenario`] for a push on a missing body.
    pub fn robot(&self, default_model: &Path) -> Result<Robot> {
        let path = self.model.clone().unwrap_or_else(|| default_model.to_path_buf());
        let convert = crate::convert::ConvertOptions { world: self.world.clone(), ..Default::default() };
        // A grasping scenario keeps its depth camera's noise in the model (camera user 0), where
        // `twin randomize` draws it per episode.
        let grasping = self.controller == "grasp";
        let mut extra = if grasping { "<size nuser_cam=\"1\"/>" } else { "" }.to_string();
        // Terrain: its geometry composed over the floor, the robot seated on it.
        let terrain = self.terrain.as_ref().filter(|t| t.kind != "flat").map(|t| t.build());
        if let Some(g) = &terrain {
            extra.push_str(&g.to_mjcf(crate::terrain::FLOOR_FRICTION));
        }
        let mut robot = Robot::load_with_extra(&path, &convert, &extra)?;
        if let Some(g) = &terrain {
            let (model, _lift) = crate::terrain::settle(&robot.model, g, &robot.feet).map_err(|e| Error::Scenario {
                path: self.path.clone(),
                line: None,
                key: Some("terrain".into()),
                message: format!("{e} ({})", path.display()),
            })?;
            robot = robot.with_model(Arc::new(model))?;
        }
        let mut model = prepare_model(&robot.model, self.armature, self.friction)?;
        if self.impratio.is_some() || self.cup.is_some() || grasping {
            let mut edit = model.edit()?;
            if grasping && let Some(cam) = model.id(ObjType::Camera, &self.grasp.camera) {
                edit.set_cam_user(cam, 0, self.grasp.camera_noise_std_m)?;
            }
            if let Some(r) = self.impratio {
                edit.set_elliptic_cone(r)?;
            }
            if let Some(c) = &self.cup {
                let missing = || Error::Scenario {
                    path: self.path.clone(),
                    line: None,
                    key: Some("cup.body".into()),
                    message: format!(
                        "the model has no free body \"{}\" with a keyframe `home`: compose a world with it (`world`)",
                        c.body
                    ),
                };
                let body = model.id(ObjType::Body, &c.body).ok_or_else(missing)?;
                let joint = (0..model.njnt())
                    .find(|&j| model.jnt_bodyid()[j] as usize == body && model.joint_type(j) == JointType::Free)
                    .ok_or_else(missing)?;
                let key = model.id(ObjType::Key, "home").ok_or_else(missing)?;
                edit.set_key_qpos(key, model.jnt_qposadr()[joint] as usize, &c.position)?;
            }
            model = edit.finish()?;
        }
        let robot = robot.with_model(Arc::new(model))?;
        for (i, p) in self.pushes.iter().enumerate() {
            if let Some(b) = &p.body
                && robot.model.id(ObjType::Body, b).is_none()
            {
                return Err(Error::Scenario {
                    path: self.path.clone(),
                    line: None,
                    key: Some(format!("push[{i}].body")),
                    message: format!("the model has no body \"{b}\""),
                });
            }
        }
        Ok(robot)
    }

    /// The scenario's controller for `model`, from twin's registry
    /// ([`crate::control::by_name_with`]) with the scenario's walking options.
    ///
    /// # Errors
    /// [`Error::Walk`] when the walker can't drive the model (e.g. unreachable steps); as
    /// [`crate::control::by_name_with`].
    pub fn controller(&self, model: &Model) -> Result<Box<dyn Controller>> {
        let options =
            ControllerOptions { walk: self.walk.clone(), grasp: self.grasp.clone(), ..ControllerOptions::default() };
        crate::control::by_name_with(&self.controller, model, &options)
    }

    /// What the gait should be.
    pub fn targets(&self) -> GaitTargets {
        GaitTargets {
            vx: self.walk.vx,
            vy: self.walk.vy,
            yaw_rate: self.walk.yaw_rate,
            step_length: self.walk.vx * self.walk.step_period,
            step_width: self.walk.step_width,
        }
    }

    /// The scenario's pushes on `model`, as disturbances of the rollout engine.
    pub fn disturbances(&self, model: &Model) -> Vec<TimedForce> {
        let base = model.free_joint().map_or(0, |f| f.body);
        self.pushes
            .iter()
            .map(|p| {
                let body = p.body.as_deref().and_then(|b| model.id(ObjType::Body, b)).unwrap_or(base);
                TimedForce::new(p.time, p.duration, p.force, body)
            })
            .collect()
    }

    /// The gait metrics of a run on `model` (an observer of the rollout engine).
    ///
    /// # Errors
    /// As [`GaitMetrics::for_model`].
    pub fn metrics(&self, model: &Model) -> Result<GaitMetrics> {
        GaitMetrics::for_model(model, &self.walk.bodies, self.targets())
    }

    /// The scenario's checks on `model`: an observer that measures the gait and gives one
    /// verdict over every threshold of `[checks]`.
    ///
    /// # Errors
    /// As [`GaitMetrics::for_model`].
    pub fn check(&self, model: &Model) -> Result<ScenarioCheck> {
        let grasp = self.checks.has_grasp().then(|| {
            crate::grasp::GraspCheck::new(
                self.checks.clone(),
                &self.cup.as_ref().map_or_else(default_cup, |c| c.body.clone()),
                self.grasp.grasp_bodies.clone(),
            )
        });
        let collisions = self.terrain.as_ref().map(|_| crate::terrain::Collisions::new(model));
        Ok(ScenarioCheck { metrics: self.metrics(model)?, checks: self.checks.clone(), grasp, collisions })
    }

    /// Each check against `summary`.
    pub fn evaluate(&self, summary: &GaitSummary) -> Vec<Verdict> {
        self.checks.evaluate(summary)
    }
}

impl Checks {
    /// Each threshold present against `summary`; a fall fails every non-empty set of checks.
    pub fn evaluate(&self, summary: &GaitSummary) -> Vec<Verdict> {
        let c = self;
        let mut out = Vec::new();
        let mut at_most = |name: &'static str, value: f64, threshold: Option<f64>| {
            if let Some(t) = threshold {
                out.push(Verdict { name, value, op: "<=", threshold: t, passed: value <= t });
            }
        };
        at_most("falls", f64::from(u8::from(summary.fell)), c.falls.map(f64::from));
        at_most("max_lateral_drift", summary.lateral_m.abs(), c.max_lateral_drift);
        at_most("max_distance", summary.distance_m, c.max_distance);
        at_most("max_slip", summary.slip_max_m, c.max_slip);
        at_most("max_mean_slip", summary.slip_mean_m, c.max_mean_slip);
        at_most("max_velocity_error", summary.velocity_rms_error_mps, c.max_velocity_error);
        at_most("max_step_length_error", summary.step_length_rms_error_m, c.max_step_length_error);
        at_most("max_cost_of_transport", summary.cost_of_transport, c.max_cost_of_transport);
        let mut at_least = |name: &'static str, value: f64, threshold: Option<f64>| {
            if let Some(t) = threshold {
                out.push(Verdict { name, value, op: ">=", threshold: t, passed: value >= t });
            }
        };
        at_least("min_forward", summary.forward_m, c.min_forward);
        at_least("min_average_speed", summary.average_speed_mps, c.min_average_speed);
        at_least("min_steps", summary.steps as f64, c.min_steps.map(|s| s as f64));
        if let Some(t) = c.min_turn_deg {
            let sign = if t < 0.0 { -1.0 } else { 1.0 };
            let turned = summary.yaw_change_rad.to_degrees();
            out.push(Verdict {
                name: "min_turn_deg",
                value: turned,
                op: ">=",
                threshold: t,
                passed: sign * turned >= sign * t,
            });
        }
        // A fall fails every run that has checks, whether or not `falls` is among them.
        if summary.fell && c.falls.is_none() && !out.is_empty() {
            out.push(Verdict { name: "falls", value: 1.0, op: "<=", threshold: 0.0, passed: false });
        }
        out
    }
}

/// Measures the gait during a rollout and checks it against a scenario's thresholds: the
/// scenario's [`Check`] for `twin sim --scenario` and `twin randomize --scenario`.
#[derive(Debug, Clone)]
pub struct ScenarioCheck {
    /// The gait metrics so far.
    pub metrics: GaitMetrics,
    checks: Checks,
    /// The grasp checks, when the scenario has grasp thresholds.
    pub grasp: Option<crate::grasp::GraspCheck>,
    /// The robot's first run-in with the terrain's boxes, when the scenario has terrain.
    pub collisions: Option<crate::terrain::Collisions>,
}

impl ScenarioCheck {
    /// Each threshold's verdict on the gait so far.
    pub fn verdicts(&self) -> Vec<Verdict> {
        let mut v = self.checks.evaluate(&self.metrics.summary());
        if let Some(g) = &self.grasp {
            v.extend(g.verdicts());
        }
        v
    }
}

impl Observer for ScenarioCheck {
    fn start(&mut self, model: &Model, data: &Data) -> Result<()> {
        if let Some(g) = self.grasp.as_mut() {
            g.start(model, data)?;
        }
        if let Some(c) = self.collisions.as_mut() {
            c.start(model, data)?;
        }
        self.metrics.start(model, data)
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        if let Some(g) = self.grasp.as_mut() {
            g.observe(step)?;
        }
        if let Some(c) = self.collisions.as_mut() {
            c.observe(step)?;
        }
        self.metrics.observe(step)
    }
}

impl ScenarioCheck {
    /// The robot's first collision with the terrain, if any.
    pub fn collision(&self) -> Option<&crate::terrain::Collision> {
        self.collisions.as_ref().and_then(|c| c.first.as_ref())
    }
}

impl Check for ScenarioCheck {
    fn name(&self) -> &str {
        "scenario"
    }

    fn verdict(&self) -> crate::engine::Verdict {
        let verdicts = self.verdicts();
        let failed: Vec<&str> = verdicts.iter().filter(|v| !v.passed).map(|v| v.name).collect();
        crate::engine::Verdict {
            name: "scenario".into(),
            passed: failed.is_empty(),
            // The whole gait summary (what `twin randomize` tabulates per episode), then the
            // grasp numbers, which the gait summary lacks.
            metrics: self
                .metrics
                .summary()
                .measurements()
                .into_iter()
                // The episode's own fall detection reports falls.
                .filter(|m| m.name != "fell")
                .chain(self.grasp.iter().flat_map(|g| g.verdicts()).map(|v| Measurement::new(v.name, v.value, "")))
                .collect(),
            details: verdicts
                .iter()
                .map(ToString::to_string)
                .chain(self.collision().map(|c| format!("collision: {c}")))
                .collect(),
            cause: (!failed.is_empty()).then(|| match self.collision() {
                // Running into the terrain, not a mystery fall.
                Some(c) => format!("failed: {} (first collision: {c})", failed.join(", ")),
                None => format!("failed: {}", failed.join(", ")),
            }),
        }
    }
}

/// `model` with every hinge/slide joint's armature raised to at least `armature` (kg·m²) and,
/// when given, every geom's sliding friction set to `friction`.
///
/// # Errors
/// [`Error::InvalidEdit`]/[`Error::MuJoCo`] from the edit.
pub fn prepare_model(model: &Model, armature: f64, friction: Option<f64>) -> Result<Model> {
    let mut edit = model.edit()?;
    for j in 0..model.njnt() {
        if matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
            let dof = model.jnt_dofadr()[j] as usize;
            if model.dof_armature()[dof] < armature {
                edit.set_dof_armature(dof, armature)?;
            }
        }
    }
    if let Some(mu) = friction {
        for g in 0..model.ngeom() {
            let f = model.geom_friction()[g];
            edit.set_geom_friction(g, [mu, f[1], f[2]])?;
        }
    }
    edit.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Scenario> {
        Scenario::parse(Path::new("s.toml"), text)
    }

    #[test]
    fn errors_name_the_file_line_and_key() {
        let e = parse("duration = 5.0\ncontroler = \"walk\"\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:2: `controler`") && e.contains("unknown field"), "{e}");
        let e = parse("duration = 5.0\n[walk]\nvx = \"fast\"\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:3: `vx`"), "{e}");
        let e = parse("duration = 5.0\n[walk]\nstep_period = -0.5\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:3: `walk.step_period`") && e.contains("positive"), "{e}");
        let e = parse("\nduration = 0\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:2: `duration`"), "{e}");
        let e = parse("duration = 1\n[checks]\nmin_speed = 0.3\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:3: `min_speed`"), "{e}");
        let s = parse("duration = 2\nmodel = \"robot.urdf\"\n[[push]]\ntime = 1\nforce = [0, 50, 0]\n").unwrap();
        assert_eq!(s.model.as_deref(), Some(Path::new("robot.urdf")));
        assert_eq!(s.pushes[0].duration, 0.1);
        assert_eq!(s.armature, WALK_ARMATURE);
    }

    #[test]
    fn grasp_keys_are_read_and_checked_with_their_lines() {
        let s = parse(
            "duration = 5\ncontroller = \"grasp\"\nworld = \"w.world\"\nimpratio = 10\nrandomize = \"r.toml\"\n\
             [cup]\nposition = [0.3, -0.1]\n[grasp]\ngrip_force_n = 6.0\n[checks]\nmin_lift_m = 0.1\n",
        )
        .unwrap();
        assert_eq!(s.world.as_deref(), Some(Path::new("w.world")));
        assert_eq!(s.randomize.as_deref(), Some(Path::new("r.toml")));
        assert_eq!(s.cup.as_ref().map(|c| (c.body.as_str(), c.position)), Some(("cup", [0.3, -0.1])));
        assert_eq!(s.grasp.grip_force_n, 6.0);
        assert!(s.checks.has_grasp());
        let e = parse("duration = 5\n[grasp]\n\ngrip_force_n = -1.0\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:4: `grasp.grip_force_n`") && e.contains("non-negative"), "{e}");
        let e = parse("duration = 5\n[grasp]\ngrip = 1.0\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:3: `grip`") && e.contains("unknown field"), "{e}");
        let e = parse("duration = 5\nimpratio = 0\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:2: `impratio`"), "{e}");
        let e = parse("duration = 5\n[cup]\nposition = [0.3]\n").unwrap_err().to_string();
        assert!(e.starts_with("s.toml:3: `position`"), "{e}");
    }

    #[test]
    fn checks_pass_and_fail_with_their_numbers() {
        let s = parse("duration = 1\n[checks]\nfalls = 0\nmin_forward = 10.0\nmax_slip = 0.01\n").unwrap();
        let summary = GaitSummary { forward_m: 12.0, slip_max_m: 0.05, ..GaitSummary::default() };
        let v = s.evaluate(&summary);
        assert_eq!(v.len(), 3);
        assert!(v.iter().find(|v| v.name == "min_forward").unwrap().passed);
        let slip = v.iter().find(|v| v.name == "max_slip").unwrap();
        assert!(!slip.passed);
        assert_eq!(slip.to_string(), "FAIL max_slip               0.0500 <= 0.01");
    }
}
