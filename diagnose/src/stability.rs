//! Balance from a log and a model: at each base pose the model is posed (base from odometry,
//! joints from the JointState series by name, interpolated) and gives the CoM (the base
//! body's subtree), the capture point (CoM + v/ω, ω = √(g / CoM height above the ground)) and
//! the support polygon: the bottom points of the collision geoms of the feet ([`Robot::feet`]
//! and the bodies under them; a mesh's points are the corners of its box) that are on the
//! ground. A foot is on the ground when its contact topic (`/contacts/<foot>`) carries more than
//! 5 % of the weight or, without one, when its lowest point is within 1 cm of the ground (the
//! feet's lowest collision point over the first half second, the median). Margins are signed distances inside the polygon
//! ([`twin_controllers::walk::metrics::support_margin`]). A loaded foot that is flat (tilt < 0.15 rad)
//! and moves horizontally faster than the slip speed for three samples slips.

use super::fall::Fall;
use super::signal::{Signal, quantile};
use serde::Serialize;
use std::sync::Arc;
use twin_core::error::Result;
use twin_core::mj::{Data, GeomType, Model};
use twin_core::robot::Robot;

/// A point (CoM or capture point) leaving the support polygon.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Exit {
    /// When it left (the last exit before the fall), s.
    pub time_secs: f64,
    /// How far it is beyond the polygon along the heading at that time plus 0.1 s (positive:
    /// ahead of the front edge; negative: behind the back edge), m.
    pub beyond_forward_m: f64,
    /// The same to the left (positive: left of the left edge; negative: right of the right edge), m.
    pub beyond_left_m: f64,
}

/// A foot slipping.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Slip {
    /// The foot body.
    pub foot: String,
    /// When it started, s.
    pub time_secs: f64,
    /// Its horizontal speed then, m/s.
    pub speed_mps: f64,
    /// The normal load on it then, N (from its contact topic; NaN without).
    pub normal_force_n: f64,
    /// Tangential over normal contact force then (its contact topic, in the foot's frame).
    pub tangential_over_normal: Option<f64>,
    /// The largest slip speed before the fall, m/s.
    pub max_speed_mps: f64,
}

/// The balance findings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stability {
    /// The model file.
    pub model: String,
    /// Smallest CoM margin before the fall (or over the log), m.
    pub com_margin_min_m: f64,
    /// CoM margin at the onset (at the end without a fall), m.
    pub com_margin_at_onset_m: f64,
    /// Smallest capture-point margin before the fall, m.
    pub cp_margin_min_m: f64,
    /// Capture-point margin at the onset, m.
    pub cp_margin_at_onset_m: f64,
    /// The CoM's last exit from the polygon before the fall.
    pub com_exit: Option<Exit>,
    /// The capture point's last exit before the fall.
    pub cp_exit: Option<Exit>,
    /// The first slip before the fall.
    pub slip: Option<Slip>,
    /// The largest horizontal speed of a loaded flat foot before the fall, m/s.
    pub max_foot_speed_mps: f64,
    #[serde(skip)]
    pub(crate) com_margin_signal: Signal,
    #[serde(skip)]
    pub(crate) cp_margin_signal: Signal,
}

/// Collision geoms of the feet and the bodies under them, per foot.
fn foot_geoms(model: &Model, feet: &[usize]) -> Vec<Vec<usize>> {
    let parent = model.body_parentid();
    let under = |mut b: usize, foot: usize| {
        while b != 0 {
            if b == foot {
                return true;
            }
            b = parent[b] as usize;
        }
        false
    };
    feet.iter()
        .map(|&f| {
            (0..model.ngeom())
                .filter(|&g| {
                    let b = model.geom_bodyid()[g] as usize;
                    (model.geom_contype()[g] != 0 || model.geom_conaffinity()[g] != 0) && under(b, f)
                })
                .collect()
        })
        .collect()
}

