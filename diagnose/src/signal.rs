//! Time series as the analysis reads them: sorted sample times (seconds from the log's time
//! origin) and values, with interpolation and the few statistics the findings use.

/// One scalar signal.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Signal {
    /// Name (`/imu gyro_x`, `left_knee position`…).
    pub name: String,
    /// Sample times, s, non-decreasing.
    pub t_secs: Vec<f64>,
    /// Values.
    pub v: Vec<f64>,
}

impl Signal {
    /// A signal from unsorted samples (sorted by time, stable).
    pub fn new(name: impl Into<String>, mut samples: Vec<(f64, f64)>) -> Signal {
        samples.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (t_secs, v) = samples.into_iter().filter(|s| s.0.is_finite()).unzip();
        Signal { name: name.into(), t_secs, v }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_secs.len()
    }

    /// Whether it has no samples.
    pub fn is_empty(&self) -> bool {
        self.t_secs.is_empty()
    }

    /// Index of the first sample at or after `t`.
    pub fn index_at(&self, t: f64) -> usize {
        self.t_secs.partition_point(|&x| x < t)
    }

    /// Linear interpolation at `t` (held at the ends; NaN when empty).
    pub fn at(&self, t: f64) -> f64 {
        let n = self.len();
        if n == 0 {
            return f64::NAN;
        }
        let i = self.index_at(t);
        if i == 0 {
            return self.v[0];
        }
        if i >= n {
            return self.v[n - 1];
        }
        let (t0, t1) = (self.t_secs[i - 1], self.t_secs[i]);
        if t1 - t0 <= 0.0 {
            return self.v[i];
        }
        let s = (t - t0) / (t1 - t0);
        self.v[i - 1] + s * (self.v[i] - self.v[i - 1])
    }

    /// The value of the last sample at or before `t` (zero-order hold; NaN before the first).
    pub fn held(&self, t: f64) -> f64 {
        let i = self.t_secs.partition_point(|&x| x <= t);
        if i == 0 { f64::NAN } else { self.v[i - 1] }
    }

    /// Samples with `t0 <= t <= t1`, as plot points.
    pub fn points(&self, t0: f64, t1: f64) -> Vec<(f64, f64)> {
        let (a, b) = (self.index_at(t0), self.t_secs.partition_point(|&x| x <= t1));
        (a..b).map(|i| (self.t_secs[i], self.v[i])).collect()
    }

    /// Values with `t0 <= t < t1`.
    pub fn values(&self, t0: f64, t1: f64) -> &[f64] {
        let (a, b) = (self.index_at(t0), self.index_at(t1));
        &self.v[a..b.max(a)]
    }

    /// Median sample interval, s (NaN with fewer than two samples).
    pub fn median_dt(&self) -> f64 {
        let mut d: Vec<f64> = self.t_secs.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0.0).collect();
        median(&mut d)
    }
}

/// Median (NaN when empty); reorders `v`.
pub fn median(v: &mut [f64]) -> f64 {
    quantile(v, 0.5)
}

/// The `q` quantile (0–1, nearest rank); NaN when empty. Reorders `v`.
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    let mut finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return f64::NAN;
    }
    finite.sort_by(f64::total_cmp);
    let k = ((q * (finite.len() - 1) as f64).round() as usize).min(finite.len() - 1);
    finite[k]
}

/// Mean and standard deviation of the finite values (NaN, NaN when none).
pub fn mean_std(v: &[f64]) -> (f64, f64) {
    let finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = finite.len() as f64;
    let mean = finite.iter().sum::<f64>() / n;
    let var = finite.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

/// Root mean square of the finite values (NaN when none).
pub fn rms(v: &[f64]) -> f64 {
    let finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() {
        return f64::NAN;
    }
    (finite.iter().map(|x| x * x).sum::<f64>() / finite.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_holds_and_summarises() {
        let s = Signal::new("x", vec![(1.0, 10.0), (0.0, 0.0), (2.0, 0.0)]);
        assert_eq!(s.t_secs, [0.0, 1.0, 2.0]);
        assert!((s.at(0.25) - 2.5).abs() < 1e-12);
        assert_eq!(s.at(-1.0), 0.0);
        assert_eq!(s.at(5.0), 0.0);
        assert_eq!(s.held(1.5), 10.0);
        assert!(s.held(-0.1).is_nan());
        assert_eq!(s.points(0.5, 2.0), vec![(1.0, 10.0), (2.0, 0.0)]);
        assert!((s.median_dt() - 1.0).abs() < 1e-12);
        assert!((rms(&[3.0, 4.0]) - 12.5f64.sqrt()).abs() < 1e-12);
        let (m, sd) = mean_std(&[1.0, 3.0]);
        assert_eq!((m, sd), (2.0, 1.0));
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
    }
}
