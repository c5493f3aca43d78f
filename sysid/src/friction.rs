//! Joint friction curves from constant-velocity sweeps (`twin sysid friction`).
//!
//! Recipe (calibration notes; IHMC, Rhoban/bam): each joint is moved at a series of constant
//! velocities, forth and back. For each joint:
//! 1. **Segments** ([`find_segments`]): the joint's velocity (logged, else the central
//!    difference of the positions) is smoothed by a moving average over
//!    [`FrictionOptions::smooth_secs`], logged or not (a drive's velocity is as noisy as a
//!    difference). Its noise is measured from the log itself: σ = 1.4826 · the median absolute
//!    deviation of the raw velocity from the smoothed one, divided by √(samples per window) for
//!    the smoothed series. A segment is a run whose smoothed samples all stay within the
//!    tolerance `max(rel_tol·|v̄|, abs_tol, 4σ)` of the run's running mean `v̄`, with
//!    `|v̄| > dead_zone`; of it only the core is kept, where samples are within half that
//!    tolerance of the run's median (the ramps, where inertia torques would not cancel, are
//!    cut), minus 10 % at each end; the core must last `min_segment_secs`. Every segment used
//!    is listed with its times ([`JointFriction::segment_spans`]; `twin sysid friction` prints
//!    them per joint).
//! 2. **±v pairing**: a `+v` segment and a `−v` segment of about the same speed (within
//!    `pair_tol`), over the positions both cover: their efforts are fitted together as a cubic
//!    in position (gravity and offsets, the same both ways) plus `±f`, so `f` is `(τ⁺ − τ⁻)/2`
//!    with gravity cancelled even where the two directions sample the positions unevenly (the
//!    difference of plain means was biased by up to 3 % at 1.3 rad/s on gravity-loaded joints);
//!    and `J·a`, the inertia torque of the speed changes still ringing in the segments (a heavy
//!    joint under a drive tuned for less: see `paired_friction`), with the acceleration `a`
//!    the central difference of the smoothed velocity across its window.
//! 3. **Fit** the richest model the paired speeds identify ([`FrictionModel`]), and say which:
//!    - with ≥ 6 speeds, **Stribeck** `τ_f(v) = Fc + (Fs − Fc)·exp(−|v/vs|^δ) + Fv·v` for
//!      `v > 0` (odd in `v`) by bounded Levenberg–Marquardt (`Fc, Fs, Fv ≥ 0`, `vs` in log
//!      space, `δ ∈ [0.5, 3]`), from a line through the fast half (`Fc`, `Fv`) and several `vs`
//!      starts; covariance `σ²(JᵀJ)⁻¹` gives 95 % confidence intervals. It is kept when the
//!      Stribeck hump is identified: `Fs − Fc` above its own 95 % half-width and every interval
//!      finite; else the data say no more than Coulomb + viscous, which is fitted instead;
//!    - with 2 to 5 speeds (or an unidentified hump), **Coulomb + viscous** `Fc + Fv·v`, by
//!      least squares weighted by each point's standard error;
//!    - with 1 speed, **Coulomb** alone.
//!
//! The Coulomb (`Fc` → `<dynamics friction>`) and viscous (`Fv` → `damping`) parts go into the
//! URDF with [`crate::writeback::update_urdf_file`]; the Stribeck terms are reported.

use crate::error::{Error, Result};
use crate::log::JointLog;
use serde::Serialize;
use std::fmt::Write as _;

/// Options of the friction fit.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct FrictionOptions {
    /// Shortest constant-velocity segment, s (default: 0.5).
    #[default(0.5)]
    pub min_segment_secs: f64,
    /// Velocity tolerance within a segment, fraction of its speed (default: 0.05).
    #[default(0.05)]
    pub rel_tol: f64,
    /// Velocity tolerance floor, rad/s (default: 0.002).
    #[default(0.002)]
    pub abs_tol: f64,
    /// Speeds below are the dead zone (stiction), rad/s (default: 0.001).
    #[default(0.001)]
    pub dead_zone: f64,
    /// Velocity tolerance floor in multiples of the smoothed velocity's measured noise σ
    /// (default: 4).
    #[default(4.0)]
    pub noise_sigmas: f64,
    /// Largest relative speed difference of a ±v pair (default: 0.1).
    #[default(0.1)]
    pub pair_tol: f64,
    /// Moving-average window of the velocity (logged or differentiated), s (default: 0.05).
    #[default(0.05)]
    pub smooth_secs: f64,
    /// Joints to fit (default: every joint with segments; empty = all).
    pub joints: Vec<String>,
}

/// A constant-velocity segment: sample range and mean velocity.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Segment {
    /// First sample.
    pub start: usize,
    /// One past the last sample.
    pub end: usize,
    /// Mean velocity, rad/s.
    pub velocity: f64,
}

/// One paired point of the friction curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CurvePoint {
    /// Speed, rad/s (mean of the pair's |v|).
    pub speed: f64,
    /// `(τ⁺ − τ⁻)/2`, N·m.
    pub friction: f64,
    /// Standard error of that mean, N·m.
    pub std_err: f64,
    /// Samples averaged (both directions).
    pub samples: usize,
    /// The `+v` segment, seconds from the log's start (first, last sample).
    pub positive_secs: [f64; 2],
    /// The `−v` segment, seconds from the log's start.
    pub negative_secs: [f64; 2],
}

/// A constant-velocity segment as the report lists it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SegmentSpan {
    /// First sample, seconds from the log's start.
    pub start_secs: f64,
    /// Last sample, seconds from the log's start.
    pub end_secs: f64,
    /// Mean velocity, rad/s.
    pub velocity: f64,
    /// Whether it made a ±v pair (a point of the curve).
    pub paired: bool,
}

