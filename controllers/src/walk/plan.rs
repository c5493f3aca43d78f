//! Footstep planning from a velocity command, the ZMP reference it implies, and swing-foot
//! trajectories.
//!
//! A step lasts `period` seconds: a double-support phase (`double_support` of it) that moves
//! the ZMP from the previous stance foot to the new one, then single support on that foot while
//! the other swings to its landing spot. Footholds follow a "centre path" advanced by the
//! command each step; each foot lands half the step width to its side of it.

use super::kin::{Side, kept_sin_cos};
use nalgebra::{Matrix2, Rotation2, Vector2};

/// `Rotation2::new(angle)` bit for bit, its `sin_cos` from [`kept_sin_cos`]: a walker's solve
/// rotates by the same few headings (the footholds', the pelvis's, their negatives) many
/// times over.
pub fn rotation(angle: f64) -> Rotation2<f64> {
    let (s, c) = kept_sin_cos(angle);
    Rotation2::from_matrix_unchecked(Matrix2::new(c, -s, s, c))
}

/// A foot placement: sole centre (world x, y, metres) and yaw (radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Foothold {
    /// Which foot.
    pub side: Side,
    /// Sole centre, world frame.
    pub pos: Vector2<f64>,
    /// Heading of the foot, radians.
    pub yaw: f64,
}

/// A velocity command in the robot's heading frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Command {
    /// Forward, m/s.
    pub vx: f64,
    /// Leftward, m/s.
    pub vy: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate: f64,
}

impl Command {
    /// Whether it asks for no motion.
    pub fn is_zero(&self) -> bool {
        self.vx == 0.0 && self.vy == 0.0 && self.yaw_rate == 0.0
    }
}

/// Timing and geometry of steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gait {
    /// Step duration, seconds.
    pub period: f64,
    /// Double-support fraction of a step.
    pub double_support: f64,
    /// Lateral distance between the soles' centres, metres.
    pub width: f64,
    /// Largest forward step (centre-path advance per step), metres.
    pub max_step_length: f64,
    /// Largest sideways advance per step, metres.
    pub max_step_lateral: f64,
    /// Largest yaw change per step, radians.
    pub max_step_yaw: f64,
    /// How far inside the stance sole's centre (toward the other foot) the ZMP is planned in
    /// single support, metres.
    pub zmp_inward: f64,
}

impl Gait {
    /// Double-support duration, seconds.
    pub fn ds_secs(&self) -> f64 {
        self.period * self.double_support
    }

    /// The foothold of the foot on `side` that lands after the centre `(c, yaw)` advanced by
    /// `cmd` for one step.
    pub fn next_center(&self, center: Vector2<f64>, yaw: f64, cmd: &Command) -> (Vector2<f64>, f64) {
        let dx = (cmd.vx * self.period).clamp(-self.max_step_length, self.max_step_length);
        let dy = (cmd.vy * self.period).clamp(-self.max_step_lateral, self.max_step_lateral);
        let dyaw = (cmd.yaw_rate * self.period).clamp(-self.max_step_yaw, self.max_step_yaw);
        (center + rotation(yaw) * Vector2::new(dx, dy), yaw + dyaw)
    }

    /// Foothold of `side` around centre `(c, yaw)`.
    pub fn foothold(&self, side: Side, center: Vector2<f64>, yaw: f64) -> Foothold {
        Foothold { side, pos: center + rotation(yaw) * Vector2::new(0.0, side.sign() * self.width / 2.0), yaw }
    }

    /// Centre of the path a foothold belongs to.
    pub fn center_of(&self, f: &Foothold) -> Vector2<f64> {
        f.pos - rotation(f.yaw) * Vector2::new(0.0, f.side.sign() * self.width / 2.0)
    }
}

