//! Commanded against actual, per joint: the command array's entries are matched to joints (the
//! model's actuators in `ctrl` order, or its DOFs for a model without actuators; without a
//! model, the JointState names in order of first appearance), each entry is compared with the
//! JointState field of its kind, interpolated at the command's times (up to the fall): RMS and
//! largest error, lag (the shift, up to 0.5 s, that best correlates actual with command) and
//! saturation (the command at or beyond the joint's limit from the model, or, without one,
//! beyond the range the joint reached while the joint sits at its end, or an effort or velocity
//! command held at its own extreme for five samples or more: clamped by its controller).
//! Oscillation: a joint
//! whose position, less its 0.1-s moving average, crosses zero at 5 Hz or more with an
//! amplitude of 5 mrad or more, before the onset.

use super::signal::{Signal, mean_std, rms};
use super::{CommandKind, Data};
use serde::Serialize;
use twin_core::control::Actuation;
use twin_core::convert::Interface;
use twin_core::log::JointStateSeries;
use twin_core::robot::Robot;

/// One joint's tracking.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointTracking {
    /// Joint name.
    pub joint: String,
    /// Index in the command array.
    pub index: usize,
    /// Commands compared.
    pub samples: usize,
    /// RMS of command − actual.
    pub rms_error: f64,
    /// Largest |command − actual|.
    pub max_error: f64,
    /// When it was largest, s.
    pub max_error_secs: f64,
    /// How late the actual follows the command, s (None: no clear correlation).
    pub lag_secs: Option<f64>,
    /// Share of the commands at or beyond the limit (0–1).
    pub saturated_fraction: f64,
    /// The limit `[low, high]` used.
    pub limit: Option<[f64; 2]>,
    /// Where the limit comes from.
    pub limit_source: String,
    /// The command of largest magnitude.
    pub peak_command: f64,
}

/// Commanded against actual.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Tracking {
    /// The command topic.
    pub topic: String,
    /// What the commands are.
    pub kind: CommandKind,
    /// Why that kind.
    pub kind_reason: String,
    /// Joints, worst first (saturated ones first, then by RMS error against the joint's scale).
    pub joints: Vec<JointTracking>,
    /// How many are "the worst" (reported and plotted).
    pub worst: usize,
}

/// Per command entry its joint (index in the JointState series), the kind the model says, and
/// where the mapping comes from.
type Mapping = (Vec<Option<usize>>, Option<CommandKind>, String);

/// The tracking, and per compared joint its name, command and actual signals.
type Compared = (Tracking, Vec<(String, Signal, Signal)>);

/// Joint index (in the JointState series) of each command entry, and the kind the model says.
fn mapping(n: usize, js: &JointStateSeries, robot: Option<&Robot>) -> std::result::Result<Mapping, String> {
    let by_name = |name: &str| js.joints.iter().position(|j| j.name == name);
    if let Some(r) = robot {
        let model = &r.model;
        let joint_name = |id: usize| r.joints.iter().find(|j| j.id == id).map(|j| j.name.as_str());
        match r.actuation {
            Actuation::Ctrl if n == r.actuators.len() => {
                let map = r.actuators.iter().map(|a| a.joint.and_then(joint_name).and_then(by_name)).collect();
                let kinds: Vec<Interface> = r.actuators.iter().map(|a| a.interface).collect();
                let count = |k: Interface| kinds.iter().filter(|x| **x == k).count();
                let kind = [Interface::Effort, Interface::Position, Interface::Velocity]
                    .into_iter()
                    .max_by_key(|k| count(*k))
                    .map(|k| match k {
                        Interface::Effort => CommandKind::Effort,
                        Interface::Position => CommandKind::Position,
                        Interface::Velocity => CommandKind::Velocity,
                    });
                return Ok((map, kind, format!("the actuators of {}", r.path.display())));
            }
            Actuation::Qfrc if n == model.nv() => {
                let map =
                    (0..n).map(|dof| r.joints.iter().find(|j| j.dof == dof).and_then(|j| by_name(&j.name))).collect();
                return Ok((map, Some(CommandKind::Effort), "joint forces of a model without actuators".into()));
            }
            _ => {}
        }
    }
    if n == js.joints.len() {
        return Ok(((0..n).map(Some).collect(), None, "commands in /joint_states order".into()));
    }
    Err(format!(
        "the commands have {n} entries but the JointState topic names {} joints{}: give the --model whose \
         actuators they drive",
        js.joints.len(),
        robot.map_or_else(String::new, |r| format!(" and {} has {} actuators", r.name, r.actuators.len()))
    ))
}

