//! The identification pipeline: condition → diagnose → regressor → base parameters → weighted
//! least squares → physically consistent fit → statistics → report.

use crate::condition::{ConditionOptions, Conditioned, condition, quote_list};
use crate::error::{Error, Result};
use crate::estimate::{Accumulator, Bounds, Identifiability, ParamKind, base_analysis, consistent_fit};
use crate::log::JointLog;
use crate::model::{LINK_PARAM_NAMES, LINK_PARAMS, MassProperties, RobotModel, physically_valid};
use crate::regressor::{FrictionModel, Layout, Regressor};
use crate::report::{BaseParamReport, BaseRowReport, JointReport, LinkReport, NrmseReport, ParamReport, Report};
use faer::Mat;
use std::time::Instant;

/// How the robot's base was held while logging.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Base {
    /// Bolted down or hung on a gantry: the base does not move (default).
    #[default]
    Fixed,
    /// Free-floating base: the log carries the base motion ([`JointLog::base`]) and, when the
    /// robot touches anything, the contact wrenches ([`JointLog::wrenches`]); the robot is
    /// loaded with [`RobotModel::from_urdf_floating`]. The free joint's 6 rows join the joint
    /// rows: `0 = Y_base·π − J_baseᵀ·w_ext`.
    Floating,
}

/// Identification options.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct SysidOptions {
    /// Filtering, resampling and decimation (default: [`ConditionOptions::default`]).
    pub condition: ConditionOptions,
    /// Friction columns per joint (default: viscous + Coulomb `sign(q̇)` + armature, no offset).
    pub friction: FrictionModel,
    /// Rows of a joint whose speed is below this (rad/s or m/s) are left out: Coulomb friction
    /// is undetermined there (default: 0.05).
    #[default(0.05)]
    pub velocity_deadzone: f64,
    /// Rows of a joint closer than this many cut-off periods (`1/cutoff_hz` of
    /// [`ConditionOptions`]) to a reversal of its velocity are left out too (default: 0.5): the
    /// low-pass filter spreads the Coulomb friction's jump over about a period on each side of
    /// the reversal, which the model's `sign(q̇)` column can't follow; kept, those rows bias the
    /// Coulomb estimate low (by 10 % and more on fast-reversing joints) and set a floor under
    /// the torque error of light joints with strong friction.
    #[default(0.5)]
    pub reversal_guard_periods: f64,
    /// Relative standard deviation of the CAD (URDF) values in the prior that keeps directions
    /// the log cannot see at CAD (default: 1.0, i.e. CAD trusted to about ±100 %: a weak pull).
    #[default(1.0)]
    pub prior_rel_std: f64,
    /// A joint whose range of motion is below this (rad or m) "barely moved" (default: 0.05).
    #[default(0.05)]
    pub min_motion: f64,
    /// Condition numbers above this are reported as an under-exciting log (default: 1e4).
    #[default(1e4)]
    pub max_condition: f64,
    /// Refuse (error) instead of warning when the diagnosis finds problems (default: false).
    pub strict: bool,
    /// Base of the robot (default: [`Base::Fixed`]).
    #[default(Base::Fixed)]
    pub base: Base,
    /// Newton-step limit of the physically consistent fit (default: 200).
    #[default(200)]
    pub max_iterations: usize,
}

/// The result of [`identify`].
#[derive(Debug, Clone)]
pub struct Identification {
    /// Column layout of the parameter vectors.
    pub layout: Layout,
    /// URDF parameters (links: standard parameters; joints: damping, friction, armature, 0).
    pub before: Vec<f64>,
    /// Identified, physically consistent parameters.
    pub after: Vec<f64>,
    /// Posterior standard deviation of each parameter.
    pub std: Vec<f64>,
    /// Identifiability of each parameter.
    pub identifiability: Vec<Identifiability>,
    /// The report.
    pub report: Report,
}

impl Identification {
    /// Identified standard parameters of link `l` (index into [`RobotModel::links`]).
    pub fn link_params(&self, l: usize) -> [f64; LINK_PARAMS] {
        let c = self.layout.link_col(l);
        self.after[c..c + LINK_PARAMS].try_into().expect("10 parameters")
    }

