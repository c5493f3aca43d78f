//! `twin check`: incremental validation of a robot model, each step PASS/FAIL with numbers and,
//! on failure, the likely cause from the workflow's troubleshooting table.
//!
//! 1. **physics**: the free-floating model, reset to keyframe `home` (else `qpos0`), holds that
//!    pose for [`CheckOptions::hold_secs`] with PD servos: base height drift, tilt, horizontal
//!    slide, deepest penetration, no divergence.
//! 2. **sensors**: after the hold, each accelerometer reads −gravity in its site frame (+9.81 up),
//!    each `framequat` matches its site's orientation, each `jointpos`/`jointvel` matches
//!    `qpos`/`qvel`.
//! 3. **control**: on a fixed-base copy (or with the base pinned), each actuated joint tracks a
//!    step and a 1 Hz sine: final error, overshoot, settling time, RMS error.
//! 4. **integration**: real-time factor of the physics step.
//!
//! The hold and the control runs are configurations of the rollout engine ([`crate::engine`]):
//! a controller that writes the servos' position targets, a disturbance that pins the base, and
//! observers that measure.
//!
//! The PD hold turns every joint actuator into a servo (`ModelEdit::set_actuator_servo`) with
//! kp = effort limit / [`CheckOptions::full_effort_error_rad`] (or, without an effort limit, a
//! 5 Hz natural frequency on the joint's inertia) and critical damping; the velocity term runs in
//! MuJoCo's implicit integrator, which keeps stiff damping on light joints stable.

use crate::control::{Controller, Observation, PdHoldOptions, pd_gains};
use crate::convert::actuated_joints;
use crate::engine::{
    Disturbance, Engine, Episode, Flow, Measurement, Observer, StepView, Verdict, observers::Divergence,
};
use crate::error::Result;
use crate::mj::{Data, FreeJoint, Integrator, Model, ObjType, SensorType};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

/// Options of [`check`]. Every field documents its default.
#[derive(Debug, Clone, smart_default::SmartDefault)]
pub struct CheckOptions {
    /// Duration of the standing hold, seconds (default: 5).
    #[default(5.0)]
    pub hold_secs: f64,
    /// Largest allowed base height change during the hold, metres (default: 0.05).
    #[default(0.05)]
    pub max_height_drift_m: f64,
    /// Largest allowed horizontal base motion during the hold, metres (default: 0.05).
    #[default(0.05)]
    pub max_slide_m: f64,
    /// Largest allowed base tilt during the hold, radians (default: 0.25).
    #[default(0.25)]
    pub max_tilt_rad: f64,
    /// Deepest allowed contact penetration, metres (default: 0.01).
    #[default(0.01)]
    pub max_penetration_m: f64,
    /// Joint error at which a servo gives its full effort limit, radians (default: 0.1).
    #[default(0.1)]
    pub full_effort_error_rad: f64,
    /// Servo natural frequency for joints without an effort limit, Hz (default: 5).
    #[default(5.0)]
    pub fallback_freq_hz: f64,
    /// Largest control step, radians or metres (default: 0.2).
    #[default(0.2)]
    pub step_amplitude: f64,
    /// Simulated seconds timed for the real-time factor (default: 2).
    #[default(2.0)]
    pub timing_secs: f64,
}

/// One measured number (the engine's [`Measurement`]).
pub type Metric = Measurement;

/// Result of one step: a [`Verdict`] named `physics`, `sensors`, `control` or `integration`.
pub type StepReport = Verdict;

/// Result of [`check`].
#[derive(Debug, Clone)]
pub struct CheckReport {
    /// The steps in order.
    pub steps: Vec<StepReport>,
}

impl CheckReport {
    /// Whether every step passed.
    pub fn passed(&self) -> bool {
        self.steps.iter().all(|s| s.passed)
    }
}

fn metric(name: impl Into<String>, value: f64, unit: &'static str) -> Metric {
    Measurement::new(name, value, unit)
}

/// The model with every joint actuator turned into a PD servo; returns also, per servo, the
/// actuator id, joint id and gear.
/// A servo: actuator id, joint id, gear.
type Servo = (usize, usize, f64);

