//! Disturbances: what acts on the robot besides its controller.

use super::Disturbance;
use crate::error::Result;
use crate::mj::{Data, Model};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

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

/// A fitted joint friction curve (`twin sysid friction`): `τ_f(v) = sgn(v)·[Fc + (Fs − Fc)·
/// exp(−|v/vs|^δ)] + Fv·v`, opposing the motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StribeckCurve {
    /// Coulomb friction `Fc`, N·m (N).
    pub coulomb: f64,
    /// Breakaway friction `Fs`, N·m (N).
    pub breakaway: f64,
    /// Stribeck velocity `vs`, rad/s (m/s).
    pub stribeck_velocity: f64,
    /// Exponent `δ`.
    pub exponent: f64,
    /// Viscous `Fv`, N·m·s/rad (N·s/m).
    pub viscous: f64,
}

impl StribeckCurve {
    /// Friction torque at velocity `v` with `sgn(v)` smoothed as `tanh(v/ε)`.
    pub fn torque(&self, v: f64, eps: f64) -> f64 {
        let s = v.abs();
        let hump =
            (self.breakaway - self.coulomb) * (-(s / self.stribeck_velocity.max(1e-12)).powf(self.exponent)).exp();
        (v / eps).tanh() * (self.coulomb + hump) + self.viscous * v
    }
}

/// Joint friction from fitted Stribeck curves, applied each step as a generalized force from
/// the joint velocity (`qfrc_applied`): the full curve, breakaway hump included, which MuJoCo's
/// Coulomb friction loss and linear damping can't express. The curve replaces the joint's own
/// friction loss and damping (see [`StribeckFriction::model_without_joint_friction`]).
///
/// Near zero velocity `sgn(v)` becomes `tanh(v/ε)`, with `ε` per joint large enough that the
/// explicit force stays stable: `(Fs/ε + Fv)·dt/M ≤ 0.5` with `M` the joint's effective
/// inertia at the reference pose (MuJoCo's `dof_invweight0`), and at least 1 mrad/s. Below
/// `ε` the joint creeps instead of sticking: static friction holds only in the smoothed sense.
#[derive(Debug, Clone, PartialEq)]
pub struct StribeckFriction {
    /// `(dof, curve)` per joint.
    pub curves: Vec<(usize, StribeckCurve)>,
    eps: Vec<f64>,
    last: Vec<f64>,
    adds: bool,
}

impl StribeckFriction {
    /// Curves on the given DOFs.
    pub fn new(curves: Vec<(usize, StribeckCurve)>) -> StribeckFriction {
        let n = curves.len();
        StribeckFriction { curves, eps: vec![1e-3; n], last: vec![0.0; n], adds: true }
    }

    /// The smoothing velocity `ε` of each curve (after [`Disturbance::start`]).
    pub fn smoothing(&self) -> &[f64] {
        &self.eps
    }

    /// `model` with the friction loss and damping of the curves' DOFs set to zero (the curves
    /// carry them).
    ///
    /// # Errors
    /// [`crate::Error::MuJoCo`] if the model can't be edited.
    pub fn model_without_joint_friction(&self, model: &Model) -> Result<Model> {
        let mut edit = model.edit()?;
        for &(dof, _) in &self.curves {
            edit.set_dof_frictionloss(dof, 0.0)?;
            edit.set_dof_damping(dof, 0.0)?;
        }
        Ok(edit.finish()?)
    }
}

impl Disturbance for StribeckFriction {
    fn start(&mut self, model: &Model, _data: &Data) -> Result<()> {
        let dt = model.timestep_secs();
        self.eps = self
            .curves
            .iter()
            .map(|&(dof, c)| {
                let invweight = model.dof_invweight0()[dof].max(0.0);
                let peak = c.breakaway.abs().max(c.coulomb.abs());
                // (peak/ε + Fv)·dt·invweight ≤ 0.5
                let room = 0.5 - c.viscous.max(0.0) * dt * invweight;
                let eps = if room > 0.0 { peak * dt * invweight / room } else { f64::INFINITY };
                eps.max(1e-3)
            })
            .collect();
        self.last = vec![0.0; self.curves.len()];
        // With actuators the controller writes `ctrl` and leaves `qfrc_applied` alone: the
        // previous step's friction is replaced rather than added to.
        self.adds = matches!(super::Actuation::of(model), super::Actuation::Qfrc);
        Ok(())
    }

