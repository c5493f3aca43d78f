//! From a raw [`JointLog`] to conditioned, uniformly sampled segments with filtered positions,
//! velocities, accelerations and torques, ready for the regressor.

use crate::error::{Error, Result};
use crate::log::JointLog;
use crate::model::RobotModel;
use crate::regressor::BaseSample;
use crate::signal::{Butterworth, derivative, median_step, resample};
use nalgebra::Quaternion;

/// Base samples on `grid` (seconds from the joint log's first sample, `t0_nanos`): the pose
/// resampled (quaternion signs made continuous), filtered, the quaternion normalised; the
/// linear velocity (world) and its derivative from the position, the angular velocity in the
/// base frame `ω = 2·vec(q* ⊗ q̇)` and its derivative.
fn condition_base(
    base: &crate::log::BaseTrajectory,
    t0_nanos: i64,
    grid: &[f64],
    filter: &Butterworth,
    pad: usize,
    dt: f64,
) -> Vec<BaseSample> {
    let tb: Vec<f64> = base.t_nanos.iter().map(|&x| (x - t0_nanos) as f64 * 1e-9).collect();
    let mut quats = base.orientation_wxyz.clone();
    for k in 1..quats.len() {
        let d: f64 = (0..4).map(|i| quats[k][i] * quats[k - 1][i]).sum();
        if d < 0.0 {
            quats[k].iter_mut().for_each(|x| *x = -*x);
        }
    }
    let pos: Vec<Vec<f64>> = (0..3)
        .map(|i| filter.filtfilt(&resample(&tb, &base.position.iter().map(|p| p[i]).collect::<Vec<_>>(), grid), pad))
        .collect();
    let quat: Vec<Vec<f64>> = (0..4)
        .map(|i| filter.filtfilt(&resample(&tb, &quats.iter().map(|q| q[i]).collect::<Vec<_>>(), grid), pad))
        .collect();
    let m = grid.len();
    let q: Vec<[f64; 4]> = (0..m)
        .map(|k| {
            let v = [quat[0][k], quat[1][k], quat[2][k], quat[3][k]];
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            v.map(|x| x / n)
        })
        .collect();
    let qdot: Vec<Vec<f64>> = (0..4).map(|i| derivative(&q.iter().map(|x| x[i]).collect::<Vec<_>>(), dt)).collect();
    let omega: Vec<[f64; 3]> = (0..m)
        .map(|k| {
            let conj = Quaternion::new(q[k][0], -q[k][1], -q[k][2], -q[k][3]);
            let p = conj * Quaternion::new(qdot[0][k], qdot[1][k], qdot[2][k], qdot[3][k]);
            [2.0 * p.i, 2.0 * p.j, 2.0 * p.k]
        })
        .collect();
    let mut vel: Vec<Vec<f64>> = pos.iter().map(|p| derivative(p, dt)).collect();
    let mut omega = omega;
    if !base.twist.is_empty() {
        // The logged twist (base frame) is filtered like the pose: a state estimator's twist
        // is far less noisy than the derivative of its pose. Linear velocity to the world frame.
        let tw: Vec<Vec<f64>> = (0..6)
            .map(|i| filter.filtfilt(&resample(&tb, &base.twist.iter().map(|t| t[i]).collect::<Vec<_>>(), grid), pad))
            .collect();
        for k in 0..m {
            let r = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                q[k][0], q[k][1], q[k][2], q[k][3],
            ));
            let v = r * nalgebra::Vector3::new(tw[0][k], tw[1][k], tw[2][k]);
            for i in 0..3 {
                vel[i][k] = v[i];
            }
            omega[k] = [tw[3][k], tw[4][k], tw[5][k]];
        }
    }
    let acc: Vec<Vec<f64>> = vel.iter().map(|v| derivative(v, dt)).collect();
    let alpha: Vec<Vec<f64>> =
        (0..3).map(|i| derivative(&omega.iter().map(|w| w[i]).collect::<Vec<_>>(), dt)).collect();
    (0..m)
        .map(|k| BaseSample {
            qpos: [pos[0][k], pos[1][k], pos[2][k], q[k][0], q[k][1], q[k][2], q[k][3]],
            qvel: [vel[0][k], vel[1][k], vel[2][k], omega[k][0], omega[k][1], omega[k][2]],
            qacc: [acc[0][k], acc[1][k], acc[2][k], alpha[0][k], alpha[1][k], alpha[2][k]],
        })
        .collect()
}

