//! Reach, grasp and lift: a [`Grasper`] controller (`grasp`) and the checks of a grasp
//! ([`GraspCheck`]).
//!
//! The controller, each step:
//! 1. **Legs**: the walking controller ([`crate::walk::Walker`]) with a zero velocity command
//!    keeps the balance: it crouches to its CoM height, then holds the CoM over the feet by the
//!    DCM feedback (stepping if pushed). Its commands for the arms and fingers are replaced.
//! 2. **Look** (while settling): the head depth camera at its rate; each frame gives a cup
//!    estimate ([`perceive::Eye::look`]); the estimate is the mean of the last
//!    `detect_frames`.
//! 3. **Plan, before moving**: the arm on the cup's side (or the one that reaches) gets a
//!    pre-grasp pose (`pregrasp_distance_m` back along the horizontal approach from the shoulder),
//!    the grasp pose (grasp frame on the cup's axis at mid-height, jaws horizontal) and the
//!    lifted pose, each solved by damped least squares on MuJoCo's Jacobians
//!    ([`arm::solve`]). A pose left farther than `reach_tolerance_m` from its target refuses the
//!    grasp: the arms never move, and [`Grasper::refusal`] says why.
//! 4. **Move**: joint-space to the pre-grasp pose, a straight approach to the grasp pose (IK
//!    each step from the measured base pose), close the fingers with `grip_force_n` each
//!    (effort-limited finger motors), lift `lift_height_m` straight up, hold.
//!
//! Arm joints track their targets with the PD gain rule of twin plus gravity compensation
//! (`qfrc_bias` of the observed state).

pub mod arm;
pub mod check;
pub mod perceive;

pub use arm::{ArmSide, IkResult, Target};
pub use check::{GraspCheck, GraspMeasure};
pub use perceive::{CupSighting, Eye};

use crate::walk::{WalkOptions, Walker};
use arm::Arm;
use nalgebra::Vector3;
use std::sync::Arc;
use twin_core::control::{Controller, Observation};
use twin_core::error::{Error, Result};
use twin_core::mj::{Data, Model};