    fn apply(&mut self, data: &mut Data, _rng: &mut ChaCha8Rng) {
        for (k, &(dof, c)) in self.curves.iter().enumerate() {
            let v = data.qvel()[dof];
            let tau = -c.torque(v, self.eps[k]);
            let q = &mut data.qfrc_applied_mut()[dof];
            if self.adds {
                *q += tau;
            } else {
                *q += tau - self.last[k];
            }
            self.last[k] = tau;
        }
    }
}

/// Puts back the state the run started from (positions, velocities, activations; not the time)
/// at the first step after `requested` is set, and clears it: the reset of the live bridge
/// (`/twin/reset_simulation`) and of the viewers (`/twin/reset`).
pub struct ResetOnRequest {
    requested: Arc<AtomicBool>,
    initial: Vec<f64>,
}

impl ResetOnRequest {
    /// A reset taken whenever `requested` is set (by a service thread).
    pub fn new(requested: Arc<AtomicBool>) -> ResetOnRequest {
        ResetOnRequest { requested, initial: Vec::new() }
    }
}

impl Disturbance for ResetOnRequest {
    fn start(&mut self, _model: &Model, data: &Data) -> Result<()> {
        self.initial = data.state(crate::mj::StateSig::PHYSICS)?;
        Ok(())
    }

    fn apply(&mut self, data: &mut Data, _rng: &mut ChaCha8Rng) {
        if self.requested.swap(false, Ordering::Relaxed) {
            // Same model, same signature: only a length mismatch could fail, and can't here.
            let _ = data.set_state(&self.initial, crate::mj::StateSig::PHYSICS);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{Controller, Observation};
    use crate::engine::{Engine, Episode};
    use rand::SeedableRng;
    use std::sync::Arc;

    /// Drives one hinge at a constant velocity with a stiff velocity loop (`qfrc_applied`).
    struct VelocityDrive {
        target: f64,
        gain: f64,
        torque: Vec<(f64, f64)>,
    }

    impl Controller for VelocityDrive {
        fn name(&self) -> &'static str {
            "velocity"
        }
        fn compute(&mut self, _model: &Model, observation: &Observation<'_>, command: &mut [f64]) {
            let v = observation.qvel[0];
            command[0] = self.gain * (self.target - v);
            self.torque.push((v, command[0]));
        }
    }

    #[test]
    fn a_joint_at_constant_velocity_shows_the_fitted_stribeck_curve() {
        let xml = r#"<mujoco><option timestep="0.001" gravity="0 0 0"/><worldbody><body>
            <joint name="j" type="hinge" axis="0 0 1" damping="3" frictionloss="2"/>
            <geom type="box" size="0.2 0.05 0.05" mass="20"/></body></worldbody></mujoco>"#;
        let model = crate::mj::Model::from_xml_str(xml).unwrap();
        let curve =
            StribeckCurve { coulomb: 0.4, breakaway: 0.9, stribeck_velocity: 0.15, exponent: 1.5, viscous: 0.2 };
        let mut friction = StribeckFriction::new(vec![(0, curve)]);
        let model = Arc::new(friction.model_without_joint_friction(&model).unwrap());
        assert_eq!(model.dof_frictionloss()[0], 0.0);
        for target in [-1.0, -0.3, -0.1, 0.05, 0.1, 0.2, 0.5, 1.0] {
            let mut drive = VelocityDrive { target, gain: 200.0, torque: Vec::new() };
            let episode = Episode { steps: 2000, ..Episode::default() };
            let mut rng = ChaCha8Rng::seed_from_u64(0);
            Engine::new().run(&model, &episode, &mut drive, &mut [&mut friction], &mut [], &mut rng).unwrap();
            assert!(friction.smoothing()[0] < 0.01, "ε = {}", friction.smoothing()[0]);
            // Steady state (last 0.5 s): the drive's torque is the friction at that velocity.
            let tail = &drive.torque[1500..];
            let v = tail.iter().map(|x| x.0).sum::<f64>() / tail.len() as f64;
            let tau = tail.iter().map(|x| x.1).sum::<f64>() / tail.len() as f64;
            let exact = v.signum()
                * (curve.coulomb
                    + (curve.breakaway - curve.coulomb)
                        * (-(v.abs() / curve.stribeck_velocity).powf(curve.exponent)).exp())
                + curve.viscous * v;
            assert!((v - target).abs() < 0.01 * target.abs() + 0.01, "v = {v}, target {target}");
            assert!((tau - exact).abs() < 0.01 * exact.abs() + 1e-3, "at {v:.3} rad/s: {tau:.4} N·m, curve {exact:.4}");
        }
    }
}
