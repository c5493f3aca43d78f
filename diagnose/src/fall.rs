//! The fall: when the base crossed the engine's fall thresholds ([`FallOptions`]: tilt from
//! upright, height against the initial one), where it started (the last time the tilt was in
//! its standing band, walked back while the tilt kept growing) and which way it went (the
//! base's z axis leaning, in the heading frame at the onset).

use super::Data;
use super::signal::{Signal, quantile};
use serde::Serialize;
use twin_core::engine::observers::FallOptions;

/// Which way the robot fell, in its heading frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Toward its +x (heading).
    Forward,
    /// Toward its −x.
    Backward,
    /// Toward its +y.
    Left,
    /// Toward its −y.
    Right,
}

impl Direction {
    /// `forward`, `backward`, `left` or `right`.
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::Forward => "forward",
            Direction::Backward => "backward",
            Direction::Left => "left",
            Direction::Right => "right",
        }
    }
}

/// A fall.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Fall {
    /// When a fall threshold was crossed, s.
    pub fall_time_secs: f64,
    /// Which threshold (`tilt 1.02 rad > 1.00 rad`, `base height 0.41 m < 0.6 × 0.69 m`).
    pub criterion: String,
    /// Where it started, s.
    pub onset_secs: f64,
    /// When the tilt last left its standing band before the fall, s.
    pub band_exit_secs: f64,
    /// The standing tilt (median over the first second or the first 30 % before the fall), rad.
    pub baseline_tilt_rad: f64,
    /// Half-width of the standing band around it, rad.
    pub band_rad: f64,
    /// Tilt at the onset, rad.
    pub tilt_at_onset_rad: f64,
    /// Direction of the fall.
    pub direction: Direction,
    /// Share of the lean along the heading at the fall (−1…1).
    pub lean_forward: f64,
    /// Share of the lean to the left at the fall (−1…1).
    pub lean_left: f64,
    /// Heading (yaw of the base's x axis) at the onset, rad.
    pub heading_rad: f64,
    /// The topic the pose came from.
    pub source: String,
}

/// Body z axis (world) and heading of quaternion `q` (x, y, z, w).
fn axes(q: [f64; 4]) -> ([f64; 3], f64) {
    let n = (q.iter().map(|v| v * v).sum::<f64>()).sqrt();
    let [x, y, z, w] = if n > 0.0 { q.map(|v| v / n) } else { [0.0, 0.0, 0.0, 1.0] };
    let zaxis = [2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)];
    let heading = (2.0 * (x * y + w * z)).atan2(1.0 - 2.0 * (y * y + z * z));
    (zaxis, heading)
}