/// One step of the schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// Start time (controller seconds).
    pub start: f64,
    /// Double-support duration, seconds.
    pub ds: f64,
    /// Single-support duration, seconds.
    pub ss: f64,
    /// Where the ZMP starts this step.
    pub zmp_from: Vector2<f64>,
    /// The planted foot.
    pub stance: Foothold,
    /// The swinging foot's start.
    pub swing_from: Foothold,
    /// Its landing.
    pub swing_to: Foothold,
    /// How far inside the stance sole's centre (toward the swing foot's side) the ZMP sits in
    /// single support, metres ([`Gait::zmp_inward`]).
    pub zmp_inward: f64,
}

impl Step {
    /// End time.
    pub fn end(&self) -> f64 {
        self.start + self.ds + self.ss
    }

    /// Where the ZMP sits in single support: the stance sole's centre moved `zmp_inward`
    /// toward the other foot.
    pub fn zmp_point(&self) -> Vector2<f64> {
        self.stance.pos + rotation(self.stance.yaw) * Vector2::new(0.0, -self.stance.side.sign() * self.zmp_inward)
    }

    /// ZMP reference at `t` within this step.
    pub fn zmp(&self, t: f64) -> Vector2<f64> {
        let tau = t - self.start;
        if tau < self.ds && self.ds > 0.0 {
            let a = (tau / self.ds).clamp(0.0, 1.0);
            // Smooth transfer (zero rate at both ends).
            let s = a * a * (3.0 - 2.0 * a);
            self.zmp_from + (self.zmp_point() - self.zmp_from) * s
        } else {
            self.zmp_point()
        }
    }

    /// Swing progress in [0, 1] at `t` (0 during double support).
    pub fn swing_phase(&self, t: f64) -> f64 {
        ((t - self.start - self.ds) / self.ss.max(1e-9)).clamp(0.0, 1.0)
    }

    /// The DCM reference at `t` within this step and the ZMP it implies, given the DCM `end`
    /// at the step's end: `ξ̇ = ω(ξ − p)` solved backward from `end` (Englsberger et al. 2015),
    /// the ZMP moving linearly from `zmp_from` to [`Step::zmp_point`] over the double support
    /// (the particular solution `p + ṗ/ω` is then exact) and staying there in single support.
    pub fn dcm(&self, t: f64, end: Vector2<f64>, omega: f64) -> (Vector2<f64>, Vector2<f64>) {
        let u = self.zmp_point();
        let tau = (t - self.start).clamp(0.0, self.ds + self.ss);
        if tau >= self.ds || self.ds <= 0.0 {
            return (u + (end - u) * (omega * (tau - self.ds - self.ss)).exp(), u);
        }
        let ds_end = u + (end - u) * (-omega * self.ss).exp();
        let rate = (u - self.zmp_from) / self.ds;
        let p = self.zmp_from + rate * tau;
        (p + rate / omega + (ds_end - u - rate / omega) * (omega * (tau - self.ds)).exp(), p)
    }
}

/// The schedule ahead: the steps from now on and where the ZMP settles after the last one.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Schedule {
    /// Current and future steps.
    pub steps: Vec<Step>,
    /// After the last step (or from `rest_start` when there is none): the ZMP moves to this
    /// point over `settle_secs` and stays.
    pub rest: Vector2<f64>,
    /// Where the ZMP starts moving to `rest` when there are no steps.
    pub rest_from: Vector2<f64>,
    /// When it starts, controller seconds (when there are no steps).
    pub rest_start: f64,
    /// Duration of the final transfer to `rest`, seconds.
    pub settle_secs: f64,
}

impl Schedule {
    /// ZMP reference at `t`; `cursor` speeds up monotone queries (start at 0).
    pub fn zmp(&self, t: f64, cursor: &mut usize) -> Vector2<f64> {
        while *cursor < self.steps.len() && t >= self.steps[*cursor].end() {
            *cursor += 1;
        }
        if let Some(step) = self.steps.get(*cursor) {
            if t < step.start {
                return step.zmp_from;
            }
            return step.zmp(t);
        }
        let (from, start) = match self.steps.last() {
            Some(last) => (last.zmp_point(), last.end()),
            None => (self.rest_from, self.rest_start),
        };
        let a = ((t - start) / self.settle_secs.max(1e-9)).clamp(0.0, 1.0);
        let s = a * a * (3.0 - 2.0 * a);
        from + (self.rest - from) * s
    }

