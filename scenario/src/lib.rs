//! Scenario files, twin's top floor: a small TOML naming the model, physics options, controller and its
//! parameters, duration, disturbances (pushes) and checks with thresholds. `twin sim
//! --scenario FILE` runs one and prints each check as PASS/FAIL with its numbers.
//!
//! ```toml
//! model = "../models/humanoid.urdf"  # relative to this file; default: the shipped humanoid
//! duration = 40.0                    # simulated seconds
//! controller = "walk"                # walk | pd-hold | passive
//! armature = 0.01                    # joint armature, kg·m² (default: walk::WALK_ARMATURE)
//! # friction = 0.8                   # sliding friction of every geom (default: the model's)
//! # contact_sensors = ["left_foot_link", "right_foot_link"]  # links given a contact sensor
//!                                    # (MuJoCo touch sensors over their collision geoms, as
//!                                    # `twin convert --contact-sensor`; default: none)
//!
//! [walk]                             # walk::WalkOptions, by field name; the gait options
//! vx = 0.3                           # not written here come from the robot (walk::derive)
//! # or a schedule, piecewise constant from each time (s, m/s, m/s, rad/s; walk::steer):
//! # commands = [[0.0, 0.25, 0.0, 0.0], [5.0, 0.0, 0.0, 0.4], [9.0, 0.0, 0.0, 0.0]]
//!
//! [[push]]                           # a force on a body (default: the floating base)
//! time = 5.0
//! duration = 0.1
//! force = [0.0, 80.0, 0.0]           # N, world frame
//!
//! [checks]                           # each present threshold is a PASS/FAIL line
//! falls = 0
//! min_forward = 10.0
//! # Tracking, any controller that gives position targets (pd-hold, position commands of a
//! # ROS node): commanded − actual joint position.
//! max_tracking_rms_rad = 0.05         # RMS of the worst-tracking joint, rad
//! max_tracking_error_rad = 0.2        # largest error of any joint at any step, rad
//! max_saturated_fraction = 0.1        # of the run with some actuator command at its limit
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
//! Your own ROS 2 node as the controller (`controller = "ros"`, see [`twin_bridges::external`] and
//! `scenarios/hold_pose.toml`), and what `twin test` asks of the scenario:
//!
//! ```toml
//! controller = "ros"
//! [ros]                               # external::RosOptions, by field name
//! command = "python3 controllers/hold_pose.py --ros-args -p use_sim_time:=true"
//! period_timeout_secs = 5.0
//! flood_commands_per_period = 10.0    # commands beyond one per period (averaged over
//! flood_window_secs = 1.0             #   this much simulated time) that fail the run
//!
//! [test]                              # TestOptions: `twin test`
//! episodes = 20
//! min_success_lower_95 = 0.8
//! ```
//!
//! Walking scenarios may put the robot on terrain (see [`twin_core::terrain`] for every kind and
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
//! On the rollout engine ([`twin_core::engine`]) a scenario is a controller
//! ([`Scenario::controller`]), disturbances ([`Scenario::disturbances`]: its pushes) and an
//! observer that measures the gait and checks it ([`Scenario::check`], a
//! [`twin_core::engine::Check`]); `twin sim` and `twin randomize` run the same pieces.

#![deny(unsafe_code)]

use std::path::{Path, PathBuf};
use std::sync::Arc;
pub use twin_controllers::checks::{Checks, Threshold};
use twin_controllers::registry::ControllerOptions;
use twin_controllers::walk::{GaitMetrics, GaitSummary, GaitTargets, WALK_ARMATURE, WalkOptions};
use twin_core::control::Controller;
use twin_core::engine::disturb::TimedForce;
use twin_core::engine::{Check, Flow, Measurement, Observer, StepView};
use twin_core::error::{Error, Result};
use twin_core::mj::{Data, JointType, Model, ObjType};
use twin_core::robot::Robot;