fn servo_model(model: &Model, opts: &CheckOptions) -> Result<(Model, Vec<Servo>)> {
    let dt = model.timestep_secs();
    let mut edit = model.edit()?;
    let mut servos = Vec::new();
    let actuators = crate::robot::actuators_of(model, &[]);
    for (j, a) in actuated_joints(model) {
        let dof = model.jnt_dofadr()[j] as usize;
        let gear = model.actuator_gear()[a][0];
        // What the actuator can give its joint (the one reading of an actuator's strength).
        let effort = Some(actuators[a].joint_effort(model)).filter(|e| e.is_finite());
        let inertia = model.dof_m0()[dof] + model.dof_armature()[dof];
        // Joint-space gains by twin's one rule, then expressed for the actuator (force = gear ·
        // actuator force, length = gear · q).
        let rule = PdHoldOptions {
            saturation_error: opts.full_effort_error_rad,
            damping_ratio: 1.0,
            min_natural_freq_hz: Some(opts.fallback_freq_hz),
            stability_dt_secs: Some(dt),
            ..PdHoldOptions::default()
        };
        let (kp_joint, kv_joint) = pd_gains(effort, inertia, &rule);
        let g2 = gear * gear;
        edit.set_actuator_servo(a, kp_joint / g2, kv_joint / g2)?;
        servos.push((a, j, gear));
    }
    edit.set_integrator(Integrator::ImplicitFast);
    Ok((edit.finish()?, servos))
}

/// The servos' position targets as the check's controller: `gear · q_target` per servo, the
/// target a fixed pose, one joint of which may follow a sine.
struct ServoTargets {
    /// (actuator, qpos address, gear) per servo.
    servos: Vec<(usize, usize, f64)>,
    target: Vec<f64>,
    sine: Option<Sine>,
    step: u64,
}

/// `target[adr] = q0 + half_amplitude · sin(ω · step · dt)`.
struct Sine {
    adr: usize,
    q0: f64,
    half_amplitude: f64,
    omega: f64,
    dt: f64,
}

impl ServoTargets {
    fn new(model: &Model, servos: &[Servo], target: Vec<f64>, sine: Option<Sine>) -> ServoTargets {
        let servos = servos.iter().map(|&(a, j, gear)| (a, model.jnt_qposadr()[j] as usize, gear)).collect();
        ServoTargets { servos, target, sine, step: 0 }
    }
}

impl Controller for ServoTargets {
    fn name(&self) -> &'static str {
        "check-servos"
    }

    fn reset(&mut self, _model: &Model, _observation: &Observation<'_>) -> Result<()> {
        self.step = 0;
        Ok(())
    }

    fn compute(&mut self, _model: &Model, _observation: &Observation<'_>, command: &mut [f64]) {
        if let Some(s) = &self.sine {
            self.target[s.adr] = s.q0 + s.half_amplitude * (s.omega * (self.step as f64 * s.dt)).sin();
        }
        for &(a, adr, gear) in &self.servos {
            command[a] = gear * self.target[adr];
        }
        self.step += 1;
    }
}

/// Holds the floating base at its home pose (position, orientation, zero velocity) every step.
struct PinBase {
    free: FreeJoint,
    home: Vec<f64>,
}

impl Disturbance for PinBase {
    fn apply(&mut self, data: &mut Data, _rng: &mut ChaCha8Rng) {
        let (qa, va) = (self.free.qpos_adr, self.free.dof);
        data.qpos_mut()[qa..qa + 7].copy_from_slice(&self.home[qa..qa + 7]);
        data.qvel_mut()[va..va + 6].fill(0.0);
    }
}

