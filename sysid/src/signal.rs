//! Signal conditioning: uniform resampling, zero-phase Butterworth low-pass (forward-backward),
//! central differences, edge trimming, and splitting at gaps.

/// One second-order section `b0 + b1 z⁻¹ + b2 z⁻² / (1 + a1 z⁻¹ + a2 z⁻²)`, unity DC gain.
#[derive(Debug, Clone, Copy)]
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

/// Digital Butterworth low-pass as cascaded sections (bilinear transform with pre-warping).
#[derive(Debug, Clone)]
pub struct Butterworth {
    sections: Vec<Biquad>,
}

impl Butterworth {
    /// Low-pass of `order` (≥ 1) with cut-off `cutoff_hz` for data sampled at `rate_hz`
    /// (`cutoff_hz < rate_hz / 2`).
    pub fn low_pass(order: usize, cutoff_hz: f64, rate_hz: f64) -> Butterworth {
        let fs2 = 2.0 * rate_hz;
        // Pre-warped analog cut-off so the digital filter has its −3 dB point at cutoff_hz.
        let wc = fs2 * (std::f64::consts::PI * cutoff_hz / rate_hz).tan();
        let n = order.max(1);
        let mut sections = Vec::new();
        for k in 0..n / 2 {
            // Analog pole in the upper half of the left half-plane.
            let theta = std::f64::consts::PI * (2 * k + n + 1) as f64 / (2 * n) as f64;
            let (pr, pi) = (wc * theta.cos(), wc * theta.sin());
            // z = (fs2 + p) / (fs2 − p)
            let (nr, ni) = (fs2 + pr, pi);
            let (dr, di) = (fs2 - pr, -pi);
            let den = dr * dr + di * di;
            let zr = (nr * dr + ni * di) / den;
            let zi = (ni * dr - nr * di) / den;
            let a1 = -2.0 * zr;
            let a2 = zr * zr + zi * zi;
            let g = (1.0 + a1 + a2) / 4.0;
            sections.push(Biquad { b: [g, 2.0 * g, g], a: [a1, a2] });
        }
        if n % 2 == 1 {
            let z = (fs2 - wc) / (fs2 + wc);
            let g = (1.0 - z) / 2.0;
            sections.push(Biquad { b: [g, g, 0.0], a: [-z, 0.0] });
        }
        Butterworth { sections }
    }

    /// Filters `x` in place, forward, each section starting in the steady state of `x[0]`.
    fn forward(&self, x: &mut [f64]) {
        if x.is_empty() {
            return;
        }
        for s in &self.sections {
            let u = x[0];
            // Direct form II transposed, state for a constant input u (unity DC gain: y = u).
            let mut s2 = (s.b[2] - s.a[1]) * u;
            let mut s1 = (1.0 - s.b[0]) * u;
            for v in x.iter_mut() {
                let xin = *v;
                let y = s.b[0] * xin + s1;
                s1 = s.b[1] * xin - s.a[0] * y + s2;
                s2 = s.b[2] * xin - s.a[1] * y;
                *v = y;
            }
        }
    }

    /// Zero-phase filtering (forward then backward), with odd-reflection padding of `pad`
    /// samples at each end so that the edges start near steady state.
    pub fn filtfilt(&self, x: &[f64], pad: usize) -> Vec<f64> {
        let n = x.len();
        if n < 2 {
            return x.to_vec();
        }
        let pad = pad.min(n - 1);
        let mut ext = Vec::with_capacity(n + 2 * pad);
        for i in (1..=pad).rev() {
            ext.push(2.0 * x[0] - x[i]);
        }
        ext.extend_from_slice(x);
        for i in 1..=pad {
            ext.push(2.0 * x[n - 1] - x[n - 1 - i]);
        }
        self.forward(&mut ext);
        ext.reverse();
        self.forward(&mut ext);
        ext.reverse();
        ext[pad..pad + n].to_vec()
    }
}

