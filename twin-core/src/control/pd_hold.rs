//! [`PdHold`]: holds the nominal pose with PD loops, and the one PD gain rule of twin
//! ([`pd_gains`]).

use super::{Actuation, Controller, Observation, nominal_pose};
use crate::convert::Interface;
use crate::error::Result;
use crate::mj::{JointType, Model};
use nalgebra::DMatrix;
use std::sync::Arc;

/// Options of [`PdHold`].
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct PdHoldOptions {
    /// Joint angle error (radians; metres for slides) at which a joint's PD torque reaches its
    /// effort limit: `kp = effort / saturation_error`. Stiff enough for the shipped humanoid's
    /// ankles to hold its whole weight. (default: 0.25)
    #[default(0.25)]
    pub saturation_error: f64,
    /// Damping ratio of each joint on its own effective inertia (`1 / dof_invweight0`):
    /// `kd = 2 · ratio · sqrt(kp · inertia)`. (default: 1.0)
    #[default(1.0)]
    pub damping_ratio: f64,
    /// Effort (N·m or N) assumed for joints and actuators without a force limit, when
    /// `min_natural_freq_hz` is not set. (default: 100.0)
    #[default(100.0)]
    pub default_effort: f64,
    /// Lowest natural frequency of a joint on its inertia, Hz: a floor on `kp`, and the
    /// stiffness of joints without an effort limit. (default: none)
    pub min_natural_freq_hz: Option<f64>,
    /// Cap `kp` at `inertia / dt²` for this timestep (seconds), so an explicit spring stays
    /// stable on the joint's own inertia. (default: none)
    pub stability_dt_secs: Option<f64>,
    /// [`PdHold`]'s cap on its loops together: the largest stability margin
    /// `a_K²/4 + a_D` of the coupled loops under the explicit step, with
    /// `a_K = √λmax(M⁻¹K)·dt` and `a_D = λmax(M⁻¹D)·dt / 2` (K, D the loops' joint-space
    /// stiffness and damping, M the inertia of the loops' joints at the home pose with every
    /// other DOF held, as a floating base standing on the ground; with them free, as in free
    /// fall, the margin may be 22 % higher). A torque held over a step from the state at its
    /// start is stable below 1
    /// (the Jury bound of semi-implicit Euler, mode by mode). Above it, every kp is scaled down
    /// by one factor (kd by its square root): light robots whose URDFs give placeholder effort
    /// limits (1000 N·m on a 2 kg quadruped) stay stable. `f64::INFINITY`: no cap. (default:
    /// 0.98; the shipped humanoid keeps its gains, down to 0.7 times its masses)
    #[default(0.98)]
    pub max_loop_margin: f64,
    /// Floor on the stiffness of the joints between a floating base and its feet, as a
    /// multiple of the stiffness gravity asks of them for the robot to stand in its home pose
    /// ([`stance_stiffness`]): a leg joint whose PD spring is softer than the weight it carries
    /// tips over, whatever its effort limit. Example-robot-data's Romeo (25.8 N·m ankles,
    /// 40.5 kg) got 103 N·m/rad per ankle from `effort / saturation_error` against the
    /// 120 N·m/rad per ankle its inverted pendulum needs, and fell in 1.4 s. `0`: no floor.
    /// (default: 3.0)
    #[default(3.0)]
    pub stance_stiffness_margin: f64,
}

/// One PD loop: a command entry driving one 1-DOF joint.
#[derive(Debug, Clone)]
pub struct PdLoop {
    /// Index in the command (`ctrl` or `qfrc_applied`).
    pub command: usize,
    /// The joint.
    pub joint: usize,
    /// Its `qpos` address.
    pub qpos_adr: usize,
    /// Its DOF.
    pub dof: usize,
    /// Stiffness, command units per rad (m).
    pub kp: f64,
    /// Damping, command units per rad/s (m/s).
    pub kd: f64,
    /// Joint torque (force) per command unit: the actuator gear, 1 for `qfrc_applied`.
    pub gear: f64,
    /// Target position, rad (m).
    pub target: f64,
    /// Command limits.
    pub limits: [f64; 2],
    /// What the command entry means: a torque (the PD law), or a position or velocity target
    /// for a servo actuator, which closes its own loop.
    pub interface: Interface,
}