/// The `controller` of a scenario driven by the user's own ROS 2 node (see [`twin_bridges::external`]).
pub const EXTERNAL_CONTROLLER: &str = "ros";

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
    contact_sensors: Vec<String>,
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
    grasp: twin_controllers::grasp::GraspOptions,
    randomize: Option<PathBuf>,
    ros: Option<twin_bridges::external::RosOptions>,
    #[serde(default)]
    test: TestOptions,
    terrain: Option<twin_core::terrain::TerrainOptions>,
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
    /// Seed of the run's random stream (sensor noise and biases, random disturbances).
    pub seed: u64,
    /// Controller name.
    pub controller: String,
    /// Joint armature given to every hinge/slide joint with less, kg·m².
    pub armature: f64,
    /// Sliding friction of every geom, if set.
    pub friction: Option<f64>,
    /// Links given a contact sensor (`convert::ConvertOptions::contact_sensors`).
    pub contact_sensors: Vec<String>,
    /// Walking options.
    pub walk: WalkOptions,
    /// The `[walk]` keys the file (or the command line) gave: [`Scenario::fit_walk`] derives
    /// the others from the robot.
    pub walk_given: std::collections::BTreeSet<String>,
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
    pub grasp: twin_controllers::grasp::GraspOptions,
    /// The randomization spec `twin randomize --scenario` uses without `--config`, resolved
    /// against the scenario's folder.
    pub randomize: Option<PathBuf>,
    /// The external controller (`controller = "ros"`, [`twin_bridges::external`]).
    pub ros: Option<twin_bridges::external::RosOptions>,
    /// What `twin test` asks of this scenario.
    pub test: TestOptions,
    /// The ground, if not the flat floor.
    pub terrain: Option<twin_core::terrain::TerrainOptions>,
}