/// Runs `steps` steps of `model` from `home` under `controller` on the rollout engine.
///
/// # Errors
/// [`crate::Error::MuJoCo`] if MuJoCo raises.
fn run(
    engine: &mut Engine,
    model: &Arc<Model>,
    home: &[f64],
    steps: u64,
    controller: &mut ServoTargets,
    disturbances: &mut [&mut dyn Disturbance],
    observers: &mut [&mut dyn Observer],
) -> Result<()> {
    let episode = Episode { initial_qpos: Some(home.to_vec()), steps, ..Episode::default() };
    // Nothing here is random: no sensor noise, no random disturbances.
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let outcome = engine.run(model, &episode, controller, disturbances, observers, &mut rng)?;
    match outcome.physics_error {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// Runs every step on `floating`; `fixed` is a fixed-base copy for the control step (else the
/// base is pinned to its home pose each step).
///
/// # Errors
/// [`crate::Error::MuJoCo`] if MuJoCo raises during the simulation.
pub fn check(floating: &Model, fixed: Option<&Model>, opts: &CheckOptions) -> Result<CheckReport> {
    let (servo, servos) = servo_model(floating, opts)?;
    let servo = Arc::new(servo);
    let mut steps = Vec::new();
    let (physics, mut data) = physics_step(&servo, &servos, opts)?;
    let diverged = physics.cause.as_deref().is_some_and(|c| c.contains("diverged"));
    steps.push(physics);
    steps.push(if diverged {
        StepReport {
            name: "sensors".into(),
            passed: false,
            metrics: vec![],
            details: vec![],
            cause: Some("not checked: the physics step diverged".into()),
        }
    } else {
        sensors_step(&mut data)?
    });
    let control = match fixed {
        Some(f) => {
            let (fm, fs) = servo_model(f, opts)?;
            control_step(Arc::new(fm), &fs, opts)?
        }
        None => control_step(servo.clone(), &servos, opts)?,
    };
    steps.push(control);
    steps.push(integration_step(&servo, &servos, opts)?);
    Ok(CheckReport { steps })
}

/// The physics step of [`check`] alone, as `twin check` reports it first: `floating` holds its
/// home pose under PD servos for [`CheckOptions::hold_secs`]; base height drift, tilt, slide and
/// the deepest penetration, passed or failed with the likely cause.
///
/// # Errors
/// [`crate::Error::MuJoCo`] if MuJoCo raises during the simulation.
pub fn physics(floating: &Model, opts: &CheckOptions) -> Result<StepReport> {
    let (servo, servos) = servo_model(floating, opts)?;
    Ok(physics_step(&Arc::new(servo), &servos, opts)?.0)
}

/// What the standing hold measures, step by step.
struct HoldWatch {
    servos: Vec<Servo>,
    home: Vec<f64>,
    base_body: Option<usize>,
    steps: usize,
    window: usize,
    start: [f64; 3],
    start_quat: Option<[f64; 4]>,
    deepest: f64,
    max_tilt: f64,
    max_drop: f64,
    max_slide: f64,
    vel_first: f64,
    vel_last: f64,
    support: Option<([f64; 2], [f64; 2])>,
    com_start: Option<[f64; 3]>,
    joint_drift: f64,
}

impl HoldWatch {
    fn base_pos(&self, data: &Data) -> [f64; 3] {
        self.base_body.map_or([0.0; 3], |b| data.xpos()[b])
    }
}

impl Observer for HoldWatch {
    fn start(&mut self, _model: &Model, data: &Data) -> Result<()> {
        self.start = self.base_pos(data);
        self.start_quat = self.base_body.map(|b| data.xquat()[b]);
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let (data, i) = (step.data, step.index as usize);
        let model = data.model();
        for (dist, _) in data.contacts() {
            self.deepest = self.deepest.max(-dist);
        }
        if i == 10 {
            // Support polygon (as a box) from the contacts after touchdown, and the CoM then.
            self.support = contact_box(data);
            if let Some(b) = self.base_body {
                self.com_start = Some(data.subtree_com()[b]);
            }
        }
        let (start, p) = (self.start, self.base_pos(data));
        self.max_drop = self.max_drop.max((start[2] - p[2]).abs());
        self.max_slide = self.max_slide.max(((p[0] - start[0]).powi(2) + (p[1] - start[1]).powi(2)).sqrt());
        if let (Some(b), Some(q0)) = (self.base_body, self.start_quat) {
            let q = data.xquat()[b];
            let a = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q0[0], q0[1], q0[2], q0[3]));
            let bq = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
            self.max_tilt = self.max_tilt.max((a.inverse() * bq).angle());
        }
        for &(_, j, _) in &self.servos {
            let adr = model.jnt_qposadr()[j] as usize;
            self.joint_drift = self.joint_drift.max((data.qpos()[adr] - self.home[adr]).abs());
        }
        let v2: f64 = self.servos.iter().map(|&(_, j, _)| data.qvel()[model.jnt_dofadr()[j] as usize].powi(2)).sum();
        if i < self.window {
            self.vel_first += v2;
        }
        if i + self.window >= self.steps {
            self.vel_last += v2;
        }
        Ok(Flow::Continue)
    }
}

