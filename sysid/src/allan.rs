//! Overlapping Allan deviation of a rate signal, its confidence band, and the noise-model fit.
//!
//! For samples `y_k` at rate `f_s` (`τ₀ = 1/f_s`) and cluster size `m` (`τ = m·τ₀`), with the
//! running sum `S_k = Σ_{i<k} y_i`:
//! `σ²(τ) = Σ_k (S_{k+2m} − 2·S_{k+m} + S_k)² / (2·m²·(n − 2m + 1))`, every start `k` used
//! (overlapping estimator, IEEE Std 952 / Riley's handbook). The mean is removed first so the
//! running sum stays small (its rounding would otherwise dominate the short-τ variance of a
//! 9.81 m/s² accelerometer).
//!
//! The noise model (IEEE Std 952, in Allan variance):
//! `σ²(τ) = 3·Q²/τ² + N²/τ + (2·ln 2/π)·B² + K²·τ/3`: quantization `Q`, white noise (angle or
//! velocity random walk) density `N` (σ at τ = 1 s of the −½ slope), bias instability `B`
//! (flat floor = 0.664·B) and bias (rate) random walk `K` (σ at τ = 3 s of the +½ slope). All
//! four coefficients are fitted at once by non-negative weighted least squares on σ²(τ): each
//! point weighted by its equivalent degrees of freedom, so the many, precise short-τ points
//! and the few, noisy long-τ points count for what they are worth.
//!
//! Confidence band: χ² interval with the equivalent degrees of freedom of the overlapping
//! estimator for the noise type that dominates the fitted model at that τ (Howe, Allan & Barnes
//! 1981, the simple formulas of NIST SP 1065 table 12), 95 % by default.

use serde::Serialize;

/// `√(2·ln 2/π)`: the Allan deviation floor of bias instability `B` is `0.664·B`.
pub const BIAS_INSTABILITY_FLOOR: f64 = 0.664_282_948_4;

/// One point of an Allan deviation curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AllanPoint {
    /// Averaging time τ, s.
    pub tau_secs: f64,
    /// Cluster size, samples.
    pub m: usize,
    /// Overlapping Allan deviation (units of the signal).
    pub adev: f64,
    /// Lower end of the confidence band.
    pub adev_low: f64,
    /// Upper end of the confidence band.
    pub adev_high: f64,
    /// Equivalent degrees of freedom used for the band.
    pub edf: f64,
}

/// Cluster sizes log-spaced `per_decade` to the decade, from 1 to `max_m`, deduplicated.
pub fn cluster_sizes(max_m: usize, per_decade: usize) -> Vec<usize> {
    let mut out: Vec<usize> = Vec::new();
    let per_decade = per_decade.max(1) as f64;
    let mut i = 0.0_f64;
    loop {
        let m = 10f64.powf(i / per_decade).round() as usize;
        if m > max_m {
            break;
        }
        if out.last() != Some(&m) {
            out.push(m);
        }
        i += 1.0;
    }
    out
}

/// Overlapping Allan deviation of `samples` (a rate: rad/s, m/s²) sampled at `rate_hz`, at
/// cluster sizes `ms` (each `< n/2`; larger ones are skipped). The band is filled by
/// [`fit_noise`]; here it is the white-noise one.
pub fn overlapping_adev(samples: &[f64], rate_hz: f64, ms: &[usize]) -> Vec<AllanPoint> {
    let n = samples.len();
    if n < 3 {
        return Vec::new();
    }
    let mean = samples.iter().sum::<f64>() / n as f64;
    let mut sum = Vec::with_capacity(n + 1);
    let mut s = 0.0;
    sum.push(0.0);
    for &y in samples {
        s += y - mean;
        sum.push(s);
    }
    let mut out = Vec::with_capacity(ms.len());
    for &m in ms {
        if m == 0 || 2 * m >= n {
            continue;
        }
        let count = n - 2 * m + 1;
        let mut acc = 0.0;
        for k in 0..count {
            let d = sum[k + 2 * m] - 2.0 * sum[k + m] + sum[k];
            acc += d * d;
        }
        let avar = acc / (2.0 * (m * m) as f64 * count as f64);
        let adev = avar.sqrt();
        let edf = edf_overlapping(NoiseType::White, n + 1, m);
        let (lo, hi) = chi2_band(adev, edf, 0.95);
        out.push(AllanPoint { tau_secs: m as f64 / rate_hz, m, adev, adev_low: lo, adev_high: hi, edf });
    }
    out
}