/// Options of the [`Grasper`]. Every field has a default; scenario files set them by name in
/// `[grasp]`.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize, smart_default::SmartDefault)]
#[serde(default, deny_unknown_fields)]
pub struct GraspOptions {
    /// Which arm grasps: `auto` (the cup's side, else the one that reaches), `left` or `right`
    /// (default: `auto`).
    #[default("auto")]
    pub arm: String,
    /// Squeeze of each finger, N (default: 8: six times what μ 0.8 needs for a 0.2 kg cup).
    #[default(8.0)]
    pub grip_force_n: f64,
    /// How high to lift the cup, m (default: 0.15).
    #[default(0.15)]
    pub lift_height_m: f64,
    /// Time to stand and look before moving, s (default: 1.6: the walker's 1 s crouch, then
    /// frames of the settled camera).
    #[default(1.6)]
    pub settle_secs: f64,
    /// The depth camera (default: `head_depth`, the camera of models/humanoid_gripper.urdf).
    #[default("head_depth")]
    pub camera: String,
    /// Camera frame rate, Hz (default: 15).
    #[default(15.0)]
    pub camera_rate_hz: f64,
    /// Depth noise standard deviation, m (default: 0.002). A scenario stores it in the model
    /// (the camera's user number 0), which wins, so that `twin randomize` can draw it.
    #[default(0.002)]
    pub camera_noise_std_m: f64,
    /// Seed of the depth noise (default: 0).
    pub camera_seed: u64,
    /// Frames whose estimates are averaged (default: 3).
    #[default(3)]
    pub detect_frames: usize,
    /// Distance of the pre-grasp pose before the grasp pose along the approach, m (default: 0.1).
    #[default(0.1)]
    pub pregrasp_distance_m: f64,
    /// Raise the hand above the table's height, s (default: 1.0).
    #[default(1.0)]
    pub raise_secs: f64,
    /// Least height of the grasp point above the table when the arm is raised, m (default:
    /// 0.04).
    #[default(0.04)]
    pub clearance_height_m: f64,
    /// Shoulder pitch backwards of the arm that does not grasp, rad (default: 0.4: its hand
    /// stays clear of the table when the trunk turns).
    #[default(0.4)]
    pub tuck_rad: f64,
    /// Shoulder roll of the raised arm (sideways, beside the table), rad (default: 1.25).
    #[default(1.25)]
    pub raise_roll_rad: f64,
    /// Move to the pre-grasp pose, s (default: 1.0).
    #[default(1.0)]
    pub reach_secs: f64,
    /// Approach from pre-grasp to grasp, s (default: 1.0).
    #[default(1.0)]
    pub approach_secs: f64,
    /// Closing the fingers, s (default: 0.6).
    #[default(0.6)]
    pub close_secs: f64,
    /// Lifting, s (default: 1.5).
    #[default(1.5)]
    pub lift_secs: f64,
    /// Largest IK position error of a planned pose that still counts as reachable, m
    /// (default: 0.01).
    #[default(0.01)]
    pub reach_tolerance_m: f64,
    /// Finger opening (each finger's joint position) while reaching, m (default: 0.05).
    #[default(0.05)]
    pub open_m: f64,
    /// PD saturation error of the arm joints, rad (default: 0.15).
    #[default(0.15)]
    pub saturation_error: f64,
    /// Shoulder roll away from the body at the start, rad (default: 0.25: the open grippers
    /// clear the thighs).
    #[default(0.25)]
    pub arms_out_rad: f64,
    /// How far the approach axis points down, rad (default: 0.1: the forearm rises slightly
    /// away from the table).
    #[default(0.1)]
    pub approach_pitch_rad: f64,
    /// Largest tilt of the jaw axis out of the horizontal in a planned pose, rad (default: 0.3;
    /// μ 0.8 holds a vertical cylinder up to 0.67).
    #[default(0.3)]
    pub max_jaw_tilt_rad: f64,
    /// Trunk joints the arms' IK may use besides the arm's own, with their IK weight (smaller:
    /// moves less) (default: none: the walker holds the trunk; e.g. `[["waist_yaw_joint", 0.2]]` lets a
    /// 4-joint arm also hold the approach level, at the price of a turning trunk).
    pub trunk_joints: Vec<(String, f64)>,
    /// Grasp frames of the left and right grippers (default: `left_grasp_link`,
    /// `right_grasp_link`).
    #[default(["left_grasp_link".into(), "right_grasp_link".into()])]
    pub grasp_bodies: [String; 2],
}

impl GraspOptions {
    /// Checks every option's range; the error names the option.
    ///
    /// # Errors
    /// `(field, message)` for the first option out of range.
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        if !["auto", "left", "right"].contains(&self.arm.as_str()) {
            return Err(("arm", format!("must be auto, left or right (got \"{}\")", self.arm)));
        }
        twin_core::bounds::positive([
            ("lift_height_m", self.lift_height_m),
            ("settle_secs", self.settle_secs),
            ("camera_rate_hz", self.camera_rate_hz),
            ("raise_secs", self.raise_secs),
            ("clearance_height_m", self.clearance_height_m),
            ("raise_roll_rad", self.raise_roll_rad),
            ("reach_secs", self.reach_secs),
            ("approach_secs", self.approach_secs),
            ("close_secs", self.close_secs),
            ("lift_secs", self.lift_secs),
            ("reach_tolerance_m", self.reach_tolerance_m),
            ("open_m", self.open_m),
            ("saturation_error", self.saturation_error),
        ])?;
        twin_core::bounds::non_negative([
            ("grip_force_n", self.grip_force_n),
            ("camera_noise_std_m", self.camera_noise_std_m),
            ("pregrasp_distance_m", self.pregrasp_distance_m),
            ("arms_out_rad", self.arms_out_rad),
            ("max_jaw_tilt_rad", self.max_jaw_tilt_rad),
            ("tuck_rad", self.tuck_rad),
        ])?;
        if self.detect_frames == 0 {
            return Err(("detect_frames", "must be at least 1".into()));
        }
        Ok(())
    }
}

/// What the grasper is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// Standing, looking.
    Settle,
    /// Joint-space move raising the hand above the table's height.
    Raise,
    /// Straight move to the pre-grasp pose.
    Reach,
    /// Straight approach to the grasp pose.
    Approach,
    /// Closing the fingers.
    Close,
    /// Lifting.
    Lift,
    /// Holding the cup up.
    Hold,
    /// Refused before moving (see [`Grasper::refusal`]).
    Refused,
}

