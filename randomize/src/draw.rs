//! Resolving a [`Spec`] against the nominal model ([`Layout`]) and drawing one episode's
//! parameters from it ([`Draw`]).

use crate::error::{Error, Result};
use crate::spec::{Dist, Mode, Spec, Term, matches};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use twin_core::control::{Actuation, reset_to_home};
use twin_core::mj::{Data, JointType, Model, ObjType};

/// The random stream of episode `index` under master seed `seed`: `stream` 0 draws the
/// parameters, 1 the noise and pushes during the episode. ChaCha streams are independent, so
/// each episode's numbers depend on (seed, index) alone, never on thread scheduling.
pub fn episode_rng(seed: u64, index: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index.wrapping_mul(2).wrapping_add(stream));
    rng
}

/// One draw from a term's distribution (not yet combined with a nominal value).
pub fn sample(term: &Term, rng: &mut impl Rng) -> f64 {
    match term.dist {
        Dist::Uniform => {
            let (low, high) = (term.low.unwrap_or(0.0), term.high.unwrap_or(0.0));
            low + (high - low) * rng.random::<f64>()
        }
        Dist::LogUniform => {
            let (low, high) = (term.low.unwrap_or(1.0).ln(), term.high.unwrap_or(1.0).ln());
            (low + (high - low) * rng.random::<f64>()).exp()
        }
        Dist::Gaussian => {
            let z: f64 = rng.sample(StandardNormal);
            term.mean.unwrap_or(0.0) + term.std.unwrap_or(0.0) * z
        }
    }
}

/// What a term acts on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Friction,
    Mass,
    Com,
    Damping,
    FrictionLoss,
    Armature,
    Strength,
    Gravity,
    ImuNoise,
    ImuBias,
    EncoderNoise,
    Latency,
    Delay,
    InitQpos,
    PushInterval,
    PushSpeed,
    ObjectPosition,
    CameraNoise,
}

/// A term bound to model objects: each target is (object, column of its draw, nominal value).
#[derive(Debug, Clone)]
struct Bound {
    kind: Kind,
    mode: Mode,
    targets: Vec<(usize, usize, f64)>,
}

/// A spec resolved against the nominal model: the draw columns (one per drawn number, named
/// e.g. `friction` or `mass:pelvis`) and what each applies to.
#[derive(Debug, Clone)]
pub struct Layout {
    bound: Vec<Bound>,
    terms: Vec<Term>,
    /// Column names, in draw order.
    pub columns: Vec<String>,
    /// Standing pose of the nominal model (`home` keyframe, else qpos0 placed on the floor).
    pub home_qpos: Vec<f64>,
    actuation: Actuation,
    /// Pushed body and push duration, seconds (`None`: pushes set the base velocity).
    pub push_body: Option<(usize, f64)>,
}

/// Parameters of one episode: the drawn numbers and what they turn into.
#[derive(Debug)]
pub struct Draw {
    /// Drawn numbers, one per [`Layout::columns`] entry.
    pub values: Vec<f64>,
    /// The nominal model with the model parameters applied (`mj_setConst` done).
    pub model: Model,
    /// White-noise standard deviation per `sensordata` entry (0 where none).
    pub sensor_noise_std: Vec<f64>,
    /// Constant bias per `sensordata` entry.
    pub sensor_bias: Vec<f64>,
    /// White-noise standard deviation per `qpos` entry (0 where none).
    pub qpos_noise_std: Vec<f64>,
    /// Control latency, steps.
    pub latency_steps: usize,
    /// Initial joint positions (len `nq`).
    pub init_qpos: Vec<f64>,
    /// Time between pushes, seconds (`None`: no pushes).
    pub push_interval_secs: Option<f64>,
    /// Size of each push, m/s.
    pub push_speed_mps: f64,
    /// Factor on each command entry (actuator strength of models without actuators).
    pub command_scale: Vec<f64>,
}

fn name_or(model: &Model, obj: ObjType, id: usize) -> String {
    let n = model.name(obj, id);
    if n.is_empty() { format!("{}{id}", obj.label()) } else { n.to_string() }
}

fn is_1dof(model: &Model, joint: usize) -> bool {
    matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide)
}