/// Power-law noise types the confidence band distinguishes (in the rate signal).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseType {
    /// White rate noise (slope −½).
    White,
    /// Flicker rate noise (bias instability, flat).
    Flicker,
    /// Random walk of the rate (slope +½).
    RandomWalk,
}

/// Equivalent degrees of freedom of the overlapping Allan variance, `big_n` phase points
/// (samples + 1), cluster size `m` (NIST SP 1065, table 12, simple approximations).
pub fn edf_overlapping(kind: NoiseType, big_n: usize, m: usize) -> f64 {
    let (n, m) = (big_n as f64, m as f64);
    let edf = match kind {
        NoiseType::White => (3.0 * (n - 1.0) / (2.0 * m) - 2.0 * (n - 2.0) / n) * 4.0 * m * m / (4.0 * m * m + 5.0),
        NoiseType::Flicker if m <= 1.0 => 2.0 * (n - 2.0).powi(2) / (2.3 * n - 4.9),
        NoiseType::Flicker => 5.0 * n * n / (4.0 * m * (n + 3.0 * m)),
        NoiseType::RandomWalk => {
            (n - 2.0) / m * ((n - 1.0).powi(2) - 3.0 * m * (n - 1.0) + 4.0 * m * m) / (n - 3.0).powi(2)
        }
    };
    edf.max(1.0)
}

/// Standard normal quantile (Acklam's rational approximation, |error| < 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] =
        [7.784_695_709_041_462e-3, 3.224_671_290_700_398e-1, 2.445_134_137_142_996, 3.754_408_661_907_416];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// χ² quantile with `nu` degrees of freedom (Wilson–Hilferty; within 1 % for ν ≥ 2).
pub fn chi2_quantile(p: f64, nu: f64) -> f64 {
    let z = normal_quantile(p);
    let a = 2.0 / (9.0 * nu);
    (nu * (1.0 - a + z * a.sqrt()).powi(3)).max(1e-12)
}

/// Confidence interval `(low, high)` of a deviation `adev` estimated with `edf` degrees of
/// freedom, at `level` (e.g. 0.95).
pub fn chi2_band(adev: f64, edf: f64, level: f64) -> (f64, f64) {
    let alpha = 1.0 - level;
    let lo = adev * (edf / chi2_quantile(1.0 - alpha / 2.0, edf)).sqrt();
    let hi = adev * (edf / chi2_quantile(alpha / 2.0, edf)).sqrt();
    (lo, hi)
}

/// Noise coefficients of one axis from its Allan deviation (units of a gyro; an accelerometer's
/// are the same with m/s for rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NoiseFit {
    /// Quantization noise `Q` (rad for a gyro: the −1 slope, `σ = √3·Q/τ`); 0 when not seen.
    pub quantization: f64,
    /// White-noise density `N`, rad/s/√Hz (m/s²/√Hz): σ at τ = 1 s of the −½ line.
    pub white_density: f64,
    /// Bias instability `B`, rad/s (m/s²): the flat floor / 0.664; 0 when not resolved.
    pub bias_instability: f64,
    /// Bias random walk `K`, rad/s²/√Hz (m/s³/√Hz): σ at τ = 3 s of the +½ line; 0 when not
    /// resolved.
    pub bias_random_walk: f64,
    /// Relative standard error of `N`, `B`, `K` from the fit's weights (0 when not resolved).
    pub rel_std: [f64; 3],
    /// RMS of `ln(σ_data/σ_model)` over the points: how well the model describes the curve.
    pub log_rms_residual: f64,
}

impl NoiseFit {
    /// Model Allan deviation at `tau_secs`.
    pub fn adev_at(&self, tau_secs: f64) -> f64 {
        self.avar_terms(tau_secs).iter().sum::<f64>().sqrt()
    }