fn actual(data: &Data, kind: CommandKind, j: usize) -> &Signal {
    match kind {
        CommandKind::Position => &data.positions[j],
        CommandKind::Velocity => &data.velocities[j],
        CommandKind::Effort => &data.efforts[j],
    }
}

/// Best lag (s) of `a` behind `c`, both sampled at the same uniform-ish instants `dt` apart.
fn lag(c: &[f64], a: &[f64], dt: f64) -> Option<f64> {
    let n = c.len().min(a.len());
    if n < 20 || dt.is_nan() || dt <= 0.0 {
        return None;
    }
    let max_k = ((0.5 / dt).round() as usize).min(n / 2).min(500);
    let (_, sc) = mean_std(&c[..n]);
    let (_, sa) = mean_std(&a[..n]);
    if !(sc > 1e-9 && sa > 1e-9) {
        return None;
    }
    // Pearson correlation of the overlapping parts at each shift.
    let mut best = (0usize, f64::NEG_INFINITY);
    for k in 0..=max_k {
        let pairs: Vec<(f64, f64)> =
            (0..n - k).map(|i| (c[i], a[i + k])).filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
        if pairs.len() < 10 {
            continue;
        }
        let m = pairs.len() as f64;
        let (mx, my) = (pairs.iter().map(|p| p.0).sum::<f64>() / m, pairs.iter().map(|p| p.1).sum::<f64>() / m);
        let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
        for (x, y) in &pairs {
            sxy += (x - mx) * (y - my);
            sxx += (x - mx) * (x - mx);
            syy += (y - my) * (y - my);
        }
        let r = if sxx > 0.0 && syy > 0.0 { sxy / (sxx * syy).sqrt() } else { f64::NEG_INFINITY };
        if r > best.1 + 1e-12 {
            best = (k, r);
        }
    }
    (best.1 > 0.5).then_some(best.0 as f64 * dt)
}

/// One `trajectory_msgs/msg/JointTrajectory` command: when it starts (s on the analysis axis:
/// its header stamp, or when it was received where the stamp is zero) and the message.
pub(crate) type TrajectoryCommand<'a> = (f64, &'a twin_core::log::JointTrajectory);

/// One joint's part of a trajectory: its start (s) and its knots (time from the start, s;
/// position).
type Segment = (f64, Vec<(f64, f64)>);