fn physics_step(model: &Arc<Model>, servos: &[(usize, usize, f64)], opts: &CheckOptions) -> Result<(StepReport, Data)> {
    let home = crate::control::nominal_pose(model);
    let free = model.free_joint();
    let n = (opts.hold_secs / model.timestep_secs()).round() as usize;
    let mut watch = HoldWatch {
        servos: servos.to_vec(),
        home: home.clone(),
        base_body: free.map(|f| f.body),
        steps: n,
        window: (1.0 / model.timestep_secs()) as usize,
        start: [0.0; 3],
        start_quat: None,
        deepest: 0.0,
        max_tilt: 0.0,
        max_drop: 0.0,
        max_slide: 0.0,
        vel_first: 0.0,
        vel_last: 0.0,
        support: None,
        com_start: None,
        joint_drift: 0.0,
    };
    let mut divergence = Divergence::default();
    let mut controller = ServoTargets::new(model, servos, home.clone(), None);
    let mut engine = Engine::new();
    run(&mut engine, model, &home, n as u64, &mut controller, &mut [], &mut [&mut divergence, &mut watch])?;
    let diverged = divergence.reason.is_some();
    let Some(data) = engine.take_data() else {
        return Err(crate::Error::Options("the engine kept no simulation (twin bug)".into()));
    };
    let HoldWatch { deepest, max_tilt, max_drop, max_slide, support, com_start, joint_drift, window, .. } = watch;
    let rms = |s: f64| (s / (window.max(1) * servos.len().max(1)) as f64).sqrt();
    let (vel_first, vel_last) = (rms(watch.vel_first), rms(watch.vel_last));
    let mut metrics = vec![
        metric("base height drift", max_drop, "m"),
        metric("base horizontal slide", max_slide, "m"),
        metric("base tilt", max_tilt, "rad"),
        metric("deepest penetration", deepest, "m"),
        metric("largest joint drift", joint_drift, "rad"),
        metric("joint speed RMS, last second", vel_last, "rad/s"),
    ];
    if free.is_none() {
        metrics.retain(|m| !m.name.starts_with("base"));
    }
    let fell = max_drop > opts.max_height_drift_m || max_tilt > opts.max_tilt_rad;
    let growing = vel_last > 2.0 * vel_first && vel_last > 0.05;
    let com = com_start.map(|c| [c[0], c[1]]);
    let outside = match (com, support) {
        (Some(c), Some((_, hi))) if c[0] > hi[0] => Some(format!(
            "falls forward: centre of mass x = {:.3} m is ahead of the support polygon (feet up to x = {:.3} m)",
            c[0], hi[0]
        )),
        (Some(c), Some((lo, _))) if c[0] < lo[0] => Some(format!(
            "falls backward: centre of mass x = {:.3} m is behind the support polygon (from x = {:.3} m)",
            c[0], lo[0]
        )),
        (Some(c), Some((lo, hi))) if c[1] < lo[1] || c[1] > hi[1] => Some(format!(
            "falls sideways: centre of mass y = {:.3} m is outside the support polygon ({:.3} … {:.3} m)",
            c[1], lo[1], hi[1]
        )),
        _ => None,
    };
    let cause = if diverged {
        Some("the simulation diverged (NaN): growing oscillation — gains too high or timestep too large".to_string())
    } else if fell && outside.is_some() {
        outside
    } else if growing {
        Some(format!("growing oscillation (joint speed RMS {vel_first:.3} → {vel_last:.3} rad/s): gains too high"))
    } else if fell {
        Some(if support.is_none() {
            "falls: nothing touches the ground after touchdown (robot not placed on the floor?)".to_string()
        } else {
            "falls although the centre of mass is over the support polygon: the PD hold is too weak (effort limits too low)".to_string()
        })
    } else if max_slide > opts.max_slide_m {
        Some(format!("foot sliding while commanded still ({max_slide:.3} m): friction too low"))
    } else if deepest > opts.max_penetration_m {
        Some(format!("deep penetration ({deepest:.4} m): contacts too soft or timestep too large"))
    } else {
        None
    };
    Ok((
        StepReport {
            name: "physics".into(),
            passed: cause.is_none(),
            metrics,
            details: vec![format!("PD hold of the home pose for {} s with {} servos", opts.hold_secs, servos.len())],
            cause,
        },
        data,
    ))
}