/// The plan made once the cup is seen.
#[derive(Debug, Clone)]
struct Plan {
    arm: usize,
    grasp: Vector3<f64>,
    approach: Vector3<f64>,
    via: Vector3<f64>,
    q_start: Vec<f64>,
    q_via: Vec<f64>,
}

/// The reach-grasp-lift controller (`grasp`): see the [module docs](self).
pub struct Grasper {
    options: GraspOptions,
    walker: Walker,
    arms: Vec<Arm>,
    eye: Option<Eye>,
    /// The observed state, forward-computed (bias forces, the camera's view).
    sim: Option<Data>,
    /// IK scratch state.
    scratch: Option<Data>,
    phase: Phase,
    phase_start: f64,
    t0: f64,
    last_frame: Option<u64>,
    sightings: Vec<CupSighting>,
    estimate: Option<CupSighting>,
    plan: Option<Plan>,
    /// Arm joint targets (per arm).
    q_des: Vec<Vec<f64>>,
    refusal: Option<String>,
    fault: Option<String>,
    /// The legs' options asked for the double-support ankle torques, which grasping turns off.
    ankle_overridden: bool,
}

impl std::fmt::Debug for Grasper {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Grasper")
            .field("phase", &self.phase)
            .field("estimate", &self.estimate)
            .field("refusal", &self.refusal)
            .finish()
    }
}

/// Smoothstep on [0, 1].
fn smooth(a: f64) -> f64 {
    let a = a.clamp(0.0, 1.0);
    a * a * (3.0 - 2.0 * a)
}

impl Grasper {
    /// A grasper for `model`: `options` for the arms, `walk` for the legs' balance (with
    /// [`WalkOptions::double_support_ankle`] off: the reaching arm moves the commanded ZMP).
    ///
    /// # Errors
    /// [`Error::Grasp`] for an option out of range or a model without grippers or camera; as
    /// [`Walker::new`].
    pub fn new(model: &Model, options: GraspOptions, walk: WalkOptions) -> Result<Grasper> {
        options.validate().map_err(|(key, m)| Error::Grasp { message: format!("option `{key}` {m}") })?;
        let ankle_overridden = walk.double_support_ankle;
        let walker = Walker::new(model, WalkOptions { double_support_ankle: false, ..walk })?;
        let mut g = Grasper {
            options,
            walker,
            arms: Vec::new(),
            eye: None,
            sim: None,
            scratch: None,
            phase: Phase::Settle,
            phase_start: 0.0,
            t0: 0.0,
            last_frame: None,
            sightings: Vec::new(),
            estimate: None,
            plan: None,
            q_des: Vec::new(),
            refusal: None,
            fault: None,
            ankle_overridden,
        };
        g.bind(model)?;
        Ok(g)
    }

    fn bind(&mut self, model: &Model) -> Result<()> {
        let o = &self.options;
        let ids: Vec<Option<usize>> =
            o.grasp_bodies.iter().map(|n| model.id(twin_core::mj::ObjType::Body, n)).collect();
        let mut arms = Vec::new();
        for (k, side) in [ArmSide::Left, ArmSide::Right].into_iter().enumerate() {
            let wanted = o.arm == "auto" || o.arm == side.label();
            if !wanted {
                continue;
            }
            arms.push(Arm::find(model, side, &o.grasp_bodies[k], ids[1 - k], o.saturation_error, &o.trunk_joints)?);
        }
        self.arms = arms;
        // The model's camera user 0 holds the noise when it has one (scenarios, randomized).
        let noise = model
            .id(twin_core::mj::ObjType::Camera, &o.camera)
            .and_then(|c| model.cam_user(c).first().copied())
            .unwrap_or(o.camera_noise_std_m);
        self.eye = Some(Eye::new(model, &o.camera, noise, o.camera_seed)?);
        Ok(())
    }

    /// The options.
    pub fn options(&self) -> &GraspOptions {
        &self.options
    }

    /// The phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The cup estimate the plan used, once made.
    pub fn estimate(&self) -> Option<&CupSighting> {
        self.estimate.as_ref()
    }

    /// Why the grasp was refused (the cup out of reach, not seen), if it was.
    pub fn refusal(&self) -> Option<&str> {
        self.refusal.as_deref()
    }

