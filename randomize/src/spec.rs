//! The randomization spec: what is drawn per episode, how, and from which distribution.
//!
//! A spec is a TOML file (`--config`). Every entry is a [`Term`]: a draw `x` from a
//! distribution, combined with the nominal value `v` by its mode: `scale` → `v·x`, `add` →
//! `v + x`, `absolute` → `x`. Draws always start from the nominal model, so nothing stacks up
//! from episode to episode. Entries absent from the file are not randomized; run
//! `twin randomize --print-config` for the default spec (used without `--config`).
//!
//! ```toml
//! [friction]            # sliding friction of the geoms (all geoms unless `select`)
//! mode = "scale"
//! dist = "uniform"
//! low = 0.5
//! high = 1.5
//!
//! [mass]                # link masses; inertias scale with them
//! mode = "scale"
//! dist = "uniform"
//! low = 0.9
//! high = 1.1
//! independent = true    # one draw per body instead of one shared draw
//!
//! [[object_mass]]       # a scene object's mass, by body name
//! select = ["cup"]
//! mode = "absolute"
//! dist = "uniform"
//! low = 0.1
//! high = 0.5
//!
//! [push]                # velocity kicks of the floating base, random horizontal direction
//! interval_secs = { mode = "absolute", dist = "uniform", low = 1.0, high = 2.0 }
//! speed_mps = { mode = "absolute", dist = "uniform", low = 0.0, high = 0.6 }
//! ```

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// How a draw combines with the nominal value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// `nominal · x` (default).
    #[default]
    Scale,
    /// `nominal + x`.
    Add,
    /// `x`.
    Absolute,
}

impl Mode {
    /// Combines a draw with the nominal value.
    pub fn apply(self, nominal: f64, x: f64) -> f64 {
        match self {
            Mode::Scale => nominal * x,
            Mode::Add => nominal + x,
            Mode::Absolute => x,
        }
    }
}

/// The distribution of a draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Dist {
    /// U(low, high).
    Uniform,
    /// exp(U(ln low, ln high)), 0 < low ≤ high: for quantities spanning decades.
    LogUniform,
    /// N(mean, std²).
    Gaussian,
}

/// One randomized quantity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Term {
    /// How the draw combines with the nominal value. (default: `scale`)
    #[serde(default)]
    pub mode: Mode,
    /// The distribution.
    pub dist: Dist,
    /// Lower bound (uniform, log-uniform).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub low: Option<f64>,
    /// Upper bound (uniform, log-uniform).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub high: Option<f64>,
    /// Mean (gaussian).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean: Option<f64>,
    /// Standard deviation (gaussian).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std: Option<f64>,
    /// Name patterns (`*` matches any run of characters) of the objects the term applies to:
    /// geoms (or their bodies) for friction, bodies for masses and COM, joints for damping,
    /// friction loss, armature, encoder noise and initial pose, actuators for strength, sensors
    /// for IMU noise and bias. (default: all objects of that kind)
    #[serde(default, skip_serializing_if = "Vec::is_empty", deserialize_with = "select_list")]
    pub select: Vec<String>,
    /// One independent draw per object instead of one draw shared by all of them.
    /// (default: false)
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub independent: bool,
}

/// `select = [...]`; an explicit empty list becomes `[""]`, which validation reports (an empty
/// pattern matches nothing), so `select = []` never silently means "every object".
fn select_list<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Vec<String>, D::Error> {
    let v = Vec::<String>::deserialize(d)?;
    Ok(if v.is_empty() { vec![String::new()] } else { v })
}

/// Terms whose resulting value is a physical quantity that cannot be negative.
const NON_NEGATIVE: [&str; 11] = [
    "camera_noise_std",
    "friction",
    "mass",
    "damping",
    "frictionloss",
    "armature",
    "actuator_strength",
    "imu_noise_std",
    "encoder_noise_std",
    "latency_steps",
    "delay_secs",
];