/// A wrench series on `grid`: linear interpolation inside the topic's span, zero outside (no
/// contact), then the effort filter.
fn condition_wrench(
    w: &crate::log::WrenchSeries,
    t0_nanos: i64,
    grid: &[f64],
    filter: &Butterworth,
    pad: usize,
) -> Vec<[f64; 6]> {
    let tw: Vec<f64> = w.t_nanos.iter().map(|&x| (x - t0_nanos) as f64 * 1e-9).collect();
    let (first, last) = (tw[0], tw[tw.len() - 1]);
    let comps: Vec<Vec<f64>> = (0..6)
        .map(|i| {
            let raw = resample(&tw, &w.wrench.iter().map(|x| x[i]).collect::<Vec<_>>(), grid);
            let raw: Vec<f64> =
                raw.iter().zip(grid).map(|(&v, &g)| if g < first || g > last { 0.0 } else { v }).collect();
            filter.filtfilt(&raw, pad)
        })
        .collect();
    (0..grid.len()).map(|k| std::array::from_fn(|i| comps[i][k])).collect()
}

/// Signal-conditioning options.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct ConditionOptions {
    /// Low-pass cut-off, Hz (default: `None`: `min(rate / 25, 20 Hz)`, i.e. 20 Hz for 500 Hz
    /// logs and faster, 4 Hz for a 100 Hz log).
    pub cutoff_hz: Option<f64>,
    /// Low-pass cut-off of the measured effort alone, Hz (default: `None`: the same as the
    /// positions'). Held-out comparisons of models conditioned at different cut-offs filter
    /// the effort they are scored against at one cut-off, so that a lower cut-off does not
    /// score better merely by smoothing the target.
    pub effort_cutoff_hz: Option<f64>,
    /// Butterworth order, applied forward and backward (default: 4).
    #[default(4)]
    pub filter_order: usize,
    /// Rate at which regressor samples are taken from the filtered signals, Hz (default:
    /// `None`: 5 × the cut-off, at most the log's rate). After the low-pass the signals hold
    /// nothing above the cut-off, so denser samples add computation, not information.
    pub regressor_rate_hz: Option<f64>,
    /// A time step larger than this many median steps splits the log into segments rather
    /// than being bridged (default: 5).
    #[default(5.0)]
    pub gap_factor: f64,
}

/// One contiguous, conditioned piece of the log. Series are `[joint][sample]`, joints in
/// [`RobotModel::joints`] order.
#[derive(Debug, Clone, Default)]
pub struct Segment {
    /// Sample times, seconds from the log's first sample.
    pub t_secs: Vec<f64>,
    /// Filtered positions.
    pub q: Vec<Vec<f64>>,
    /// Velocities (derivative of the filtered positions).
    pub qd: Vec<Vec<f64>>,
    /// Accelerations (second derivative of the filtered positions).
    pub qdd: Vec<Vec<f64>>,
    /// Filtered efforts.
    pub tau: Vec<Vec<f64>>,
    /// Floating base state per sample (empty for a fixed base): pose filtered like the joint
    /// positions, velocity and acceleration differentiated from it, in MuJoCo's free-joint form.
    pub base: Vec<BaseSample>,
    /// External wrenches `[wrench][sample]`, filtered like the efforts (body frame, torque about
    /// the body origin), one series per [`JointLog::wrenches`] entry.
    pub wrench: Vec<Vec<[f64; 6]>>,
}