    /// The arm that grasps, once planned.
    pub fn arm(&self) -> Option<ArmSide> {
        self.plan.as_ref().map(|p| self.arms[p.arm].side)
    }

    /// The walker keeping the balance.
    pub fn walker(&self) -> &Walker {
        &self.walker
    }

    /// Copies the observed state into `sim` and runs a forward pass.
    fn sync(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        let sim = match self.sim.as_mut() {
            Some(s) => s,
            None => self.sim.insert(Data::new(Arc::new(model.try_clone()?))?),
        };
        sim.qpos_mut().copy_from_slice(observation.qpos);
        sim.qvel_mut().copy_from_slice(observation.qvel);
        sim.set_time_secs(observation.time_secs);
        sim.forward()?;
        if self.scratch.is_none() {
            let model = sim.model().clone();
            self.scratch = Some(Data::new(model)?);
        }
        Ok(())
    }

    /// Solves `target` for arm `a` from `q` on the scratch state set to the observed `qpos`.
    fn ik(&mut self, a: usize, qpos: &[f64], target: &Target, q: &mut [f64], iterations: usize) -> Result<IkResult> {
        let scratch =
            self.scratch.as_mut().ok_or_else(|| Error::Grasp { message: "IK before the first observation".into() })?;
        scratch.qpos_mut().copy_from_slice(qpos);
        arm::solve(scratch, &self.arms[a], target, q, iterations, 0.05)
    }

    /// The plan for the estimate `cup`, or why the cup can't be grasped.
    fn plan(&mut self, qpos: &[f64], cup: &CupSighting) -> std::result::Result<Plan, String> {
        let grasp = Vector3::new(cup.centre_world.x, cup.centre_world.y, cup.table_height_m + cup.height_m / 2.0);
        let mut order: Vec<usize> = (0..self.arms.len()).collect();
        // The arm whose shoulder is nearer the cup first.
        let sim = self.sim.as_ref().ok_or("no observation yet")?;
        let shoulders: Vec<Vector3<f64>> =
            self.arms.iter().map(|a| Vector3::from(sim.xpos()[a.shoulder_body])).collect();
        if shoulders.len() == 2 && (grasp - shoulders[1]).xy().norm() < (grasp - shoulders[0]).xy().norm() {
            order.reverse();
        }
        let mut why = Vec::new();
        for a in order {
            let q_start = self.arms[a].q(qpos);
            let mut q = q_start.clone();
            // The grasp pose first (its approach axis is the approach path): position alone
            // (well-posed from a hanging arm), then with the jaw level and the approach pitch.
            let reach = Target { position: grasp, approach: None };
            self.ik(a, qpos, &reach, &mut q, 200).map_err(|e| e.to_string())?;
            let target = Target { position: grasp, approach: Some(self.options.approach_pitch_rad) };
            let r = self.ik(a, qpos, &target, &mut q, 400).map_err(|e| e.to_string())?;
            let mut failed = (r.position_error_m > self.options.reach_tolerance_m
                || r.jaw_tilt_rad > self.options.max_jaw_tilt_rad)
                .then_some(("grasp", grasp, r));
            let mut dir = self.approach_of(a, qpos, &q).unwrap_or_else(|| {
                let s = shoulders[a];
                Vector3::new(grasp.x - s.x, grasp.y - s.y, 0.0)
            });
            if dir.norm() < 1e-6 {
                dir = Vector3::x();
            }
            dir.normalize_mut();
            let q_grasp = q.clone();
            let pre = grasp - dir * self.options.pregrasp_distance_m;
            let lifted = grasp + Vector3::z() * self.options.lift_height_m;
            // The arm first rises sideways (shoulder roll only), beside the table: the hand moves
            // over the table only once it is above it.
            let q_via = self.raised(a, &q_start);
            let via = self.grasp_point(a, qpos, &q_via).unwrap_or(pre);
            if failed.is_none() && via.z < cup.table_height_m + self.options.clearance_height_m {
                failed = Some((
                    "raised",
                    via,
                    IkResult {
                        position_error_m: cup.table_height_m + self.options.clearance_height_m - via.z,
                        jaw_tilt_rad: 0.0,
                    },
                ));
            }
            if failed.is_none() {
                for (name, p) in [("pre-grasp", pre), ("lifted", lifted)] {
                    let mut qq = q_grasp.clone();
                    let target = Target { position: p, approach: Some(self.options.approach_pitch_rad) };
                    let r = self.ik(a, qpos, &target, &mut qq, 300).map_err(|e| e.to_string())?;
                    if r.position_error_m > self.options.reach_tolerance_m
                        || r.jaw_tilt_rad > self.options.max_jaw_tilt_rad
                    {
                        failed = Some((name, p, r));
                        break;
                    }
                }
            }
            match failed {
                None => return Ok(Plan { arm: a, grasp, approach: dir, via, q_start, q_via }),
                Some((name, p, r)) => why.push(format!(
                    "the {} arm's {name} pose at ({:.3}, {:.3}, {:.3}) m is off by {:.3} m (jaw tilt {:.2} rad)",
                    self.arms[a].side.label(),
                    p.x,
                    p.y,
                    p.z,
                    r.position_error_m,
                    r.jaw_tilt_rad
                )),
            }
        }
        Err(format!(
            "the cup seen at ({:.3}, {:.3}, {:.3}) m is out of reach: {}; tolerance {} m (reach_tolerance_m)",
            cup.centre_world.x,
            cup.centre_world.y,
            cup.centre_world.z,
            why.join("; "),
            self.options.reach_tolerance_m
        ))
    }