/// The friction model a joint's data identify (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FrictionModel {
    /// Coulomb, breakaway, Stribeck velocity and exponent, viscous (≥ 6 speeds, hump identified).
    Stribeck,
    /// Coulomb + viscous (2 speeds or more).
    CoulombViscous,
    /// Coulomb alone (one speed).
    Coulomb,
}

impl FrictionModel {
    /// Its name in reports.
    pub fn label(self) -> &'static str {
        match self {
            FrictionModel::Stribeck => "Stribeck",
            FrictionModel::CoulombViscous => "Coulomb + viscous",
            FrictionModel::Coulomb => "Coulomb",
        }
    }
}

/// Stribeck parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct Stribeck {
    /// Coulomb friction `Fc`, N·m.
    pub coulomb: f64,
    /// Breakaway (static) friction `Fs`, N·m.
    pub breakaway: f64,
    /// Stribeck velocity `vs`, rad/s.
    pub stribeck_velocity: f64,
    /// Exponent `δ`.
    pub exponent: f64,
    /// Viscous `Fv`, N·m·s/rad.
    pub viscous: f64,
}

impl Stribeck {
    /// Friction torque at velocity `v` (odd in `v`).
    pub fn torque(&self, v: f64) -> f64 {
        if v == 0.0 {
            return 0.0;
        }
        let s = v.abs();
        v.signum()
            * (self.coulomb
                + (self.breakaway - self.coulomb) * (-(s / self.stribeck_velocity).powf(self.exponent)).exp())
            + self.viscous * v
    }
    fn from_vec(x: [f64; 5]) -> Stribeck {
        Stribeck { coulomb: x[0], breakaway: x[1], stribeck_velocity: x[2].exp(), exponent: x[3], viscous: x[4] }
    }
}

/// The fit of one joint.
#[derive(Debug, Clone, Serialize)]
pub struct JointFriction {
    /// Joint.
    pub joint: String,
    /// The model fitted: the richest the data identify.
    pub model: FrictionModel,
    /// Why not a richer model (empty for Stribeck).
    pub model_note: String,
    /// Fitted curve. Without the Stribeck terms `breakaway` equals `coulomb` (the hump is zero)
    /// and `stribeck_velocity`, `exponent` are 1 and unused; without viscous, `viscous` is 0.
    pub fit: Stribeck,
    /// 95 % half-widths of `[Fc, Fs, vs, δ, Fv]` (vs: from the log-space interval, the larger
    /// side); NaN (`null` in JSON) for the terms the model does not have.
    pub ci95: [f64; 5],
    /// RMS residual, N·m.
    pub rms_residual: f64,
    /// The data.
    pub points: Vec<CurvePoint>,
    /// Segments found (both directions).
    pub segments: usize,
    /// Every segment found, paired or not, in time order.
    pub segment_spans: Vec<SegmentSpan>,
}

/// Friction fits of a sweep log.
#[derive(Debug, Clone, Serialize)]
pub struct FrictionReport {
    /// The log.
    pub log: String,
    /// Per fitted joint.
    pub joints: Vec<JointFriction>,
}

/// Velocity of joint `j` (the logged one where every sample has one, else the central
/// difference of the positions), smoothed by a moving average over `smooth_secs`, and the
/// measured noise σ of the smoothed series (see the module docs), rad/s.
fn joint_velocity(log: &JointLog, j: usize, smooth_secs: f64) -> (Vec<f64>, f64) {
    let n = log.len();
    let t = |k: usize| log.t_nanos[k] as f64 * 1e-9;
    let raw: Vec<f64> = if log.velocity[j].iter().all(|v| v.is_finite()) {
        log.velocity[j].clone()
    } else {
        let q = &log.position[j];
        (0..n)
            .map(|k| {
                let (a, b) = (k.saturating_sub(1), (k + 1).min(n.saturating_sub(1)));
                if b > a { (q[b] - q[a]) / (t(b) - t(a)) } else { 0.0 }
            })
            .collect()
    };
    if n < 2 {
        return (raw, 0.0);
    }
    let dt = (t(n - 1) - t(0)) / (n - 1) as f64;
    let half = ((smooth_secs / dt / 2.0).round() as usize).max(1);
    let mut prefix = vec![0.0; n + 1];
    for k in 0..n {
        prefix[k + 1] = prefix[k] + raw[k];
    }
    let smooth: Vec<f64> = (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(n));
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect();
    let mut dev: Vec<f64> = raw.iter().zip(&smooth).map(|(r, s)| (r - s).abs()).filter(|d| d.is_finite()).collect();
    let sigma_raw = if dev.is_empty() {
        0.0
    } else {
        let mid = dev.len() / 2;
        1.4826 * *dev.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    (smooth, sigma_raw / ((2 * half + 1) as f64).sqrt())
}

/// Constant-velocity segments of the smoothed velocity series `v` at times `t_nanos`, whose
/// measured noise is `noise_sigma` rad/s (see the module docs for the criteria).
pub fn find_segments(t_nanos: &[i64], v: &[f64], noise_sigma: f64, opts: &FrictionOptions) -> Vec<Segment> {
    let mut out = Vec::new();
    let n = v.len();
    let floor = opts.abs_tol.max(opts.noise_sigmas * noise_sigma);
    let mut start = 0;
    while start < n {
        // Grow a run while every sample stays within tolerance of the run's running mean.
        let mut sum = v[start];
        let mut end = start + 1;
        while end < n {
            let mean = sum / (end - start) as f64;
            let tol = (opts.rel_tol * mean.abs()).max(floor);
            if !v[end].is_finite() || (v[end] - mean).abs() > tol {
                break;
            }
            sum += v[end];
            end += 1;
        }
        let mean = sum / (end - start) as f64;
        let secs = (t_nanos[end - 1] - t_nanos[start]) as f64 * 1e-9;
        if secs >= opts.min_segment_secs && mean.abs() > opts.dead_zone && mean.is_finite() {
            // The run may have grown into the ramps (its mean drifts along): keep the core whose
            // samples are within half the tolerance of the run's median, where the joint is not
            // accelerating (inertia torques there would not cancel in the ±v pairing), then drop
            // a 10 % margin at each end.
            let mut sorted: Vec<f64> = v[start..end].to_vec();
            sorted.sort_by(f64::total_cmp);
            let median = sorted[sorted.len() / 2];
            let core_tol = 0.5 * (opts.rel_tol * median.abs()).max(floor);
            let (mut a, mut b) = (start, end);
            while a < b && (v[a] - median).abs() > core_tol {
                a += 1;
            }
            while b > a && (v[b - 1] - median).abs() > core_tol {
                b -= 1;
            }
            let core_secs = if b > a { (t_nanos[b - 1] - t_nanos[a]) as f64 * 1e-9 } else { 0.0 };
            if core_secs >= opts.min_segment_secs {
                let margin = (b - a) / 10;
                let (a, b) = (a + margin, b - margin);
                let velocity = v[a..b].iter().sum::<f64>() / (b - a) as f64;
                out.push(Segment { start: a, end: b, velocity });
            }
            start = end;
        } else {
            start += 1;
        }
    }
    out
}

/// Acceleration of the smoothed velocity `v` (rad/s²): its central difference across the
/// smoothing window (`smooth_secs`), one-sided at the ends of the log.
fn joint_acceleration(t_nanos: &[i64], v: &[f64], smooth_secs: f64) -> Vec<f64> {
    let n = v.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let t = |k: usize| t_nanos[k] as f64 * 1e-9;
    let dt = (t(n - 1) - t(0)) / (n - 1) as f64;
    let half = ((smooth_secs / dt / 2.0).round() as usize).max(1);
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half).min(n - 1));
            if b > a && t(b) > t(a) { (v[b] - v[a]) / (t(b) - t(a)) } else { 0.0 }
        })
        .collect()
}