impl Segment {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_secs.len()
    }
    /// Whether the segment is empty.
    pub fn is_empty(&self) -> bool {
        self.t_secs.is_empty()
    }
}

/// The conditioned log.
#[derive(Debug, Clone, Default)]
pub struct Conditioned {
    /// The log's sample rate (median), Hz.
    pub rate_hz: f64,
    /// Cut-off used, Hz.
    pub cutoff_hz: f64,
    /// Filter order used.
    pub filter_order: usize,
    /// Regressor sample rate, Hz.
    pub regressor_rate_hz: f64,
    /// Samples in the raw log.
    pub raw_samples: usize,
    /// Segments after gaps, trimming and decimation.
    pub segments: Vec<Segment>,
    /// Range of motion of each joint over the used data, rad or m.
    pub joint_range: Vec<f64>,
    /// RMS velocity of each joint, rad/s or m/s.
    pub joint_rms_velocity: Vec<f64>,
    /// Things the user should know (dropped segments, extra joints).
    pub warnings: Vec<String>,
}

impl Conditioned {
    /// Total number of conditioned samples.
    pub fn samples(&self) -> usize {
        self.segments.iter().map(Segment::len).sum()
    }
}

/// Matches the log's joints to the model's: index into the log of each model joint.
///
/// # Errors
/// [`Error::BadLog`] listing the model joints that the log lacks (and the log's joints).
pub fn match_joints(log: &JointLog, robot: &RobotModel) -> Result<(Vec<usize>, Vec<String>)> {
    let mut missing = Vec::new();
    let mut map = Vec::new();
    for joint in &robot.joints {
        match log.joint_index(&joint.name) {
            Some(i) => map.push(i),
            None => missing.push(joint.name.clone()),
        }
    }
    if !missing.is_empty() {
        return Err(log.bad(format!(
            "joint names do not match {}: the robot's joint(s) {} are not in the log, which has {}. \
             Log joint names must be the URDF's <joint name> values",
            robot.urdf_path.display(),
            quote_list(&missing),
            quote_list(&log.joint_names),
        )));
    }
    let extra: Vec<String> = log.joint_names.iter().filter(|n| robot.joint_index(n).is_none()).cloned().collect();
    let mut warnings = Vec::new();
    if !extra.is_empty() {
        warnings.push(format!("log joint(s) {} are not joints of the robot and were ignored", quote_list(&extra)));
    }
    Ok((map, warnings))
}

pub(crate) fn quote_list(names: &[String]) -> String {
    const MAX: usize = 8;
    let mut s: Vec<String> = names.iter().take(MAX).map(|n| format!("\"{n}\"")).collect();
    if names.len() > MAX {
        s.push(format!("and {} more", names.len() - MAX));
    }
    if s.is_empty() { "none".into() } else { s.join(", ") }
}