/// How far the free-fall estimate of the loops' stability margin may exceed
/// [`PdHoldOptions::max_loop_margin`] (see [`PdHold`]'s stability cap). 1.0 since the cap is
/// applied mode by mode: with 1.22 (what one factor on every loop allowed) several modes sat at
/// a free-fall margin of 1.2 at once and Solo, Solo12 and Bolt diverged in their first second
/// (|q̇| up to 5·10⁶); with 1.0 none does.
const FREE_FALL_ALLOWANCE: f64 = 1.0;

/// Rate at which a velocity servo is sent back to its target, 1/s: `q̇_cmd = rate · (q_target − q)`.
const VELOCITY_SERVO_RATE: f64 = 10.0;

/// Holds the nominal pose ([`nominal_pose`]) with PD control on every actuated hinge/slide joint:
/// `τ = kp·(q_target − q) − kd·q̇`, clamped to the actuator's range / the joint's effort.
/// With actuators ([`crate::robot::actuators_of`]), each joint-transmission actuator drives its
/// joint: a torque actuator gets the PD torque / gear, a position servo its target position
/// (`gear · q_target`), a velocity servo a velocity back to the target; without actuators, every
/// hinge and slide joint gets `qfrc_applied`. Gains are capped for stability on each joint's
/// coupled inertia at the model's timestep ([`PdHoldOptions::max_loop_margin`]).
#[derive(Debug, Clone)]
pub struct PdHold {
    options: PdHoldOptions,
    pub(super) loops: Vec<PdLoop>,
}

impl PdHold {
    /// A PD hold for `model`; the targets are set by [`Controller::reset`].
    pub fn new(model: &Model, options: PdHoldOptions) -> PdHold {
        let mut hold = PdHold { options, loops: Vec::new() };
        hold.build(model);
        hold
    }

    /// The loops, in command order (targets are set by [`Controller::reset`]).
    pub fn loops(&self) -> &[PdLoop] {
        &self.loops
    }

    /// The gains `(kp, kd)` of each loop, in command order.
    pub fn gains(&self) -> Vec<(f64, f64)> {
        self.loops.iter().map(|l| (l.kp, l.kd)).collect()
    }

    fn build(&mut self, model: &Model) {
        let actuation = Actuation::of(model);
        let limits = actuation.limits(model);
        let o = &self.options;
        let stance = if o.stance_stiffness_margin > 0.0 { stance_stiffness(model) } else { vec![0.0; model.nv()] };
        let gains = |effort: f64, dof: usize, gear: f64| {
            let inertia = 1.0 / model.dof_invweight0()[dof].max(1e-12);
            let (mut kp, mut kd) = pd_gains(Some(effort), inertia, o);
            let floor = o.stance_stiffness_margin * stance[dof];
            if floor > kp {
                kp = floor;
                kd = 2.0 * o.damping_ratio * (kp * inertia).sqrt();
            }
            // Joint-space gains, expressed in command units (torque = gear · ctrl).
            (kp / gear, kd / gear)
        };
        self.loops.clear();
        match actuation {
            Actuation::Ctrl => {
                for a in crate::robot::actuators_of(model, &[]) {
                    // Only joint transmissions on 1-DOF joints are PD-able; others get 0.
                    let (Some(joint), gear) = (a.joint, a.gear) else { continue };
                    if gear == 0.0 {
                        continue;
                    }
                    let [lo, hi] = limits[a.id];
                    let dof = model.jnt_dofadr()[joint] as usize;
                    // The torque the actuator can give its joint (the one reading of it).
                    let effort = a.joint_effort(model);
                    // A servo closes its own loop here (`compute` sends it the target); its
                    // gains are the rule's for its force limit, for controllers that command
                    // torque through it (the walker). None without a force limit.
                    let (kp, kd) = if effort.is_finite() { gains(effort, dof, gear) } else { (0.0, 0.0) };
                    self.loops.push(PdLoop {
                        command: a.id,
                        joint,
                        qpos_adr: model.jnt_qposadr()[joint] as usize,
                        dof,
                        kp,
                        kd,
                        gear,
                        target: 0.0,
                        limits: [lo, hi],
                        interface: a.interface,
                    });
                }
            }
            Actuation::Qfrc => {
                for joint in 0..model.njnt() {
                    if !matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide) {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[joint] as usize;
                    let [lo, hi] = limits[dof];
                    let (kp, kd) = gains(hi.abs().min(lo.abs()), dof, 1.0);
                    self.loops.push(PdLoop {
                        command: dof,
                        joint,
                        qpos_adr: model.jnt_qposadr()[joint] as usize,
                        dof,
                        kp,
                        kd,
                        gear: 1.0,
                        target: 0.0,
                        limits: [lo, hi],
                        interface: Interface::Effort,
                    });
                }
            }
        }
        if let Some(scales) = self.stability_scales(model) {
            let mut k = 0;
            for l in &mut self.loops {
                if l.interface == Interface::Effort && l.kp > 0.0 {
                    l.kp *= scales[k];
                    l.kd *= scales[k].sqrt();
                    k += 1;
                }
            }
        }
    }