    /// Arm `a`'s joints at `q` with the shoulder rolled out to `raise_roll_rad`.
    fn raised(&self, a: usize, q: &[f64]) -> Vec<f64> {
        let arm = &self.arms[a];
        let sign = match arm.side {
            ArmSide::Left => 1.0,
            ArmSide::Right => -1.0,
        };
        let model = self.sim.as_ref().map(|s| s.model().clone());
        let mut out = q.to_vec();
        if let Some(model) = model {
            for (k, l) in arm.joints.iter().enumerate() {
                let axis = model.jnt_axis()[l.joint];
                if axis[0].abs() > 0.9 {
                    let v = sign * axis[0].signum() * self.options.raise_roll_rad;
                    out[k] = l.range.map_or(v, |[lo, hi]| v.clamp(lo, hi));
                    break;
                }
            }
        }
        out
    }

    /// Arm `a`'s joints at `q` with the shoulder pitched back by `tuck_rad` (its first joint
    /// about y).
    fn tucked(&self, a: usize, q: &[f64]) -> Vec<f64> {
        let mut out = q.to_vec();
        if let Some(model) = self.sim.as_ref().map(|s| s.model().clone()) {
            let n_trunk = self.options.trunk_joints.len();
            for (k, l) in self.arms[a].joints.iter().enumerate().skip(n_trunk) {
                let axis = model.jnt_axis()[l.joint];
                if axis[1].abs() > 0.9 {
                    let v = out[k] + axis[1].signum() * self.options.tuck_rad;
                    out[k] = l.range.map_or(v, |[lo, hi]| v.clamp(lo, hi));
                    break;
                }
            }
        }
        out
    }

    /// Arm `a`'s grasp point with its joints at `q`.
    fn grasp_point(&mut self, a: usize, qpos: &[f64], q: &[f64]) -> Option<Vector3<f64>> {
        let body = self.arms[a].grasp_body;
        let scratch = self.posed(a, qpos, q)?;
        Some(Vector3::from(scratch.xpos()[body]))
    }

    /// Arm `a`'s approach axis (world) with its joints at `q`.
    fn approach_of(&mut self, a: usize, qpos: &[f64], q: &[f64]) -> Option<Vector3<f64>> {
        let body = self.arms[a].grasp_body;
        let m = self.posed(a, qpos, q)?.xmat()[body];
        Some(Vector3::new(-m[2], -m[5], -m[8]))
    }

    /// The scratch data at `qpos` with arm `a`'s joints at `q`, its kinematics computed.
    fn posed(&mut self, a: usize, qpos: &[f64], q: &[f64]) -> Option<&Data> {
        let scratch = self.scratch.as_mut()?;
        scratch.qpos_mut().copy_from_slice(qpos);
        for (l, &v) in self.arms[a].joints.iter().zip(q) {
            scratch.qpos_mut()[l.qpos_adr] = v;
        }
        scratch.kinematics_with_velocity().ok()?;
        Some(scratch)
    }