/// Axis-aligned box of the contact points' x, y (world), if any.
fn contact_box(data: &Data) -> Option<([f64; 2], [f64; 2])> {
    let n = data.ncon();
    if n == 0 {
        return None;
    }
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in data.contact_positions() {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    Some((lo, hi))
}

fn sensors_step(data: &mut Data) -> Result<StepReport> {
    let model = data.model().clone();
    data.forward()?;
    let g = Vector3::from(model.gravity());
    let mut metrics = Vec::new();
    let mut details = Vec::new();
    let mut worst_acc = 0.0f64;
    let mut worst_quat = 0.0f64;
    let mut worst_joint = 0.0f64;
    let mut n_imu = 0;
    let mut n_joint = 0;
    let sd = data.sensordata().to_vec();
    for s in 0..model.nsensor() {
        let adr = model.sensor_adr()[s] as usize;
        let obj = model.sensor_objid()[s].max(0) as usize;
        match model.sensor_kind(s) {
            SensorType::Accelerometer => {
                let r = Matrix3::from_row_slice(&data.site_xmat()[obj]);
                let expected = r.transpose() * (-g);
                let got = Vector3::new(sd[adr], sd[adr + 1], sd[adr + 2]);
                let err = (got - expected).norm();
                worst_acc = worst_acc.max(err);
                n_imu += 1;
                details.push(format!(
                    "{}: reads ({:.3}, {:.3}, {:.3}) m/s², gravity in its frame ({:.3}, {:.3}, {:.3})",
                    model.name(ObjType::Sensor, s),
                    got.x,
                    got.y,
                    got.z,
                    expected.x,
                    expected.y,
                    expected.z
                ));
            }
            SensorType::FrameQuat if model.sensor_object(s) == Some(ObjType::Site) => {
                let r = Matrix3::from_row_slice(&data.site_xmat()[obj]);
                let site = UnitQuaternion::from_matrix(&r);
                let got = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    sd[adr],
                    sd[adr + 1],
                    sd[adr + 2],
                    sd[adr + 3],
                ));
                worst_quat = worst_quat.max((site.inverse() * got).angle());
            }
            SensorType::JointPos => {
                let q = data.qpos()[model.jnt_qposadr()[obj] as usize];
                worst_joint = worst_joint.max((sd[adr] - q).abs());
                n_joint += 1;
            }
            SensorType::JointVel => {
                let v = data.qvel()[model.jnt_dofadr()[obj] as usize];
                worst_joint = worst_joint.max((sd[adr] - v).abs());
            }
            _ => {}
        }
    }
    metrics.push(metric("accelerometer error vs gravity", worst_acc, "m/s²"));
    metrics.push(metric("orientation error vs body", worst_quat, "rad"));
    metrics.push(metric("joint sensor error", worst_joint, "rad"));
    if n_imu == 0 {
        details.push("no accelerometer in the model: IMU not checked".into());
    }
    if n_joint == 0 {
        details.push("no jointpos sensors in the model".into());
    }
    let cause = if worst_acc > 0.2 {
        Some("the accelerometer does not read gravity at rest: the IMU site is mis-oriented or the robot is still moving".to_string())
    } else if worst_quat > 1e-6 {
        Some("framequat disagrees with its site: wrong frame in the sensor definition".to_string())
    } else if worst_joint > 1e-9 {
        Some("joint sensors disagree with the joint state".to_string())
    } else {
        None
    };
    Ok(StepReport { name: "sensors".into(), passed: cause.is_none(), metrics, details, cause })
}