    /// The four terms of the model Allan variance at τ: quantization, white, flicker, walk.
    pub fn avar_terms(&self, tau: f64) -> [f64; 4] {
        [
            3.0 * self.quantization.powi(2) / (tau * tau),
            self.white_density.powi(2) / tau,
            (BIAS_INSTABILITY_FLOOR * self.bias_instability).powi(2),
            self.bias_random_walk.powi(2) * tau / 3.0,
        ]
    }

    /// The noise type that dominates the model at τ (for the confidence band).
    fn dominant(&self, tau: f64) -> NoiseType {
        let t = self.avar_terms(tau);
        if t[3] >= t[2] && t[3] >= t[1] + t[0] {
            NoiseType::RandomWalk
        } else if t[2] >= t[1] + t[0] {
            NoiseType::Flicker
        } else {
            NoiseType::White
        }
    }
}

/// Fits the noise model to `points` (from [`overlapping_adev`] of `n_samples` samples) and
/// recomputes their confidence bands for the dominant noise type at each τ.
///
/// Non-negative weighted least squares on σ²: every subset of the four terms is solved
/// (4 unknowns: 15 subsets) and the best one with all coefficients ≥ 0 kept; weights are the
/// points' degrees of freedom over the model's σ⁴ (iterated twice), i.e. relative errors.
#[allow(clippy::needless_range_loop)] // small dense normal equations, indexed as written
pub fn fit_noise(points: &mut [AllanPoint], n_samples: usize, level: f64) -> NoiseFit {
    let mut fit = NoiseFit {
        quantization: 0.0,
        white_density: 0.0,
        bias_instability: 0.0,
        bias_random_walk: 0.0,
        rel_std: [0.0; 3],
        log_rms_residual: 0.0,
    };
    if points.is_empty() {
        return fit;
    }
    let basis = |tau: f64| [3.0 / (tau * tau), 1.0 / tau, BIAS_INSTABILITY_FLOOR.powi(2), tau / 3.0];
    // First pass: weights from the data (relative errors), white-noise dof.
    let mut weights: Vec<f64> = points.iter().map(|p| p.edf / p.adev.powi(4).max(1e-300)).collect();
    let mut coef = [0.0; 4];
    let mut cov_diag = [0.0; 4];
    for pass in 0..3 {
        let mut best: Option<(f64, [f64; 4], [f64; 4])> = None;
        for mask in 1u32..16 {
            let idx: Vec<usize> = (0..4).filter(|i| mask & (1 << i) != 0).collect();
            let k = idx.len();
            // Normal equations, columns scaled to unit norm for conditioning.
            let mut a = vec![vec![0.0; k]; k];
            let mut b = vec![0.0; k];
            let mut scale = vec![0.0; k];
            for (p, &w) in points.iter().zip(&weights) {
                let phi = basis(p.tau_secs);
                for (r, &i) in idx.iter().enumerate() {
                    scale[r] += w * phi[i] * phi[i];
                }
            }
            for s in &mut scale {
                *s = s.sqrt().max(1e-300);
            }
            for (p, &w) in points.iter().zip(&weights) {
                let phi = basis(p.tau_secs);
                let y = p.adev * p.adev;
                for (r, &i) in idx.iter().enumerate() {
                    b[r] += w * phi[i] / scale[r] * y;
                    for (c, &j) in idx.iter().enumerate() {
                        a[r][c] += w * phi[i] / scale[r] * phi[j] / scale[c];
                    }
                }
            }
            let Some((x, inv_diag)) = solve_spd(&a, &b) else { continue };
            if x.iter().any(|&v| v < 0.0) {
                continue;
            }
            let mut c = [0.0; 4];
            let mut cd = [0.0; 4];
            for (r, &i) in idx.iter().enumerate() {
                c[i] = x[r] / scale[r];
                cd[i] = inv_diag[r] / (scale[r] * scale[r]);
            }
            let cost: f64 = points
                .iter()
                .zip(&weights)
                .map(|(p, &w)| {
                    let phi = basis(p.tau_secs);
                    let model: f64 = (0..4).map(|i| c[i] * phi[i]).sum();
                    w * (model - p.adev * p.adev).powi(2)
                })
                .sum();
            if best.as_ref().is_none_or(|(bc, _, _)| cost < *bc) {
                best = Some((cost, c, cd));
            }
        }
        let Some((_, c, cd)) = best else { break };
        coef = c;
        cov_diag = cd;
        fit.quantization = (coef[0]).sqrt();
        fit.white_density = coef[1].sqrt();
        fit.bias_instability = coef[2].sqrt();
        fit.bias_random_walk = coef[3].sqrt();
        if pass < 2 {
            for (p, w) in points.iter_mut().zip(weights.iter_mut()) {
                p.edf = edf_overlapping(fit.dominant(p.tau_secs), n_samples + 1, p.m);
                let model = fit.adev_at(p.tau_secs).max(1e-300);
                *w = p.edf / model.powi(4);
            }
        }
    }
    // Covariance of the coefficients: the weights are 2/(variance of σ²) up to the factor 2
    // (var(σ̂²)/σ⁴ = 2/edf): scale by 2.
    for (i, slot) in [1usize, 2, 3].iter().enumerate() {
        fit.rel_std[i] = if coef[*slot] > 0.0 { 0.5 * (2.0 * cov_diag[*slot]).sqrt() / coef[*slot] } else { 0.0 };
    }
    let mut ss = 0.0;
    for p in points.iter_mut() {
        let (lo, hi) = chi2_band(p.adev, p.edf, level);
        p.adev_low = lo;
        p.adev_high = hi;
        ss += (p.adev / fit.adev_at(p.tau_secs).max(1e-300)).ln().powi(2);
    }
    fit.log_rms_residual = (ss / points.len() as f64).sqrt();
    fit
}

