//! ZMP preview control of the linear inverted pendulum (Kajita et al. 2003, with Katayama's
//! integral-action formulation): per axis the state is `(c, ċ, c̈)`, the input the CoM jerk,
//! the output the ZMP `p = c − (h/g)·c̈`; gains come from the discrete Riccati equation.

use nalgebra::{Matrix1, Matrix3, Matrix4, Vector3, Vector4};

/// Gains of the preview controller for one CoM height and time step.
#[derive(Debug, Clone)]
pub struct PreviewGains {
    a: Matrix3<f64>,
    b: Vector3<f64>,
    c: Vector3<f64>,
    gi: f64,
    gx: Vector3<f64>,
    /// Preview gains on the future ZMP reference, `gd[j]` for sample `k + 1 + j`.
    gd: Vec<f64>,
}

impl PreviewGains {
    /// Gains for time step `dt_secs`, CoM height `com_height_m`, gravity `g`, ZMP error weight
    /// `qe`, jerk weight `r` and `horizon` future samples.
    pub fn new(dt_secs: f64, com_height_m: f64, g: f64, qe: f64, r: f64, horizon: usize) -> PreviewGains {
        let t = dt_secs;
        let a = Matrix3::new(1.0, t, t * t / 2.0, 0.0, 1.0, t, 0.0, 0.0, 1.0);
        let b = Vector3::new(t * t * t / 6.0, t * t / 2.0, t);
        let c = Vector3::new(1.0, 0.0, -com_height_m / g);
        // Augmented system: state (Σ e, x), e = p − p_ref.
        let ca = c.transpose() * a;
        let mut at = Matrix4::zeros();
        at[(0, 0)] = 1.0;
        for k in 0..3 {
            at[(0, k + 1)] = ca[k];
            for l in 0..3 {
                at[(k + 1, l + 1)] = a[(k, l)];
            }
        }
        let bt = Vector4::new(c.dot(&b), b[0], b[1], b[2]);
        let it = Vector4::new(1.0, 0.0, 0.0, 0.0);
        let mut q = Matrix4::zeros();
        q[(0, 0)] = qe;
        // Riccati iteration to convergence.
        let mut p = q;
        for _ in 0..100_000 {
            let s = r + (bt.transpose() * p * bt)[(0, 0)];
            let pb = p * bt;
            let next = at.transpose() * p * at - at.transpose() * pb * (1.0 / s) * pb.transpose() * at + q;
            let diff = (next - p).abs().max();
            p = next;
            if diff < 1e-11 * p.abs().max().max(1.0) {
                break;
            }
        }
        let s = r + (bt.transpose() * p * bt)[(0, 0)];
        let k: Matrix1<f64> = Matrix1::new(1.0 / s);
        let kk = k * bt.transpose() * p * at; // 1×4
        let gi = kk[(0, 0)];
        let gx = Vector3::new(kk[(0, 1)], kk[(0, 2)], kk[(0, 3)]);
        let ac = at - bt * kk;
        let mut x = -ac.transpose() * p * it;
        let mut gd = Vec::with_capacity(horizon);
        gd.push(-gi);
        for _ in 1..horizon {
            gd.push((bt.transpose() * x)[(0, 0)] / s);
            x = ac.transpose() * x;
        }
        PreviewGains { a, b, c, gi, gx, gd }
    }

    /// Number of future samples used.
    pub fn horizon(&self) -> usize {
        self.gd.len()
    }
}

/// One axis of the preview controller's state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PreviewAxis {
    /// CoM position, velocity, acceleration.
    pub x: [f64; 3],
    /// Integrated ZMP error.
    pub sum_error: f64,
}

impl PreviewAxis {
    /// At rest at `c`.
    pub fn at(c: f64) -> PreviewAxis {
        PreviewAxis { x: [c, 0.0, 0.0], sum_error: 0.0 }
    }

    /// At CoM `c` moving at `v`, with the integrated error that makes the state at rest at `c`
    /// under a constant reference `c` an equilibrium: the control law is not translation
    /// invariant without it, and a restart away from the origin would jerk the CoM.
    pub fn restart(gains: &PreviewGains, c: f64, v: f64) -> PreviewAxis {
        let sum_gd: f64 = gains.gd.iter().sum();
        let sum_error = if gains.gi.abs() > 0.0 { -(gains.gx[0] + sum_gd) * c / gains.gi } else { 0.0 };
        PreviewAxis { x: [c, v, 0.0], sum_error }
    }

    /// The ZMP of the current state.
    pub fn zmp(&self, gains: &PreviewGains) -> f64 {
        gains.c.dot(&Vector3::from(self.x))
    }

    /// One step: `reference[j]` is the ZMP reference at sample `k + j` (`reference[0]` now).
    pub fn step(&mut self, gains: &PreviewGains, reference: &[f64]) {
        let x = Vector3::from(self.x);
        self.sum_error += gains.c.dot(&x) - reference[0];
        let mut u = -gains.gi * self.sum_error - gains.gx.dot(&x);
        for (j, g) in gains.gd.iter().enumerate() {
            let r = reference.get(j + 1).or(reference.last()).copied().unwrap_or(0.0);
            u -= g * r;
        }
        let next = gains.a * x + gains.b * u;
        self.x = [next[0], next[1], next[2]];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preview_tracks_a_zmp_step_with_the_com_leading() {
        let dt = 0.005;
        let gains = PreviewGains::new(dt, 0.8, 9.81, 1.0, 1e-6, 320);
        let mut axis = PreviewAxis::at(0.0);
        let reference = |k: usize| if k as f64 * dt >= 2.0 { 0.1 } else { 0.0 };
        let mut max_before = 0.0_f64;
        let mut buf = vec![0.0; 321];
        for k in 0..1200 {
            for (j, r) in buf.iter_mut().enumerate() {
                *r = reference(k + j);
            }
            axis.step(&gains, &buf);
            if (k as f64) * dt < 2.0 {
                max_before = max_before.max(axis.x[0]);
            }
        }
        // The CoM starts moving before the ZMP step (preview) and settles on it.
        assert!(max_before > 0.02, "{max_before}");
        assert!((axis.x[0] - 0.1).abs() < 1e-3, "{:?}", axis.x);
        assert!((axis.zmp(&gains) - 0.1).abs() < 1e-3);
    }
}