    /// Identified `(viscous, coulomb, armature)` of joint `j`.
    pub fn joint_friction(&self, j: usize) -> (f64, f64, f64) {
        let c = self.layout.joint_col(j);
        (self.after[c], self.after[c + 1], self.after[c + 2])
    }
}

/// URDF values of every parameter, in [`Layout`] order.
pub fn cad_params(robot: &RobotModel, layout: &Layout) -> Vec<f64> {
    let mut p = vec![0.0; layout.ncols()];
    for (l, link) in robot.links.iter().enumerate() {
        p[layout.link_col(l)..layout.link_col(l) + LINK_PARAMS].copy_from_slice(&link.cad);
    }
    for (j, joint) in robot.joints.iter().enumerate() {
        let c = layout.joint_col(j);
        p[c] = joint.damping;
        p[c + 1] = joint.friction;
        p[c + 2] = joint.armature;
    }
    p
}

/// Columns a floating base's rows can be non-zero in: every link the free joint moves.
fn base_columns(robot: &RobotModel, layout: &Layout) -> Vec<usize> {
    let mut cols = Vec::new();
    for (l, link) in robot.links.iter().enumerate() {
        if link.floating {
            cols.extend(layout.link_col(l)..layout.link_col(l) + LINK_PARAMS);
        }
    }
    cols
}

/// Names of a floating base's 6 rows (the free joint's DOFs).
pub const BASE_ROW_NAMES: [&str; 6] = [
    "base force x (N)",
    "base force y (N)",
    "base force z (N)",
    "base torque x (N·m)",
    "base torque y (N·m)",
    "base torque z (N·m)",
];

/// Columns joint `j`'s rows can be non-zero in.
pub(crate) fn joint_columns(robot: &RobotModel, layout: &Layout, j: usize) -> Vec<usize> {
    let mut cols = Vec::new();
    for (l, link) in robot.links.iter().enumerate() {
        if link.ancestor_joints.contains(&j) {
            cols.extend(layout.link_col(l)..layout.link_col(l) + LINK_PARAMS);
        }
    }
    let c = layout.joint_col(j);
    cols.extend(c..c + layout.friction.columns_per_joint());
    cols
}

/// Body ids of the log's wrench series: `(series index, body)` for the series whose frame is a
/// body of the robot; warnings for the others.
pub(crate) fn wrench_bodies(robot: &RobotModel, log: &JointLog) -> (Vec<(usize, usize)>, Vec<String>) {
    let mut found = Vec::new();
    let mut warnings = Vec::new();
    for (i, w) in log.wrenches.iter().enumerate() {
        match robot.model.id(twin_core::mj::ObjType::Body, &w.body) {
            Some(b) if b > 0 => found.push((i, b)),
            _ => warnings.push(format!(
                "wrench topic {} is expressed in frame \"{}\", which is not a link of {}: ignored \
                 (contact wrenches must name the link they act on in header.frame_id)",
                w.topic,
                w.body,
                robot.urdf_path.display()
            )),
        }
    }
    (found, warnings)
}

