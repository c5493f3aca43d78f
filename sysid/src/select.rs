//! Defaults chosen from the data: held-out validation and time-blocked cross-validation.
//!
//! `twin sysid` without `--validate` holds out the last [`SelectOptions::held_out_fraction`]
//! of the log (30 %). On the first part it chooses the low-pass cut-off and the friction model
//! by time-blocked cross-validation ([`select`]): the part is cut into
//! [`SelectOptions::folds`] contiguous blocks of time; each candidate is fitted on all blocks
//! but one and scored on that one (never shuffled samples: neighbouring samples are
//! correlated), by its mean per-joint torque NRMSE. The cut-off is chosen first (with a smooth
//! Coulomb model and an offset, which real data need), then the friction model at that
//! cut-off; every candidate's score is reported. The held-out part then scores the URDF before,
//! the fit and any `--compare` model on the same samples ([`models_nrmse`]), and the fit written
//! back is refitted on the whole log with the chosen settings.
//!
//! Candidates are scored against the measured effort filtered at one cut-off for all
//! ([`SelectOptions::effort_cutoff_hz`]): scored each against its own filtered effort, a low
//! cut-off would win by smoothing the target rather than by predicting it.

use crate::condition::condition;
use crate::error::{Error, Result};
use crate::extension::JointFriction;
use crate::identify::{Identification, SysidOptions, for_each_sample, identify, wrench_bodies};
use crate::log::JointLog;
use crate::model::{LINK_PARAMS, LinkParams, RobotModel};
use crate::regressor::{FrictionModel, Regressor};

/// Options of [`select`] and the held-out split.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct SelectOptions {
    /// Fraction of the log (by time, at its end) held out from fitting and selection
    /// (default: 0.3).
    #[default(0.3)]
    pub held_out_fraction: f64,
    /// Number of contiguous time blocks of the cross-validation (default: 3).
    #[default(3)]
    pub folds: usize,
    /// Cut-off candidates, Hz; those at or above 0.4 × the log's Nyquist rate are skipped
    /// (default: 4, 6, 8, 10, 12, 15, 20, 25).
    #[default(vec![4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 25.0])]
    pub cutoffs_hz: Vec<f64>,
    /// Smooth-Coulomb velocity scales tried, rad/s or m/s (default: 0.02, 0.05, 0.1); `sign(q̇)`
    /// with the dead zone is always tried too.
    #[default(vec![0.02, 0.05, 0.1])]
    pub smoothings: Vec<f64>,
    /// Cut-off of the effort the candidates are scored against, Hz (default: `None`: the
    /// highest cut-off candidate the log's rate allows).
    pub effort_cutoff_hz: Option<f64>,
    /// Choose the cut-off (false: keep the one given).
    #[default(true)]
    pub choose_cutoff: bool,
    /// Choose the friction model (false: keep the one given).
    #[default(true)]
    pub choose_friction: bool,
}

/// One candidate's cross-validation result.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// Cut-off, Hz.
    pub cutoff_hz: f64,
    /// Friction model, as [`FrictionModel::describe`] says it.
    pub friction: String,
    /// Mean over folds and joints of the held-out torque NRMSE (`None`: the fit failed, see
    /// `error`).
    pub score: Option<f64>,
    /// Per joint, mean over folds.
    pub per_joint: Vec<f64>,
    /// Why the candidate could not be fitted.
    pub error: Option<String>,
    /// Whether this candidate was chosen.
    pub chosen: bool,
}

/// The result of [`select`].
#[derive(Debug, Clone)]
pub struct Selection {
    /// Options with the chosen cut-off and friction model.
    pub options: SysidOptions,
    /// Every candidate tried, in the order tried (cut-offs, then friction models).
    pub candidates: Vec<Candidate>,
}

/// A model to score: rigid-body parameters of `robot`'s links and each joint's friction.
#[derive(Debug, Clone)]
pub struct ScoredModel<'a> {
    /// The robot the parameters belong to (its links and joints).
    pub robot: &'a RobotModel,
    /// Standard parameters of each of `robot.links`.
    pub links: Vec<LinkParams>,
    /// Friction of each of `robot.joints` (same order).
    pub friction: Vec<JointFriction>,
}