/// A joint's response to a position step: overshoot, settling time, final error, and the error
/// envelope early and late (a growing oscillation).
struct StepWatch {
    adr: usize,
    q0: f64,
    amplitude: f64,
    steps: usize,
    dt: f64,
    peak: f64,
    settle: f64,
    tail_err: f64,
    env_a: f64,
    env_b: f64,
}

impl Observer for StepWatch {
    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let (i, dt, amp) = (step.index as usize, self.dt, self.amplitude);
        let q = step.data.qpos()[self.adr];
        let e = q - (self.q0 + amp);
        let over = (q - self.q0) / amp - 1.0;
        self.peak = self.peak.max(over);
        if e.abs() > 0.05 * amp.abs() {
            self.settle = (i + 1) as f64 * dt;
        }
        if i + (0.1 / dt) as usize >= self.steps {
            self.tail_err = self.tail_err.max(e.abs());
        }
        let t = i as f64 * dt;
        if (1.0..1.25).contains(&t) {
            self.env_a = self.env_a.max(e.abs());
        }
        if t >= 1.25 {
            self.env_b = self.env_b.max(e.abs());
        }
        Ok(Flow::Continue)
    }
}

/// Squared tracking error of a 1 Hz sine of half the step amplitude, after 0.5 s.
struct SineWatch {
    adr: usize,
    q0: f64,
    half_amplitude: f64,
    omega: f64,
    dt: f64,
    sq: f64,
    count: usize,
}

impl Observer for SineWatch {
    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let t = step.index as f64 * self.dt;
        if t >= 0.5 {
            let e = step.data.qpos()[self.adr] - (self.q0 + self.half_amplitude * (self.omega * (t + self.dt)).sin());
            self.sq += e * e;
            self.count += 1;
        }
        Ok(Flow::Continue)
    }
}