/// Calls `f(rows, target, ext, used)` for every conditioned sample: the regressor rows
/// ([`Regressor::nrows`] × ncols), the measured side `τ + Jᵀ·w_ext` (joints) and `Jᵀ·w_ext`
/// (base rows), the external part `Jᵀ·w_ext` alone, and per joint whether its row is used: its
/// speed at least `opts.velocity_deadzone` and its velocity's nearest reversal at least
/// `opts.reversal_guard_periods` cut-off periods away.
pub(crate) fn for_each_sample(
    robot: &RobotModel,
    reg: &mut Regressor<'_>,
    data: &Conditioned,
    wrenches: &[(usize, usize)],
    opts: &SysidOptions,
    mut f: impl FnMut(&[f64], &[f64], &[f64], &[bool]),
) -> Result<()> {
    let guard_secs = opts.reversal_guard_periods / data.cutoff_hz;
    let nj = robot.joints.len();
    let nr = reg.nrows();
    let ncols = reg.layout().ncols();
    let mut rows = vec![0.0; nr * ncols];
    let mut ext = vec![0.0; nr];
    let mut target = vec![0.0; nr];
    let mut w = Vec::with_capacity(wrenches.len());
    let (mut q, mut qd, mut qdd) = (vec![0.0; nj], vec![0.0; nj], vec![0.0; nj]);
    let mut used_now = vec![false; nj];
    for seg in &data.segments {
        let used: Vec<Vec<bool>> =
            (0..nj).map(|j| rows_used(&seg.t_secs, &seg.qd[j], opts.velocity_deadzone, guard_secs)).collect();
        for k in 0..seg.len() {
            for j in 0..nj {
                q[j] = seg.q[j][k];
                qd[j] = seg.qd[j][k];
                qdd[j] = seg.qdd[j][k];
            }
            for (u, joint_used) in used_now.iter_mut().zip(&used) {
                *u = joint_used[k];
            }
            match (robot.floating.is_some(), seg.base.get(k)) {
                (true, Some(b)) => reg.compute_floating(b, &q, &qd, &qdd, &mut rows)?,
                _ => reg.compute(&q, &qd, &qdd, &mut rows)?,
            }
            w.clear();
            w.extend(wrenches.iter().map(|&(i, body)| (body, seg.wrench[i][k])));
            if w.is_empty() {
                ext.fill(0.0);
            } else {
                reg.external_forces(&w, &mut ext)?;
            }
            for r in 0..nr {
                target[r] = if r < nj { seg.tau[r][k] } else { 0.0 } + ext[r];
            }
            f(&rows, &target, &ext, &used_now);
        }
    }
    Ok(())
}

/// Whether each sample of one joint's velocity `qd` (at times `t_secs`) makes a row: at least
/// `deadzone` fast and more than `guard_secs` from the nearest sign change of `qd`.
fn rows_used(t_secs: &[f64], qd: &[f64], deadzone: f64, guard_secs: f64) -> Vec<bool> {
    let n = qd.len();
    // Time of the last reversal at or before each sample, then of the next one after it.
    let mut last = vec![f64::NEG_INFINITY; n];
    for k in 1..n {
        last[k] = if qd[k].signum() != qd[k - 1].signum() { 0.5 * (t_secs[k] + t_secs[k - 1]) } else { last[k - 1] };
    }
    let mut next = f64::INFINITY;
    let mut used = vec![false; n];
    for k in (0..n).rev() {
        if k + 1 < n && qd[k].signum() != qd[k + 1].signum() {
            next = 0.5 * (t_secs[k] + t_secs[k + 1]);
        }
        used[k] = qd[k].abs() >= deadzone && t_secs[k] - last[k] > guard_secs && next - t_secs[k] > guard_secs;
    }
    used
}

/// Feeds every conditioned sample into `acc` (joint rows left out where
/// [`for_each_sample`] says; base rows always in).
fn accumulate(
    robot: &RobotModel,
    reg: &mut Regressor<'_>,
    data: &Conditioned,
    wrenches: &[(usize, usize)],
    opts: &SysidOptions,
    acc: &mut Accumulator,
) -> Result<()> {
    let nj = robot.joints.len();
    let nr = reg.nrows();
    let ncols = reg.layout().ncols();
    for_each_sample(robot, reg, data, wrenches, opts, |rows, target, _, used| {
        for r in 0..nr {
            if r >= nj || used[r] {
                acc.push(r, &rows[r * ncols..(r + 1) * ncols], target[r]);
            }
        }
    })?;
    acc.finish();
    Ok(())
}