    /// The factor on each torque loop's kp (in loop order, servos skipped) that brings the
    /// coupled loops' stability margin down to [`PdHoldOptions::max_loop_margin`], when it is
    /// above (see there); `None` when it is not, or when the inertia can't be evaluated.
    ///
    /// The loops that are scaled are those of the mode that breaks the margin: each round
    /// takes the largest eigenvalue's mode of `K^½ M⁻¹ K^½` (or of the damping's, whichever
    /// term dominates) and scales each loop by the factor that mode needs, raised to its
    /// share of the mode (`v_i² / max v²`): a light wrist with a placeholder effort limit gets
    /// soft, the legs keep the stiffness they stand with. (One factor on every loop took the
    /// G1's ankles to 0.37 of their gains, 51 N·m/rad for its 33 kg, and it fell in 1.1 s; the
    /// iCub's to 5·10⁻¹⁰.) After [`MODE_ROUNDS`] rounds, one factor on every loop finishes.
    fn stability_scales(&self, model: &Model) -> Option<Vec<f64>> {
        let cap = self.options.max_loop_margin;
        let torque: Vec<&PdLoop> =
            self.loops.iter().filter(|l| l.interface == Interface::Effort && l.kp > 0.0).collect();
        if !cap.is_finite() || torque.is_empty() {
            return None;
        }
        let mut data = crate::mj::Data::new(Arc::new(model.clone())).ok()?;
        data.qpos_mut().copy_from_slice(&nominal_pose(model));
        data.forward().ok()?;
        let nv = model.nv();
        let m = DMatrix::from_row_slice(nv, nv, &data.full_mass_matrix());
        let n = torque.len();
        let dofs: Vec<usize> = torque.iter().map(|l| l.dof).collect();
        // The loops' joints' inertia lies between two bounds: every other DOF held (a floating
        // base standing on the ground; the inverse of M's block of those joints) and every other
        // DOF free (a base in free fall: the block of M⁻¹). The held one must meet the margin;
        // the free one may exceed it by FREE_FALL_ALLOWANCE, as a robot on the ground is held
        // by it.
        let held = DMatrix::from_fn(n, n, |i, j| m[(dofs[i], dofs[j])]).cholesky()?.inverse();
        let full_inv = m.cholesky()?.inverse();
        let free = DMatrix::from_fn(n, n, |i, j| full_inv[(dofs[i], dofs[j])]);
        let dt = model.timestep_secs();
        let kp: Vec<f64> = torque.iter().map(|l| (l.kp * l.gear).max(0.0)).collect();
        let kd: Vec<f64> = torque.iter().map(|l| (l.kd * l.gear).max(0.0)).collect();
        // Per bound: the factor on every loop that meets its cap (`None`: met), and the mode
        // that needs it (the unit eigenvector of the dominating term).
        let needed = |m_inv: &DMatrix<f64>, cap: f64, s: &[f64]| -> Option<(f64, nalgebra::DVector<f64>)> {
            let largest = |gain: &[f64], power: f64| {
                let r: Vec<f64> = gain.iter().zip(s).map(|(g, s)| (g * s.powf(power)).sqrt()).collect();
                let e = DMatrix::from_fn(n, n, |i, j| r[i] * m_inv[(i, j)] * r[j]).symmetric_eigen();
                let k = e.eigenvalues.imax();
                (e.eigenvalues[k], e.eigenvectors.column(k).into_owned())
            };
            let (lk, vk) = largest(&kp, 1.0);
            let (ld, vd) = largest(&kd, 0.5);
            let a_k = lk.max(0.0).sqrt() * dt;
            let a_d = ld * dt / 2.0;
            if !(a_k.is_finite() && a_d.is_finite()) || a_k * a_k / 4.0 + a_d <= cap {
                return None;
            }
            // With kp·s and kd·√s the margin is s·a_K²/4 + √s·a_D: solve for √s.
            let r = (-a_d + (a_d * a_d + a_k * a_k * cap).sqrt()) / (a_k * a_k / 2.0);
            Some((r * r, if a_k * a_k / 4.0 >= a_d { vk } else { vd }))
        };
        let mut s = vec![1.0; n];
        let mut scaled = false;
        for round in 0..=MODE_ROUNDS {
            let worst = match (needed(&held, cap, &s), needed(&free, cap * FREE_FALL_ALLOWANCE, &s)) {
                (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
                (a, b) => a.or(b),
            };
            let Some((factor, mode)) = worst else { break };
            scaled = true;
            if !(factor.is_finite() && factor > 0.0) {
                return None;
            }
            if round == MODE_ROUNDS {
                s.iter_mut().for_each(|x| *x *= factor);
                break;
            }
            let top = mode.iter().fold(0.0_f64, |a, v| a.max(v * v));
            for (x, v) in s.iter_mut().zip(mode.iter()) {
                *x *= factor.powf(v * v / top.max(1e-300));
            }
        }
        scaled.then_some(s)
    }
}

/// Rounds of [`PdHold`]'s mode-by-mode stability scaling before one factor on every loop.
const MODE_ROUNDS: usize = 40;

/// Per DOF (len `nv`), the stiffness gravity asks of each hinge for the robot to stand on its
/// feet in the home pose, N·m/rad (0 on other DOFs, and on every DOF of a robot without a
/// floating base or feet): on a joint between the floating base and a foot, the robot as an
/// inverted pendulum on it, `m·g·(z_com − z_joint)` shared by the feet; on any other joint, the
/// part of the robot it carries when that part's centre of mass is above it (a torso on its
/// waist), `m_sub·g·(z_sub − z_joint)`; each for the part of the joint's axis that tips it (its
/// horizontal part; a yaw axis carries nothing). Feet: [`crate::robot::find_feet`].
pub fn stance_stiffness(model: &Model) -> Vec<f64> {
    let mut out = vec![0.0; model.nv()];
    let Some(base) = model.free_joint() else { return out };
    let Ok(feet) = crate::robot::find_feet(model) else { return out };
    if feet.is_empty() {
        return out;
    }
    let Ok(mut data) = crate::mj::Data::new(Arc::new(model.clone())) else { return out };
    data.qpos_mut().copy_from_slice(&nominal_pose(model));
    if data.forward().is_err() {
        return out;
    }
    let g = -model.gravity()[2];
    let parent = model.body_parentid();
    let mut on_leg = vec![false; model.nbody()];
    for &foot in &feet {
        let mut b = foot;
        while b != base.body && b != 0 {
            on_leg[b] = true;
            b = parent[b] as usize;
        }
    }
    let (com_z, mass) = (data.subtree_com()[base.body][2], model.body_subtreemass()[base.body]);
    for j in 0..model.njnt() {
        let b = model.jnt_bodyid()[j] as usize;
        if model.joint_type(j) != JointType::Hinge || !model.in_subtree(base.body, b) {
            continue;
        }
        let x = data.xmat()[b];
        let (p, a) = (model.jnt_pos()[j], model.jnt_axis()[j]);
        let anchor_z = data.xpos()[b][2] + x[6] * p[0] + x[7] * p[1] + x[8] * p[2];
        let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt().max(1e-12);
        let axis_z = (x[6] * a[0] + x[7] * a[1] + x[8] * a[2]) / norm;
        let load = if on_leg[b] {
            mass * g / feet.len() as f64 * (com_z - anchor_z)
        } else {
            model.body_subtreemass()[b] * g * (data.subtree_com()[b][2] - anchor_z)
        };
        out[model.jnt_dofadr()[j] as usize] = load.max(0.0) * (1.0 - axis_z * axis_z);
    }
    out
}

impl Controller for PdHold {
    fn name(&self) -> &'static str {
        "pd-hold"
    }