/// Hampel filter of `x` (half-window 3): a sample farther from its window's median than
/// 8 robust standard deviations of the window, 20 typical steps (median |Δx|) and 50
/// quantisation steps (smallest non-zero |Δx|) is replaced by that median. Smooth motion and
/// encoder dither stay as they are. Returns each replaced sample and how far it was off.
pub fn despike(x: &mut [f64]) -> Vec<(usize, f64)> {
    const HALF: usize = 3;
    if x.len() < 2 * HALF + 1 {
        return Vec::new();
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let mut steps: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let quantum = steps.iter().copied().filter(|d| *d > 0.0).fold(f64::INFINITY, f64::min);
    let typical = median(&mut steps);
    let floor = (20.0 * typical).max(if quantum.is_finite() { 50.0 * quantum } else { 0.0 });
    let orig = x.to_vec();
    let mut out = Vec::new();
    let mut window = Vec::with_capacity(2 * HALF + 1);
    for k in 0..orig.len() {
        let (a, b) = (k.saturating_sub(HALF), (k + HALF + 1).min(orig.len()));
        window.clear();
        window.extend_from_slice(&orig[a..b]);
        let med = median(&mut window);
        let mut dev: Vec<f64> = orig[a..b].iter().map(|v| (v - med).abs()).collect();
        let mad = 1.4826 * median(&mut dev);
        let off = orig[k] - med;
        if floor > 0.0 && off.abs() > (8.0 * mad).max(floor) {
            x[k] = med;
            out.push((k, off));
        }
    }
    out
}

/// The warning for the samples [`despike`] replaced in one joint's `what` series (`ts`: their
/// times, s): how many, the first few times and the worst offset.
fn spike_warning(joint: &str, what: &str, spikes: &[(usize, f64)], ts: &[f64], guess: &str) -> Option<String> {
    let &(k, worst) = spikes.iter().max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))?;
    const LISTED: usize = 5;
    let mut times: Vec<String> = spikes.iter().take(LISTED).map(|(k, _)| format!("{:.3}", ts[*k])).collect();
    if spikes.len() > LISTED {
        times.push(format!("… ({} more)", spikes.len() - LISTED));
    }
    Some(format!(
        "joint \"{joint}\": {} {what} sample(s) jump away from their neighbours and back (worst {worst:+.4} \
         at t = {:.3} s from the log's start; all at t = {} s): {guess} Replaced by the median of their \
         neighbours (Hampel filter) before filtering, so they do not pull the fit",
        spikes.len(),
        ts[k],
        times.join(", ")
    ))
}

