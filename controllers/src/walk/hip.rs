//! The hip strategy: the third balance strategy after the ankles and stepping (Pratt et al.
//! 2006, capture point with a flywheel; Stephens 2007, push recovery; Englsberger's CMP-based
//! DCM control). When the commanded ZMP leaves what the feet can give, rotating the upper body
//! about the hips moves the centroidal moment pivot (CMP) beyond the ZMP: a torque `τ` on the
//! centroidal angular momentum puts the CMP `τ / (m·g)` from the ZMP, and the DCM diverges from
//! the CMP (`ξ̇ = ω(ξ − CMP)`), not from the ZMP. A forward DCM error pitches the upper body
//! forward (the hips go back), a leftward one rolls it to the left. The rotation is bounded, so
//! it only buys time until a recovery step lands; then the upper body comes back upright.
//!
//! The lean is a trajectory the pelvis orientation follows (the leg IK puts it on the hips):
//! driven, its angular acceleration is the one that gives the missing part of the CMP,
//! `α = gain · m·g·e / I`, `e` the commanded ZMP's distance beyond the feet's support (during
//! a recovery step the DCM's beyond the stance sole: the step's ZMP is planned at the sole's
//! edge) and `I` the upper body's moment of inertia about the hips (from the model's tree);
//! undriven, it coasts to the end of a step, then returns upright, critically damped. The
//! walker's tilt feedback acts on the tilt less the lean, so it holds the lean.

use super::kin::{Body, Frames, Tree};
use nalgebra::{Vector2, Vector3};
use twin_core::mj::Model;

/// Excess of the commanded ZMP that drives no lean, m: the millimetres the feet's clamped
/// forces and the sensors' noise leave in quiet standing would otherwise hold a lean (and keep
/// it from returning) for good.
const DEADBAND_M: f64 = 0.005;

/// Options of the hip strategy (part of [`super::WalkOptions`]).
#[derive(Debug, Clone, Copy)]
pub struct HipParams {
    /// Part of the commanded ZMP's excess beyond the feet that the upper body's rotation gives.
    pub gain: f64,
    /// Largest lean of the upper body (roll, pitch), rad.
    pub max_lean_rad: [f64; 2],
    /// Time constant of the return upright, s.
    pub return_secs: f64,
}

/// The hip strategy's state: the commanded lean of the upper body.
#[derive(Debug, Clone, Default)]
pub struct HipStrategy {
    /// Lean (roll, pitch) in the feet's heading frame, rad.
    lean_rad: Vector2<f64>,
    /// Its rate, rad/s.
    rate_rad_s: Vector2<f64>,
    /// The upper body's moments of inertia about the hips' roll and pitch axes, kg·m².
    inertia_kg_m2: Vector2<f64>,
    /// The robot's weight, N.
    weight_n: f64,
}

impl HipStrategy {
    /// The strategy for the robot `body` of `tree` in the configuration `frames` (the home
    /// pose): the upper body is everything on the pelvis but the legs, turning about the point
    /// between the legs' first joints.
    pub fn new(model: &Model, tree: &Tree, frames: &Frames, body: &Body, gravity_m_s2: f64) -> HipStrategy {
        let roots = [tree.joint_body(body.legs[0].joints[0]), tree.joint_body(body.legs[1].joints[0])];
        let hips = (frames.anchor[body.legs[0].joints[0]] + frames.anchor[body.legs[1].joints[0]]) / 2.0;
        let pelvis_rot = frames.xrot[body.pelvis];
        let axes = [pelvis_rot * Vector3::x(), pelvis_rot * Vector3::y()];
        let mut inertia = [0.0; 2];
        for b in 1..frames.xpos.len() {
            if !tree.is_below(b, body.pelvis) || roots.iter().any(|&r| tree.is_below(b, r)) {
                continue;
            }
            let mass = model.body_mass()[b];
            let c = frames.xpos[b] + frames.xrot[b] * Vector3::from(model.body_ipos()[b]);
            let principal = model.body_inertia()[b];
            let own = (principal[0] + principal[1] + principal[2]) / 3.0;
            for (k, axis) in axes.iter().enumerate() {
                let r = c - hips;
                let perp = r - axis * axis.dot(&r);
                inertia[k] += mass * perp.norm_squared() + own;
            }
        }
        HipStrategy {
            lean_rad: Vector2::zeros(),
            rate_rad_s: Vector2::zeros(),
            inertia_kg_m2: Vector2::new(inertia[0], inertia[1]).map(|i| i.max(1e-6)),
            weight_n: tree.total_mass_kg * gravity_m_s2,
        }
    }