    fn position_targets(&self, emit: &mut dyn FnMut(usize, f64)) {
        for l in &self.loops {
            emit(l.qpos_adr, l.target);
        }
    }

    fn reset(&mut self, model: &Model, _observation: &Observation<'_>) -> Result<()> {
        // Gains follow the episode's model (effort limits, gear and inertia may be randomized).
        self.build(model);
        let nominal = nominal_pose(model);
        for l in &mut self.loops {
            l.target = nominal[l.qpos_adr];
        }
        Ok(())
    }

    fn compute(&mut self, _model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
        command.fill(0.0);
        for l in &self.loops {
            let error = l.target - observation.qpos[l.qpos_adr];
            let u = match l.interface {
                Interface::Effort => l.kp * error - l.kd * observation.qvel[l.dof],
                // Actuator length and velocity are gear · q and gear · q̇.
                Interface::Position => l.gear * l.target,
                Interface::Velocity => l.gear * VELOCITY_SERVO_RATE * error,
            };
            command[l.command] = u.clamp(l.limits[0], l.limits[1]);
        }
    }
}

/// The PD gain rule of twin, in joint space: `kp = effort / saturation_error` (the error at
/// which the torque reaches the effort limit; `default_effort` without a finite positive
/// limit), bounded by the options' natural-frequency floor and explicit-stability cap when
/// set, and `kd = 2 · damping_ratio · sqrt(kp · inertia)` (critical damping at ratio 1).
/// `inertia` is the joint's effective inertia, kg·m² (kg for slides).
pub fn pd_gains(effort: Option<f64>, inertia: f64, o: &PdHoldOptions) -> (f64, f64) {
    let omega = o.min_natural_freq_hz.map(|f| 2.0 * std::f64::consts::PI * f);
    let mut kp = match (effort.filter(|e| e.is_finite() && *e > 0.0), omega) {
        (Some(e), _) => e / o.saturation_error,
        // Without an effort limit: the natural frequency when given, else the default effort.
        (None, Some(w)) => inertia * w * w,
        (None, None) => o.default_effort / o.saturation_error,
    };
    if let Some(dt) = o.stability_dt_secs {
        // Explicit stiffness must keep ω·dt below 1 on the joint's own inertia.
        kp = kp.min(inertia / (dt * dt));
    }
    if let Some(w) = omega {
        kp = kp.max(inertia * w * w);
    }
    (kp, 2.0 * o.damping_ratio * (kp * inertia).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Actuation;
    use crate::mj::Data;

    /// Runs `hold` for `steps` steps from the nominal pose; returns the largest |q̇| and the final
    /// joint errors.
    fn hold_run(model: &Arc<Model>, hold: &mut PdHold, steps: usize) -> (f64, Vec<f64>) {
        let mut data = Data::new(model.clone()).unwrap();
        data.qpos_mut().copy_from_slice(&nominal_pose(model));
        data.forward().unwrap();
        hold.reset(model, &Observation::of(&data)).unwrap();
        let actuation = Actuation::of(model);
        let mut command = vec![0.0; actuation.len(model)];
        let mut max_qvel: f64 = 0.0;
        for _ in 0..steps {
            hold.compute(model, &Observation::of(&data), &mut command);
            actuation.apply(&mut data, &command);
            data.step().unwrap();
            max_qvel =
                data.qvel().iter().fold(max_qvel, |m, v| if v.is_finite() { m.max(v.abs()) } else { f64::INFINITY });
        }
        let errors = hold.loops().iter().map(|l| data.qpos()[l.qpos_adr] - l.target).collect();
        (max_qvel, errors)
    }

    #[test]
    fn light_arm_with_placeholder_effort_limits_holds_with_capped_gains() {
        // 20 g links and 1000 N·m "limits": kp = 4000 N·m/rad on ~1e-5 kg·m² is ω·dt ≈ 40.
        let xml = r#"<mujoco><option timestep="0.002"/><worldbody>
            <body name="a"><joint name="j1" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01" mass="0.02"/>
            <body name="b" pos="0.1 0 0"><joint name="j2" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.01" mass="0.02"/>
            </body></body></worldbody><actuator>
            <motor joint="j1" ctrlrange="-1000 1000"/><motor joint="j2" ctrlrange="-1000 1000"/></actuator></mujoco>"#;
        let model = Arc::new(Model::from_xml_str(xml).unwrap());
        let mut uncapped =
            PdHold::new(&model, PdHoldOptions { max_loop_margin: f64::INFINITY, ..PdHoldOptions::default() });
        let (qvel, _) = hold_run(&model, &mut uncapped, 200);
        assert!(qvel > 1e3, "without the cap the explicit loop diverges (max |q̇| {qvel})");
        let mut capped = PdHold::new(&model, PdHoldOptions::default());
        assert!(capped.stability_scales(&model).is_none(), "the built gains meet the margin already");
        let kp_ratio = capped.loops()[0].kp / uncapped.loops()[0].kp;
        assert!(kp_ratio < 1e-2, "kp scaled by {kp_ratio}");
        let (qvel, errors) = hold_run(&model, &mut capped, 1000);
        assert!(qvel < 5.0, "max |q̇| {qvel} rad/s");
        // Still a hold: gravity would swing the links down by π/2; they stay within 3°.
        assert!(errors.iter().all(|e| e.abs() < 0.05), "final errors {errors:?} rad");
    }

    #[test]
    fn position_servos_get_target_positions_not_torques() {
        let xml = r#"<mujoco><option timestep="0.002"/><worldbody>
            <body name="a"><joint name="j1" axis="0 1 0" ref="0"/><geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="1"/>
            <body name="b" pos="0.3 0 0"><joint name="j2" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="1"/>
            </body></body></worldbody><keyframe><key name="home" qpos="0.3 -0.2"/></keyframe><actuator>
            <position joint="j1" kp="200" gear="2" ctrlrange="-3 3"/><motor joint="j2" ctrlrange="-50 50"/></actuator></mujoco>"#;
        let model = Arc::new(Model::from_xml_str(xml).unwrap());
        let mut hold = PdHold::new(&model, PdHoldOptions::default());
        assert_eq!(hold.loops()[0].interface, Interface::Position);
        assert_eq!(hold.loops()[1].interface, Interface::Effort);
        let mut data = Data::new(model.clone()).unwrap();
        data.qpos_mut().copy_from_slice(&nominal_pose(&model));
        data.forward().unwrap();
        hold.reset(&model, &Observation::of(&data)).unwrap();
        let mut command = vec![0.0; 2];
        // Away from home, the servo still gets its target (gear · 0.3 rad), not a PD torque.
        data.qpos_mut()[0] = -0.5;
        hold.compute(&model, &Observation::of(&data), &mut command);
        assert!((command[0] - 0.6).abs() < 1e-12, "servo command {}", command[0]);
        let (qvel, errors) = hold_run(&model, &mut hold, 1500);
        assert!(qvel.is_finite());
        // The servo (kp 200 per unit of gear · q) holds 1 kg·0.15 m of gravity within ~0.01 rad.
        assert!(errors[0].abs() < 0.02 && errors[1].abs() < 0.02, "errors {errors:?}");
    }
}