/// Prior scale of each parameter (its typical size), for the weak pull toward CAD.
fn prior_scales(robot: &RobotModel, layout: &Layout) -> Vec<f64> {
    let mut s = vec![1.0; layout.ncols()];
    for (l, link) in robot.links.iter().enumerate() {
        let m = link.cad[0].max(1e-6);
        let tr = link.cad[4] + link.cad[6] + link.cad[9];
        let len = (tr / (2.0 * m)).max(0.0).sqrt().max(0.01);
        let c = layout.link_col(l);
        s[c] = m;
        for k in 1..4 {
            s[c + k] = m * len;
        }
        for k in 4..10 {
            s[c + k] = m * len * len;
        }
    }
    for (j, joint) in robot.joints.iter().enumerate() {
        let c = layout.joint_col(j);
        s[c] = joint.damping.max(0.1);
        s[c + 1] = joint.friction.max(0.1);
        s[c + 2] = joint.armature.max(0.01);
        if layout.friction.offset {
            s[c + 3] = 1.0;
        }
        if let Some(k) = layout.friction.asymmetry_col() {
            s[c + k] = 0.1;
        }
    }
    s
}

fn nrmse_from(acc: &Accumulator, j: usize, params: &[f64]) -> f64 {
    let zero = vec![0.0; params.len()];
    let tau2 = acc.residual2(j, &zero);
    if tau2 <= 0.0 { f64::NAN } else { (acc.residual2(j, params) / tau2).sqrt() }
}