/// A scenario's `[test]` table: what `twin test` runs and asks.
///
/// ```toml
/// [test]
/// episodes = 20                 # randomized episodes (0: the nominal run only)
/// min_success_lower_95 = 0.8    # least lower bound of the success rate's 95 % Wilson interval
/// seed = 1                      # master seed of the randomized episodes
/// ```
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestOptions {
    /// Randomized episodes (spec: the scenario's `randomize` file, or twin's default spec)
    /// (default: 0, the nominal run only).
    #[serde(default)]
    pub episodes: u64,
    /// Least lower bound of the success rate's 95 % Wilson interval over the randomized
    /// episodes, 0–1 (default: 0.5 when `episodes` > 0).
    pub min_success_lower_95: Option<f64>,
    /// Master seed of the randomized episodes (default: 0).
    #[serde(default)]
    pub seed: u64,
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
    /// The scenario of a command line without a file: `controller` for `duration_secs`, every
    /// other key at its default (what a file with only these two keys gives), named
    /// `<command line>`.
    pub fn defaults(controller: &str, duration_secs: f64) -> Scenario {
        Scenario {
            path: PathBuf::from("<command line>"),
            model: None,
            duration_secs,
            seed: 0,
            controller: controller.to_string(),
            armature: WALK_ARMATURE,
            friction: None,
            contact_sensors: Vec::new(),
            walk: WalkOptions::default(),
            walk_given: Default::default(),
            pushes: Vec::new(),
            checks: Checks::default(),
            world: None,
            impratio: None,
            cup: None,
            grasp: twin_controllers::grasp::GraspOptions::default(),
            randomize: None,
            ros: None,
            test: TestOptions::default(),
            terrain: None,
        }
    }

    /// Reads and checks `path`.
    ///
    /// # Errors
    /// [`Error::File`] if it can't be read; [`Error::Scenario`] naming the line and key for
    /// unknown keys, wrong types and impossible values.
    pub fn load(path: impl AsRef<Path>) -> Result<Scenario> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| Error::io(path.to_path_buf(), source))?;
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
        let external = file.controller == EXTERNAL_CONTROLLER;
        if !external && !twin_controllers::registry::CONTROLLERS.contains(&file.controller.as_str()) {
            return Err(bad(
                None,
                "controller",
                format!(
                    "unknown controller \"{}\" (available: {}, or {EXTERNAL_CONTROLLER} for your own ROS 2 node with a [ros] table)",
                    file.controller,
                    twin_controllers::registry::CONTROLLERS.join(", ")
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
        match (&file.ros, external) {
            (Some(r), true) => r.validate().map_err(|(key, m)| bad(Some("ros"), key, m))?,
            (None, true) => {
                return Err(bad(
                    None,
                    "controller",
                    "controller = \"ros\" needs a [ros] table with the command that starts your node \
                     (e.g. command = \"python3 my_controller.py --ros-args -p use_sim_time:=true\")"
                        .into(),
                ));
            }
            (Some(_), false) => {
                return Err(bad(None, "controller", "a [ros] table is for controller = \"ros\"".into()));
            }
            (None, false) => {}
        }
        if let Some(p) = file.test.min_success_lower_95
            && !(0.0..=1.0).contains(&p)
        {
            return Err(bad(Some("test"), "min_success_lower_95", format!("must be within 0..=1 (got {p})")));
        }
        file.grasp.validate().map_err(|(key, m)| bad(Some("grasp"), key, m))?;
        file.checks.validate().map_err(|(key, m)| bad(Some("checks"), key, m))?;
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
        // The `[walk]` keys written (parsed once more as a plain table: serde's defaults hide them).
        let walk_given = toml::from_str::<toml::Table>(text)
            .ok()
            .and_then(|t| t.get("walk").and_then(|w| w.as_table()).map(|w| w.keys().cloned().collect()))
            .unwrap_or_default();
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
            contact_sensors: file.contact_sensors,
            walk: file.walk,
            walk_given,
            pushes: file.push,
            checks: file.checks,
            world,
            impratio: file.impratio,
            cup: file.cup,
            grasp: file.grasp,
            randomize,
            ros: file.ros,
            test: file.test,
            terrain: file.terrain,
        })
    }

    /// Whether the scenario's controller is an external ROS 2 node (`controller = "ros"`).
    pub fn is_external(&self) -> bool {
        self.controller == EXTERNAL_CONTROLLER
    }

    /// The folder of the scenario file (where relative paths and a `[ros]` command start).
    pub fn folder(&self) -> PathBuf {
        match self.path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// Loads the scenario's robot (`default_model` when it names none) with its physics
    /// options applied.
    ///
    /// # Errors
    /// As [`Robot::load`]; [`Error::Scenario`] for a push on a missing body.
    pub fn robot(&self, default_model: &Path) -> Result<Robot> {
        self.robot_with_delay_buffer(default_model, 0.0)
    }

    /// [`Scenario::robot`] with every actuator's command-history buffer spanning
    /// `delay_buffer_secs` (`ConvertOptions::delay_buffer_secs`: a randomized command delay).
    ///
    /// # Errors
    /// As [`Scenario::robot`].
    pub fn robot_with_delay_buffer(&self, default_model: &Path, delay_buffer_secs: f64) -> Result<Robot> {
        let path = self.model.clone().unwrap_or_else(|| default_model.to_path_buf());
        let convert = twin_core::convert::ConvertOptions {
            world: self.world.clone(),
            contact_sensors: self.contact_sensors.clone(),
            delay_buffer_secs,
            ..Default::default()
        };
        // A grasping scenario keeps its depth camera's noise in the model (camera user 0), where
        // `twin randomize` draws it per episode.
        let grasping = self.controller == "grasp";
        let mut extra = if grasping { "<size nuser_cam=\"1\"/>" } else { "" }.to_string();
        // Terrain: its geometry composed over the floor, the robot seated on it.
        let terrain = self.terrain.as_ref().filter(|t| t.kind != "flat").map(|t| t.build());
        if let Some(g) = &terrain {
            extra.push_str(&g.to_mjcf(twin_core::terrain::FLOOR_FRICTION));
        }
        let mut robot = Robot::load_with_extra(&path, &convert, &extra).map_err(|e| match e {
            // A link of `contact_sensors` the robot lacks: the scenario's key is what to mend.
            Error::Convert(twin_convert::Error::NoSuchLink { path: urdf, link, links }) => Error::Scenario {
                path: self.path.clone(),
                line: std::fs::read_to_string(&self.path).ok().and_then(|t| line_of_key(&t, None, "contact_sensors")),
                key: Some("contact_sensors".into()),
                message: format!(
                    "{} has no link \"{link}\" for a contact sensor: name one of its links: {}",
                    urdf.display(),
                    links.join(", ")
                ),
            },
            other => other,
        })?;
        if let Some(g) = &terrain {
            let (model, _lift) =
                twin_core::terrain::settle(&robot.model, g, &robot.feet).map_err(|e| Error::Scenario {
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

    /// The walking options for the robot `model` ([`WalkOptions::for_robot`]): every option the
    /// robot's proportions give ([`twin_controllers::walk::derive::DERIVED`]) that the scenario (or the
    /// command line, through [`Scenario::walk_given`]) does not set is derived from it, and
    /// counts as given from then on (a second call changes nothing). For the shipped humanoid
    /// they are the defaults. Only a walking scenario (`controller = "walk"`) is fitted.
    ///
    /// # Errors
    /// [`Error::Walk`] when the walker can't drive the model: no two legs with feet, or steps
    /// the legs can't reach (the message says what to change).
    pub fn fit_walk(&mut self, model: &Model) -> Result<()> {
        if self.controller != "walk" {
            return Ok(());
        }
        let given = self.walk_given.clone();
        self.walk = self.walk.for_robot(model, &|key| given.contains(key))?;
        self.walk_given.extend(twin_controllers::walk::derive::DERIVED.iter().map(|k| k.to_string()));
        Ok(())
    }

    /// The scenario's controller for `model`, from twin's registry
    /// ([`twin_controllers::registry::by_name_with`]) with the scenario's walking options.
    ///
    /// # Errors
    /// [`Error::Walk`] when the walker can't drive the model (e.g. unreachable steps); as
    /// [`twin_controllers::registry::by_name_with`].
    pub fn controller(&self, model: &Model) -> Result<Box<dyn Controller>> {
        if self.is_external() {
            return Err(Error::Options(format!(
                "{}: controller = \"ros\" is a process twin starts (twin_bridges::external), not one of twin's own",
                self.path.display()
            )));
        }
        let options =
            ControllerOptions { walk: self.walk.clone(), grasp: self.grasp.clone(), ..ControllerOptions::default() };
        twin_controllers::registry::by_name_with(&self.controller, model, &options)
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
        Ok(GaitMetrics::for_model(model, &self.walk.bodies, self.targets())?.with_commands(self.walk.commands.clone()))
    }

    /// The scenario's checks on `model`: an observer that measures the gait and gives one
    /// verdict over every threshold of `[checks]`.
    ///
    /// # Errors
    /// As [`GaitMetrics::for_model`].
    pub fn check(&self, model: &Model) -> Result<ScenarioCheck> {
        let grasp = self.checks.has_grasp().then(|| {
            twin_controllers::grasp::GraspCheck::new(
                self.checks.clone(),
                &self.cup.as_ref().map_or_else(default_cup, |c| c.body.clone()),
                self.grasp.grasp_bodies.clone(),
            )
        });
        let collisions = self.terrain.as_ref().map(|_| twin_core::terrain::Collisions::new(model));
        let tracking = self.checks.has_tracking().then(twin_core::tracking::Tracking::new);
        Ok(ScenarioCheck { metrics: self.metrics(model)?, checks: self.checks.clone(), grasp, collisions, tracking })
    }

    /// Each check against `summary`.
    pub fn evaluate(&self, summary: &GaitSummary) -> Vec<Threshold> {
        self.checks.evaluate(summary)
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
    pub grasp: Option<twin_controllers::grasp::GraspCheck>,
    /// The robot's first run-in with the terrain's boxes, when the scenario has terrain.
    pub collisions: Option<twin_core::terrain::Collisions>,
    /// Commanded against actual joint positions, when the scenario has tracking thresholds.
    pub tracking: Option<twin_core::tracking::Tracking>,
}

impl ScenarioCheck {
    /// Each threshold's verdict on the gait so far.
    pub fn verdicts(&self) -> Vec<Threshold> {
        let mut v = self.checks.evaluate(&self.metrics.summary());
        if let Some(g) = &self.grasp {
            v.extend(g.verdicts());
        }
        if let Some(t) = &self.tracking {
            v.extend(self.checks.evaluate_tracking(&t.summary()));
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
        if let Some(t) = self.tracking.as_mut() {
            t.start(model, data)?;
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
        if let Some(t) = self.tracking.as_mut() {
            t.observe(step)?;
        }
        self.metrics.observe(step)
    }
}

impl ScenarioCheck {
    /// The robot's first collision with the terrain, if any.
    pub fn collision(&self) -> Option<&twin_core::terrain::Collision> {
        self.collisions.as_ref().and_then(|c| c.first.as_ref())
    }
}

impl Check for ScenarioCheck {
    fn name(&self) -> &str {
        "scenario"
    }

    fn verdict(&self) -> twin_core::engine::Verdict {
        let verdicts = self.verdicts();
        let failed: Vec<&str> = verdicts.iter().filter(|v| !v.passed).map(|v| v.name).collect();
        twin_core::engine::Verdict {
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
                .chain(
                    self.tracking
                        .iter()
                        .flat_map(|t| self.checks.evaluate_tracking(&t.summary()))
                        .map(|v| Measurement::new(v.name, v.value, "")),
                )
                .collect(),
            details: verdicts
                .iter()
                .map(ToString::to_string)
                .chain(self.collision().map(|c| format!("collision: {c}")))
                .chain(self.tracking.iter().map(|t| t.summary().to_string()))
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
    Ok(edit.finish()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Scenario> {
        Scenario::parse(Path::new("s.toml"), text)
    }

    /// Asserts that `text` is refused with a message that starts with `start` (the file, the
    /// line and the key) and contains `contains`.
    fn assert_refused(text: &str, start: &str, contains: &str) {
        let e = parse(text).unwrap_err().to_string();
        assert!(e.starts_with(start) && e.contains(contains), "{text:?}: {e}");
    }

    #[test]
    fn errors_name_the_file_line_and_key() {
        assert_refused("duration = 5.0\ncontroler = \"walk\"\n", "s.toml:2: `controler`", "unknown field");
        assert_refused("duration = 5.0\n[walk]\nvx = \"fast\"\n", "s.toml:3: `vx`", "");
        assert_refused("duration = 5.0\n[walk]\nstep_period = -0.5\n", "s.toml:3: `walk.step_period`", "positive");
        assert_refused("\nduration = 0\n", "s.toml:2: `duration`", "");
        assert_refused("duration = 1\n[checks]\nmin_speed = 0.3\n", "s.toml:3: `min_speed`", "");
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
        assert_refused(
            "duration = 5\n[grasp]\n\ngrip_force_n = -1.0\n",
            "s.toml:4: `grasp.grip_force_n`",
            "non-negative",
        );
        assert_refused("duration = 5\n[grasp]\ngrip = 1.0\n", "s.toml:3: `grip`", "unknown field");
        assert_refused("duration = 5\nimpratio = 0\n", "s.toml:2: `impratio`", "");
        assert_refused("duration = 5\n[cup]\nposition = [0.3]\n", "s.toml:3: `position`", "");
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

    #[test]
    fn tracking_thresholds_are_range_checked_and_fail_without_targets() {
        assert_refused(
            "duration = 1\n[checks]\nfalls = 0\nmax_saturated_fraction = 1.5\n",
            "s.toml:4: `checks.max_saturated_fraction`",
            "0..=1",
        );
        assert_refused(
            "duration = 1\n[checks]\nmax_tracking_rms_rad = -0.1\n",
            "s.toml:3: `checks.max_tracking_rms_rad`",
            "non-negative",
        );
        let s = parse("duration = 1\n[checks]\nmax_tracking_rms_rad = 0.05\nmax_saturated_fraction = 0.1\n").unwrap();
        assert!(s.checks.has_tracking());
        let summary = twin_core::tracking::TrackingSummary {
            joints: vec![twin_core::tracking::JointTracking { joint: "elbow".into(), rms: 0.08, max: 0.3 }],
            saturated_secs: 0.05,
            sim_secs: 1.0,
        };
        let v = s.checks.evaluate_tracking(&summary);
        assert_eq!(v.len(), 2);
        assert_eq!(v[0].to_string(), "FAIL max_tracking_rms_rad   0.0800 <= 0.05");
        assert_eq!(v[1].to_string(), "PASS max_saturated_fraction 0.0500 <= 0.1");
        // No position targets: the error is unknown and fails.
        let none =
            s.checks.evaluate_tracking(&twin_core::tracking::TrackingSummary { sim_secs: 1.0, ..Default::default() });
        assert!(!none[0].passed && none[0].value.is_nan());
    }
}