    fn set_phase(&mut self, phase: Phase, t: f64) {
        self.phase = phase;
        self.phase_start = t;
    }

    /// Looks through the camera when a frame is due.
    fn look(&mut self, model: &Model, t: f64) {
        let frame = (t * self.options.camera_rate_hz).floor() as u64;
        if self.last_frame == Some(frame) {
            return;
        }
        self.last_frame = Some(frame);
        let (Some(eye), Some(sim)) = (self.eye.as_mut(), self.sim.as_ref()) else { return };
        match eye.look(model, sim) {
            Ok(s) => {
                self.sightings.push(s);
                let n = self.options.detect_frames;
                if self.sightings.len() > n {
                    self.sightings.remove(0);
                }
            }
            Err(_) => self.sightings.clear(),
        }
    }

    /// Arm `a`'s joint targets from the Cartesian target `p` (incremental IK from the last
    /// targets).
    fn track(&mut self, a: usize, qpos: &[f64], p: Vector3<f64>, approach: Vector3<f64>) {
        let mut q = self.q_des[a].clone();
        let _ = approach;
        let target = Target { position: p, approach: Some(self.options.approach_pitch_rad) };
        match self.ik(a, qpos, &target, &mut q, 3) {
            Ok(_) => self.q_des[a] = q,
            Err(e) => self.fault = Some(e.to_string()),
        }
    }
}