/// World points at the bottom of geom `g` (box corners, sphere and capsule centres, the centre
/// of others), with their heights.
fn bottom_points(model: &Model, data: &Data, g: usize, out: &mut Vec<[f64; 3]>) {
    let c = data.geom_xpos()[g];
    let m = data.geom_xmat()[g];
    let s = model.geom_size()[g];
    let at = |l: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|i| c[i] + m[3 * i] * l[0] + m[3 * i + 1] * l[1] + m[3 * i + 2] * l[2])
    };
    match model.geom_kind(g) {
        GeomType::Box => {
            for k in 0..8 {
                let sign = |b: usize| if k & (1 << b) == 0 { -1.0 } else { 1.0 };
                let p = at([sign(0) * s[0], sign(1) * s[1], sign(2) * s[2]]);
                out.push(p);
            }
        }
        GeomType::Capsule | GeomType::Cylinder => {
            let r = s[0];
            for sign in [-1.0, 1.0] {
                let p = at([0.0, 0.0, sign * s[1]]);
                out.push([p[0], p[1], p[2] - r]);
            }
        }
        GeomType::Sphere => out.push([c[0], c[1], c[2] - s[0]]),
        _ => {
            // A mesh (or other shape): the corners of MuJoCo's box around it in its frame, not
            // its bounding sphere (a sole's sphere reaches half its length below the ground).
            let [cx, cy, cz, hx, hy, hz] = model.geom_aabb()[g];
            for k in 0..8 {
                let sign = |b: usize| if k & (1 << b) == 0 { -1.0 } else { 1.0 };
                out.push(at([cx + sign(0) * hx, cy + sign(1) * hy, cz + sign(2) * hz]));
            }
        }
    }
}

/// Signed distance of `p` beyond the extent of `pts` along unit `dir` (positive: beyond the
/// far side; negative: beyond the near side; zero: within).
fn beyond(pts: &[[f64; 2]], p: [f64; 2], dir: [f64; 2]) -> f64 {
    let proj = |q: [f64; 2]| q[0] * dir[0] + q[1] * dir[1];
    let (lo, hi) =
        pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| (lo.min(proj(*q)), hi.max(proj(*q))));
    let x = proj(p);
    if x > hi {
        x - hi
    } else if x < lo {
        x - lo
    } else {
        0.0
    }
}

/// Per foot: world position, flat, loaded, normal force (N), tangential/normal ratio.
type FootState = ([f64; 3], bool, bool, f64, Option<f64>);

/// Per posed sample: per foot, its bottom points (world) that may support it.
type Candidates = Vec<(usize, Vec<(usize, Vec<[f64; 3]>)>)>;

/// A contact's force magnitude and tangential/normal ratio.
type SignalPair<'a> = (&'a Signal, &'a Signal);

/// One posed sample.
struct Posed {
    t: f64,
    com: [f64; 3],
    /// Support points (xy) of the feet on the ground.
    support: Vec<[f64; 2]>,
    heading: f64,
    /// Per foot: world position, flat (tilt small), loaded.
    feet: Vec<FootState>,
}