impl<'a> ScoredModel<'a> {
    /// The URDF as `robot` compiles it: its inertias, `<dynamics>` and `<twin_sysid>` friction
    /// (`block`, by joint name; `<dynamics>` where the block has no entry).
    pub fn of_urdf(robot: &'a RobotModel, block: &[JointFriction]) -> ScoredModel<'a> {
        ScoredModel {
            robot,
            links: robot.links.iter().map(|l| l.cad).collect(),
            friction: robot
                .joints
                .iter()
                .map(|j| {
                    block
                        .iter()
                        .find(|b| b.name == j.name)
                        .cloned()
                        .unwrap_or_else(|| JointFriction::from_dynamics(&j.name, j.damping, j.friction, j.armature))
                })
                .collect(),
        }
    }

    /// The identified model of `ident` (on `robot`).
    pub fn of_identification(robot: &'a RobotModel, ident: &Identification) -> ScoredModel<'a> {
        ScoredModel {
            robot,
            links: (0..robot.links.len()).map(|l| ident.link_params(l)).collect(),
            friction: joint_frictions(robot, ident),
        }
    }
}

/// Each joint's identified friction model of `ident`.
pub fn joint_frictions(robot: &RobotModel, ident: &Identification) -> Vec<JointFriction> {
    let fm = ident.layout.friction;
    robot
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            let c = ident.layout.joint_col(j);
            let p = &ident.after;
            JointFriction {
                name: joint.name.clone(),
                offset: if fm.offset { p[c + 3] } else { 0.0 },
                viscous: p[c],
                coulomb: p[c + 1],
                smoothing: fm.coulomb_smoothing,
                velocity_shift: 0.0,
                asymmetry: fm.asymmetry_col().map_or(0.0, |k| p[c + k]),
                armature: p[c + 2],
            }
        })
        .collect()
}

/// Per-joint torque NRMSE (`rms(τ_model − τ_log) / rms(τ_log)`) of each model on `log`,
/// conditioned with `opts`, for the joints of `reference` (by name; NaN for a joint a model's
/// robot lacks). Every model is scored on the same samples: those `reference`'s conditioning
/// uses for identification (outside the velocity dead zone and the reversal guard).
///
/// # Errors
/// As [`condition`]; [`Error::Option`] for a floating base.
pub fn models_nrmse(
    reference: &RobotModel,
    log: &JointLog,
    opts: &SysidOptions,
    models: &[ScoredModel<'_>],
) -> Result<Vec<Vec<f64>>> {
    if reference.floating.is_some() {
        return Err(Error::Option {
            name: "base",
            message: "held-out scoring of models is for fixed-base robots; validate a floating base with --validate"
                .into(),
        });
    }
    let nj = reference.joints.len();
    // Which samples count: the reference's rows.
    let mut used_rows: Vec<Vec<bool>> = Vec::new();
    let mut measured: Vec<Vec<f64>> = Vec::new();
    {
        let data = condition(log, reference, &opts.condition)?;
        let (wrenches, _) = wrench_bodies(reference, log);
        let mut reg = Regressor::new(reference, FrictionModel::default())?;
        for_each_sample(reference, &mut reg, &data, &wrenches, opts, |_, target, _, used| {
            used_rows.push(used.to_vec());
            measured.push(target[..nj].to_vec());
        })?;
    }
    let mut out = Vec::new();
    for model in models {
        let data = condition(log, model.robot, &opts.condition)?;
        let (wrenches, _) = wrench_bodies(model.robot, log);
        let mut reg = Regressor::new(model.robot, FrictionModel::default())?;
        let layout = reg.layout();
        let ncols = layout.ncols();
        let mnj = model.robot.joints.len();
        // Model joint of each reference joint.
        let map: Vec<Option<usize>> = reference.joints.iter().map(|j| model.robot.joint_index(&j.name)).collect();
        let (mut err2, mut tau2) = (vec![0.0; nj], vec![0.0; nj]);
        let mut k = 0;
        let mut mismatch = false;
        for_each_sample(model.robot, &mut reg, &data, &wrenches, opts, |rows, _, _, _| {
            let (Some(used), Some(tau)) = (used_rows.get(k), measured.get(k)) else {
                mismatch = true;
                return;
            };
            for (r, m) in map.iter().enumerate() {
                let Some(mj) = *m else { continue };
                if !used[r] || mj >= mnj {
                    continue;
                }
                let row = &rows[mj * ncols..(mj + 1) * ncols];
                let mut pred = 0.0;
                for (l, p) in model.links.iter().enumerate() {
                    let c = layout.link_col(l);
                    pred += (0..LINK_PARAMS).map(|i| row[c + i] * p[i]).sum::<f64>();
                }
                let c = layout.joint_col(mj);
                pred += model.friction[mj].torque(row[c], row[c + 2]);
                err2[r] += (pred - tau[r]) * (pred - tau[r]);
                tau2[r] += tau[r] * tau[r];
            }
            k += 1;
        })?;
        if mismatch || k != used_rows.len() {
            return Err(Error::Numerical(format!(
                "{} and {} condition the log differently ({} vs {} samples); they cannot be scored on the same samples",
                model.robot.urdf_path.display(),
                reference.urdf_path.display(),
                k,
                used_rows.len()
            )));
        }
        out.push(
            (0..nj)
                .map(|r| if map[r].is_some() && tau2[r] > 0.0 { (err2[r] / tau2[r]).sqrt() } else { f64::NAN })
                .collect(),
        );
    }
    Ok(out)
}

/// The part of `log` from fraction `from` to `to` of its time span (`0 ≤ from < to ≤ 1`).
pub fn time_slice(log: &JointLog, from: f64, to: f64) -> JointLog {
    let (t0, t1) = (log.t_nanos.first().copied().unwrap_or(0), log.t_nanos.last().copied().unwrap_or(0));
    let at = |f: f64| t0 + ((t1 - t0) as f64 * f).round() as i64;
    let (a, b) = (at(from), at(to));
    let keep = |t: i64| t >= a && (t < b || (to >= 1.0 && t <= b));
    slice_where(log, keep)
}

/// `log` without the samples in `[from, to)` of its time span: the rest, with a gap there.
fn time_without(log: &JointLog, from: f64, to: f64) -> JointLog {
    let (t0, t1) = (log.t_nanos.first().copied().unwrap_or(0), log.t_nanos.last().copied().unwrap_or(0));
    let at = |f: f64| t0 + ((t1 - t0) as f64 * f).round() as i64;
    let (a, b) = (at(from), at(to));
    slice_where(log, |t| t < a || t >= b || (to >= 1.0 && t > b))
}

fn slice_where(log: &JointLog, keep: impl Fn(i64) -> bool) -> JointLog {
    let idx: Vec<usize> = (0..log.len()).filter(|&k| keep(log.t_nanos[k])).collect();
    let pick = |v: &Vec<Vec<f64>>| v.iter().map(|s| idx.iter().map(|&k| s[k]).collect()).collect();
    JointLog {
        joint_names: log.joint_names.clone(),
        t_nanos: idx.iter().map(|&k| log.t_nanos[k]).collect(),
        position: pick(&log.position),
        velocity: pick(&log.velocity),
        effort: pick(&log.effort),
        source: log.source.clone(),
        base: log.base.clone(),
        wrenches: log.wrenches.clone(),
    }
}

/// The median sample rate of `log`, Hz.
fn rate_of(log: &JointLog) -> Option<f64> {
    let mut dt: Vec<i64> = log.t_nanos.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 0).collect();
    if dt.is_empty() {
        return None;
    }
    dt.sort_unstable();
    Some(1e9 / dt[dt.len() / 2] as f64)
}