/// Central differences (one-sided at the ends) of samples spaced `dt_secs`.
pub fn derivative(x: &[f64], dt_secs: f64) -> Vec<f64> {
    let n = x.len();
    let mut d = vec![0.0; n];
    if n < 2 {
        return d;
    }
    d[0] = (x[1] - x[0]) / dt_secs;
    d[n - 1] = (x[n - 1] - x[n - 2]) / dt_secs;
    for i in 1..n - 1 {
        d[i] = (x[i + 1] - x[i - 1]) / (2.0 * dt_secs);
    }
    d
}

/// Linear interpolation of samples `(t, x)` (t increasing) at times `grid`.
pub fn resample(t: &[f64], x: &[f64], grid: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(grid.len());
    let mut i = 0;
    for &g in grid {
        while i + 2 < t.len() && t[i + 1] < g {
            i += 1;
        }
        if t.len() == 1 {
            out.push(x[0]);
            continue;
        }
        let (t0, t1) = (t[i], t[i + 1]);
        let w = if t1 > t0 { ((g - t0) / (t1 - t0)).clamp(0.0, 1.0) } else { 0.0 };
        out.push(x[i] + w * (x[i + 1] - x[i]));
    }
    out
}

/// Median of positive differences of `t`.
pub fn median_step(t: &[f64]) -> Option<f64> {
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).filter(|&d| d > 0.0).collect();
    if d.is_empty() {
        return None;
    }
    d.sort_by(f64::total_cmp);
    Some(d[d.len() / 2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn butterworth_gain_at_dc_cutoff_and_stopband() {
        let (fs, fc) = (1000.0, 20.0);
        for order in [2, 3, 4] {
            let f = Butterworth::low_pass(order, fc, fs);
            let gain = |hz: f64| {
                let n = 20000;
                let x: Vec<f64> = (0..n).map(|i| (2.0 * std::f64::consts::PI * hz * i as f64 / fs).sin()).collect();
                let mut y = x.clone();
                f.forward(&mut y);
                let rms = |v: &[f64]| (v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64).sqrt();
                rms(&y[n / 2..]) / rms(&x[n / 2..])
            };
            assert!((gain(0.5) - 1.0).abs() < 1e-3, "order {order}");
            assert!((gain(fc) - std::f64::consts::FRAC_1_SQRT_2).abs() < 5e-3, "order {order}");
            // Butterworth: |H(10 fc)| ≈ 10^-order.
            assert!(gain(10.0 * fc) < 1.5 * 10f64.powi(-(order as i32)), "order {order}");
        }
    }

    #[test]
    fn filtfilt_has_no_phase_lag_and_keeps_ramps() {
        let fs = 500.0;
        let f = Butterworth::low_pass(4, 10.0, fs);
        let x: Vec<f64> =
            (0..2000).map(|i| (2.0 * std::f64::consts::PI * 1.0 * i as f64 / fs).sin() + 0.3 * i as f64 / fs).collect();
        let y = f.filtfilt(&x, 150);
        for i in 100..1900 {
            assert!((y[i] - x[i]).abs() < 1e-3, "sample {i}: {} vs {}", y[i], x[i]);
        }
    }

    #[test]
    fn derivative_and_resample_are_exact_on_polynomials() {
        let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.01).collect();
        let x: Vec<f64> = t.iter().map(|t| 3.0 * t * t - t).collect();
        let d = derivative(&x, 0.01);
        for i in 1..49 {
            assert!((d[i] - (6.0 * t[i] - 1.0)).abs() < 1e-9);
        }
        let grid = [0.005, 0.2, 0.4851];
        let lin: Vec<f64> = t.iter().map(|t| 2.0 * t + 1.0).collect();
        let r = resample(&t, &lin, &grid);
        for (g, v) in grid.iter().zip(r) {
            assert!((v - (2.0 * g + 1.0)).abs() < 1e-12);
        }
    }
}
