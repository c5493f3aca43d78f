//! Footstep planning from a velocity command, the ZMP reference it implies, and swing-foot
//! trajectories.
//!
//! A step lasts `period` seconds: a double-support phase (`double_support` of it) that moves
//! the ZMP from the previous stance foot to the new one, then single support on that foot while
//! the other swings to its landing spot. Footholds follow a "centre path" advanced by the
//! command each step; each foot lands half the step width to its side of it.

use super::kin::Side;
use nalgebra::{Rotation2, Vector2};

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
        (center + Rotation2::new(yaw) * Vector2::new(dx, dy), yaw + dyaw)
    }

    /// Foothold of `side` around centre `(c, yaw)`.
    pub fn foothold(&self, side: Side, center: Vector2<f64>, yaw: f64) -> Foothold {
        Foothold { side, pos: center + Rotation2::new(yaw) * Vector2::new(0.0, side.sign() * self.width / 2.0), yaw }
    }

    /// Centre of the path a foothold belongs to.
    pub fn center_of(&self, f: &Foothold) -> Vector2<f64> {
        f.pos - Rotation2::new(f.yaw) * Vector2::new(0.0, f.side.sign() * self.width / 2.0)
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
}

impl Step {
    /// End time.
    pub fn end(&self) -> f64 {
        self.start + self.ds + self.ss
    }

    /// ZMP reference at `t` within this step.
    pub fn zmp(&self, t: f64) -> Vector2<f64> {
        let tau = t - self.start;
        if tau < self.ds && self.ds > 0.0 {
            let a = (tau / self.ds).clamp(0.0, 1.0);
            // Smooth transfer (zero rate at both ends).
            let s = a * a * (3.0 - 2.0 * a);
            self.zmp_from + (self.stance.pos - self.zmp_from) * s
        } else {
            self.stance.pos
        }
    }

    /// Swing progress in [0, 1] at `t` (0 during double support).
    pub fn swing_phase(&self, t: f64) -> f64 {
        ((t - self.start - self.ds) / self.ss.max(1e-9)).clamp(0.0, 1.0)
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
            Some(last) => (last.stance.pos, last.end()),
            None => (self.rest_from, self.rest_start),
        };
        let a = ((t - start) / self.settle_secs.max(1e-9)).clamp(0.0, 1.0);
        let s = a * a * (3.0 - 2.0 * a);
        from + (self.rest - from) * s
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
}