fn control_step(model: Arc<Model>, servos: &[(usize, usize, f64)], opts: &CheckOptions) -> Result<StepReport> {
    let home = crate::control::nominal_pose(&model);
    let free = model.free_joint();
    let dt = model.timestep_secs();
    let mut engine = Engine::new();
    let mut details = Vec::new();
    let (mut worst_err, mut worst_over, mut worst_settle, mut worst_rms) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut failures = 0;
    let mut growing_any = false;
    let mut pin = free.map(|free| PinBase { free, home: home.clone() });
    for &(_, j, _) in servos {
        let adr = model.jnt_qposadr()[j] as usize;
        let q0 = home[adr];
        let amp = if model.jnt_limited()[j] {
            let [lo, hi] = model.jnt_range()[j];
            let width = hi - lo;
            let a = opts.step_amplitude.min(0.25 * width);
            if q0 + a <= hi { a } else { -a }
        } else {
            opts.step_amplitude
        };
        let mut disturbances: Vec<&mut dyn Disturbance> = pin.iter_mut().map(|p| p as &mut dyn Disturbance).collect();
        // Step.
        let mut target = home.clone();
        target[adr] = q0 + amp;
        let n = (1.5 / dt) as usize;
        let mut watch = StepWatch {
            adr,
            q0,
            amplitude: amp,
            steps: n,
            dt,
            peak: 0.0,
            settle: 0.0,
            tail_err: 0.0,
            env_a: 0.0,
            env_b: 0.0,
        };
        let mut controller = ServoTargets::new(&model, servos, target, None);
        run(&mut engine, &model, &home, n as u64, &mut controller, &mut disturbances, &mut [&mut watch])?;
        let StepWatch { peak, settle, tail_err, env_a, env_b, .. } = watch;
        let growing = env_b > 1.5 * env_a && env_b > 0.05 * amp.abs();
        // Sine, 1 Hz, 2 s.
        let n = (2.0 / dt) as usize;
        let omega = 2.0 * std::f64::consts::PI;
        let sine = Sine { adr, q0, half_amplitude: 0.5 * amp, omega, dt };
        let mut watch = SineWatch { adr, q0, half_amplitude: 0.5 * amp, omega, dt, sq: 0.0, count: 0 };
        let mut controller = ServoTargets::new(&model, servos, home.clone(), Some(sine));
        run(&mut engine, &model, &home, n as u64, &mut controller, &mut disturbances, &mut [&mut watch])?;
        let (sq, cnt) = (watch.sq, watch.count);
        let diverged = engine.data().is_some_and(Data::diverged);
        let rms = (sq / cnt.max(1) as f64).sqrt() / (0.5 * amp.abs());
        let rel_err = tail_err / amp.abs();
        worst_err = worst_err.max(rel_err);
        worst_over = worst_over.max(peak);
        worst_settle = worst_settle.max(settle);
        worst_rms = worst_rms.max(rms);
        let ok = rel_err <= 0.2 && peak <= 0.3 && rms <= 0.5 && !growing && !diverged;
        growing_any |= growing || diverged;
        if !ok {
            failures += 1;
            details.push(format!(
                "{}: step error {:.0} %, overshoot {:.0} %, settling {:.2} s, sine RMS error {:.0} %{}",
                model.name(ObjType::Joint, j),
                rel_err * 100.0,
                peak * 100.0,
                settle,
                rms * 100.0,
                if growing { ", growing oscillation" } else { "" }
            ));
        }
    }
    details.insert(
        0,
        format!(
            "{} actuated joints, step of ±{} and 1 Hz sine of half that, on a {} base",
            servos.len(),
            opts.step_amplitude,
            if free.is_some() { "pinned" } else { "fixed" }
        ),
    );
    let cause = if failures == 0 {
        None
    } else if growing_any {
        Some("growing oscillation: gains too high".to_string())
    } else if worst_over > 0.3 {
        Some("overshoot: damping too low for the gains".to_string())
    } else {
        Some("tracking error: effort limits or gains too low for the load".to_string())
    };
    Ok(StepReport {
        name: "control".into(),
        passed: failures == 0 && !servos.is_empty() || servos.is_empty(),
        metrics: vec![
            metric("worst step error (last 0.1 s, of step)", worst_err * 100.0, "%"),
            metric("worst overshoot", worst_over.max(0.0) * 100.0, "%"),
            metric("worst settling time (5 % band)", worst_settle, "s"),
            metric("worst sine RMS error (of amplitude)", worst_rms * 100.0, "%"),
            metric("joints failing", failures as f64, ""),
        ],
        details,
        cause,
    })
}

fn integration_step(model: &Arc<Model>, servos: &[(usize, usize, f64)], opts: &CheckOptions) -> Result<StepReport> {
    // MuJoCo's own step loop (`mj_step` n times, in C) on the held pose: the physics' speed,
    // without any of twin's per-step work.
    let mut data = Data::new(model.clone())?;
    let home = crate::control::nominal_pose(model);
    data.qpos_mut().copy_from_slice(&home);
    for (a, adr, gear) in ServoTargets::new(model, servos, home.clone(), None).servos {
        data.ctrl_mut()[a] = gear * home[adr];
    }
    let n = (opts.timing_secs / model.timestep_secs()).round().max(1.0) as u64;
    let start = std::time::Instant::now();
    data.step_n(n)?;
    let wall = start.elapsed().as_secs_f64().max(1e-9);
    let rtf = opts.timing_secs / wall;
    let cause = (rtf < 1.0).then(|| {
        format!(
            "real-time factor {rtf:.2} < 1: timestep too small ({} s) for this machine, or too many contacts",
            model.timestep_secs()
        )
    });
    Ok(StepReport {
        name: "integration".into(),
        passed: cause.is_none(),
        metrics: vec![
            metric("real-time factor", rtf, "×"),
            metric("step time", wall / n as f64 * 1e6, "µs"),
            metric("timestep", model.timestep_secs(), "s"),
        ],
        details: vec![],
        cause,
    })
}