/// Identifies `robot`'s link inertias and joint friction from `log`.
///
/// # Errors
/// [`Error::BadLog`] for unusable logs (no effort, unmatched joints, NaNs …),
/// [`Error::NotExcited`] when the robot did not move enough (or, with `strict`, any diagnosis
/// problem), [`Error::Option`] for floating base or bad options, [`Error::Numerical`].
pub fn identify(robot: &RobotModel, log: &JointLog, opts: &SysidOptions) -> Result<Identification> {
    let started = Instant::now();
    // Results must not depend on the thread count: faer's parallel kernels may sum in a
    // different order. The matrices here are small; sequential costs little.
    faer::set_global_parallelism(faer::Par::Seq);
    match (opts.base, &robot.floating, &log.base) {
        (Base::Fixed, None, _) | (Base::Floating, Some(_), Some(_)) => {}
        (Base::Fixed, Some(_), _) => {
            return Err(Error::Option {
                name: "base",
                message: "the robot was loaded with a floating base; use Base::Floating, or RobotModel::from_urdf \
                          for a fixed base"
                    .into(),
            });
        }
        (Base::Floating, None, _) => {
            return Err(Error::Option {
                name: "base",
                message: "Base::Floating needs the robot loaded with RobotModel::from_urdf_floating".into(),
            });
        }
        (Base::Floating, Some(_), None) => {
            return Err(Error::BadLog {
                source_name: log.source.clone(),
                message: "--base floating needs the base motion in the log (nav_msgs/msg/Odometry of the base \
                          link); record it, or hang the robot on a gantry and use --base fixed"
                    .into(),
            });
        }
    }
    if !(opts.prior_rel_std > 0.0 && opts.prior_rel_std.is_finite()) {
        return Err(Error::Option {
            name: "prior_rel_std",
            message: format!("{} must be positive and finite", opts.prior_rel_std),
        });
    }
    let data = condition(log, robot, &opts.condition)?;
    let mut warnings = data.warnings.clone();
    let nj = robot.joints.len();
    let (wrenches, wrench_warnings) = wrench_bodies(robot, log);
    warnings.extend(wrench_warnings);
    let base_description = match (&robot.floating, &log.base) {
        (Some(_), Some(b)) => {
            if wrenches.is_empty() {
                warnings.push(
                    "no contact wrench topic (geometry_msgs/msg/WrenchStamped with a link's name as \
                     header.frame_id) in the log: the base rows assume the robot touched nothing (free flight, \
                     momentum conserved); if it stood or walked, record the contact wrenches"
                        .to_string(),
                );
            }
            format!("floating base (base motion from {}, {} contact wrench topics)", b.topic, wrenches.len())
        }
        _ => "fixed base".to_string(),
    };

    // Diagnosis of excitation, before any fitting.
    let still: Vec<String> =
        (0..nj).filter(|&j| data.joint_range[j] < opts.min_motion).map(|j| robot.joints[j].name.clone()).collect();
    let mut problems = Vec::new();
    if still.len() == nj {
        return Err(Error::NotExcited {
            source_name: log.source.clone(),
            problems: vec![format!(
                "no joint moved more than {} rad: the robot stood still. Log the robot following an \
                 exciting trajectory (e.g. sums of sines over each joint's range)",
                opts.min_motion
            )],
        });
    }
    if !still.is_empty() {
        problems.push(format!(
            "joint(s) {} barely moved (range < {} rad): their friction and the inertia they alone see \
             stay near the URDF values",
            quote_list(&still),
            opts.min_motion
        ));
    }

    let fm = opts.friction;
    let mut reg = Regressor::new(robot, fm)?;
    let layout = reg.layout();
    let n = layout.ncols();
    let nr = reg.nrows();
    let mut cols: Vec<Vec<usize>> = (0..nj).map(|j| joint_columns(robot, &layout, j)).collect();
    for _ in nj..nr {
        cols.push(base_columns(robot, &layout));
    }
    let mut acc = Accumulator::new(n, cols);
    accumulate(robot, &mut reg, &data, &wrenches, opts, &mut acc)?;
    let total_rows = acc.total_rows();
    let few: Vec<String> = (0..nj).filter(|&j| acc.rows(j) < 50).map(|j| robot.joints[j].name.clone()).collect();
    if !few.is_empty() {
        problems.push(format!(
            "joint(s) {} were almost never faster than the {} rad/s dead zone",
            quote_list(&few),
            opts.velocity_deadzone
        ));
    }

    let before = cad_params(robot, &layout);
    // Effort semantics: the CAD model should explain the torques up to CAD errors.
    for (j, joint) in robot.joints.iter().enumerate() {
        let wp2 = acc.quadratic(j, &before, 0.0);
        let t2 = acc.residual2(j, &vec![0.0; n]);
        let d2 = acc.residual2(j, &before);
        if wp2 > 0.0 && t2 > 0.0 {
            let gain = (wp2 + t2 - d2) / (2.0 * wp2);
            if gain < 0.0 {
                problems.push(format!(
                    "joint \"{}\": the logged effort has the opposite sign of what the URDF model predicts \
                     (best gain {gain:.2}); check the effort sign convention",
                    joint.name
                ));
            } else if !(0.33..=3.0).contains(&gain) {
                problems.push(format!(
                    "joint \"{}\": the logged effort is {gain:.2}× what the URDF model predicts; is it motor \
                     current or motor-side torque rather than joint torque?",
                    joint.name
                ));
            }
        }
    }

    // Pass 1: unweighted least squares for the per-joint noise levels.
    // Row groups (each joint; each base row) get their own noise level: a base row carries
    // force or torque on the whole robot, with its own scale and noise (odometry differentiated
    // twice, wrench sensors), so one weight for all would let one kind of row dominate.
    let rz1 = acc.compressed(&vec![1.0; nr]);
    let ba1 = base_analysis(&rz1, total_rows)?;
    let rank1 = ba1.rank.max(1);
    let sigma: Vec<f64> = (0..nr)
        .map(|j| {
            let rows = acc.rows(j) as f64;
            let dof = (rows * (1.0 - rank1 as f64 / total_rows as f64)).max(1.0);
            let s = (acc.residual2(j, &ba1.ols) / dof).sqrt();
            let t = (acc.residual2(j, &vec![0.0; n]) / rows.max(1.0)).sqrt();
            // A floor so a perfectly fitted joint does not take all the weight.
            s.max(1e-6 * t).max(1e-12)
        })
        .collect();
    let weights: Vec<f64> = sigma.iter().map(|s| 1.0 / s).collect();
    // Pass 2: weighted.
    let rz = acc.compressed(&weights);
    let ba = base_analysis(&rz, total_rows)?;
    if ba.condition > opts.max_condition {
        problems.push(format!(
            "condition number {:.3e} of the base regressor exceeds {:.0e}: the log excites some \
             combinations weakly; their estimates lean on the URDF values",
            ba.condition, opts.max_condition
        ));
    }
    if opts.strict && !problems.is_empty() {
        return Err(Error::NotExcited { source_name: log.source.clone(), problems });
    }
    warnings.extend(problems);

    // Physically consistent fit: H = RᵀR + P, b = Rᵀz + P·π_cad.
    let scales = prior_scales(robot, &layout);
    let prior: Vec<f64> = scales.iter().map(|s| 1.0 / (opts.prior_rel_std * s).powi(2)).collect();
    let r = Mat::from_fn(n, n, |i, j| rz[(i, j)]);
    let mut h = r.transpose() * &r;
    let mut b = vec![0.0; n];
    for i in 0..n {
        b[i] = (0..=i).map(|k| rz[(k, i)] * rz[(k, n)]).sum::<f64>() + prior[i] * before[i];
        h[(i, i)] += prior[i];
    }
    let mut kinds = vec![ParamKind::Free; n];
    for l in 0..layout.links {
        let c = layout.link_col(l);
        kinds[c] = ParamKind::Link;
        for k in 1..LINK_PARAMS {
            kinds[c + k] = ParamKind::LinkRest;
        }
    }
    for j in 0..nj {
        let c = layout.joint_col(j);
        for k in 0..3 {
            kinds[c + k] = ParamKind::NonNegative;
        }
    }
    // Constant part of the cost: ‖z‖² + ρ² + Σ p·π_cad², so that f + offset is the χ²-like cost.
    let offset = (0..=n).map(|i| rz[(i, n)] * rz[(i, n)]).sum::<f64>()
        + (0..n).map(|i| prior[i] * before[i] * before[i]).sum::<f64>();
    // A body's fixed-joint links keep their URDF share: the physical constraint is on the rest,
    // the URDF link's own share, which is what the write-back puts in its `<inertial>`.
    let mut shift = vec![0.0; n];
    for (l, link) in robot.links.iter().enumerate() {
        shift[layout.link_col(l)..layout.link_col(l) + LINK_PARAMS].copy_from_slice(&link.welded);
    }
    let fit = consistent_fit(
        &h,
        &b,
        offset,
        &before,
        &Bounds { kinds: &kinds, scales: &scales, shift: &shift },
        opts.max_iterations,
    )?;
    let (after, iterations) = (fit.params, fit.steps);
    if fit.max_ridge > 1e-8 {
        warnings.push(format!(
            "the physically consistent fit needed a regularisation of {:.1e} (relative) on some Newton steps: \
             the data leave some directions nearly flat; the prior holds them near the URDF values",
            fit.max_ridge
        ));
    }
    // Posterior covariance σ²·H⁻¹ (data and prior together), column by column.
    let s2 = ba.sigma2.max(1e-300);
    let std: Vec<f64> = (0..n)
        .map(|i| {
            let mut e = vec![0.0; n];
            e[i] = 1.0;
            crate::estimate::solve_spd(&h, &e).map_or(f64::INFINITY, |x| (s2 * x.solution[i]).max(0.0).sqrt())
        })
        .collect();

    // Report.
    let param_report = |name: &str, i: usize| ParamReport {
        name: name.to_string(),
        before: before[i],
        after: after[i],
        std: std[i],
        identifiability: ba.identifiability[i],
    };
    let links: Vec<LinkReport> = robot
        .links
        .iter()
        .enumerate()
        .map(|(l, link)| {
            let c = layout.link_col(l);
            let p: [f64; LINK_PARAMS] = after[c..c + LINK_PARAMS].try_into().expect("10");
            let mp = MassProperties::from_params(&p);
            let (mass_kg, com_link, inertia_com) = mp.map_or((p[0], [f64::NAN; 3], [f64::NAN; 6]), |mp| {
                let i = mp.inertia_com;
                (
                    mp.mass_kg,
                    [mp.com_link.x, mp.com_link.y, mp.com_link.z],
                    [i[(0, 0)], i[(0, 1)], i[(0, 2)], i[(1, 1)], i[(1, 2)], i[(2, 2)]],
                )
            });
            LinkReport {
                name: link.name.clone(),
                params: (0..LINK_PARAMS).map(|k| param_report(LINK_PARAM_NAMES[k], c + k)).collect(),
                mass_kg,
                com_link,
                inertia_com,
                physically_valid: physically_valid(&p),
            }
        })
        .collect();
    let joints: Vec<JointReport> = robot
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let c = layout.joint_col(j);
            JointReport {
                name: joint.name.clone(),
                params: fm.column_names().iter().enumerate().map(|(k, name)| param_report(name, c + k)).collect(),
                range_of_motion: data.joint_range[j],
                rms_velocity: data.joint_rms_velocity[j],
                noise_std: sigma[j],
            }
        })
        .collect();
    let label = |i: usize| -> String {
        if i < layout.links * LINK_PARAMS {
            format!("{}[{}]", LINK_PARAM_NAMES[i % LINK_PARAMS], robot.links[i / LINK_PARAMS].name)
        } else {
            let k = i - layout.links * LINK_PARAMS;
            let per = fm.columns_per_joint();
            format!("{}[{}]", fm.column_names()[k % per], robot.joints[k / per].name)
        }
    };
    let base_parameters = ba
        .base
        .iter()
        .map(|bp| {
            let mut expression = label(bp.lead);
            let mut terms = bp.terms.clone();
            terms.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            for (i, (other, coef)) in terms.iter().enumerate() {
                if i == 4 {
                    expression.push_str(&format!(" + … ({} more)", terms.len() - 4));
                    break;
                }
                let sign = if *coef < 0.0 { '−' } else { '+' };
                expression.push_str(&format!(" {sign} {:.4}·{}", coef.abs(), label(*other)));
            }
            BaseParamReport {
                expression,
                value: bp.value,
                std: bp.std,
                rel_std_percent: if bp.value != 0.0 { 100.0 * bp.std / bp.value.abs() } else { f64::INFINITY },
            }
        })
        .collect();
    let training_nrmse = robot
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| NrmseReport {
            joint: joint.name.clone(),
            before: nrmse_from(&acc, j, &before),
            after: nrmse_from(&acc, j, &after),
        })
        .collect();
    let base_rows = (nj..nr)
        .map(|r| {
            let rows = acc.rows(r).max(1) as f64;
            let rms = |p: &[f64]| (acc.residual2(r, p) / rows).sqrt();
            BaseRowReport {
                row: BASE_ROW_NAMES[r - nj].to_string(),
                rms_external: rms(&vec![0.0; n]),
                before_rms: rms(&before),
                after_rms: rms(&after),
                noise_std: sigma[r],
            }
        })
        .collect();
    let report = Report {
        generator: concat!("twin/", env!("CARGO_PKG_VERSION")).to_string(),
        robot: robot.urdf_path.display().to_string(),
        log: log.source.clone(),
        base: if robot.floating.is_some() { "floating" } else { "fixed" }.into(),
        base_description,
        log_samples: data.raw_samples,
        rate_hz: data.rate_hz,
        cutoff_hz: data.cutoff_hz,
        filter_order: data.filter_order,
        regressor_rate_hz: data.regressor_rate_hz,
        segments: data.segments.len(),
        rows: total_rows,
        parameters: n,
        rank: ba.rank,
        condition_number: ba.condition,
        fit_iterations: iterations,
        wall_secs: started.elapsed().as_secs_f64(),
        warnings,
        links,
        joints,
        base_parameters,
        training_nrmse,
        base_rows,
        validation_nrmse: None,
        validation_log: None,
        selection: Vec::new(),
        held_out: None,
        joint_friction: Vec::new(),
    };
    let mut ident = Identification { layout, before, after, std, identifiability: ba.identifiability, report };
    ident.report.joint_friction = crate::select::joint_frictions(robot, &ident);
    Ok(ident)
}