/// Friction of a ±v pair over the positions `[lo, hi]` both cover: least squares of the
/// efforts of both segments on a cubic in position (gravity and offsets, the same both ways),
/// `±f` (the friction, odd in velocity) and `J·a` (the inertia torque of what speed changes
/// are left in the segments, `accel` being the joint's acceleration): unlike the difference of
/// plain means, this does not assume both directions sample the positions alike, nor that the
/// drive held its speed. A heavy joint tracked by a drive tuned for less rings after each speed
/// change, through the segment: a base yaw joint moving a stretched arm (4.9 kg m²) under a
/// drive tuned for a third of that rings so into the cruise, and the inertia torque, odd in the
/// direction as friction is, bent its curve: on such a sweep made by MuJoCo
/// (`tests/python/arm_sweep.py`) the yaw joint came out Coulomb 1.01 and viscous −0.23 against
/// 0.8 and 0.35 (and 0.84 / 0.27 with a drive tuned for half), 0.798 and 0.363 with the `J·a`
/// term; the joints whose drives held their speed are unchanged. Returns `(f, σ_f, samples)`.
#[allow(clippy::needless_range_loop)] // 6 × 6 normal equations, indexed as written
fn paired_friction(
    log: &JointLog,
    j: usize,
    accel: &[f64],
    pos: &Segment,
    neg: &Segment,
    lo: f64,
    hi: f64,
) -> Option<(f64, f64, usize)> {
    const F: usize = 4;
    let (mid, half) = (0.5 * (lo + hi), (0.5 * (hi - lo)).max(1e-12));
    let mut a = [[0.0; 6]; 6];
    let mut b = [0.0; 6];
    let mut rows = Vec::new();
    for (seg, sign) in [(pos, 1.0), (neg, -1.0)] {
        for k in seg.start..seg.end {
            let (q, e) = (log.position[j][k], log.effort[j][k]);
            if !(lo..=hi).contains(&q) || !e.is_finite() || !accel[k].is_finite() {
                continue;
            }
            let x = (q - mid) / half;
            rows.push(([1.0, x, x * x, x * x * x, sign, accel[k]], e));
        }
    }
    let n_pos = rows.iter().filter(|r| r.0[F] > 0.0).count();
    if n_pos < 6 || rows.len() - n_pos < 6 {
        return None;
    }
    for (phi, e) in &rows {
        for p in 0..6 {
            b[p] += phi[p] * e;
            for q in 0..6 {
                a[p][q] += phi[p] * phi[q];
            }
        }
    }
    let coef = solve5(a, b)?;
    let ss: f64 = rows.iter().map(|(phi, e)| (e - (0..6).map(|p| phi[p] * coef[p]).sum::<f64>()).powi(2)).sum();
    let sigma2 = ss / (rows.len() - 6) as f64;
    let mut unit = [0.0; 6];
    unit[F] = 1.0;
    let var = solve5(a, unit)?[F] * sigma2;
    Some((coef[F], var.max(0.0).sqrt(), rows.len()))
}

/// First and last sample of `s`, seconds from the log's start.
fn segment_secs(log: &JointLog, s: &Segment) -> [f64; 2] {
    let at = |k: usize| (log.t_nanos[k] - log.t_nanos[0]) as f64 * 1e-9;
    [at(s.start), at(s.end.saturating_sub(1).max(s.start))]
}