/// Solves a small symmetric positive definite system by Cholesky; also returns the diagonal
/// of the inverse. `None` when not positive definite.
#[allow(clippy::needless_range_loop)] // textbook index form of a 4 × 4 factorisation
fn solve_spd(a: &[Vec<f64>], b: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
    let n = b.len();
    let mut l = vec![vec![0.0; n]; n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if s <= 1e-13 * a[i][i].abs().max(1e-300) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let solve = |rhs: &[f64]| {
        let mut y = rhs.to_vec();
        for i in 0..n {
            for k in 0..i {
                y[i] -= l[i][k] * y[k];
            }
            y[i] /= l[i][i];
        }
        for i in (0..n).rev() {
            for k in i + 1..n {
                y[i] -= l[k][i] * y[k];
            }
            y[i] /= l[i][i];
        }
        y
    };
    let x = solve(b);
    let mut diag = vec![0.0; n];
    for (i, d) in diag.iter_mut().enumerate() {
        let mut e = vec![0.0; n];
        e[i] = 1.0;
        *d = solve(&e)[i];
    }
    Some((x, diag))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    #[test]
    fn white_noise_adev_is_sigma_over_sqrt_m_and_quantiles_are_right() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<f64> = (0..200_000).map(|_| 0.5 * rng.sample::<f64, _>(StandardNormal)).collect();
        let pts = overlapping_adev(&x, 100.0, &[1, 10, 100]);
        for p in &pts {
            let expect = 0.5 / (p.m as f64).sqrt();
            assert!((p.adev / expect - 1.0).abs() < 0.03, "{p:?}");
            assert!(p.adev_low < expect && expect < p.adev_high, "{p:?}");
        }
        assert!((normal_quantile(0.975) - 1.959_964).abs() < 1e-5);
        // χ²_0.95(10) = 18.307.
        assert!((chi2_quantile(0.95, 10.0) / 18.307 - 1.0).abs() < 0.01);
    }

    #[test]
    fn cluster_sizes_are_log_spaced_and_unique() {
        let ms = cluster_sizes(1000, 10);
        assert_eq!(ms[..5], [1, 2, 3, 4, 5]);
        assert_eq!(*ms.last().unwrap(), 1000);
        assert!(ms.windows(2).all(|w| w[1] > w[0]));
    }
}