/// Poses the model along the log and measures CoM, capture point, support and slip.
///
/// # Errors
/// [`twin_core::Error::MuJoCo`] when posing fails.
pub(crate) fn compute(
    robot: &Robot,
    poses: &[super::Pose],
    positions: &[Signal],
    contacts: &[super::ContactSignals<'_>],
    fall: Option<&Fall>,
    slip_speed_mps: f64,
) -> Result<Stability> {
    let model: &Arc<Model> = &robot.model;
    let Some(base) = robot.base else { unreachable!("checked by the caller") };
    let mut data = Data::new(model.clone())?;
    let mut qpos = twin_core::control::nominal_pose(model);
    let joints: Vec<(usize, &Signal)> = robot
        .joints
        .iter()
        .filter_map(|j| {
            let name = format!("{} position", j.name);
            positions.iter().find(|s| s.name == name).map(|s| (j.qpos_adr, s))
        })
        .collect();
    let weight = model.total_mass_kg() * -model.gravity()[2];
    let g = -model.gravity()[2];
    let geoms = foot_geoms(model, &robot.feet);
    let foot_names: Vec<String> = robot.feet.iter().map(|&b| twin_core::topics::body_frame(robot, b)).collect();
    // Each foot's contact topic, if the log has one (`/contacts/<frame>`).
    let foot_contacts: Vec<Option<SignalPair<'_>>> = foot_names
        .iter()
        .map(|n| {
            let topic = format!("/contacts/{}", twin_core::topics::topic_safe(n));
            contacts.iter().find(|(t, _, _)| *t == topic).map(|(_, f, r)| (*f, *r))
        })
        .collect();
    let end = fall.map_or(f64::INFINITY, |f| f.fall_time_secs + 0.25);
    // Poses past the fall tell nothing about balance; at most ~2000 per second of log.
    let mut posed: Vec<Posed> = Vec::new();
    let mut lowest: Vec<(f64, f64)> = Vec::new();
    let mut pts3 = Vec::new();
    let mut candidates: Candidates = Vec::new();
    let mut foot_up: Vec<Option<[f64; 3]>> = vec![None; geoms.len()];
    for &(t, q, p) in poses.iter().filter(|s| s.0 <= end) {
        let Some(p) = p else { continue };
        if posed.last().is_some_and(|l| t - l.t < 5e-4) {
            continue;
        }
        let a = base.qpos_adr;
        qpos[a..a + 3].copy_from_slice(&p);
        // MuJoCo quaternions are w x y z.
        qpos[a + 3..a + 7].copy_from_slice(&[q[3], q[0], q[1], q[2]]);
        for (adr, s) in &joints {
            let v = s.at(t);
            if v.is_finite() {
                qpos[*adr] = v;
            }
        }
        data.qpos_mut().copy_from_slice(&qpos);
        data.kinematics_with_velocity()?;
        let com = data.subtree_com()[base.body];
        let xm = data.xmat()[base.body];
        let heading = xm[3].atan2(xm[0]);
        let mut feet = Vec::new();
        let mut support_candidates: Vec<(usize, Vec<[f64; 3]>)> = Vec::new();
        for (k, gs) in geoms.iter().enumerate() {
            pts3.clear();
            for &geom in gs {
                bottom_points(model, &data, geom, &mut pts3);
            }
            let fb = robot.feet[k];
            let fm = data.xmat()[fb];
            // Flat: the foot's axis that pointed up at the first pose (any foot frame) still
            // within 0.15 rad of up.
            let up = *foot_up[k].get_or_insert([fm[6], fm[7], fm[8]]);
            let flat = fm[6] * up[0] + fm[7] * up[1] + fm[8] * up[2] > 0.15f64.cos();
            let (normal, ratio) = match foot_contacts[k] {
                Some((force, ratio)) => (force.held(t), Some(ratio.held(t)).filter(|r| r.is_finite())),
                None => (f64::NAN, None),
            };
            feet.push((data.xpos()[fb], flat, false, normal, ratio));
            support_candidates.push((k, pts3.clone()));
        }
        // The feet's lowest collision point (not the robot's: a visual mesh's bounding sphere
        // reaches below the ground the feet stand on).
        let feet_low =
            support_candidates.iter().flat_map(|(_, p)| p.iter().map(|q| q[2])).fold(f64::INFINITY, f64::min);
        if feet_low.is_finite() {
            lowest.push((t, feet_low));
        }
        posed.push(Posed { t, com, support: Vec::new(), heading, feet });
        // Support is decided once the ground height is known (below); keep the candidates.
        candidates.push((posed.len() - 1, support_candidates));
    }
    // Ground: the feet's lowest collision point over the first half second.
    let t0 = lowest.first().map_or(0.0, |l| l.0);
    let mut early: Vec<f64> = lowest.iter().filter(|l| l.0 <= t0 + 0.5).map(|l| l.1).collect();
    let ground = quantile(&mut early, 0.5);
    for (i, cands) in candidates {
        let p = &mut posed[i];
        for (k, pts) in cands {
            let low = pts.iter().map(|q| q[2]).fold(f64::INFINITY, f64::min);
            let loaded = match foot_contacts[k] {
                Some(_) => p.feet[k].3 > 0.05 * weight,
                None => low <= ground + 0.01,
            };
            p.feet[k].2 = loaded;
            if loaded {
                p.support.extend(pts.iter().filter(|q| q[2] <= low + 0.005).map(|q| [q[0], q[1]]));
            }
        }
    }
    // Margins.
    let n = posed.len();
    let mut com_m = Vec::with_capacity(n);
    let mut cp_m = Vec::with_capacity(n);
    let mut cps = Vec::with_capacity(n);
    for i in 0..n {
        let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
        let dt = posed[b].t - posed[a].t;
        let v = if dt > 0.0 {
            [(posed[b].com[0] - posed[a].com[0]) / dt, (posed[b].com[1] - posed[a].com[1]) / dt]
        } else {
            [0.0, 0.0]
        };
        let h = (posed[i].com[2] - ground).max(0.05);
        let omega = (g / h).sqrt();
        let com = [posed[i].com[0], posed[i].com[1]];
        let cp = [com[0] + v[0] / omega, com[1] + v[1] / omega];
        cps.push(cp);
        let mut pts = posed[i].support.clone();
        if pts.is_empty() {
            com_m.push((posed[i].t, f64::NAN));
            cp_m.push((posed[i].t, f64::NAN));
            continue;
        }
        com_m.push((posed[i].t, twin_controllers::walk::metrics::support_margin(&mut pts.clone(), com)));
        cp_m.push((posed[i].t, twin_controllers::walk::metrics::support_margin(&mut pts, cp)));
    }
    let fall_t = fall.map_or(f64::INFINITY, |f| f.fall_time_secs);
    let onset_t = fall.map_or(posed.last().map_or(0.0, |p| p.t), |f| f.onset_secs);
    let before = |m: &[(f64, f64)]| {
        m.iter().filter(|x| x.0 <= fall_t && x.1.is_finite()).map(|x| x.1).fold(f64::INFINITY, f64::min)
    };
    let at = |m: &[(f64, f64)], t: f64| {
        m.iter()
            .filter(|x| x.1.is_finite())
            .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))
            .map_or(f64::NAN, |x| x.1)
    };
    // The last exit before the fall (a fall only: a walking robot's capture point leaves the
    // polygon at every step).
    let exit = |m: &[(f64, f64)], point: &dyn Fn(usize) -> [f64; 2]| -> Option<Exit> {
        fall?;
        let idx: Vec<usize> = (0..m.len()).filter(|&i| m[i].0 <= fall_t && m[i].1.is_finite()).collect();
        let last_inside = idx.iter().rev().find(|&&i| m[i].1 >= 0.0).copied();
        let first_out = match last_inside {
            Some(li) => idx.iter().find(|&&i| i > li).copied()?,
            None => *idx.first()?,
        };
        // Where it is 0.1 s later (or at the fall), against the polygon then.
        let t_eval = (m[first_out].0 + 0.1).min(fall_t);
        let j = idx.iter().rev().find(|&&i| m[i].0 <= t_eval).copied().unwrap_or(first_out);
        let (s, c) = posed[j].heading.sin_cos();
        let p = point(j);
        Some(Exit {
            time_secs: m[first_out].0,
            beyond_forward_m: beyond(&posed[j].support, p, [c, s]),
            beyond_left_m: beyond(&posed[j].support, p, [-s, c]),
        })
    };
    let com_exit = exit(&com_m, &|j| [posed[j].com[0], posed[j].com[1]]);
    let cp_exit = exit(&cp_m, &|j| cps[j]);
    // Slip: a loaded flat foot moving, three samples in a row.
    let mut slip: Option<Slip> = None;
    let mut max_speed = 0.0f64;
    let mut run = vec![0usize; robot.feet.len()];
    let limit = fall.map_or(f64::INFINITY, |f| f.onset_secs.max(f.fall_time_secs - 0.2));
    for i in 1..n {
        if posed[i].t > limit {
            break;
        }
        let dt = posed[i].t - posed[i - 1].t;
        if dt <= 0.0 {
            continue;
        }
        for k in 0..robot.feet.len() {
            let (p1, flat, loaded, normal, ratio) = posed[i].feet[k];
            let (p0, flat0, loaded0, _, _) = posed[i - 1].feet[k];
            if !(flat && loaded && flat0 && loaded0) {
                run[k] = 0;
                continue;
            }
            let speed = (p1[0] - p0[0]).hypot(p1[1] - p0[1]) / dt;
            max_speed = max_speed.max(speed);
            run[k] = if speed > slip_speed_mps { run[k] + 1 } else { 0 };
            if run[k] == 3 && slip.is_none() {
                let start = i - 2;
                slip = Some(Slip {
                    foot: foot_names[k].clone(),
                    time_secs: posed[start].t,
                    speed_mps: speed,
                    normal_force_n: normal,
                    tangential_over_normal: ratio,
                    max_speed_mps: 0.0,
                });
            }
        }
    }
    if let Some(s) = slip.as_mut() {
        s.max_speed_mps = max_speed;
    }
    let com_margin_signal = Signal::new("CoM margin", com_m.clone());
    let cp_margin_signal = Signal::new("capture point margin", cp_m.clone());
    Ok(Stability {
        model: robot.path.display().to_string(),
        com_margin_min_m: before(&com_m),
        com_margin_at_onset_m: at(&com_m, onset_t),
        cp_margin_min_m: before(&cp_m),
        cp_margin_at_onset_m: at(&cp_m, onset_t),
        com_exit,
        cp_exit,
        slip,
        max_foot_speed_mps: max_speed,
        com_margin_signal,
        cp_margin_signal,
    })
}