/// The joint position a stream of trajectories commands, as a trajectory controller follows
/// it: each joint follows the latest trajectory naming it that has started (a new one replaces
/// the old, as `joint_trajectory_controller` does), linearly between its points by
/// `time_from_start`, from the position commanded when it starts (the previous trajectory's,
/// else the actual position `actual`) to its first point, and holds its last point after the
/// end. Sampled at `times` (s); returns the joints in order of first appearance and per time
/// one position per joint (NaN before the first trajectory naming it).
pub(crate) fn sample_trajectories(
    trajectories: &[TrajectoryCommand<'_>],
    times: &[f64],
    actual: &dyn Fn(&str, f64) -> f64,
) -> (Vec<String>, Vec<(f64, Vec<f64>)>) {
    let mut order: Vec<usize> = (0..trajectories.len()).collect();
    order.sort_by(|&a, &b| trajectories[a].0.total_cmp(&trajectories[b].0).then(a.cmp(&b)));
    let mut names: Vec<String> = Vec::new();
    for &k in &order {
        for n in &trajectories[k].1.joint_names {
            if !names.contains(n) {
                names.push(n.clone());
            }
        }
    }
    // Per joint: its segments, in start order.
    let mut per_joint: Vec<Vec<Segment>> = vec![Vec::new(); names.len()];
    for (j, name) in names.iter().enumerate() {
        for &k in &order {
            let (start, msg) = trajectories[k];
            let Some(col) = msg.joint_names.iter().position(|n| n == name) else { continue };
            let knots: Vec<(f64, f64)> = msg
                .points
                .iter()
                .filter_map(|p| p.positions.get(col).map(|q| (p.time_from_start_nanos as f64 * 1e-9, *q)))
                .filter(|(t, q)| t.is_finite() && q.is_finite())
                .collect();
            if !knots.is_empty() {
                per_joint[j].push((start, knots));
            }
        }
    }
    // The commanded position of joint `j` under segment `s` at `t` (at or after its start).
    fn along(segments: &[Segment], s: usize, t: f64, from: f64) -> f64 {
        let (start, knots) = &segments[s];
        let tau = t - start;
        let (mut t0, mut q0) = (0.0, from);
        for &(tk, qk) in knots {
            if tau <= tk {
                return if tk - t0 <= 0.0 { qk } else { q0 + (qk - q0) * (tau - t0) / (tk - t0) };
            }
            (t0, q0) = (tk, qk);
        }
        q0
    }
    // Where each segment starts from: the command in force then, else the actual position.
    let mut from: Vec<Vec<f64>> = Vec::with_capacity(names.len());
    for (j, segments) in per_joint.iter().enumerate() {
        let mut f: Vec<f64> = Vec::with_capacity(segments.len());
        for s in 0..segments.len() {
            let start = segments[s].0;
            let q = if s == 0 { actual(&names[j], start) } else { along(segments, s - 1, start, f[s - 1]) };
            f.push(q);
        }
        from.push(f);
    }
    let mut out = Vec::with_capacity(times.len());
    for &t in times {
        let q: Vec<f64> = per_joint
            .iter()
            .zip(&from)
            .map(|(segments, f)| {
                let s = segments.partition_point(|(start, _)| *start <= t);
                if s == 0 { f64::NAN } else { along(segments, s - 1, t, f[s - 1]) }
            })
            .collect();
        if q.iter().any(|x| x.is_finite()) {
            out.push((t, q));
        }
    }
    (names, out)
}

/// Compares the commands with the joints; also returns each compared joint's command and
/// actual signals (for the plots).
#[allow(clippy::too_many_arguments)]
pub(crate) fn compare(
    topic: &str,
    commands: &[(f64, &[f64])],
    trajectory_joints: Option<&[String]>,
    js: &JointStateSeries,
    data: &Data,
    robot: Option<&Robot>,
    kind: Option<CommandKind>,
    end: Option<f64>,
    worst: usize,
) -> std::result::Result<Compared, String> {
    let n = commands.iter().map(|(_, d)| d.len()).max().unwrap_or(0);
    if n == 0 {
        return Err(format!("{topic}: the commands are empty"));
    }
    let (map, model_kind, map_reason) = match trajectory_joints {
        Some(names) => {
            let map: Vec<Option<usize>> = names.iter().map(|n| js.joints.iter().position(|j| j.name == *n)).collect();
            if map.iter().all(Option::is_none) {
                return Err(format!(
                    "{topic}: none of the trajectory's joints ({}) is in the JointState topic",
                    names.join(", ")
                ));
            }
            (map, Some(CommandKind::Position), "trajectory points (positions, interpolated in time)".to_string())
        }
        None => mapping(n, js, robot)?,
    };
    let end = end.unwrap_or(f64::INFINITY);
    let cmds: Vec<(f64, &[f64])> = commands.iter().filter(|(t, d)| *t <= end && d.len() == n).copied().collect();
    let command_signal = |i: usize, name: &str| {
        Signal::new(
            format!("{name} command"),
            cmds.iter().filter(|(_, d)| d[i].is_finite()).map(|(t, d)| (*t, d[i])).collect(),
        )
    };
    let available = |k: CommandKind| {
        map.iter().flatten().any(|&j| match k {
            CommandKind::Position => true,
            CommandKind::Velocity => js.joints[j].has_velocity(),
            CommandKind::Effort => js.joints[j].has_effort(),
        })
    };
    // The kind: given, the model's, or the JointState field the commands match best.
    let (kind, kind_reason) = match (kind, model_kind) {
        (Some(k), _) => (k, "as given".to_string()),
        (None, Some(k)) if trajectory_joints.is_some() => (k, map_reason.clone()),
        (None, Some(k)) => (k, format!("as {map_reason} take")),
        (None, None) => {
            let mut best: Option<(CommandKind, f64)> = None;
            let mut scores = Vec::new();
            for k in [CommandKind::Position, CommandKind::Velocity, CommandKind::Effort] {
                if !available(k) {
                    continue;
                }
                let mut errs: Vec<f64> = map
                    .iter()
                    .enumerate()
                    .filter_map(|(i, j)| j.map(|j| (i, j)))
                    .filter_map(|(i, j)| {
                        let a = actual(data, k, j);
                        let e: Vec<f64> = cmds.iter().map(|(t, d)| d[i] - a.at(*t)).collect();
                        let (_, sa) = mean_std(&a.v);
                        let (_, sc) = mean_std(&cmds.iter().map(|(_, d)| d[i]).collect::<Vec<_>>());
                        let scale = sa.max(sc);
                        (scale > 1e-9).then(|| rms(&e) / scale)
                    })
                    .collect();
                let score = super::signal::median(&mut errs);
                if score.is_finite() {
                    scores.push(format!("{} {score:.3}", k.as_str()));
                    if best.is_none_or(|b| score < b.1) {
                        best = Some((k, score));
                    }
                }
            }
            match best {
                Some((k, _)) => (
                    k,
                    format!(
                        "they match the joints' {} best (median RMS error / spread: {})",
                        k.as_str(),
                        scores.join(", ")
                    ),
                ),
                None => (CommandKind::Position, "no JointState field varies; read as positions".into()),
            }
        }
    };
    if !available(kind) {
        return Err(format!(
            "{topic}: commands are {} but the JointState topic has no {} values",
            kind.as_str(),
            kind.as_str()
        ));
    }
    let times: Vec<f64> = cmds.iter().map(|(t, _)| *t).collect();
    let dt = Signal { name: String::new(), t_secs: times.clone(), v: vec![0.0; times.len()] }.median_dt();
    let mut joints = Vec::new();
    let mut pairs = Vec::new();
    for (i, j) in map.iter().enumerate() {
        let Some(j) = *j else { continue };
        let name = js.joints[j].name.clone();
        let a = actual(data, kind, j);
        if a.v.iter().all(|x| !x.is_finite()) {
            continue;
        }
        // A joint a trajectory names only from some time on: compared from then.
        let (times, c): (Vec<f64>, Vec<f64>) =
            cmds.iter().filter(|(_, d)| d[i].is_finite()).map(|(t, d)| (*t, d[i])).unzip();
        if c.is_empty() {
            continue;
        }
        let a_at: Vec<f64> = times.iter().map(|&t| a.at(t)).collect();
        let e: Vec<f64> = c.iter().zip(&a_at).map(|(c, a)| c - a).collect();
        let (mut max_error, mut max_error_secs) = (0.0f64, f64::NAN);
        for (k, x) in e.iter().enumerate() {
            if x.abs() > max_error {
                max_error = x.abs();
                max_error_secs = times[k];
            }
        }
        // Limits: the model's, else the range the joint reached.
        let model_joint = robot.and_then(|r| r.joints.iter().find(|mj| mj.name == name));
        let model_limit = model_joint.and_then(|mj| match kind {
            CommandKind::Position => mj.range,
            CommandKind::Velocity => mj.velocity_limit.map(|v| [-v, v]),
            CommandKind::Effort => mj.effort_limit.map(|v| [-v, v]),
        });
        let (limit, limit_source, saturated) = match model_limit {
            Some(l) => {
                let tol = 1e-6 * (l[1] - l[0]).abs().max(1e-9);
                let sat = c.iter().filter(|&&x| x >= l[1] - tol || x <= l[0] + tol).count();
                (Some(l), format!("the model's {} limit", kind.as_str()), sat)
            }
            None => {
                let (lo, hi) = a_at
                    .iter()
                    .filter(|x| x.is_finite())
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(*x), h.max(*x)));
                let range = hi - lo;
                // Beyond the range the joint reached, with the joint at that end.
                let mut sat: Vec<bool> = c
                    .iter()
                    .zip(&a_at)
                    .map(|(c, a)| {
                        range.is_finite()
                            && range > 1e-12
                            && ((*c > hi + 0.02 * range && *a >= hi - 0.01 * range)
                                || (*c < lo - 0.02 * range && *a <= lo + 0.01 * range))
                    })
                    .collect();
                // An effort or velocity command clamped by its controller: runs of five or more
                // samples exactly at the command's own extreme.
                let (cmin, cmax) = c
                    .iter()
                    .filter(|x| x.is_finite())
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(*x), h.max(*x)));
                let crange = cmax - cmin;
                let mut clamped = false;
                if kind != CommandKind::Position && crange.is_finite() && crange > 1e-9 {
                    let tol = 1e-9 * crange.max(cmax.abs());
                    for extreme in [cmin, cmax] {
                        let mut k = 0;
                        while k < c.len() {
                            let start = k;
                            while k < c.len() && (c[k] - extreme).abs() <= tol {
                                k += 1;
                            }
                            if k - start >= 5 {
                                clamped = true;
                                sat[start..k].iter_mut().for_each(|s| *s = true);
                            }
                            k = k.max(start + 1);
                        }
                    }
                }
                let count = sat.iter().filter(|s| **s).count();
                if clamped {
                    (Some([cmin, cmax]), "the command's own clamp (runs at its extreme)".to_string(), count)
                } else if range.is_finite() && range > 1e-12 {
                    (Some([lo, hi]), "the range the joint reached".to_string(), count)
                } else {
                    (None, "no limit".to_string(), 0)
                }
            }
        };
        let peak_command =
            c.iter().copied().filter(|x| x.is_finite()).fold(0.0f64, |m, x| if x.abs() > m.abs() { x } else { m });
        joints.push(JointTracking {
            joint: name.clone(),
            index: i,
            samples: c.len(),
            rms_error: rms(&e),
            max_error,
            max_error_secs,
            lag_secs: lag(&c, &a_at, dt),
            saturated_fraction: if c.is_empty() { 0.0 } else { saturated as f64 / c.len() as f64 },
            limit,
            limit_source,
            peak_command,
        });
        pairs.push((name.clone(), command_signal(i, &name), Signal { name: a.name.clone(), ..a.clone() }));
    }
    // Worst first: saturated ones (≥ 1 %), then RMS error against the joint's scale.
    let scale = |j: &JointTracking| match j.limit {
        Some(l) if l[1] > l[0] => (l[1] - l[0]) / 2.0,
        _ => j.peak_command.abs().max(1e-9),
    };
    joints.sort_by(|a, b| {
        let sa = a.saturated_fraction >= 0.01;
        let sb = b.saturated_fraction >= 0.01;
        sb.cmp(&sa)
            .then(if sa && sb {
                b.saturated_fraction.total_cmp(&a.saturated_fraction)
            } else {
                std::cmp::Ordering::Equal
            })
            .then((b.rms_error / scale(b)).total_cmp(&(a.rms_error / scale(a))))
    });
    Ok((Tracking { topic: topic.to_string(), kind, kind_reason, joints, worst }, pairs))
}