/// Mean per-joint cross-validated NRMSE of `opts` on `log` (time-blocked, `folds` blocks),
/// effort scored at `effort_cutoff_hz`.
fn cross_validate(
    robot: &RobotModel,
    log: &JointLog,
    opts: &SysidOptions,
    folds: usize,
    effort_cutoff_hz: f64,
) -> Result<Vec<f64>> {
    let nj = robot.joints.len();
    let mut sum = vec![0.0; nj];
    let mut count = vec![0usize; nj];
    let mut score_opts = opts.clone();
    score_opts.condition.effort_cutoff_hz = Some(effort_cutoff_hz);
    // Identification must not refuse a fold for a diagnosis the whole log would pass.
    let mut fit_opts = opts.clone();
    fit_opts.strict = false;
    for f in 0..folds {
        let (a, b) = (f as f64 / folds as f64, (f + 1) as f64 / folds as f64);
        let train = time_without(log, a, b);
        let test = time_slice(log, a, b);
        let ident = identify(robot, &train, &fit_opts)?;
        let model = ScoredModel::of_identification(robot, &ident);
        let nrmse = models_nrmse(robot, &test, &score_opts, &[model])?;
        for j in 0..nj {
            if nrmse[0][j].is_finite() {
                sum[j] += nrmse[0][j];
                count[j] += 1;
            }
        }
    }
    Ok((0..nj).map(|j| if count[j] > 0 { sum[j] / count[j] as f64 } else { f64::NAN }).collect())
}

fn mean(v: &[f64]) -> f64 {
    let finite: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if finite.is_empty() { f64::NAN } else { finite.iter().sum::<f64>() / finite.len() as f64 }
}