/// Per-joint torque NRMSE (`rms(τ_model − τ_log) / rms(τ_log)`) of `params` on the held-out
/// `log`, conditioned as for identification, on the rows identification would use (outside the
/// velocity dead zone and the reversal guard, where no friction model predicts the torque).
///
/// # Errors
/// As [`identify`]'s conditioning.
pub fn validate(robot: &RobotModel, log: &JointLog, opts: &SysidOptions, params: &[&[f64]]) -> Result<Vec<Vec<f64>>> {
    if robot.floating.is_some() && log.base.is_none() {
        return Err(Error::BadLog {
            source_name: log.source.clone(),
            message: "the held-out log has no base motion (nav_msgs/msg/Odometry) for the floating base".into(),
        });
    }
    let data = condition(log, robot, &opts.condition)?;
    let (wrenches, _) = wrench_bodies(robot, log);
    let nj = robot.joints.len();
    let mut reg = Regressor::new(robot, opts.friction)?;
    let ncols = reg.layout().ncols();
    let mut err2 = vec![vec![0.0; nj]; params.len()];
    let mut tau2 = vec![0.0; nj];
    for_each_sample(robot, &mut reg, &data, &wrenches, opts, |rows, target, ext, used| {
        for j in 0..nj {
            if !used[j] {
                continue;
            }
            // Normalised by the measured torque; the prediction is Y·π − Jᵀ·w_ext.
            let t = target[j];
            tau2[j] += (t - ext[j]) * (t - ext[j]);
            let row = &rows[j * ncols..(j + 1) * ncols];
            for (p, e) in params.iter().zip(err2.iter_mut()) {
                let pred: f64 = row.iter().zip(p.iter()).map(|(a, b)| a * b).sum();
                e[j] += (pred - t) * (pred - t);
            }
        }
    })?;
    Ok(err2.iter().map(|e| (0..nj).map(|j| (e[j] / tau2[j]).sqrt()).collect()).collect())
}