/// Paired friction points of joint `j` from its segments, `accel` being the joint's
/// acceleration at each sample (see `paired_friction`).
pub fn pair_segments(
    log: &JointLog,
    j: usize,
    accel: &[f64],
    segments: &[Segment],
    opts: &FrictionOptions,
) -> Vec<CurvePoint> {
    let range = |s: &Segment| {
        let q = &log.position[j][s.start..s.end];
        let lo = q.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let mut used = vec![false; segments.len()];
    let mut out = Vec::new();
    for (a, pos) in segments.iter().enumerate().filter(|(_, s)| s.velocity > 0.0) {
        // The unused negative segment closest in speed.
        let best = segments
            .iter()
            .enumerate()
            .filter(|(b, s)| !used[*b] && s.velocity < 0.0)
            .map(|(b, s)| (b, (s.velocity.abs() / pos.velocity - 1.0).abs()))
            .filter(|(_, d)| *d <= opts.pair_tol)
            .min_by(|x, y| x.1.total_cmp(&y.1));
        let Some((b, _)) = best else { continue };
        let neg = &segments[b];
        let (lo_a, hi_a) = range(pos);
        let (lo_b, hi_b) = range(neg);
        let (lo, hi) = (lo_a.max(lo_b), hi_a.min(hi_b));
        // A moving pair needs common ground; a pair at one position (a joint spinning in place
        // is not possible here) falls back to whole segments.
        let (lo, hi) = if hi > lo { (lo, hi) } else { continue };
        let Some((friction, std_err, samples)) = paired_friction(log, j, accel, pos, neg, lo, hi) else { continue };
        used[b] = true;
        let _ = a;
        out.push(CurvePoint {
            speed: 0.5 * (pos.velocity - neg.velocity),
            friction,
            std_err,
            samples,
            positive_secs: segment_secs(log, pos),
            negative_secs: segment_secs(log, neg),
        });
    }
    out.sort_by(|x, y| x.speed.total_cmp(&y.speed));
    out
}

/// Fits the Stribeck curve to paired points by bounded Levenberg–Marquardt: the curve, 95 %
/// confidence half-widths of `[Fc, Fs, vs, δ, Fv]`, the RMS residual (N·m) and the 95 %
/// half-width of the hump `Fs − Fc`.
///
/// # Errors
/// [`Error::Numerical`] with fewer than 6 points (5 parameters).
#[allow(clippy::needless_range_loop)] // 5 × 5 normal equations, indexed as written
pub fn fit_stribeck(points: &[CurvePoint]) -> Result<(Stribeck, [f64; 5], f64, f64)> {
    if points.len() < 6 {
        return Err(Error::Numerical(format!(
            "{} paired speeds; the Stribeck curve (5 parameters) needs at least 6",
            points.len()
        )));
    }
    let v: Vec<f64> = points.iter().map(|p| p.speed).collect();
    let y: Vec<f64> = points.iter().map(|p| p.friction).collect();
    let vmax = v.iter().copied().fold(0.0, f64::max);
    let vmin = v.iter().copied().fold(f64::INFINITY, f64::min);
    // Line through the fast half: Coulomb and viscous starts.
    let fast: Vec<usize> = (points.len() / 2..points.len()).collect();
    let (mx, my) = (
        fast.iter().map(|&i| v[i]).sum::<f64>() / fast.len() as f64,
        fast.iter().map(|&i| y[i]).sum::<f64>() / fast.len() as f64,
    );
    let sxy: f64 = fast.iter().map(|&i| (v[i] - mx) * (y[i] - my)).sum();
    let sxx: f64 = fast.iter().map(|&i| (v[i] - mx).powi(2)).sum();
    let fv0 = if sxx > 0.0 { (sxy / sxx).max(0.0) } else { 0.0 };
    let fc0 = (my - fv0 * mx).max(0.0);
    let fs0 = y[0].max(fc0);
    let cost = |x: &[f64; 5]| -> f64 {
        let s = Stribeck::from_vec(*x);
        v.iter().zip(&y).map(|(&vi, &yi)| (s.torque(vi) - yi).powi(2)).sum()
    };
    let lower = [0.0, 0.0, (0.1 * vmin.max(1e-6)).ln(), 0.5, 0.0];
    let upper = [f64::INFINITY, f64::INFINITY, (2.0 * vmax).ln(), 3.0, f64::INFINITY];
    let clamp = |x: &mut [f64; 5]| {
        for i in 0..5 {
            x[i] = x[i].clamp(lower[i], upper[i]);
        }
    };
    let jac = |x: &[f64; 5]| -> Vec<[f64; 5]> {
        let s = Stribeck::from_vec(*x);
        v.iter()
            .map(|&vi| {
                let u = (vi / s.stribeck_velocity).powf(s.exponent);
                let e = (-u).exp();
                let d = s.breakaway - s.coulomb;
                [1.0 - e, e, d * e * u * s.exponent, -d * e * u * (vi / s.stribeck_velocity).ln(), vi]
            })
            .collect()
    };
    let mut best: Option<([f64; 5], f64)> = None;
    for k in 0..8 {
        // vs starts log-spaced over the measured speeds.
        let vs0 = vmin * (vmax / vmin).powf(k as f64 / 7.0) * 0.5;
        let mut x = [fc0, fs0, vs0.max(1e-6).ln(), 1.0, fv0];
        clamp(&mut x);
        let mut c = cost(&x);
        let mut lambda = 1e-3;
        for _ in 0..300 {
            let jm = jac(&x);
            let s = Stribeck::from_vec(x);
            let r: Vec<f64> = v.iter().zip(&y).map(|(&vi, &yi)| yi - s.torque(vi)).collect();
            let mut a = [[0.0; 5]; 5];
            let mut g = [0.0; 5];
            for (row, ri) in jm.iter().zip(&r) {
                for p in 0..5 {
                    g[p] += row[p] * ri;
                    for q in 0..5 {
                        a[p][q] += row[p] * row[q];
                    }
                }
            }
            let mut improved = false;
            for _ in 0..20 {
                let mut m = a;
                for p in 0..5 {
                    m[p][p] += lambda * (a[p][p] + 1e-12);
                }
                let Some(step) = solve5(m, g) else {
                    lambda *= 10.0;
                    continue;
                };
                let mut xn = x;
                for p in 0..5 {
                    xn[p] += step[p];
                }
                clamp(&mut xn);
                let cn = cost(&xn);
                if cn < c {
                    let rel = (c - cn) / c.max(1e-300);
                    x = xn;
                    c = cn;
                    lambda = (lambda * 0.3).max(1e-12);
                    improved = rel > 1e-12;
                    break;
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        if best.as_ref().is_none_or(|b| c < b.1) {
            best = Some((x, c));
        }
    }
    let (x, c) = best.expect("8 starts");
    let dof = (points.len() - 5).max(1) as f64;
    let sigma2 = c / dof;
    let jm = jac(&x);
    let mut a = [[0.0; 5]; 5];
    for row in &jm {
        for p in 0..5 {
            for q in 0..5 {
                a[p][q] += row[p] * row[q];
            }
        }
    }
    let mut ci = [f64::NAN; 5];
    let t = t975(dof);
    for p in 0..5 {
        let mut e = [0.0; 5];
        e[p] = 1.0;
        if let Some(col) = solve5(a, e) {
            ci[p] = t * (sigma2 * col[p]).max(0.0).sqrt();
        }
    }
    let hump_ci =
        solve5(a, [-1.0, 1.0, 0.0, 0.0, 0.0]).map_or(f64::NAN, |col| t * (sigma2 * (col[1] - col[0])).max(0.0).sqrt());
    let fit = Stribeck::from_vec(x);
    // vs: the log-space half-width converted to the larger side.
    ci[2] = fit.stribeck_velocity * (ci[2].exp() - 1.0);
    Ok((fit, ci, (c / points.len() as f64).sqrt(), hump_ci))
}

/// Student t 97.5 % quantile for `dof` degrees of freedom (1.96 for many), approximated.
fn t975(dof: f64) -> f64 {
    1.96 + 2.4 / dof + 3.0 / (dof * dof)
}

/// Fits Coulomb + viscous `Fc + Fv·v` to ≥ 2 paired points by least squares weighted by each
/// point's standard error: the curve (no hump), 95 % half-widths (`[Fc, NaN, NaN, NaN, Fv]`)
/// and the RMS residual, N·m. The intervals use the points' errors, scaled up by the residual
/// when it exceeds them.
///
/// # Errors
/// [`Error::Numerical`] with fewer than 2 distinct speeds.
pub fn fit_coulomb_viscous(points: &[CurvePoint]) -> Result<(Stribeck, [f64; 5], f64)> {
    let w = |p: &CurvePoint| 1.0 / p.std_err.max(1e-9).powi(2);
    let (mut s00, mut s01, mut s11, mut b0, mut b1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for p in points {
        let wi = w(p);
        s00 += wi;
        s01 += wi * p.speed;
        s11 += wi * p.speed * p.speed;
        b0 += wi * p.friction;
        b1 += wi * p.speed * p.friction;
    }
    let det = s00 * s11 - s01 * s01;
    if points.len() < 2 || det.abs() <= 1e-12 * s00 * s11 {
        return Err(Error::Numerical(format!(
            "{} paired speed(s); Coulomb + viscous needs 2 distinct speeds",
            points.len()
        )));
    }
    let fc = (s11 * b0 - s01 * b1) / det;
    let fv = (s00 * b1 - s01 * b0) / det;
    let residual = |p: &CurvePoint| p.friction - fc - fv * p.speed;
    let chi2: f64 = points.iter().map(|p| w(p) * residual(p).powi(2)).sum();
    let dof = points.len() as f64 - 2.0;
    let scale = if dof > 0.0 { (chi2 / dof).max(1.0) } else { 1.0 };
    let t = if dof > 0.0 { t975(dof) } else { 1.96 };
    let ci = [t * (scale * s11 / det).sqrt(), f64::NAN, f64::NAN, f64::NAN, t * (scale * s00 / det).sqrt()];
    let rms = (points.iter().map(|p| residual(p).powi(2)).sum::<f64>() / points.len() as f64).sqrt();
    let fit = Stribeck { coulomb: fc, breakaway: fc, stribeck_velocity: 1.0, exponent: 1.0, viscous: fv };
    Ok((fit, ci, rms))
}

/// Coulomb friction from one paired speed: the point's value, its 95 % half-width.
fn fit_coulomb(point: &CurvePoint) -> (Stribeck, [f64; 5], f64) {
    let fc = point.friction;
    let fit = Stribeck { coulomb: fc, breakaway: fc, stribeck_velocity: 1.0, exponent: 1.0, viscous: 0.0 };
    (fit, [1.96 * point.std_err, f64::NAN, f64::NAN, f64::NAN, f64::NAN], 0.0)
}

/// The richest model `points` identify (see the module docs), fitted: model, why not a richer
/// one, curve, 95 % half-widths, RMS residual.
///
/// # Errors
/// [`Error::Numerical`] without any point.
#[allow(clippy::type_complexity)]
pub fn fit_richest(points: &[CurvePoint]) -> Result<(FrictionModel, String, Stribeck, [f64; 5], f64)> {
    let n = points.len();
    let coulomb_viscous = |note: String| -> Result<_> {
        let (fit, ci, rms) = fit_coulomb_viscous(points)?;
        Ok((FrictionModel::CoulombViscous, note, fit, ci, rms))
    };
    match n {
        0 => Err(Error::Numerical("no paired speed".into())),
        1 => {
            let (fit, ci, rms) = fit_coulomb(&points[0]);
            Ok((
                FrictionModel::Coulomb,
                "1 paired speed: Coulomb only (viscous needs 2 speeds, Stribeck 6)".into(),
                fit,
                ci,
                rms,
            ))
        }
        2..=5 => coulomb_viscous(format!("{n} paired speeds: Coulomb + viscous (Stribeck needs 6)")),
        _ => {
            let (fit, ci, rms, hump_ci) = fit_stribeck(points)?;
            let hump = fit.breakaway - fit.coulomb;
            if ci.iter().all(|c| c.is_finite()) && hump_ci.is_finite() && hump > hump_ci {
                Ok((FrictionModel::Stribeck, String::new(), fit, ci, rms))
            } else {
                coulomb_viscous(format!(
                    "{n} paired speeds, but the Stribeck hump is not identified (Fs − Fc = {:.4} ± {:.4} N·m): \
                     Coulomb + viscous",
                    hump, hump_ci
                ))
            }
        }
    }
}

#[allow(clippy::needless_range_loop)] // Gaussian elimination on a 5 × 5 system, indexed as written
fn solve5<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for c in 0..N {
        let p = (c..N).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..N {
            let f = a[r][c] / a[c][c];
            for k in c..N {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; N];
    for r in (0..N).rev() {
        let s: f64 = (r + 1..N).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Finds segments, pairs them and fits every joint of `log` (or [`FrictionOptions::joints`]).
///
/// # Errors
/// [`Error::BadLog`] naming a joint without effort, without constant-velocity segments, or
/// without ±v pairs; [`Error::Numerical`] when too few speeds remain.
pub fn identify_friction(log: &JointLog, opts: &FrictionOptions) -> Result<FrictionReport> {
    log.check_shape()?;
    if log.len() < 10 {
        return Err(log.bad(format!("{} samples: a sweep log needs constant-velocity segments", log.len())));
    }
    let joints: Vec<usize> = if opts.joints.is_empty() {
        (0..log.joint_names.len()).collect()
    } else {
        opts.joints
            .iter()
            .map(|n| {
                log.joint_index(n).ok_or_else(|| {
                    log.bad(format!("no joint \"{n}\" in the log (joints: {})", log.joint_names.join(", ")))
                })
            })
            .collect::<Result<_>>()?
    };
    // Joints are independent: fitted in parallel, reported in the log's order.
    use rayon::prelude::*;
    let fitted: Vec<Result<std::result::Result<JointFriction, String>>> = joints
        .into_par_iter()
        .map(|j| {
            let name = &log.joint_names[j];
            if log.effort[j].iter().all(|e| !e.is_finite()) {
                return Err(log.bad(format!("joint \"{name}\" has no effort: friction needs the joint torque")));
            }
            let (v, noise_sigma) = joint_velocity(log, j, opts.smooth_secs);
            let segments = find_segments(&log.t_nanos, &v, noise_sigma, opts);
            if segments.is_empty() {
                return Ok(Err(format!(
                    "joint \"{name}\": no constant-velocity segment (≥ {} s within ±{} %)",
                    opts.min_segment_secs,
                    100.0 * opts.rel_tol
                )));
            }
            let accel = joint_acceleration(&log.t_nanos, &v, opts.smooth_secs);
            let points = pair_segments(log, j, &accel, &segments, opts);
            if points.is_empty() {
                return Ok(Err(format!(
                    "joint \"{name}\": {} constant-velocity segment(s) but no +v/−v pair of the same speed over common positions",
                    segments.len()
                )));
            }
            let (model, model_note, fit, ci95, rms) = fit_richest(&points).map_err(|e| {
                log.bad(format!("joint \"{name}\": {e}; sweep more speeds (log-spaced across the Stribeck region)"))
            })?;
            let segment_spans = segments
                .iter()
                .map(|s| {
                    let [start_secs, end_secs] = segment_secs(log, s);
                    let paired = points.iter().any(|p| p.positive_secs[0] == start_secs || p.negative_secs[0] == start_secs);
                    SegmentSpan { start_secs, end_secs, velocity: s.velocity, paired }
                })
                .collect();
            Ok(Ok(JointFriction {
                joint: name.clone(),
                model,
                model_note,
                fit,
                ci95,
                rms_residual: rms,
                points,
                segments: segments.len(),
                segment_spans,
            }))
        })
        .collect();
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    for f in fitted {
        match f? {
            Ok(joint) => out.push(joint),
            Err(why) => skipped.push(why),
        }
    }
    if out.is_empty() {
        return Err(log.bad(format!(
            "no joint has a usable velocity sweep:\n  - {}\nmove each joint at constant velocities, forth and back over the same range, each for at least {} s",
            skipped.join("\n  - "),
            opts.min_segment_secs
        )));
    }
    if !opts.joints.is_empty() && !skipped.is_empty() {
        return Err(log.bad(format!("asked joints without a usable sweep:\n  - {}", skipped.join("\n  - "))));
    }
    Ok(FrictionReport { log: log.source.clone(), joints: out })
}

impl FrictionReport {
    /// Per joint, the model fitted and the constant-velocity segments used: each ±v pair with
    /// its times, then the segments left unpaired.
    pub fn segments_text(&self) -> String {
        let mut out = String::new();
        for j in &self.joints {
            let _ = writeln!(
                out,
                "{}: {} segment(s), {} paired speed(s) → {}{}",
                j.joint,
                j.segments,
                j.points.len(),
                j.model.label(),
                if j.model_note.is_empty() { String::new() } else { format!(" ({})", j.model_note) }
            );
            for p in &j.points {
                let _ = writeln!(
                    out,
                    "  ±{:.4} rad/s: +v {:.2}–{:.2} s, −v {:.2}–{:.2} s, {} samples, (τ⁺ − τ⁻)/2 = {:.4} ± {:.4} N·m",
                    p.speed,
                    p.positive_secs[0],
                    p.positive_secs[1],
                    p.negative_secs[0],
                    p.negative_secs[1],
                    p.samples,
                    p.friction,
                    1.96 * p.std_err
                );
            }
            let unpaired: Vec<String> = j
                .segment_spans
                .iter()
                .filter(|s| !s.paired)
                .map(|s| format!("{:+.4} rad/s at {:.2}–{:.2} s", s.velocity, s.start_secs, s.end_secs))
                .collect();
            if !unpaired.is_empty() {
                let _ = writeln!(out, "  unpaired: {}", unpaired.join("; "));
            }
        }
        out
    }

    /// The terminal table.
    pub fn table(&self) -> String {
        let g = crate::number::format_number;
        let mut out = String::from("Friction from constant-velocity sweeps (95 % intervals; — : not in the model):\n");
        let _ = writeln!(
            out,
            "  {:<20} {:>18} {:>18} {:>18} {:>18} {:>14} {:>18} {:>7} {:>10}",
            "joint", "model", "Fc (N·m)", "Fs (N·m)", "vs (rad/s)", "δ", "Fv (N·m·s/rad)", "speeds", "rms (N·m)"
        );
        for j in &self.joints {
            let f = &j.fit;
            let pm = |v: f64, c: f64| if c.is_nan() { "—".to_string() } else { format!("{} ±{}", g(v), g(c)) };
            let _ = writeln!(
                out,
                "  {:<20} {:>18} {:>18} {:>18} {:>18} {:>14} {:>18} {:>7} {:>10}",
                j.joint,
                j.model.label(),
                pm(f.coulomb, j.ci95[0]),
                pm(f.breakaway, j.ci95[1]),
                pm(f.stribeck_velocity, j.ci95[2]),
                pm(f.exponent, j.ci95[3]),
                pm(f.viscous, j.ci95[4]),
                j.points.len(),
                g(j.rms_residual)
            );
        }
        out
    }

    /// The report as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("the report serializes")
    }

    /// URDF `<dynamics>` updates: `friction` = Coulomb, `damping` = viscous.
    pub fn joint_updates(&self) -> Vec<crate::writeback::JointUpdate> {
        self.joints
            .iter()
            .map(|j| crate::writeback::JointUpdate {
                name: j.joint.clone(),
                damping: j.fit.viscous,
                friction: j.fit.coulomb,
            })
            .collect()
    }

    /// SVG: per joint, the paired points and the fitted curve (log speed axis).
    pub fn svg(&self) -> String {
        let panels: Vec<crate::plot::Plot> = self
            .joints
            .iter()
            .map(|j| {
                let mut p =
                    crate::plot::Plot::new(&format!("Friction of {}", j.joint), "speed (rad/s)", "friction (N·m)");
                p.log_x = true;
                let (lo, hi) = (j.points[0].speed, j.points[j.points.len() - 1].speed);
                let curve: Vec<(f64, f64)> = (0..=100)
                    .map(|k| {
                        let v = lo * 0.8 * (hi * 1.25 / (lo * 0.8)).powf(k as f64 / 100.0);
                        (v, j.fit.torque(v))
                    })
                    .collect();
                p.band(
                    j.points
                        .iter()
                        .map(|c| (c.speed, c.friction - 1.96 * c.std_err, c.friction + 1.96 * c.std_err))
                        .collect(),
                    crate::plot::COLORS[0],
                );
                p.points(
                    "(τ⁺ − τ⁻)/2",
                    j.points.iter().map(|c| (c.speed, c.friction)).collect(),
                    crate::plot::COLORS[0],
                );
                p.line(&format!("{} fit", j.model.label()), curve, crate::plot::COLORS[1]);
                p
            })
            .collect();
        crate::plot::stack_svg(&panels)
    }
}

/// Options of a synthetic sweep ([`synth_sweep`]).
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct SweepOptions {
    /// Speeds swept, rad/s (default: 14 log-spaced from 0.005 to 2).
    #[default((0..14).map(|k| 0.005 * (400f64).powf(k as f64 / 13.0)).collect())]
    pub speeds: Vec<f64>,
    /// Log rate, Hz (default: 500).
    #[default(500.0)]
    pub rate_hz: f64,
    /// Effort noise, N·m (default: 0.05).
    #[default(0.05)]
    pub effort_noise: f64,
    /// Velocity noise of the drive's reported velocity, rad/s (default: 0.0005).
    #[default(0.0005)]
    pub velocity_noise: f64,
    /// Encoder resolution in bits per turn (default: 17).
    #[default(17)]
    pub encoder_bits: u32,
    /// Seed (default: 1).
    #[default(1)]
    pub seed: u64,
    /// Longest time at one speed, s (default: 4): slow sweeps cover a shorter stroke.
    #[default(4.0)]
    pub max_segment_secs: f64,
    /// Largest stroke, rad (default: 1.0, within the joint's range).
    #[default(1.0)]
    pub max_stroke: f64,
}

/// A synthetic sweep log of the robot of `urdf`: each joint in turn moves forth and back at
/// every speed (cosine ramps of 0.2 s in and out, the other joints held at mid-range, so
/// gravity loads it), and its effort is MuJoCo's inverse dynamics (gravity, inertia) plus
/// `truth[j]`'s Stribeck friction plus Gaussian noise; positions quantized.
///
/// # Errors
/// Loading errors of the URDF; [`Error::Core`] if MuJoCo fails.
pub fn synth_sweep(urdf: &std::path::Path, truth: &[Stribeck], opts: &SweepOptions) -> Result<JointLog> {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;
    use std::f64::consts::PI;
    let source = crate::model::UrdfSource::read(urdf)?;
    let model = std::sync::Arc::new(source.model("", false)?);
    let robot = crate::model::RobotModel::of_urdf(&source, model.clone(), false)?;
    let nj = robot.joints.len();
    let mut data = twin_core::mj::Data::new(model.clone())?;
    let ranges: Vec<(f64, f64)> = robot
        .joints
        .iter()
        .map(|j| {
            let jid = model.dof_jntid()[j.dof] as usize;
            if model.jnt_limited()[jid] {
                let r = model.jnt_range()[jid];
                (r[0], r[1])
            } else {
                (-PI, PI)
            }
        })
        .collect();
    let home: Vec<f64> = ranges.iter().map(|(lo, hi)| 0.5 * (lo + hi)).collect();
    let dt = 1.0 / opts.rate_hz;
    let ramp = 0.2;
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let resolution = 2.0 * PI / (1u64 << opts.encoder_bits) as f64;
    let mut log = JointLog::new(
        robot.joints.iter().map(|j| j.name.clone()).collect(),
        format!("synthetic sweep of {}", urdf.display()),
    );
    let mut t = 0.0;
    let mut q = home.clone();
    let nv = model.nv();
    let mut emit = |data: &mut twin_core::mj::Data,
                    q: &[f64],
                    qd: &[f64],
                    qdd: &[f64],
                    t: f64,
                    log: &mut JointLog|
     -> Result<()> {
        for (j, joint) in robot.joints.iter().enumerate() {
            data.qpos_mut()[joint.qpos_adr] = q[j];
            data.qvel_mut()[joint.dof] = qd[j];
        }
        let mut acc = vec![0.0; nv];
        for (j, joint) in robot.joints.iter().enumerate() {
            acc[joint.dof] = qdd[j];
        }
        data.qacc_mut().copy_from_slice(&acc);
        data.kinematics_with_velocity()?;
        let tau = data.rne(true)?;
        let mut p = vec![0.0; nj];
        let mut v = vec![0.0; nj];
        let mut e = vec![0.0; nj];
        for (j, joint) in robot.joints.iter().enumerate() {
            p[j] = (q[j] / resolution).round() * resolution;
            e[j] = tau[joint.dof] + truth[j].torque(qd[j]) + opts.effort_noise * rng.sample::<f64, _>(StandardNormal);
            v[j] = qd[j] + opts.velocity_noise * rng.sample::<f64, _>(StandardNormal);
        }
        log.push((t * 1e9).round() as i64, &p, &v, &e);
        Ok(())
    };
    for j in 0..nj {
        let (lo, hi) = ranges[j];
        let mut targets: Vec<(f64, f64)> = Vec::new();
        for &speed in &opts.speeds {
            let stroke = (speed * opts.max_segment_secs).min(opts.max_stroke).min(0.8 * (hi - lo));
            targets.push((home[j] + 0.5 * stroke, speed));
            targets.push((home[j] - 0.5 * stroke, speed));
        }
        targets.push((home[j], 0.5));
        for (target, speed) in targets {
            // Ramp up, cruise, ramp down: v(s) = speed·(1 − cos(π s/ramp))/2 in the ramps.
            let start = q[j];
            let dist = (target - start).abs();
            let speed = speed.min(dist / ramp).max(1e-9);
            let cruise = ((dist - speed * ramp) / speed).max(0.0);
            let total = 2.0 * ramp + cruise;
            let sign = if target >= start { 1.0 } else { -1.0 };
            let steps = (total / dt).ceil() as usize;
            let mut qj = q.clone();
            let mut qd = vec![0.0; nj];
            let mut qdd = vec![0.0; nj];
            for k in 0..=steps {
                let s = (k as f64 * dt).min(total);
                let (vel, acc, travelled) = if s < ramp {
                    let w = PI * s / ramp;
                    (
                        0.5 * speed * (1.0 - w.cos()),
                        0.5 * speed * PI / ramp * w.sin(),
                        0.5 * speed * (s - ramp / PI * w.sin()),
                    )
                } else if s < ramp + cruise {
                    (speed, 0.0, 0.5 * speed * ramp + speed * (s - ramp))
                } else {
                    let r = s - ramp - cruise;
                    let w = PI * r / ramp;
                    (
                        0.5 * speed * (1.0 + w.cos()),
                        -0.5 * speed * PI / ramp * w.sin(),
                        0.5 * speed * ramp + speed * cruise + 0.5 * speed * (r + ramp / PI * w.sin()),
                    )
                };
                qj[j] = start + sign * travelled;
                qd[j] = sign * vel;
                qdd[j] = sign * acc;
                emit(&mut data, &qj, &qd, &qdd, t, &mut log)?;
                t += dt;
            }
            q[j] = qj[j];
            // Rest 0.3 s.
            for _ in 0..(0.3 / dt) as usize {
                emit(&mut data, &q, &vec![0.0; nj], &vec![0.0; nj], t, &mut log)?;
                t += dt;
            }
        }
    }
    Ok(log)
}

/// The fitted curves of a [`FrictionReport::to_json`] file (`twin sysid friction --report`):
/// `(joint, curve)` per joint, e.g. for `twin sim --friction-fit`.
///
/// # Errors
/// [`Error::Core`]; [`Error::Option`] naming the file when it is not such a report.
pub fn read_fits(path: &std::path::Path) -> Result<Vec<(String, Stribeck)>> {
    #[derive(serde::Deserialize)]
    struct Entry {
        joint: String,
        fit: Stribeck,
    }
    #[derive(serde::Deserialize)]
    struct Fits {
        joints: Vec<Entry>,
    }
    let text = twin_core::fsio::read_to_string(path)?;
    let fits: Fits = serde_json::from_str(&text).map_err(|e| Error::Option {
        name: "friction fit",
        message: format!("{}: not a `twin sysid friction --report` JSON ({e})", path.display()),
    })?;
    if fits.joints.is_empty() {
        return Err(Error::Option { name: "friction fit", message: format!("{}: no joint fits", path.display()) });
    }
    Ok(fits.joints.into_iter().map(|e| (e.joint, e.fit)).collect())
}