impl Layout {
    /// Binds every term of `spec` to the objects of `model` it selects.
    ///
    /// # Errors
    /// [`Error::Spec`] when a `select` pattern matches nothing (listing some names that exist)
    /// or a term needs something the model lacks (pushes without a floating base).
    pub fn new(spec: &Spec, model: &Model) -> Result<Layout> {
        Self::build(spec, model, false).map(|(layout, _)| layout)
    }

    /// Like [`Layout::new`], but terms whose objects the model lacks (e.g. IMU noise on a
    /// model without IMU sensors) are left out instead of being an error; returns their keys.
    /// For the default spec, which must work on any model.
    ///
    /// # Errors
    /// As [`Layout::new`] for other problems.
    pub fn new_skipping_missing(spec: &Spec, model: &Model) -> Result<(Layout, Vec<String>)> {
        Self::build(spec, model, true)
    }

    fn build(spec: &Spec, model: &Model, skip_missing: bool) -> Result<(Layout, Vec<String>)> {
        let mut data = Data::new(std::sync::Arc::new(model.try_clone()?))?;
        reset_to_home(&mut data)?;
        let home_qpos = data.qpos().to_vec();
        let actuation = Actuation::of(model);
        let mut layout =
            Layout { bound: Vec::new(), terms: Vec::new(), columns: Vec::new(), home_qpos, actuation, push_body: None };
        if let Some(p) = &spec.push
            && let Some(name) = &p.body
        {
            let body = model.id(ObjType::Body, name).ok_or_else(|| Error::Spec {
                path: None,
                key: "push".into(),
                message: format!("the model has no body named \"{name}\" to push"),
            })?;
            layout.push_body = Some((body, p.duration_secs.unwrap_or(0.1)));
        }
        let mut skipped = Vec::new();
        for (key, term) in spec.terms() {
            if !layout.bind(&key, term, model, skip_missing)? {
                skipped.push(key);
            }
        }
        Ok((layout, skipped))
    }