    /// The DCM at the end of the first step, from the steps after it backward ([`Step::dcm`]);
    /// after the last step the DCM is taken at `rest` (its influence has decayed by
    /// `e^(−ω·T)` per step in between).
    pub fn first_end_dcm(&self, omega: f64) -> Vector2<f64> {
        let mut end = self.rest;
        for step in self.steps.iter().skip(1).rev() {
            end = step.dcm(step.start, end, omega).0;
        }
        end
    }
}

/// The DCM error (one axis of the stance foot's frame) `τ` seconds ahead under ankle feedback:
/// the ZMP is put `gain · e` from its reference, within `±reach` (the sole), so
/// `ė = ω(e − sat(gain · e))`: inside the reach the error decays at `ω(gain − 1)`, beyond it
/// it diverges from the edge at `ω`. Closed form, piecewise.
pub fn dcm_error_ahead(e: f64, reach: f64, gain: f64, omega: f64, tau: f64) -> f64 {
    let (sign, e) = (e.signum(), e.abs());
    let decay = omega * (gain - 1.0);
    let reach = reach.max(0.0);
    if gain * e <= reach {
        return sign * e * (-decay * tau).exp();
    }
    if e >= reach {
        return sign * (reach + (e - reach) * (omega * tau).exp());
    }
    // Saturated but shrinking toward `reach / gain`, then decaying.
    let knee = reach / gain;
    let t1 = ((reach - knee) / (reach - e)).ln() / omega;
    if t1 >= tau {
        sign * (reach - (reach - e) * (omega * tau).exp())
    } else {
        sign * knee * (-decay * (tau - t1)).exp()
    }
}

/// Swing-foot position offset along the way and height at phase `s` ∈ [0, 1]: minimum-jerk
/// horizontal blend and a vertical bump with zero velocity and acceleration at both ends
/// (`64 s³ (1 − s)³`, 1 at mid-swing).
pub fn swing_profile(s: f64) -> (f64, f64) {
    let s = s.clamp(0.0, 1.0);
    let blend = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
    let lift = 64.0 * (s * (1.0 - s)).powi(3);
    (blend, lift)
}