/// A joint that oscillates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Oscillation {
    /// Joint name.
    pub joint: String,
    /// Zero crossings of the detrended position / 2 per second, Hz.
    pub frequency_hz: f64,
    /// √2 × RMS of the detrended position, rad.
    pub amplitude: f64,
    /// Span analysed, s.
    pub from_secs: f64,
    /// Span analysed, s.
    pub to_secs: f64,
}

/// Joints oscillating before `until` (the whole log when None), strongest first.
pub(crate) fn oscillations(positions: &[Signal], until: Option<f64>) -> Vec<Oscillation> {
    let mut out = Vec::new();
    for s in positions {
        let n = s.index_at(until.unwrap_or(f64::INFINITY));
        if n < 50 {
            continue;
        }
        let dt = s.median_dt();
        if dt.is_nan() || dt <= 0.0 {
            continue;
        }
        let half = ((0.05 / dt).round() as usize).max(1);
        let x = &s.v[..n];
        // Moving average by prefix sums.
        let mut prefix = vec![0.0; n + 1];
        for i in 0..n {
            prefix[i + 1] = prefix[i] + if x[i].is_finite() { x[i] } else { 0.0 };
        }
        let d: Vec<f64> = (half..n.saturating_sub(half))
            .map(|i| x[i] - (prefix[i + half + 1] - prefix[i - half]) / (2 * half + 1) as f64)
            .collect();
        if d.len() < 20 {
            continue;
        }
        let r = rms(&d);
        if !(r.is_finite() && r * std::f64::consts::SQRT_2 >= 0.005) {
            continue;
        }
        let mut sign = 0i8;
        let mut changes = 0usize;
        for v in &d {
            let now = if *v > 0.5 * r {
                1
            } else if *v < -0.5 * r {
                -1
            } else {
                0
            };
            if now != 0 {
                if sign != 0 && now != sign {
                    changes += 1;
                }
                sign = now;
            }
        }
        let (t0, t1) = (s.t_secs[half], s.t_secs[n - 1 - half]);
        let span = t1 - t0;
        if span <= 0.0 {
            continue;
        }
        let f = changes as f64 / 2.0 / span;
        if f >= 5.0 {
            out.push(Oscillation {
                joint: s.name.trim_end_matches(" position").to_string(),
                frequency_hz: f,
                amplitude: r * std::f64::consts::SQRT_2,
                from_secs: t0,
                to_secs: t1,
            });
        }
    }
    out.sort_by(|a, b| b.amplitude.total_cmp(&a.amplitude));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_a_lag_and_an_oscillation() {
        let dt = 0.002;
        let c: Vec<f64> = (0..2000).map(|i| (i as f64 * dt * 3.0).sin()).collect();
        let a: Vec<f64> = (0..2000).map(|i| ((i as f64 * dt - 0.04) * 3.0).sin()).collect();
        let l = lag(&c, &a, dt).unwrap();
        assert!((l - 0.04).abs() < 1.5 * dt, "{l}");
        // 12 Hz, 0.02 rad on a slow 0.5 Hz swing.
        let s = Signal {
            name: "knee position".into(),
            t_secs: (0..2000).map(|i| i as f64 * dt).collect(),
            v: (0..2000)
                .map(|i| {
                    let t = i as f64 * dt;
                    0.3 * (t * std::f64::consts::PI).sin() + 0.02 * (t * 2.0 * std::f64::consts::PI * 12.0).sin()
                })
                .collect(),
        };
        let o = oscillations(&[s], None);
        assert_eq!(o.len(), 1);
        assert_eq!(o[0].joint, "knee");
        assert!((o[0].frequency_hz - 12.0).abs() < 0.5, "{o:?}");
        assert!((o[0].amplitude - 0.02).abs() < 0.006, "{o:?}");
    }
}