impl Term {
    /// Refuses draws that give impossible values: a negative friction, mass, damping, noise or
    /// latency (scale or absolute mode: the draw itself must be ≥ 0), a push interval ≤ 0.
    fn validate_range(&self, key: &str, path: Option<&Path>) -> Result<()> {
        let err = |message: String| Error::Spec { path: path.map(Path::to_path_buf), key: key.to_string(), message };
        let non_negative = NON_NEGATIVE.contains(&key) || key.starts_with("object_mass.");
        let interval = key == "push.interval_secs";
        if !(non_negative || interval) || self.mode == Mode::Add {
            return Ok(());
        }
        let lowest = match self.dist {
            Dist::Uniform | Dist::LogUniform => self.low.unwrap_or(0.0),
            // A gaussian reaches any value; its mean at least must be in range.
            Dist::Gaussian => self.mean.unwrap_or(0.0),
        };
        if interval && (lowest.is_nan() || lowest <= 0.0) {
            return Err(err(format!(
                "a push interval must be > 0 s (the lowest draw is {lowest}); e.g. low = 1.0, high = 3.0"
            )));
        }
        if non_negative && lowest < 0.0 {
            return Err(err(format!(
                "this quantity cannot be negative but the lowest draw is {lowest} (mode {}): use a range ≥ 0",
                if self.mode == Mode::Scale { "scale" } else { "absolute" }
            )));
        }
        Ok(())
    }

    /// A uniform draw in `mode`, shared by all objects.
    pub fn uniform(mode: Mode, low: f64, high: f64) -> Term {
        Term {
            mode,
            dist: Dist::Uniform,
            low: Some(low),
            high: Some(high),
            mean: None,
            std: None,
            select: Vec::new(),
            independent: false,
        }
    }

    /// A gaussian draw in `mode`, shared by all objects.
    pub fn gaussian(mode: Mode, mean: f64, std: f64) -> Term {
        Term {
            dist: Dist::Gaussian,
            low: None,
            high: None,
            mean: Some(mean),
            std: Some(std),
            ..Term::uniform(mode, 0.0, 0.0)
        }
    }

    /// The same term with one draw per object.
    pub fn independent(mut self) -> Term {
        self.independent = true;
        self
    }

    /// The same term restricted to objects matching `patterns`.
    pub fn select(mut self, patterns: &[&str]) -> Term {
        self.select = patterns.iter().map(|p| p.to_string()).collect();
        self
    }

    /// Checks that the distribution's parameters are present and consistent.
    fn validate(&self, key: &str, path: Option<&Path>) -> Result<()> {
        let err = |message: String| Error::Spec { path: path.map(Path::to_path_buf), key: key.to_string(), message };
        let finite = |name: &str, v: Option<f64>| -> Result<f64> {
            match v {
                Some(v) if v.is_finite() => Ok(v),
                Some(v) => Err(err(format!("`{name}` must be a finite number, got {v}"))),
                None => Err(err(format!(
                    "dist = \"{}\" needs `{name}`",
                    match self.dist {
                        Dist::Uniform => "uniform",
                        Dist::LogUniform => "log-uniform",
                        Dist::Gaussian => "gaussian",
                    }
                ))),
            }
        };
        match self.dist {
            Dist::Uniform | Dist::LogUniform => {
                let (low, high) = (finite("low", self.low)?, finite("high", self.high)?);
                if low > high {
                    return Err(err(format!("low ({low}) must not exceed high ({high})")));
                }
                if self.dist == Dist::LogUniform && low <= 0.0 {
                    return Err(err(format!(
                        "log-uniform needs 0 < low, got low = {low}; use dist = \"uniform\" for \
                         ranges that include 0"
                    )));
                }
                if self.mean.is_some() || self.std.is_some() {
                    return Err(err("`mean`/`std` belong to dist = \"gaussian\"; use `low`/`high`".into()));
                }
            }
            Dist::Gaussian => {
                finite("mean", self.mean)?;
                let std = finite("std", self.std)?;
                if std < 0.0 {
                    return Err(err(format!("std must be ≥ 0, got {std}")));
                }
                if self.low.is_some() || self.high.is_some() {
                    return Err(err("`low`/`high` belong to uniform distributions; use `mean`/`std`".into()));
                }
            }
        }
        for p in &self.select {
            if p.is_empty() {
                return Err(err(
                    "an empty `select` pattern (or `select = []`) matches nothing; leave `select` out to \
                     apply the term to every object, or remove the term to randomize nothing"
                        .into(),
                ));
            }
        }
        Ok(())
    }
}

/// Push disturbances: every `interval_secs` (drawn once per episode) a horizontal push of size
/// `speed_mps` (drawn once per episode; the change of the whole robot's velocity it amounts
/// to) in a direction drawn per push. Without `body`, the push sets the floating base's
/// velocity at once (the whole robot moves as one); with `body`, it is a force on that body's
/// centre of mass over `duration_secs` with impulse `total mass · speed_mps`, as a shove at
/// that height: the rest of the robot, feet included, must follow through its joints and the
/// ground. Nominal value of both draws is 0, so use `mode = "absolute"` (or `add`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Push {
    /// Time between pushes, seconds; the first push comes after one interval.
    pub interval_secs: Term,
    /// Size of each push as a velocity change of the whole robot, m/s.
    pub speed_mps: Term,
    /// Body pushed (e.g. the torso); without it, the floating base's velocity is set.
    /// (default: none)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body: Option<String>,
    /// How long a push on `body` lasts, seconds. (default: 0.1)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_secs: Option<f64>,
}