/// Wraps an angle to (−π, π].
pub fn wrap(a: f64) -> f64 {
    let mut a = a % std::f64::consts::TAU;
    if a > std::f64::consts::PI {
        a -= std::f64::consts::TAU;
    } else if a <= -std::f64::consts::PI {
        a += std::f64::consts::TAU;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gait() -> Gait {
        Gait {
            period: 0.6,
            double_support: 0.2,
            width: 0.18,
            max_step_length: 0.2,
            max_step_lateral: 0.1,
            max_step_yaw: 0.3,
            zmp_inward: 0.0,
        }
    }

    /// The memo gives the library's rotation bit for bit, for angles met again, colliding in
    /// a slot, negated, zero of either sign and not finite.
    #[test]
    fn rotation_is_the_librarys_bit_for_bit() {
        let mut angles: Vec<f64> = (0..200).map(|k| (k as f64 * 0.7311).sin() * 4.0).collect();
        angles.extend([0.0, -0.0, 1e-300, -1e-300, std::f64::consts::PI, 1e6, f64::NAN, f64::INFINITY]);
        let negated: Vec<f64> = angles.iter().map(|a| -a).collect();
        angles.extend(negated);
        for _ in 0..3 {
            for &a in &angles {
                let (memo, library) = (rotation(a).into_inner(), Rotation2::new(a).into_inner());
                for (m, l) in memo.iter().zip(library.iter()) {
                    assert!(m.to_bits() == l.to_bits() || (m.is_nan() && l.is_nan()), "{a}: {memo} {library}");
                }
            }
        }
    }

    #[test]
    fn footholds_alternate_around_an_advancing_centre() {
        let g = gait();
        let cmd = Command { vx: 0.25, vy: 0.0, yaw_rate: 0.0 };
        let (c1, y1) = g.next_center(Vector2::zeros(), 0.0, &cmd);
        assert!((c1.x - 0.15).abs() < 1e-12 && y1 == 0.0);
        let left = g.foothold(Side::Left, c1, y1);
        assert!((left.pos.y - 0.09).abs() < 1e-12);
        assert!((g.center_of(&left) - c1).norm() < 1e-12);
        // Clamped to the longest step.
        let (c2, _) = g.next_center(Vector2::zeros(), 0.0, &Command { vx: 5.0, ..cmd });
        assert!((c2.x - 0.2).abs() < 1e-12);
        let (s, z) = swing_profile(0.5);
        assert!((s - 0.5).abs() < 1e-12 && (z - 1.0).abs() < 1e-12);
        assert_eq!(swing_profile(0.0), (0.0, 0.0));
        assert!((wrap(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    }

    /// The closed-form DCM reference satisfies `ξ̇ = ω(ξ − p)` in both phases, is continuous at
    /// the end of double support and ends at `end`.
    #[test]
    fn dcm_reference_obeys_the_pendulum() {
        let omega = 4.0;
        let right = Foothold { side: Side::Right, pos: Vector2::new(0.1, -0.09), yaw: 0.0 };
        let left = Foothold { side: Side::Left, pos: Vector2::new(0.0, 0.09), yaw: 0.0 };
        let step = Step {
            start: 1.0,
            ds: 0.1,
            ss: 0.4,
            zmp_from: left.pos,
            stance: right,
            swing_from: left,
            swing_to: Foothold { pos: Vector2::new(0.25, 0.09), ..left },
            zmp_inward: 0.01,
        };
        let end = Vector2::new(0.2, 0.0);
        assert!((step.dcm(step.end(), end, omega).0 - end).norm() < 1e-12);
        let h = 1e-6;
        for t in [1.02, 1.05, 1.09, 1.2, 1.45] {
            let (xi, p) = step.dcm(t, end, omega);
            let rate = (step.dcm(t + h, end, omega).0 - step.dcm(t - h, end, omega).0) / (2.0 * h);
            assert!((rate - (xi - p) * omega).norm() < 1e-5, "{t}: {rate} {}", (xi - p) * omega);
        }
        let before = step.dcm(1.1 - 1e-9, end, omega).0;
        let after = step.dcm(1.1 + 1e-9, end, omega).0;
        assert!((before - after).norm() < 1e-6);
        // The first step's end DCM is the second step's start DCM.
        let second = Step { start: step.end(), zmp_from: right.pos, stance: step.swing_to, ..step };
        let schedule = Schedule { steps: vec![step, second], rest: Vector2::new(0.25, 0.0), ..Schedule::default() };
        let start_of_second = second.dcm(second.start, schedule.rest, omega).0;
        assert!((schedule.first_end_dcm(omega) - start_of_second).norm() < 1e-12);
    }

    /// Ankle feedback: a small error decays at `ω(gain − 1)`, one beyond the sole grows from its
    /// edge at `ω`, one between `reach/gain` and `reach` shrinks onto the linear region; the
    /// closed form matches a fine integration.
    #[test]
    fn dcm_error_ahead_matches_integration() {
        let (omega, gain, reach) = (4.0, 1.5, 0.06);
        for e0 in [0.0, 0.02, -0.03, 0.05, 0.059, 0.07, -0.2] {
            for tau in [0.05, 0.2, 0.45] {
                let mut e: f64 = e0;
                let n = 200_000;
                for _ in 0..n {
                    let p = (gain * e).clamp(-reach, reach);
                    e += omega * (e - p) * tau / n as f64;
                }
                let closed = dcm_error_ahead(e0, reach, gain, omega, tau);
                assert!((closed - e).abs() < 1e-5 * (1.0 + e.abs()), "{e0} {tau}: {closed} {e}");
            }
        }
        // No ankle reach: the error grows as e^(ωτ).
        assert!((dcm_error_ahead(0.1, 0.0, gain, omega, 0.25) - 0.1 * 1.0_f64.exp()).abs() < 1e-12);
    }
}