/// Conditions `log` for `robot`.
///
/// # Errors
/// [`Error::BadLog`] for unmatched joints, missing effort, NaN/∞ in positions or efforts,
/// timestamps going backwards, or too little data; [`Error::Option`] for a bad cut-off.
pub fn condition(log: &JointLog, robot: &RobotModel, opts: &ConditionOptions) -> Result<Conditioned> {
    log.check_shape()?;
    let (map, mut warnings) = match_joints(log, robot)?;
    let n = log.len();
    if n < 10 {
        return Err(log.bad(format!("only {n} samples: a log of at least a few seconds is needed")));
    }
    let no_effort: Vec<String> = robot
        .joints
        .iter()
        .zip(&map)
        .filter(|&(_, &i)| log.effort[i].iter().all(|x| x.is_nan()))
        .map(|(j, _)| j.name.clone())
        .collect();
    if !no_effort.is_empty() {
        return Err(log.bad(format!(
            "no effort (torque) for joint(s) {}: identification needs measured joint torques \
             (JointState.effort, or `<joint>/effort` CSV columns)",
            quote_list(&no_effort)
        )));
    }
    let t0 = log.t_nanos[0];
    for (what, series) in [("position", &log.position), ("effort", &log.effort)] {
        for (joint, &i) in robot.joints.iter().zip(&map) {
            let bad: Vec<usize> = (0..n).filter(|&k| !series[i][k].is_finite()).collect();
            if let Some(&k) = bad.first() {
                return Err(log.bad(format!(
                    "{} {what} value(s) of joint \"{}\" are NaN or infinite, the first at t = {:.6} s \
                     (sample {k}); twin does not interpolate over missing data: remove those samples \
                     (the log is then split at the gap)",
                    bad.len(),
                    joint.name,
                    (log.t_nanos[k] - t0) as f64 * 1e-9
                )));
            }
        }
    }
    if let Some(k) = (1..n).find(|&k| log.t_nanos[k] < log.t_nanos[k - 1]) {
        return Err(log.bad(format!(
            "timestamps go backwards at sample {k} (t = {:.6} s after {:.6} s); sort the log by time",
            (log.t_nanos[k] - t0) as f64 * 1e-9,
            (log.t_nanos[k - 1] - t0) as f64 * 1e-9
        )));
    }
    let t: Vec<f64> = log.t_nanos.iter().map(|&x| (x - t0) as f64 * 1e-9).collect();
    let dt = median_step(&t).ok_or_else(|| log.bad("all timestamps are equal".into()))?;
    let rate_hz = 1.0 / dt;
    let cutoff_hz = opts.cutoff_hz.unwrap_or((rate_hz / 25.0).min(20.0));
    if !(cutoff_hz > 0.0 && cutoff_hz < 0.45 * rate_hz) {
        return Err(Error::Option {
            name: "cutoff_hz",
            message: format!("{cutoff_hz} Hz must be positive and below 0.45 × the log's rate ({rate_hz:.1} Hz)"),
        });
    }
    let order = opts.filter_order.clamp(1, 8);
    let regressor_rate_hz = opts.regressor_rate_hz.unwrap_or(5.0 * cutoff_hz).min(rate_hz);
    let decimate = ((rate_hz / regressor_rate_hz).floor() as usize).max(1);
    let filter = Butterworth::low_pass(order, cutoff_hz, rate_hz);
    let effort_cutoff_hz = opts.effort_cutoff_hz.unwrap_or(cutoff_hz);
    if !(effort_cutoff_hz > 0.0 && effort_cutoff_hz < 0.45 * rate_hz) {
        return Err(Error::Option {
            name: "effort_cutoff_hz",
            message: format!(
                "{effort_cutoff_hz} Hz must be positive and below 0.45 × the log's rate ({rate_hz:.1} Hz)"
            ),
        });
    }
    let effort_filter = Butterworth::low_pass(order, effort_cutoff_hz, rate_hz);
    // Edge transients of the forward-backward filter last a few cut-off periods.
    let trim = (3.0 * rate_hz / cutoff_hz.min(effort_cutoff_hz)).ceil() as usize;
    let pad = trim;

    // Raw segments: split where the step is a gap; drop repeated timestamps.
    // A joint sample inside a gap of the base odometry is a gap too (never bridged).
    let in_base_gap: Vec<bool> = match &log.base {
        Some(base) => {
            let tb: Vec<f64> = base.t_nanos.iter().map(|&x| (x - t0) as f64 * 1e-9).collect();
            let step = median_step(&tb).unwrap_or(dt);
            t.iter()
                .map(|&x| {
                    let i = tb.partition_point(|&b| b < x);
                    i == 0 && tb[0] > x || i >= tb.len() || (i > 0 && tb[i] - tb[i - 1] > opts.gap_factor * step)
                })
                .collect()
        }
        None => vec![false; n],
    };
    let mut bounds = Vec::new();
    let mut start = None;
    for k in 0..n {
        if in_base_gap[k] {
            if let Some(s0) = start.take() {
                bounds.push((s0, k));
            }
            continue;
        }
        match start {
            None => start = Some(k),
            Some(s0) if k > 0 && t[k] - t[k - 1] > opts.gap_factor * dt => {
                bounds.push((s0, k));
                start = Some(k);
            }
            Some(_) => {}
        }
    }
    if let Some(s0) = start {
        bounds.push((s0, n));
    }
    if bounds.len() > 1 {
        warnings.push(format!(
            "the log has {} gap(s) longer than {:.0} ms; its {} pieces were conditioned separately",
            bounds.len() - 1,
            opts.gap_factor * dt * 1e3,
            bounds.len()
        ));
    }
    let nj = robot.joints.len();
    let mut segments = Vec::new();
    let mut dropped_secs = 0.0;
    for &(a, b) in &bounds {
        let span = t[b - 1] - t[a];
        let m = (span / dt).floor() as usize + 1;
        if m < 2 * trim + 20 {
            dropped_secs += span;
            continue;
        }
        let grid: Vec<f64> = (0..m).map(|i| t[a] + i as f64 * dt).collect();
        // Strictly increasing times for interpolation.
        let mut idx: Vec<usize> = Vec::with_capacity(b - a);
        for k in a..b {
            if idx.last().is_none_or(|&l| t[k] > t[l]) {
                idx.push(k);
            }
        }
        let ts: Vec<f64> = idx.iter().map(|&k| t[k]).collect();
        let keep: Vec<usize> = (trim..m - trim).step_by(decimate).collect();
        let mut seg = Segment { t_secs: keep.iter().map(|&i| grid[i]).collect(), ..Segment::default() };
        for &i in &map {
            let mut raw_q: Vec<f64> = idx.iter().map(|&k| log.position[i][k]).collect();
            // A glitched encoder reading becomes, after filtering and differentiating twice, a
            // burst of huge accelerations that pulls the fit: such samples are replaced first.
            let spikes = despike(&mut raw_q);
            if let Some(w) = spike_warning(&log.joint_names[i], "position", &spikes, &ts, "glitched encoder readings?")
            {
                warnings.push(w);
            }
            let mut raw_tau: Vec<f64> = idx.iter().map(|&k| log.effort[i][k]).collect();
            // Likewise a glitched torque reading: the low-pass would smear it over several
            // regressor rows, where it no longer looks like one bad sample, and pull the fit by
            // many standard deviations. A sample is the last place it can be told apart.
            let spikes = despike(&mut raw_tau);
            if let Some(w) = spike_warning(&log.joint_names[i], "effort", &spikes, &ts, "glitched torque readings?") {
                warnings.push(w);
            }
            let q = filter.filtfilt(&resample(&ts, &raw_q, &grid), pad);
            let tau = effort_filter.filtfilt(&resample(&ts, &raw_tau, &grid), pad);
            let qd = derivative(&q, dt);
            let qdd = derivative(&qd, dt);
            seg.q.push(keep.iter().map(|&i| q[i]).collect());
            seg.qd.push(keep.iter().map(|&i| qd[i]).collect());
            seg.qdd.push(keep.iter().map(|&i| qdd[i]).collect());
            seg.tau.push(keep.iter().map(|&i| tau[i]).collect());
        }
        if let Some(base) = &log.base {
            let all = condition_base(base, t0, &grid, &filter, pad, dt);
            seg.base = keep.iter().map(|&i| all[i]).collect();
        }
        for w in &log.wrenches {
            let all = condition_wrench(w, t0, &grid, &filter, pad);
            seg.wrench.push(keep.iter().map(|&i| all[i]).collect());
        }
        segments.push(seg);
    }
    if dropped_secs > 0.0 {
        warnings.push(format!(
            "{dropped_secs:.2} s of the log in pieces shorter than {:.2} s were not used (the filter needs \
             {:.2} s at each end)",
            (2 * trim + 20) as f64 * dt,
            trim as f64 * dt
        ));
    }
    if segments.is_empty() {
        return Err(log.bad(format!(
            "no piece of the log is long enough: at {rate_hz:.1} Hz with a {cutoff_hz:.1} Hz cut-off, \
             each piece needs at least {:.2} s without gaps",
            (2 * trim + 20) as f64 * dt
        )));
    }
    let mut joint_range = vec![0.0; nj];
    let mut joint_rms_velocity = vec![0.0; nj];
    let total: usize = segments.iter().map(Segment::len).sum();
    for j in 0..nj {
        let (mut lo, mut hi, mut ss) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
        for s in &segments {
            for k in 0..s.len() {
                lo = lo.min(s.q[j][k]);
                hi = hi.max(s.q[j][k]);
                ss += s.qd[j][k] * s.qd[j][k];
            }
        }
        joint_range[j] = hi - lo;
        joint_rms_velocity[j] = (ss / total.max(1) as f64).sqrt();
    }
    Ok(Conditioned {
        rate_hz,
        cutoff_hz,
        filter_order: order,
        regressor_rate_hz: rate_hz / decimate as f64,
        raw_samples: n,
        segments,
        joint_range,
        joint_rms_velocity,
        warnings,
    })
}