/// Chooses the cut-off and the friction model for `log` by time-blocked cross-validation
/// (see the module docs), starting from `base` (whose cut-off and friction model are kept
/// where `sel` says not to choose them).
///
/// When no candidate can be scored, `base` stands (cut-off `min(rate/25, 20 Hz)` if it had
/// none); each candidate's error is in [`Candidate::error`].
///
/// # Errors
/// [`Error::Option`] for bad selection options; [`Error::BadLog`] for a log whose timestamps
/// are all equal.
pub fn select(robot: &RobotModel, log: &JointLog, base: &SysidOptions, sel: &SelectOptions) -> Result<Selection> {
    if !(2..=10).contains(&sel.folds) {
        return Err(Error::Option { name: "folds", message: format!("{} must be 2 to 10", sel.folds) });
    }
    let rate = rate_of(log).ok_or_else(|| log.bad("all timestamps are equal".into()))?;
    let allowed: Vec<f64> = sel.cutoffs_hz.iter().copied().filter(|&c| c > 0.0 && c < 0.2 * rate).collect();
    let effort_cutoff_hz =
        sel.effort_cutoff_hz.unwrap_or_else(|| allowed.iter().copied().fold(rate / 25.0, f64::max).min(0.2 * rate));
    let mut candidates = Vec::new();
    let mut options = base.clone();
    let mut last_error = None;
    // Candidates are independent fits: scored in parallel, each sequential inside, so the scores
    // (and the choice) do not depend on the thread count.
    let mut stage = |trials: Vec<SysidOptions>, candidates: &mut Vec<Candidate>| -> Option<(f64, usize)> {
        use rayon::prelude::*;
        let results: Vec<Result<Vec<f64>>> =
            trials.par_iter().map(|o| cross_validate(robot, log, o, sel.folds, effort_cutoff_hz)).collect();
        let mut best: Option<(f64, usize)> = None;
        for (o, r) in trials.iter().zip(results) {
            let (score, per_joint, error) = match r {
                Ok(per_joint) => {
                    let s = mean(&per_joint);
                    (s.is_finite().then_some(s), per_joint, None)
                }
                Err(e) => {
                    let text = e.to_string();
                    last_error = Some(e);
                    (None, Vec::new(), Some(text))
                }
            };
            if let Some(s) = score
                && best.is_none_or(|(b, _)| s < b)
            {
                best = Some((s, candidates.len()));
            }
            candidates.push(Candidate {
                cutoff_hz: o.condition.cutoff_hz.unwrap_or(f64::NAN),
                friction: o.friction.describe(),
                score,
                per_joint,
                error,
                chosen: false,
            });
        }
        best
    };
    if sel.choose_cutoff && base.condition.cutoff_hz.is_none() {
        let trials: Vec<SysidOptions> = allowed
            .iter()
            .map(|&c| {
                let mut probe = base.clone();
                if sel.choose_friction {
                    probe.friction = FrictionModel { coulomb_smoothing: Some(0.05), offset: true, asymmetry: false };
                }
                probe.condition.cutoff_hz = Some(c);
                probe
            })
            .collect();
        if let Some((_, i)) = stage(trials, &mut candidates) {
            options.condition.cutoff_hz = Some(candidates[i].cutoff_hz);
            candidates[i].chosen = !sel.choose_friction;
        }
    }
    if options.condition.cutoff_hz.is_none() {
        options.condition.cutoff_hz = Some((rate / 25.0).min(20.0));
    }
    if sel.choose_friction {
        let mut models = vec![
            FrictionModel { coulomb_smoothing: None, offset: false, asymmetry: false },
            FrictionModel { coulomb_smoothing: None, offset: true, asymmetry: false },
        ];
        for &eps in &sel.smoothings {
            models.push(FrictionModel { coulomb_smoothing: Some(eps), offset: true, asymmetry: false });
            models.push(FrictionModel { coulomb_smoothing: Some(eps), offset: true, asymmetry: true });
        }
        let trials: Vec<SysidOptions> = models
            .iter()
            .map(|&fm| {
                let mut probe = options.clone();
                probe.friction = fm;
                probe
            })
            .collect();
        if let Some((_, i)) = stage(trials, &mut candidates) {
            candidates[i].chosen = true;
            options.friction = models[i - (candidates.len() - models.len())];
        }
    }
    // No candidate could be scored (a log too short to cut into folds at these cut-offs, or
    // one identification refuses anyway): the base options stand, and the fit on the whole
    // part says what is wrong with the log if anything is.
    let _ = last_error;
    Ok(Selection { options, candidates })
}

/// The candidates' scores as a table (one line each, the chosen marked).
pub fn candidates_table(candidates: &[Candidate]) -> String {
    let mut s = String::from(
        "cut-off and friction model chosen by time-blocked cross-validation (mean per-joint torque NRMSE):\n",
    );
    for c in candidates {
        let mark = if c.chosen { "*" } else { " " };
        match (c.score, &c.error) {
            (Some(score), _) => {
                s.push_str(&format!("  {mark} {:>5.1} Hz  {:<48} {:>7.4}\n", c.cutoff_hz, c.friction, score))
            }
            (None, Some(e)) => {
                s.push_str(&format!("  {mark} {:>5.1} Hz  {:<48} failed: {e}\n", c.cutoff_hz, c.friction))
            }
            (None, None) => s.push_str(&format!("  {mark} {:>5.1} Hz  {:<48} no score\n", c.cutoff_hz, c.friction)),
        }
    }
    s
}