/// The whole spec. Every field is optional: `None` / empty means not randomized.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Spec {
    /// Sliding friction of geoms (`select` matches geom names or their body's name). MuJoCo
    /// combines two geoms' friction by their maximum, so scaling every geom scales every
    /// contact.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub friction: Option<Term>,
    /// Body masses, kg; each body's inertia scales with its mass.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass: Option<Term>,
    /// Centre-of-mass offset of bodies, metres, per axis of the body frame (nominal: the COM).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub com_offset: Option<Term>,
    /// Joint viscous damping, N·m·s/rad.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping: Option<Term>,
    /// Joint dry friction loss, N·m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frictionloss: Option<Term>,
    /// Joint armature (reflected rotor inertia), kg·m².
    #[serde(skip_serializing_if = "Option::is_none")]
    pub armature: Option<Term>,
    /// Actuator strength: the gear of each actuator (the controller's torque factor for models
    /// without actuators).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actuator_strength: Option<Term>,
    /// Gravity along z, m/s² (nominal: the model's, e.g. −9.81).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gravity: Option<Term>,
    /// Standard deviation of white noise on IMU readings (gyro, accelerometer sensors; nominal:
    /// each sensor's `noise` attribute).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub imu_noise_std: Option<Term>,
    /// Constant bias of IMU readings per episode (nominal 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub imu_bias: Option<Term>,
    /// Standard deviation of white noise on joint position readings, rad (nominal 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub encoder_noise_std: Option<Term>,
    /// Control latency: the controller sees the state this many steps late (rounded to an
    /// integer ≥ 0; nominal 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latency_steps: Option<Term>,
    /// Command delay of each actuator's drive, seconds (MuJoCo's actuator `delay`: every
    /// controller's commands reach the joint this late; `mode = "abs"` draws it in seconds,
    /// `scale` scales the robot's own `<twin_actuator>` delay). Separate from `latency_steps`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_secs: Option<Term>,
    /// Initial joint positions around the home pose, rad (clamped to joint ranges).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub init_qpos: Option<Term>,
    /// Push disturbances of the floating base.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub push: Option<Push>,
    /// Masses of scene objects by body name (`select` required), kg; applied after `mass`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub object_mass: Vec<Term>,
    /// Start position of scene objects (free bodies, e.g. a cup on a table) by body name
    /// (`select` required), m: one draw for x and one for y, combined with the start position
    /// (usually `mode = "add"`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub object_position: Vec<Term>,
    /// Standard deviation of depth-camera noise, m (cameras whose model keeps it: the camera's
    /// user number 0, as grasping scenarios do; `select`: camera names).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_noise_std: Option<Term>,
}

impl Spec {
    /// The spec used without `--config`, after the seed workflow and common practice: friction
    /// × U(0.5, 1.5); each body's mass × U(0.9, 1.1) with its inertia; IMU noise σ
    /// U(0.001, 0.01); joints start within ±0.02 rad of home; pushes every U(1.5, 3) s of
    /// U(0, 0.6) m/s.
    pub fn default_spec() -> Spec {
        Spec {
            friction: Some(Term::uniform(Mode::Scale, 0.5, 1.5)),
            mass: Some(Term::uniform(Mode::Scale, 0.9, 1.1).independent()),
            imu_noise_std: Some(Term::uniform(Mode::Absolute, 0.001, 0.01)),
            init_qpos: Some(Term::uniform(Mode::Add, -0.02, 0.02).independent()),
            push: Some(Push {
                interval_secs: Term::uniform(Mode::Absolute, 1.5, 3.0),
                speed_mps: Term::uniform(Mode::Absolute, 0.0, 0.6),
                body: None,
                duration_secs: None,
            }),
            ..Spec::default()
        }
    }

