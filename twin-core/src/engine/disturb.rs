//! Disturbances: what acts on the robot besides its controller.

use super::Disturbance;
use crate::error::Result;
use crate::mj::{Data, Model};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Horizontal pushes in a random direction at a fixed interval, from the first interval on.
/// Without a body, each push adds `speed_mps` to the floating base's horizontal velocity at
/// once; with one, a force on that body changes the whole robot's momentum by
/// `total mass · speed_mps` over `duration_secs`. Models without a floating base are not
/// pushed.
#[derive(Debug, Clone, PartialEq)]
pub struct Push {
    /// Time between pushes, seconds.
    pub interval_secs: f64,
    /// Size of each push, m/s.
    pub speed_mps: f64,
    /// Push this body with a force for this long (seconds) instead of kicking the base.
    pub body: Option<(usize, f64)>,
    base_dof: Option<usize>,
    total_mass_kg: f64,
    next_secs: f64,
    force: [f64; 2],
    until_secs: f64,
}

impl Push {
    /// Pushes every `interval_secs` of `speed_mps`, on `body` (id, duration) or the base.
    pub fn new(interval_secs: f64, speed_mps: f64, body: Option<(usize, f64)>) -> Push {
        Push {
            interval_secs,
            speed_mps,
            body,
            base_dof: None,
            total_mass_kg: 0.0,
            next_secs: interval_secs,
            force: [0.0; 2],
            until_secs: f64::NEG_INFINITY,
        }
    }
}

impl Disturbance for Push {
    fn start(&mut self, model: &Model, _data: &Data) -> Result<()> {
        self.base_dof = model.free_joint().map(|f| f.dof);
        self.total_mass_kg = model.total_mass_kg();
        self.next_secs = self.interval_secs;
        self.force = [0.0; 2];
        self.until_secs = f64::NEG_INFINITY;
        Ok(())
    }

    fn apply(&mut self, data: &mut Data, rng: &mut ChaCha8Rng) {
        let Some(dof) = self.base_dof else { return };
        let dt = data.model().timestep_secs();
        let now = data.time_secs();
        if now + 0.5 * dt >= self.next_secs {
            let angle = rng.random::<f64>() * std::f64::consts::TAU;
            let (dx, dy) = (self.speed_mps * angle.cos(), self.speed_mps * angle.sin());
            match self.body {
                None => {
                    data.qvel_mut()[dof] += dx;
                    data.qvel_mut()[dof + 1] += dy;
                }
                Some((_, duration)) => {
                    self.force = [dx * self.total_mass_kg / duration, dy * self.total_mass_kg / duration];
                    self.until_secs = now + duration;
                }
            }
            self.next_secs += self.interval_secs;
        }
        if let Some((body, _)) = self.body {
            let active = now + 0.5 * dt < self.until_secs;
            let f = &mut data.xfrc_applied_mut()[body];
            (f[0], f[1]) = if active { (self.force[0], self.force[1]) } else { (0.0, 0.0) };
        }
    }
}

/// A constant force (world frame, N) on one body during a time window: a scripted push, as
/// scenario files give them. The body's `xfrc_applied` force is written while the window is
/// open and cleared on the step after it closes.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedForce {
    /// Start, simulated seconds.
    pub start_secs: f64,
    /// Duration, seconds.
    pub duration_secs: f64,
    /// Force, world frame, N.
    pub force: [f64; 3],
    /// The body pushed.
    pub body: usize,
    active: bool,
}

impl TimedForce {
    /// `force` on `body` from `start_secs` for `duration_secs`.
    pub fn new(start_secs: f64, duration_secs: f64, force: [f64; 3], body: usize) -> TimedForce {
        TimedForce { start_secs, duration_secs, force, body, active: false }
    }
}

impl Disturbance for TimedForce {
    fn start(&mut self, _model: &Model, _data: &Data) -> Result<()> {
        self.active = false;
        Ok(())
    }

    fn apply(&mut self, data: &mut Data, _rng: &mut ChaCha8Rng) {
        let t = data.time_secs();
        let on = t >= self.start_secs && t < self.start_secs + self.duration_secs;
        if on || self.active {
            let f = &mut data.xfrc_applied_mut()[self.body];
            for (fk, pk) in f.iter_mut().zip(self.force) {
                *fk = if on { pk } else { 0.0 };
            }
        }
        self.active = on;
    }
}