    /// Advances the lean by `dt_secs` with `excess_m` (heading frame, x forward, y left) the
    /// commanded ZMP's distance beyond what the feet give, `stepping` while one foot swings;
    /// the lean (roll, pitch) and its rate, rad and rad/s.
    ///
    /// Per axis: driven, the lean accelerates as the excess asks, but never faster than it can
    /// stop at the largest lean by braking as hard (the flywheel's bang-bang). Undriven during
    /// a step while it still turns outward, it coasts and brakes only as much as stopping at
    /// the largest lean needs: braking moves the CMP back toward the fall, better done once
    /// the foot has landed. Otherwise it returns upright, critically damped (`return_secs`).
    pub fn update(
        &mut self,
        excess_m: Vector2<f64>,
        stepping: bool,
        dt_secs: f64,
        p: &HipParams,
    ) -> (Vector2<f64>, Vector2<f64>) {
        // Roll about +x leans the top toward −y: a leftward excess rolls negative.
        let drive = [-excess_m.y, excess_m.x].map(|e| if e.abs() > DEADBAND_M { e } else { 0.0 });
        let tau = p.return_secs.max(dt_secs);
        for (k, &drive) in drive.iter().enumerate() {
            let (lean, rate, max) = (self.lean_rad[k], self.rate_rad_s[k], p.max_lean_rad[k]);
            let outward = rate * lean > 0.0 || (lean == 0.0 && rate != 0.0);
            // Deceleration that stops an outward turn at the largest lean, rad/s².
            let room = (max - lean.abs()).max(1e-6);
            let stop = rate * rate / (2.0 * room);
            let accel = if drive != 0.0 {
                let a = p.gain * self.weight_n * drive / self.inertia_kg_m2[k];
                if outward && a * rate >= 0.0 && stop >= a.abs() { -stop.copysign(rate) } else { a }
            } else if outward && stepping {
                -stop.copysign(rate)
            } else {
                -lean / (tau * tau) - 2.0 * rate / tau
            };
            let mut rate = rate + accel * dt_secs;
            let mut lean = lean + rate * dt_secs;
            if lean.abs() > max {
                lean = max.copysign(lean);
                if rate * lean > 0.0 {
                    rate = 0.0;
                }
            }
            self.lean_rad[k] = lean;
            self.rate_rad_s[k] = rate;
        }
        (self.lean_rad, self.rate_rad_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::walk::WalkOptions;

    fn strategy() -> HipStrategy {
        // The shipped humanoid's numbers, roughly: 350 N, 2 kg·m² about the hips.
        HipStrategy {
            lean_rad: Vector2::zeros(),
            rate_rad_s: Vector2::zeros(),
            inertia_kg_m2: Vector2::new(2.0, 2.0),
            weight_n: 350.0,
        }
    }

    const PARAMS: HipParams = HipParams { gain: 1.0, max_lean_rad: [0.15, 0.4], return_secs: 0.4 };

    #[test]
    fn leans_into_the_fall_as_fast_as_the_excess_asks_and_stops_at_its_bound() {
        let mut hip = strategy();
        let dt = 0.002;
        // 5 cm beyond the toes: α = 350 · 0.05 / 2 = 8.75 rad/s², pitch forward only.
        let (lean, rate) = hip.update(Vector2::new(0.05, 0.0), true, dt, &PARAMS);
        assert!((rate.y - 8.75 * dt).abs() < 1e-12 && rate.x == 0.0 && lean.x == 0.0, "{rate:?}");
        for _ in 0..500 {
            hip.update(Vector2::new(0.05, 0.0), true, dt, &PARAMS);
        }
        // Braked to rest at the largest pitch, never past it.
        assert!((hip.lean_rad.y - 0.4).abs() < 1e-3 && hip.rate_rad_s.y.abs() < 0.05, "{:?}", hip.lean_rad);
        // A leftward excess rolls the top to the left (negative roll), within its own bound.
        let mut hip = strategy();
        for _ in 0..500 {
            hip.update(Vector2::new(0.0, 0.05), true, dt, &PARAMS);
        }
        assert!((hip.lean_rad.x + 0.15).abs() < 1e-3 && hip.lean_rad.y == 0.0, "{:?}", hip.lean_rad);
    }

    #[test]
    fn coasts_through_a_step_then_returns_upright() {
        let mut hip = strategy();
        let dt = 0.002;
        // 0.2 s at 8.75 rad/s²: 1.75 rad/s, 0.175 rad.
        for _ in 0..100 {
            hip.update(Vector2::new(0.05, 0.0), true, dt, &PARAMS);
        }
        let (lean0, rate0) = (hip.lean_rad.y, hip.rate_rad_s.y);
        assert!((rate0 - 1.75).abs() < 1e-9 && (lean0 - 0.175).abs() < 0.002, "{lean0} {rate0}");
        // The excess gone mid-step: the lean keeps turning (braking only to stop at 0.4 rad).
        hip.update(Vector2::zeros(), true, dt, &PARAMS);
        assert!(hip.rate_rad_s.y > 0.9 * rate0 && hip.lean_rad.y > lean0);
        // Landed: back upright within a few time constants, without overshoot.
        let mut least = f64::INFINITY;
        for _ in 0..1500 {
            hip.update(Vector2::zeros(), false, dt, &PARAMS);
            least = least.min(hip.lean_rad.y);
        }
        assert!(hip.lean_rad.y.abs() < 0.01 && least > -0.01, "{} (least {least})", hip.lean_rad.y);
        // Millimetres of excess (quiet standing) move nothing.
        let mut hip = strategy();
        hip.update(Vector2::new(0.004, -0.004), false, dt, &PARAMS);
        assert_eq!(hip.lean_rad, Vector2::zeros());
    }

    #[test]
    fn options_out_of_range_name_the_option() {
        let bad = [
            WalkOptions { hip_gain: -1.0, ..WalkOptions::default() },
            WalkOptions { hip_gain: f64::NAN, ..WalkOptions::default() },
            WalkOptions { hip_max_lean_rad: [0.1, 1.5], ..WalkOptions::default() },
            WalkOptions { hip_return_secs: 0.0, ..WalkOptions::default() },
        ];
        let names = ["hip_gain", "hip_gain", "hip_max_lean_rad", "hip_return_secs"];
        for (o, name) in bad.iter().zip(names) {
            assert_eq!(o.validate().unwrap_err().0, name);
        }
        assert!(WalkOptions { hip_gain: 1.0, ..WalkOptions::default() }.validate().is_ok());
    }
}