/// The URDF edits of an identification: the links and joints the log determined (at least one
/// parameter identifiable alone or in combination).
pub fn urdf_updates(
    robot: &RobotModel,
    ident: &Identification,
) -> (Vec<crate::writeback::LinkUpdate>, Vec<crate::writeback::JointUpdate>) {
    let layout = &ident.layout;
    let seen =
        |c: usize, n: usize| ident.identifiability[c..c + n].iter().any(|i| *i != Identifiability::NotIdentifiable);
    let links = robot
        .links
        .iter()
        .enumerate()
        .filter(|&(l, _)| seen(layout.link_col(l), LINK_PARAMS))
        .filter_map(|(l, link)| {
            // The URDF link's own share: fixed-joint links lumped into its body keep their values.
            let own = link.own_params(&ident.link_params(l));
            if link.welded != [0.0; LINK_PARAMS] && !physically_valid(&own) {
                return None;
            }
            MassProperties::from_params(&own).map(|mp| {
                // A link identified on the boundary of physical validity (a triangle inequality
                // holding with equality) could cross it when the URDF's 7 significant digits
                // round it: 2e-6 of the trace added isotropically keeps a margin (far below σ).
                let e = mp.inertia_com.symmetric_eigenvalues();
                let trace = mp.inertia_com.trace().max(0.0);
                let margin = (e[0] + e[1] - e[2]).min(e[1] + e[2] - e[0]).min(e[0] + e[2] - e[1]).min(e.min());
                let inertia_com = if margin < 1e-5 * trace {
                    mp.inertia_com + nalgebra::Matrix3::identity() * (2e-6 * trace)
                } else {
                    mp.inertia_com
                };
                crate::writeback::LinkUpdate {
                    name: link.name.clone(),
                    mass_kg: mp.mass_kg,
                    com_link: mp.com_link,
                    inertia_com,
                }
            })
        })
        .collect();
    let joints = robot
        .joints
        .iter()
        .enumerate()
        .filter(|&(j, _)| seen(layout.joint_col(j), 2))
        .map(|(j, joint)| {
            let (viscous, coulomb, _) = ident.joint_friction(j);
            crate::writeback::JointUpdate { name: joint.name.clone(), damping: viscous, friction: coulomb }
        })
        .collect();
    (links, joints)
}