impl Controller for Grasper {
    fn name(&self) -> &'static str {
        "grasp"
    }

    fn reset(&mut self, model: &Model, observation: &Observation<'_>) -> Result<()> {
        self.walker.reset(model, observation)?;
        self.bind(model)?;
        self.sim = None;
        self.scratch = None;
        self.sync(model, observation)?;
        self.t0 = observation.time_secs;
        self.set_phase(Phase::Settle, 0.0);
        self.last_frame = None;
        self.sightings.clear();
        self.estimate = None;
        self.plan = None;
        self.refusal = None;
        self.fault = None;
        self.q_des = self.arms.iter().map(|a| a.q(observation.qpos)).collect();
        Ok(())
    }

    fn initial_qpos(&self, model: &Model, qpos: &mut [f64]) {
        // Arms slightly out to the sides, so that the open grippers clear the thighs.
        for arm in &self.arms {
            let sign = match arm.side {
                ArmSide::Left => 1.0,
                ArmSide::Right => -1.0,
            };
            for l in &arm.joints {
                let axis = model.jnt_axis()[l.joint];
                if axis[0].abs() > 0.9 {
                    let v = qpos[l.qpos_adr] + sign * axis[0].signum() * self.options.arms_out_rad;
                    qpos[l.qpos_adr] = l.range.map_or(v, |[lo, hi]| v.clamp(lo, hi));
                }
            }
        }
    }

    fn compute(&mut self, model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        self.walker.compute(model, observation, command);
        let t = observation.time_secs - self.t0;
        if let Err(e) = self.sync(model, observation) {
            self.fault = Some(e.to_string());
        }
        let o = self.options.clone();
        let qpos = observation.qpos;
        // Phase transitions.
        match self.phase {
            Phase::Settle => {
                if t >= o.settle_secs - o.detect_frames as f64 / o.camera_rate_hz - 0.05 {
                    self.look(model, t);
                }
                if t >= o.settle_secs {
                    self.estimate = CupSighting::mean(&self.sightings);
                    match self.estimate {
                        None => {
                            self.refusal = Some(format!(
                                "no cup seen by camera \"{}\" in the last {} frames",
                                o.camera, o.detect_frames
                            ));
                            self.set_phase(Phase::Refused, t);
                        }
                        Some(cup) => match self.plan(qpos, &cup) {
                            Ok(plan) => {
                                // The other arm swings back, out of the table's way.
                                for b in 0..self.arms.len() {
                                    if b != plan.arm {
                                        self.q_des[b] = self.tucked(b, &self.q_des[b]);
                                    }
                                }
                                self.plan = Some(plan);
                                self.set_phase(Phase::Raise, t);
                            }
                            Err(why) => {
                                self.refusal = Some(why);
                                self.set_phase(Phase::Refused, t);
                            }
                        },
                    }
                }
            }
            Phase::Raise if t - self.phase_start >= o.raise_secs => self.set_phase(Phase::Reach, t),
            Phase::Reach if t - self.phase_start >= o.reach_secs => self.set_phase(Phase::Approach, t),
            Phase::Approach if t - self.phase_start >= o.approach_secs => self.set_phase(Phase::Close, t),
            Phase::Close if t - self.phase_start >= o.close_secs => self.set_phase(Phase::Lift, t),
            Phase::Lift if t - self.phase_start >= o.lift_secs => self.set_phase(Phase::Hold, t),
            _ => {}
        }
        // Arm targets.
        let s = t - self.phase_start;
        if let Some(plan) = self.plan.clone() {
            let a = plan.arm;
            let pre = plan.grasp - plan.approach * o.pregrasp_distance_m;
            match self.phase {
                Phase::Raise => {
                    let k = smooth(s / o.raise_secs);
                    self.q_des[a] = plan.q_start.iter().zip(&plan.q_via).map(|(a, b)| a + (b - a) * k).collect();
                }
                Phase::Reach => {
                    let k = smooth(s / o.reach_secs);
                    self.track(a, qpos, plan.via + (pre - plan.via) * k, plan.approach);
                }
                Phase::Approach => {
                    let k = smooth(s / o.approach_secs);
                    self.track(a, qpos, pre + (plan.grasp - pre) * k, plan.approach);
                }
                Phase::Close => self.track(a, qpos, plan.grasp, plan.approach),
                Phase::Lift | Phase::Hold => {
                    let k = if self.phase == Phase::Lift { smooth(s / o.lift_secs) } else { 1.0 };
                    self.track(a, qpos, plan.grasp + Vector3::z() * (o.lift_height_m * k), plan.approach);
                }
                _ => {}
            }
        }
        // Arm and finger commands.
        let closing = matches!(self.phase, Phase::Close | Phase::Lift | Phase::Hold);
        let grasping_arm = self.plan.as_ref().map(|p| p.arm);
        let bias = self.sim.as_ref().map(|s| s.qfrc_bias().to_vec());
        for (a, arm) in self.arms.iter().enumerate() {
            for (l, &q_des) in arm.joints.iter().zip(&self.q_des[a]) {
                let ff = bias.as_ref().map_or(0.0, |b| b[l.dof]);
                let tau = l.kp * (q_des - qpos[l.qpos_adr]) - l.kd * observation.qvel[l.dof] + ff;
                command[l.command] = (tau / l.gear).clamp(l.limits[0], l.limits[1]);
            }
            let [f0, f1] = [&arm.fingers[0], &arm.fingers[1]];
            let mid = (qpos[f0.qpos_adr] + qpos[f1.qpos_adr]) / 2.0;
            for f in [f0, f1] {
                let q = qpos[f.qpos_adr];
                let v = observation.qvel[f.dof];
                let force = if closing && grasping_arm == Some(a) {
                    // Squeeze with the set force; a weak spring keeps the fingers symmetric. The
                    // fingers' joint damping (50 N·s/m in the URDF, integrated implicitly) caps
                    // the closing speed at 0.16 m/s, so the pads meet the cup without a blow.
                    -o.grip_force_n + 100.0 * (mid - q)
                } else {
                    f.kp * (o.open_m - q) - f.kd * v
                };
                command[f.command] = (force / f.gear).clamp(f.limits[0], f.limits[1]);
            }
        }
    }

    fn report(&self) -> Vec<String> {
        let mut out = Vec::new();
        if let Some(c) = &self.estimate {
            out.push(format!(
                "grasp: cup seen at ({:.4}, {:.4}, {:.4}) m, radius {:.4} m, height {:.4} m, table at {:.4} m",
                c.centre_world.x, c.centre_world.y, c.centre_world.z, c.radius_m, c.height_m, c.table_height_m
            ));
        }
        if let Some(side) = self.arm() {
            out.push(format!("grasp: {} arm, phase {:?}", side.label(), self.phase));
        }
        if let Some(r) = &self.refusal {
            out.push(format!("grasp: refused before moving: {r}"));
        }
        if let Some(f) = &self.fault {
            out.push(format!("grasp: fault: {f}"));
        }
        if self.ankle_overridden {
            out.push(
                "grasp: [walk] double_support_ankle = true overridden: the legs balance without the \
                 double-support ankle torques while the arm reaches (they tip the torso forward)"
                    .into(),
            );
        }
        out
    }
}
