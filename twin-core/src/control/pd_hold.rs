//! [`PdHold`]: holds the nominal pose with PD loops, and the one PD gain rule of twin
//! ([`pd_gains`]).

use super::{Actuation, Controller, Observation, nominal_pose};
use crate::error::Result;
use crate::mj::{JointType, Model};

/// Options of [`PdHold`].
#[derive(Debug, Clone, PartialEq)]
pub struct PdHoldOptions {
    /// Joint angle error (radians; metres for slides) at which a joint's PD torque reaches its
    /// effort limit: `kp = effort / saturation_error`. Stiff enough for the shipped humanoid's
    /// ankles to hold its whole weight. (default: 0.25)
    pub saturation_error: f64,
    /// Damping ratio of each joint on its own effective inertia (`1 / dof_invweight0`):
    /// `kd = 2 · ratio · sqrt(kp · inertia)`. (default: 1.0)
    pub damping_ratio: f64,
    /// Effort (N·m or N) assumed for joints and actuators without a force limit, when
    /// `min_natural_freq_hz` is not set. (default: 100.0)
    pub default_effort: f64,
    /// Lowest natural frequency of a joint on its inertia, Hz: a floor on `kp`, and the
    /// stiffness of joints without an effort limit. (default: none)
    pub min_natural_freq_hz: Option<f64>,
    /// Cap `kp` at `inertia / dt²` for this timestep (seconds), so an explicit spring stays
    /// stable on the joint's own inertia. (default: none)
    pub stability_dt_secs: Option<f64>,
}

impl Default for PdHoldOptions {
    fn default() -> Self {
        PdHoldOptions {
            saturation_error: 0.25,
            damping_ratio: 1.0,
            default_effort: 100.0,
            min_natural_freq_hz: None,
            stability_dt_secs: None,
        }
    }
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
}

/// Holds the nominal pose ([`nominal_pose`]) with PD control on every actuated hinge/slide joint:
/// `τ = kp·(q_target − q) − kd·q̇`, clamped to the actuator's range / the joint's effort.
/// With actuators, each joint-transmission actuator drives its joint (torque / gear);
/// without, every hinge and slide joint gets `qfrc_applied`.
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
        let gains = |effort: f64, dof: usize, gear: f64| {
            let inertia = 1.0 / model.dof_invweight0()[dof].max(1e-12);
            let (kp, kd) = pd_gains(Some(effort), inertia, o);
            // Joint-space gains, expressed in command units (torque = gear · ctrl).
            (kp / gear, kd / gear)
        };
        self.loops.clear();
        match actuation {
            Actuation::Ctrl => {
                for (u, &[lo, hi]) in limits.iter().enumerate() {
                    // Only joint transmissions on 1-DOF joints are PD-able; others get 0.
                    if model.actuator_trntype()[u] as u32 != mujoco_sys::mjtTrn_mjTRN_JOINT {
                        continue;
                    }
                    let joint = model.actuator_trnid()[u][0] as usize;
                    if !matches!(model.joint_type(joint), JointType::Hinge | JointType::Slide) {
                        continue;
                    }
                    let gear = model.actuator_gear()[u][0];
                    if gear == 0.0 {
                        continue;
                    }
                    let dof = model.jnt_dofadr()[joint] as usize;
                    let mut effort = (hi.abs().min(lo.abs())) * gear.abs();
                    if model.actuator_forcelimited()[u] {
                        let [flo, fhi] = model.actuator_forcerange()[u];
                        effort = effort.min(flo.abs().min(fhi.abs()));
                    }
                    if model.jnt_actfrclimited()[joint] {
                        let [jlo, jhi] = model.jnt_actfrcrange()[joint];
                        effort = effort.min(jlo.abs().min(jhi.abs()));
                    }
                    let (kp, kd) = gains(effort, dof, gear);
                    self.loops.push(PdLoop {
                        command: u,
                        joint,
                        qpos_adr: model.jnt_qposadr()[joint] as usize,
                        dof,
                        kp,
                        kd,
                        gear,
                        target: 0.0,
                        limits: [lo, hi],
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
                    });
                }
            }
        }
    }
}

impl Controller for PdHold {
    fn name(&self) -> &'static str {
        "pd-hold"
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
            let u = l.kp * error - l.kd * observation.qvel[l.dof];
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