    /// Reads and validates a spec file.
    ///
    /// # Errors
    /// [`Error::Io`], [`Error::SpecSyntax`] (TOML errors with line and column, unknown keys),
    /// [`Error::Spec`] for inconsistent entries.
    pub fn from_file(path: &Path) -> Result<Spec> {
        let text = twin_core::fsio::read_to_string(path)?;
        let spec: Spec = toml::from_str(&text).map_err(|e| Error::SpecSyntax {
            path: path.to_path_buf(),
            message: twin_core::fsio::cap_message(e.to_string().trim()),
        })?;
        spec.validate(Some(path))?;
        Ok(spec)
    }

    /// Parses a spec from TOML text (no file).
    ///
    /// # Errors
    /// As [`Spec::from_file`], with `<spec>` as the path.
    pub fn from_toml_str(text: &str) -> Result<Spec> {
        let spec: Spec = toml::from_str(text).map_err(|e| Error::SpecSyntax {
            path: PathBuf::from("<spec>"),
            message: twin_core::fsio::cap_message(e.to_string().trim()),
        })?;
        spec.validate(None)?;
        Ok(spec)
    }

    /// The spec as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a Spec always serializes")
    }

    /// All terms with their keys, in the fixed order draws are made.
    pub fn terms(&self) -> Vec<(String, &Term)> {
        let mut out = Vec::new();
        let singles: [(&str, &Option<Term>); 15] = [
            ("friction", &self.friction),
            ("mass", &self.mass),
            ("com_offset", &self.com_offset),
            ("damping", &self.damping),
            ("frictionloss", &self.frictionloss),
            ("armature", &self.armature),
            ("actuator_strength", &self.actuator_strength),
            ("gravity", &self.gravity),
            ("imu_noise_std", &self.imu_noise_std),
            ("imu_bias", &self.imu_bias),
            ("encoder_noise_std", &self.encoder_noise_std),
            ("latency_steps", &self.latency_steps),
            ("delay_secs", &self.delay_secs),
            ("init_qpos", &self.init_qpos),
            ("camera_noise_std", &self.camera_noise_std),
        ];
        for (key, term) in singles {
            if let Some(t) = term {
                out.push((key.to_string(), t));
            }
        }
        if let Some(p) = &self.push {
            out.push(("push.interval_secs".into(), &p.interval_secs));
            out.push(("push.speed_mps".into(), &p.speed_mps));
        }
        for (i, t) in self.object_mass.iter().enumerate() {
            out.push((format!("object_mass.{i}"), t));
        }
        for (i, t) in self.object_position.iter().enumerate() {
            out.push((format!("object_position.{i}"), t));
        }
        out
    }

    /// The longest command delay the `delay_secs` term can draw on `model`, seconds, when it
    /// is longer than some actuator's history buffer holds (the robot must then be converted
    /// with buffers that long, `ConvertOptions::delay_buffer_secs`); `None` otherwise. A
    /// gaussian's reach is taken as mean + 6 std.
    pub fn delay_buffer_secs(&self, model: &twin_core::mj::Model) -> Option<f64> {
        let t = self.delay_secs.as_ref()?;
        let reach = match t.dist {
            Dist::Gaussian => t.mean.unwrap_or(0.0) + 6.0 * t.std.unwrap_or(0.0).abs(),
            _ => t.high.unwrap_or(0.0),
        };
        let nominal = model.actuator_delay().iter().copied().fold(0.0, f64::max);
        let longest = match t.mode {
            Mode::Scale => reach * nominal,
            Mode::Add => nominal + reach,
            Mode::Absolute => reach,
        };
        let dt = model.timestep_secs();
        let held = (0..model.nu())
            .map(|u| f64::from((model.actuator_history()[u][0] - 1).max(0)) * dt)
            .fold(f64::INFINITY, f64::min);
        (longest > held + 1e-12).then_some(longest)
    }

    /// The term with key `key` (as [`Spec::terms`] names them), if the spec has it.
    pub fn term_mut(&mut self, key: &str) -> Option<&mut Term> {
        let single = match key {
            "friction" => &mut self.friction,
            "mass" => &mut self.mass,
            "com_offset" => &mut self.com_offset,
            "damping" => &mut self.damping,
            "frictionloss" => &mut self.frictionloss,
            "armature" => &mut self.armature,
            "actuator_strength" => &mut self.actuator_strength,
            "gravity" => &mut self.gravity,
            "imu_noise_std" => &mut self.imu_noise_std,
            "imu_bias" => &mut self.imu_bias,
            "encoder_noise_std" => &mut self.encoder_noise_std,
            "latency_steps" => &mut self.latency_steps,
            "delay_secs" => &mut self.delay_secs,
            "init_qpos" => &mut self.init_qpos,
            "camera_noise_std" => &mut self.camera_noise_std,
            "push.interval_secs" => return self.push.as_mut().map(|p| &mut p.interval_secs),
            "push.speed_mps" => return self.push.as_mut().map(|p| &mut p.speed_mps),
            _ => {
                let (list, i) = key.split_once('.')?;
                let i: usize = i.parse().ok()?;
                return match list {
                    "object_mass" => self.object_mass.get_mut(i),
                    "object_position" => self.object_position.get_mut(i),
                    _ => None,
                };
            }
        };
        single.as_mut()
    }

    /// Checks every term.
    ///
    /// # Errors
    /// [`Error::Spec`] naming the first bad entry.
    pub fn validate(&self, path: Option<&Path>) -> Result<()> {
        for (key, term) in self.terms() {
            term.validate(&key, path)?;
            term.validate_range(&key, path)?;
        }
        if let Some(d) = self.push.as_ref().and_then(|p| p.duration_secs)
            && !(d > 0.0 && d.is_finite())
        {
            return Err(Error::Spec {
                path: path.map(Path::to_path_buf),
                key: "push".into(),
                message: format!("duration_secs must be a positive number, got {d}"),
            });
        }
        for (i, t) in self.object_position.iter().enumerate() {
            if t.select.is_empty() {
                return Err(Error::Spec {
                    path: path.map(Path::to_path_buf),
                    key: format!("object_position.{i}"),
                    message: "needs `select = [\"body name\"]` naming the object".into(),
                });
            }
        }
        for (i, t) in self.object_mass.iter().enumerate() {
            if t.select.is_empty() {
                return Err(Error::Spec {
                    path: path.map(Path::to_path_buf),
                    key: format!("object_mass.{i}"),
                    message: "needs `select = [\"body name\"]` naming the object".into(),
                });
            }
        }
        Ok(())
    }
}