    /// Binds one term; `Ok(false)` when it matched nothing and `skip_missing` is set.
    fn bind(&mut self, key: &str, term: &Term, model: &Model, skip_missing: bool) -> Result<bool> {
        let spec_err = |message: String| Error::Spec { path: None, key: key.to_string(), message };
        let select = |n: &str| term.select.is_empty() || term.select.iter().any(|p| matches(p, n));
        // (object id, name used for matching, name in column, nominal value, share group)
        let mut objects: Vec<(usize, String, f64, usize)> = Vec::new();
        let kind;
        let base = key.split(['.', ':']).next().unwrap_or(key);
        match base {
            "friction" => {
                kind = Kind::Friction;
                for g in 0..model.ngeom() {
                    let gname = name_or(model, ObjType::Geom, g);
                    let bname = model.name(ObjType::Body, model.geom_bodyid()[g] as usize).to_string();
                    if select(&gname) || (!bname.is_empty() && select(&bname)) {
                        objects.push((g, gname, model.geom_friction()[g][0], 0));
                    }
                }
            }
            "mass" | "object_mass" => {
                kind = Kind::Mass;
                for b in 1..model.nbody() {
                    let name = name_or(model, ObjType::Body, b);
                    if model.body_mass()[b] > 0.0 && select(&name) {
                        objects.push((b, name, model.body_mass()[b], 0));
                    }
                }
            }
            "com_offset" => {
                kind = Kind::Com;
                for b in 1..model.nbody() {
                    let name = name_or(model, ObjType::Body, b);
                    if model.body_mass()[b] > 0.0 && select(&name) {
                        for (axis, a) in ["x", "y", "z"].iter().enumerate() {
                            objects.push((b * 3 + axis, format!("{name}:{a}"), model.body_ipos()[b][axis], axis));
                        }
                    }
                }
            }
            "damping" | "frictionloss" | "armature" | "encoder_noise_std" | "init_qpos" => {
                kind = match base {
                    "damping" => Kind::Damping,
                    "frictionloss" => Kind::FrictionLoss,
                    "armature" => Kind::Armature,
                    "encoder_noise_std" => Kind::EncoderNoise,
                    _ => Kind::InitQpos,
                };
                for j in (0..model.njnt()).filter(|&j| is_1dof(model, j)) {
                    let name = name_or(model, ObjType::Joint, j);
                    if !select(&name) {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[j] as usize;
                    let adr = model.jnt_qposadr()[j] as usize;
                    let (object, nominal) = match kind {
                        Kind::Damping => (dof, model.dof_damping()[dof]),
                        Kind::FrictionLoss => (dof, model.dof_frictionloss()[dof]),
                        Kind::Armature => (dof, model.dof_armature()[dof]),
                        Kind::EncoderNoise => (adr, 0.0),
                        _ => (adr, self.home_qpos[adr]),
                    };
                    objects.push((object, name, nominal, 0));
                }
            }
            "actuator_strength" => {
                kind = Kind::Strength;
                match self.actuation {
                    Actuation::Ctrl => {
                        for u in 0..model.nu() {
                            let name = name_or(model, ObjType::Actuator, u);
                            if select(&name) {
                                objects.push((u, name, model.actuator_gear()[u][0], 0));
                            }
                        }
                    }
                    Actuation::Qfrc => {
                        for j in (0..model.njnt()).filter(|&j| is_1dof(model, j)) {
                            let name = name_or(model, ObjType::Joint, j);
                            if select(&name) {
                                objects.push((model.jnt_dofadr()[j] as usize, name, 1.0, 0));
                            }
                        }
                    }
                }
            }
            "gravity" => {
                kind = Kind::Gravity;
                objects.push((0, String::new(), model.gravity()[2], 0));
            }
            "imu_noise_std" | "imu_bias" => {
                kind = if base == "imu_bias" { Kind::ImuBias } else { Kind::ImuNoise };
                for s in 0..model.nsensor() {
                    let name = name_or(model, ObjType::Sensor, s);
                    let imu = model.sensor_is_imu(s);
                    let chosen = if term.select.is_empty() { imu } else { select(&name) };
                    if !chosen {
                        continue;
                    }
                    let adr = model.sensor_adr()[s] as usize;
                    for k in 0..model.sensor_dim()[s] as usize {
                        let nominal = if kind == Kind::ImuNoise { model.sensor_noise()[s] } else { 0.0 };
                        objects.push((adr + k, format!("{name}[{k}]"), nominal, 0));
                    }
                }
            }
            "object_position" => {
                kind = Kind::ObjectPosition;
                for j in 0..model.njnt() {
                    let b = model.jnt_bodyid()[j] as usize;
                    let name = name_or(model, ObjType::Body, b);
                    if model.joint_type(j) == JointType::Free && select(&name) {
                        let adr = model.jnt_qposadr()[j] as usize;
                        for (axis, a) in ["x", "y"].iter().enumerate() {
                            objects.push((adr + axis, format!("{name}:{a}"), self.home_qpos[adr + axis], axis));
                        }
                    }
                }
            }
            "camera_noise_std" => {
                kind = Kind::CameraNoise;
                for c in 0..model.ncam() {
                    let name = name_or(model, ObjType::Camera, c);
                    if let Some(&nominal) = model.cam_user(c).first()
                        && select(&name)
                    {
                        objects.push((c, name, nominal, 0));
                    }
                }
            }
            "delay_secs" => {
                kind = Kind::Delay;
                for u in 0..model.nu() {
                    let name = name_or(model, ObjType::Actuator, u);
                    if select(&name) {
                        objects.push((u, name, model.actuator_delay()[u], 0));
                    }
                }
            }
            "latency_steps" => {
                kind = Kind::Latency;
                objects.push((0, String::new(), 0.0, 0));
            }
            "push" => {
                if model.free_joint().is_none() {
                    return Err(spec_err(
                        "pushes need a floating base (a free joint); remove [push] for fixed-base \
                         models"
                            .into(),
                    ));
                }
                kind = if key.ends_with("interval_secs") { Kind::PushInterval } else { Kind::PushSpeed };
                objects.push((0, String::new(), 0.0, 0));
            }
            other => unreachable!("Spec::terms yields no key {other}"),
        }
        if objects.is_empty() && skip_missing {
            return Ok(false);
        }
        if objects.is_empty() {
            let what = match kind {
                Kind::Friction => ("geom", ObjType::Geom),
                Kind::Mass | Kind::Com => ("body with mass", ObjType::Body),
                Kind::Strength if self.actuation == Actuation::Ctrl => ("actuator", ObjType::Actuator),
                Kind::ImuNoise | Kind::ImuBias => ("gyro/accelerometer sensor", ObjType::Sensor),
                Kind::ObjectPosition => ("free body (scene object)", ObjType::Body),
                Kind::CameraNoise => ("camera keeping its noise (user 0; grasping scenarios)", ObjType::Camera),
                _ => ("hinge or slide joint", ObjType::Joint),
            };
            let count = match what.1 {
                ObjType::Geom => model.ngeom(),
                ObjType::Body => model.nbody(),
                ObjType::Actuator => model.nu(),
                ObjType::Sensor => model.nsensor(),
                ObjType::Camera => model.ncam(),
                _ => model.njnt(),
            };
            let names: Vec<String> =
                (0..count).map(|i| model.name(what.1, i).to_string()).filter(|n| !n.is_empty()).take(8).collect();
            return Err(spec_err(format!(
                "select = {:?} matches no {} of the model (some names: {})",
                term.select,
                what.0,
                if names.is_empty() { "none".to_string() } else { names.join(", ") }
            )));
        }
        // Column naming: the key for one shared draw, key:object for independent draws.
        let label = if base == "object_mass" || base == "object_position" {
            format!("{base}:{}", term.select.join("|"))
        } else {
            key.to_string()
        };
        let mut targets = Vec::new();
        let mut group_columns: Vec<Option<usize>> = vec![None; 3];
        for (object, name, nominal, group) in objects {
            let column = if term.independent && !name.is_empty() {
                self.columns.push(format!("{label}:{name}"));
                self.columns.len() - 1
            } else if let Some(c) = group_columns[group] {
                c
            } else {
                let suffix = if matches!(kind, Kind::Com | Kind::ObjectPosition) {
                    format!(":{}", ["x", "y", "z"][group])
                } else {
                    String::new()
                };
                self.columns.push(format!("{label}{suffix}"));
                group_columns[group] = Some(self.columns.len() - 1);
                self.columns.len() - 1
            };
            targets.push((object, column, nominal));
        }
        self.bound.push(Bound { kind, mode: term.mode, targets });
        // Columns of one term are contiguous; remember which term draws them.
        self.terms.push(term.clone());
        Ok(true)
    }

    /// Which term draws each column.
    fn column_terms(&self) -> Vec<&Term> {
        let mut out = vec![None; self.columns.len()];
        for (bound, term) in self.bound.iter().zip(&self.terms) {
            for &(_, column, _) in &bound.targets {
                out[column] = Some(term);
            }
        }
        out.into_iter().map(|t| t.expect("every column belongs to a term")).collect()
    }

    /// Draws episode `episode`'s parameters from `rng` and applies them to a copy of `nominal`.
    ///
    /// # Errors
    /// [`Error::Apply`] when a drawn value is physically invalid (e.g. a mass ≤ 0 from a
    /// gaussian draw), [`Error::Core`] if MuJoCo fails to copy the model.
    pub fn draw(&self, nominal: &Model, episode: u64, rng: &mut impl Rng) -> Result<Draw> {
        let values: Vec<f64> = self.column_terms().into_iter().map(|t| sample(t, rng)).collect();
        self.apply(nominal, episode, values)
    }

    /// Applies given column values (as drawn by [`Layout::draw`]) to a copy of `nominal`.
    ///
    /// # Errors
    /// As [`Layout::draw`].
    pub fn apply(&self, nominal: &Model, episode: u64, values: Vec<f64>) -> Result<Draw> {
        let apply_err = |source: twin_core::mj::Error| Error::Apply { episode, source: source.into() };
        let mut edit = nominal.edit()?;
        let mut com: Vec<Option<[f64; 3]>> = vec![None; nominal.nbody()];
        // Expand per-sensor noise to per-sensordata entries (MuJoCo stores it per sensor).
        let mut sensor_noise_std = vec![0.0; nominal.nsensordata()];
        for (s, &noise) in nominal.sensor_noise().iter().enumerate() {
            let adr = nominal.sensor_adr()[s] as usize;
            for k in 0..nominal.sensor_dim()[s] as usize {
                sensor_noise_std[adr + k] = noise;
            }
        }
        let mut sensor_bias = vec![0.0; nominal.nsensordata()];
        let mut qpos_noise_std = vec![0.0; nominal.nq()];
        let mut latency_steps = 0;
        let mut init_qpos = self.home_qpos.clone();
        let mut push_interval_secs = None;
        let mut push_speed_mps = 0.0;
        let mut command_scale = vec![1.0; self.actuation.len(nominal)];
        for bound in &self.bound {
            for &(object, column, nominal_value) in &bound.targets {
                let v = bound.mode.apply(nominal_value, values[column]);
                match bound.kind {
                    Kind::Friction => {
                        let f = nominal.geom_friction()[object];
                        edit.set_geom_friction(object, [v.max(0.0), f[1], f[2]]).map_err(apply_err)?;
                    }
                    Kind::Mass => {
                        let ratio = v / nominal_value;
                        let inertia = nominal.body_inertia()[object].map(|i| i * ratio);
                        edit.set_body_mass(object, v).map_err(apply_err)?;
                        edit.set_body_inertia(object, inertia).map_err(apply_err)?;
                    }
                    Kind::Com => {
                        let (body, axis) = (object / 3, object % 3);
                        let c = com[body].get_or_insert(nominal.body_ipos()[body]);
                        c[axis] = v;
                    }
                    Kind::Damping => {
                        edit.set_dof_damping(object, v.max(0.0)).map_err(apply_err)?;
                    }
                    Kind::FrictionLoss => {
                        edit.set_dof_frictionloss(object, v.max(0.0)).map_err(apply_err)?;
                    }
                    Kind::Armature => {
                        edit.set_dof_armature(object, v.max(0.0)).map_err(apply_err)?;
                    }
                    Kind::Strength => match self.actuation {
                        Actuation::Ctrl => {
                            let mut gear = nominal.actuator_gear()[object];
                            gear[0] = v;
                            edit.set_actuator_gear(object, gear).map_err(apply_err)?;
                        }
                        Actuation::Qfrc => command_scale[object] = v,
                    },
                    Kind::Gravity => {
                        let g = nominal.gravity();
                        edit.set_gravity([g[0], g[1], v]).map_err(apply_err)?;
                    }
                    Kind::ImuNoise => sensor_noise_std[object] = v.abs(),
                    Kind::ImuBias => sensor_bias[object] = v,
                    Kind::EncoderNoise => qpos_noise_std[object] = v.abs(),
                    Kind::Delay => {
                        edit.set_actuator_delay(object, v.max(0.0)).map_err(apply_err)?;
                    }
                    Kind::Latency => latency_steps = v.round().max(0.0) as usize,
                    Kind::InitQpos => {
                        let joint = (0..nominal.njnt())
                            .find(|&j| nominal.jnt_qposadr()[j] as usize == object)
                            .expect("bound to a joint's qpos address");
                        init_qpos[object] = if nominal.jnt_limited()[joint] {
                            let [lo, hi] = nominal.jnt_range()[joint];
                            v.clamp(lo, hi)
                        } else {
                            v
                        };
                    }
                    Kind::ObjectPosition => init_qpos[object] = v,
                    Kind::CameraNoise => {
                        edit.set_cam_user(object, 0, v.max(0.0)).map_err(apply_err)?;
                    }
                    Kind::PushInterval => push_interval_secs = Some(v),
                    Kind::PushSpeed => push_speed_mps = v,
                }
            }
        }
        for (body, c) in com.into_iter().enumerate() {
            if let Some(c) = c {
                edit.set_body_com(body, c).map_err(apply_err)?;
            }
        }
        let model = edit.finish().map_err(apply_err)?;
        let push_interval_secs = push_interval_secs.filter(|&s| s > 0.0 && push_speed_mps != 0.0);
        Ok(Draw {
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::Spec;

    /// A scene object's start and a depth camera's noise are drawn per episode within their
    /// ranges, into the initial state and the model.
    #[test]
    fn object_position_and_camera_noise_are_drawn() {
        let model = Model::from_xml_str(
            r#"<mujoco><size nuser_cam="1"/><worldbody><geom type="plane" size="1 1 0.1"/>
               <camera name="eye" pos="0 0 1" user="0.002"/>
               <body name="cup" pos="0.3 -0.1 0.05"><freejoint/><geom type="cylinder" size="0.04 0.05" mass="0.2"/></body>
               </worldbody></mujoco>"#,
        )
        .unwrap();
        let spec = Spec::from_toml_str(
            "[[object_position]]\nselect = [\"cup\"]\nmode = \"add\"\ndist = \"uniform\"\nlow = -0.05\nhigh = 0.05\n\
             [camera_noise_std]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = 0.0\nhigh = 0.006\n",
        )
        .unwrap();
        let layout = Layout::new(&spec, &model).unwrap();
        assert_eq!(layout.columns, ["camera_noise_std", "object_position:cup:x", "object_position:cup:y"]);
        let mut seen_x = Vec::new();
        for episode in 0..20 {
            let draw = layout.draw(&model, episode, &mut episode_rng(3, episode, 0)).unwrap();
            let (x, y) = (draw.init_qpos[0], draw.init_qpos[1]);
            assert!((x - 0.3).abs() <= 0.05 && (y + 0.1).abs() <= 0.05, "{x} {y}");
            assert_eq!((x, y), (0.3 + draw.values[1], -0.1 + draw.values[2]));
            let noise = draw.model.cam_user(0)[0];
            assert!((0.0..=0.006).contains(&noise) && noise == draw.values[0], "{noise}");
            seen_x.push(x);
        }
        assert!(seen_x.iter().any(|&x| x > 0.32) && seen_x.iter().any(|&x| x < 0.28), "{seen_x:?}");
    }

    /// A drawn command delay is MuJoCo's actuator delay of the episode's model: a torque step
    /// reaches the joint that late; a model whose buffers are too short says so.
    #[test]
    fn command_delay_is_drawn_into_the_model_and_acts_at_the_joint() {
        let xml = |nsample: u32| {
            format!(
                r#"<mujoco><option timestep="0.001" gravity="0 0 0"/><worldbody><body><joint name="j" type="hinge"/>
                   <geom size="0.1" mass="1"/></body></worldbody>
                   <actuator><motor name="m" joint="j" nsample="{nsample}"/></actuator></mujoco>"#
            )
        };
        let spec =
            Spec::from_toml_str("[delay_secs]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = 0.0\nhigh = 0.015\n")
                .unwrap();
        let short = Model::from_xml_str(&xml(5)).unwrap();
        assert_eq!(spec.delay_buffer_secs(&short), Some(0.015));
        let model = Model::from_xml_str(&xml(17)).unwrap();
        assert_eq!(spec.delay_buffer_secs(&model), None);
        let layout = Layout::new(&spec, &model).unwrap();
        assert_eq!(layout.columns, ["delay_secs"]);
        let mut seen = Vec::new();
        for episode in 0..6 {
            let draw = layout.draw(&model, episode, &mut episode_rng(5, episode, 0)).unwrap();
            let delay = draw.model.actuator_delay()[0];
            assert!((0.0..=0.015).contains(&delay) && delay == draw.values[0], "{delay}");
            let mut data = twin_core::mj::Data::new(std::sync::Arc::new(draw.model)).unwrap();
            data.ctrl_mut()[0] = 1.0;
            let mut arrived = None;
            for k in 0..30 {
                data.step().unwrap();
                if arrived.is_none() && data.qfrc_actuator()[0] != 0.0 {
                    arrived = Some(k as f64 * 0.001);
                }
            }
            // Linear interpolation between samples: the torque starts within a step of the delay.
            let arrived = arrived.unwrap();
            assert!((arrived - delay).abs() <= 0.001 + 1e-9, "delay {delay}, torque after {arrived}");
            seen.push(delay);
        }
        assert!(seen.iter().any(|&d| d < 0.005) && seen.iter().any(|&d| d > 0.01), "{seen:?}");
        let e = Layout::new(&spec, &short).unwrap().draw(&short, 0, &mut episode_rng(5, 1, 0));
        assert!(e.is_err());
    }
}