/// Finds the fall in `poses` (time s, orientation x y z w, position when known); fills the
/// tilt and height signals of `data`.
pub(crate) fn find(
    poses: &[super::Pose],
    options: &FallOptions,
    data: &mut Data,
    notes: &mut Vec<String>,
) -> Option<Fall> {
    if poses.is_empty() {
        return None;
    }
    let mut samples: Vec<(f64, f64, [f64; 3], f64, f64)> = poses
        .iter()
        .map(|(t, q, p)| {
            let (zaxis, heading) = axes(*q);
            (*t, zaxis[2].clamp(-1.0, 1.0).acos(), zaxis, heading, p.map_or(f64::NAN, |p| p[2]))
        })
        .collect();
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    data.tilt = Signal {
        name: "base tilt".into(),
        t_secs: samples.iter().map(|s| s.0).collect(),
        v: samples.iter().map(|s| s.1).collect(),
    };
    if samples.iter().any(|s| s.4.is_finite()) {
        data.height = Signal {
            name: "base height".into(),
            t_secs: data.tilt.t_secs.clone(),
            v: samples.iter().map(|s| s.4).collect(),
        };
    }
    let t_start = samples[0].0;
    // Initial height: median over the first 0.2 s (a planar odometry's z = 0 gives none).
    let mut early: Vec<f64> = samples.iter().take_while(|s| s.0 <= t_start + 0.2).map(|s| s.4).collect();
    let z0 = quantile(&mut early, 0.5);
    let z_fall = (z0.is_finite() && z0 > 0.05).then_some(z0 * options.height_fraction);
    if z0.is_finite() && z0 <= 0.05 {
        notes.push(format!("base height at the start is {z0:.3} m (planar odometry?): falls by tilt only"));
    }
    let fall_at = samples.iter().position(|s| s.1 > options.tilt_rad || z_fall.is_some_and(|f| s.4 < f))?;
    let fs = samples[fall_at];
    let criterion = if fs.1 > options.tilt_rad {
        format!("tilt {:.3} rad > {:.3} rad", fs.1, options.tilt_rad)
    } else {
        format!("base height {:.3} m < {} × {:.3} m", fs.4, options.height_fraction, z0)
    };
    // The standing band: the first second, at most the first 30 % before the fall.
    let base_end = t_start + (0.3 * (fs.0 - t_start)).min(1.0);
    let mut base: Vec<f64> = samples.iter().take_while(|s| s.0 <= base_end).map(|s| s.1).collect();
    let baseline = quantile(&mut base, 0.5);
    let spread = quantile(&mut base, 0.95) - quantile(&mut base, 0.05);
    let band = (2.0 * spread).max(0.03);
    // Last sample in the band before the fall; then back while the tilt kept growing.
    let exit = (0..fall_at).rev().find(|&i| samples[i].1 <= baseline + band).unwrap_or(0);
    let mut onset = exit;
    while onset > 0 && samples[onset - 1].1 < samples[onset].1 - 1e-6 {
        onset -= 1;
    }
    // Direction: the lean at the fall, in the heading frame at the onset.
    let heading = samples[onset].3;
    let (s, c) = heading.sin_cos();
    let z = fs.2;
    let (fwd, left) = (c * z[0] + s * z[1], -s * z[0] + c * z[1]);
    let n = fwd.hypot(left).max(1e-12);
    let (fwd, left) = (fwd / n, left / n);
    let direction = if fwd.abs() >= left.abs() {
        if fwd >= 0.0 { Direction::Forward } else { Direction::Backward }
    } else if left >= 0.0 {
        Direction::Left
    } else {
        Direction::Right
    };
    Some(Fall {
        fall_time_secs: fs.0,
        criterion,
        onset_secs: samples[onset].0,
        band_exit_secs: samples[exit].0,
        baseline_tilt_rad: baseline,
        band_rad: band,
        tilt_at_onset_rad: samples[onset].1,
        direction,
        lean_forward: fwd,
        lean_left: left,
        heading_rad: heading,
        source: String::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A base that stands still for 1 s, then rotates about its heading's y axis (pitching
    /// forward) at 1 rad/s, heading 90° (facing +y): falls forward, i.e. toward world +y.
    #[test]
    fn finds_the_onset_and_direction_of_a_pitch_over() {
        let yaw = std::f64::consts::FRAC_PI_2;
        let poses: Vec<_> = (0..300)
            .map(|i| {
                let t = i as f64 * 0.01;
                let pitch = (t - 1.0).max(0.0);
                // q = yaw about z, then pitch about the body's y.
                let (cy, sy) = ((yaw / 2.0).cos(), (yaw / 2.0).sin());
                let (cp, sp) = ((pitch / 2.0).cos(), (pitch / 2.0).sin());
                let q = [-sy * sp, cy * sp, sy * cp, cy * cp];
                (t, q, Some([0.0, 0.0, 0.7 * pitch.cos()]))
            })
            .collect();
        let mut data = Data::default();
        let f = find(&poses, &FallOptions::default(), &mut data, &mut Vec::new()).unwrap();
        assert!((f.onset_secs - 1.0).abs() < 0.011, "{f:?}");
        // Tilt 1.0 rad at t = 2.0 (height 0.7·cos(1.0) = 0.378 < 0.42 first: cos < 0.6 at 0.927).
        assert!((f.fall_time_secs - 1.93).abs() < 0.011, "{f:?}");
        assert_eq!(f.direction, Direction::Forward, "{f:?}");
        assert!((f.heading_rad - yaw).abs() < 1e-9);
    }
}