/// Whether `name` matches `pattern`, where `*` matches any run of characters.
pub fn matches(pattern: &str, name: &str) -> bool {
    let parts: Vec<&str> = pattern.split('*').collect();
    if parts.len() == 1 {
        return pattern == name;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !name.starts_with(first) || name.len() < first.len() + last.len() || !name.ends_with(last) {
        return false;
    }
    let mut rest = &name[first.len()..name.len() - last.len()];
    for part in &parts[1..parts.len() - 1] {
        match rest.find(part) {
            Some(i) => rest = &rest[i + part.len()..],
            None => return false,
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glob_patterns() {
        assert!(matches("*", "pelvis"));
        assert!(matches("left_*", "left_foot_link"));
        assert!(matches("*foot*", "left_foot_link"));
        assert!(matches("*_link", "left_foot_link"));
        assert!(!matches("right_*", "left_foot_link"));
        assert!(matches("a*b*c", "axxbyyc"));
        assert!(!matches("a*b*c", "axxcyyb"));
        assert!(!matches("ab*ba", "aba"));
    }

    #[test]
    fn default_spec_round_trips_through_toml() {
        let spec = Spec::default_spec();
        let back = Spec::from_toml_str(&spec.to_toml()).unwrap();
        assert_eq!(spec, back);
    }

    #[test]
    fn bad_specs_name_the_entry() {
        let e = Spec::from_toml_str("[friction]\ndist = \"uniform\"\nlow = 2\nhigh = 1\n").unwrap_err().to_string();
        assert!(e.contains("[friction]") && e.contains("must not exceed"), "{e}");
        let e = Spec::from_toml_str("[frcition]\ndist = \"uniform\"\n").unwrap_err().to_string();
        assert!(e.contains("frcition") && e.contains("line 1"), "{e}");
        let e = Spec::from_toml_str("[mass]\ndist = \"log-uniform\"\nlow = 0\nhigh = 1\n").unwrap_err().to_string();
        assert!(e.contains("0 < low"), "{e}");
        let e =
            Spec::from_toml_str("[[object_mass]]\ndist = \"gaussian\"\nmean = 1\nstd = 0.1\n").unwrap_err().to_string();
        assert!(e.contains("object_mass.0") && e.contains("select"), "{e}");
        let e =
            Spec::from_toml_str("[[object_position]]\nmode = \"add\"\ndist = \"uniform\"\nlow = -0.1\nhigh = 0.1\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("object_position.0") && e.contains("select"), "{e}");
        let e = Spec::from_toml_str(
            "[camera_noise_std]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = -0.01\nhigh = 0.01\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("camera_noise_std"), "{e}");
    }
}
