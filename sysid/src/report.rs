//! The identification report: what the terminal table and `--report sysid.json` show.

use crate::estimate::Identifiability;
use serde::Serialize;
use std::fmt::Write as _;

/// One parameter: before (URDF), after (identified), its standard deviation, identifiability.
#[derive(Debug, Clone, Serialize)]
pub struct ParamReport {
    /// `m`, `hx`, … `Izz`, `viscous`, `coulomb`, `armature`, `offset`.
    pub name: String,
    /// Value in the URDF (armature: the model's, 0 for URDF).
    pub before: f64,
    /// Identified value.
    pub after: f64,
    /// Posterior standard deviation (data and CAD prior together).
    pub std: f64,
    /// Whether the log determines it.
    pub identifiability: Identifiability,
}

/// A link's identified inertial parameters.
#[derive(Debug, Clone, Serialize)]
pub struct LinkReport {
    /// Link name.
    pub name: String,
    /// Standard parameters `[m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]` (inertia about the
    /// link frame origin).
    pub params: Vec<ParamReport>,
    /// Mass, kg, after.
    pub mass_kg: f64,
    /// Centre of mass in the link frame, m, after.
    pub com_link: [f64; 3],
    /// Inertia about the centre of mass (link axes), `[ixx, ixy, ixz, iyy, iyz, izz]`, after.
    pub inertia_com: [f64; 6],
    /// Pseudo-inertia positive definite (always true for the consistent fit).
    pub physically_valid: bool,
}

/// A joint's identified friction and armature.
#[derive(Debug, Clone, Serialize)]
pub struct JointReport {
    /// Joint name.
    pub name: String,
    /// `viscous` (N·m·s/rad, URDF `damping`), `coulomb` (N·m, URDF `friction`), `armature`
    /// (kg·m², not in URDF), `offset` (N·m) when enabled.
    pub params: Vec<ParamReport>,
    /// Range of motion in the log, rad or m.
    pub range_of_motion: f64,
    /// RMS velocity in the log.
    pub rms_velocity: f64,
    /// Estimated effort noise (residual standard deviation), N·m: the weighting of its rows.
    pub noise_std: f64,
}

/// One identifiable (base) parameter: a combination of standard parameters.
#[derive(Debug, Clone, Serialize)]
pub struct BaseParamReport {
    /// E.g. `m[forearm] + 0.42·hx[wrist]`.
    pub expression: String,
    /// Weighted least-squares value.
    pub value: f64,
    /// Standard deviation.
    pub std: f64,
    /// Relative standard deviation, percent: `100·σ/|β|`.
    pub rel_std_percent: f64,
}

/// Torque fit quality of one joint: `NRMSE = rms(τ_model − τ_log) / rms(τ_log)`.
#[derive(Debug, Clone, Serialize)]
pub struct NrmseReport {
    /// Joint name.
    pub joint: String,
    /// With the URDF's parameters.
    pub before: f64,
    /// With the identified parameters.
    pub after: f64,
}

/// Fit of one floating-base row (the free joint's force or torque balance `0 = Y_base·π −
/// Jᵀ·w_ext`), as RMS residuals in N or N·m.
#[derive(Debug, Clone, Serialize)]
pub struct BaseRowReport {
    /// E.g. `base force z (N)`.
    pub row: String,
    /// RMS of the measured side `Jᵀ·w_ext` (0 in free flight).
    pub rms_external: f64,
    /// RMS residual with the URDF's parameters.
    pub before_rms: f64,
    /// RMS residual with the identified parameters.
    pub after_rms: f64,
    /// Estimated noise (residual standard deviation): the weighting of the row.
    pub noise_std: f64,
}

/// Everything `twin sysid` found.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// twin's version.
    pub generator: String,
    /// The robot (URDF).
    pub robot: String,
    /// The log.
    pub log: String,
    /// `fixed` (robot bolted down or on a gantry) or `floating`.
    pub base: String,
    /// In words, e.g. `floating base (base motion from /odom, 2 contact wrench topics)`.
    pub base_description: String,
    /// Samples in the log.
    pub log_samples: usize,
    /// Log rate, Hz.
    pub rate_hz: f64,
    /// Low-pass cut-off, Hz.
    pub cutoff_hz: f64,
    /// Butterworth order (applied forward and backward).
    pub filter_order: usize,
    /// Regressor sample rate, Hz.
    pub regressor_rate_hz: f64,
    /// Conditioned segments.
    pub segments: usize,
    /// Regressor rows used (one per joint and sample, outside the velocity dead zone).
    pub rows: usize,
    /// Standard parameters (links × 10 + joints × friction terms).
    pub parameters: usize,
    /// Number of identifiable combinations (rank of the regressor).
    pub rank: usize,
    /// Condition number of the base regressor (columns scaled to unit norm).
    pub condition_number: f64,
    /// Iterations of the physically consistent fit.
    pub fit_iterations: usize,
    /// Wall time of the identification, seconds.
    pub wall_secs: f64,
    /// Diagnostics the user should read.
    pub warnings: Vec<String>,
    /// Links.
    pub links: Vec<LinkReport>,
    /// Joints.
    pub joints: Vec<JointReport>,
    /// Identifiable combinations with their statistics.
    pub base_parameters: Vec<BaseParamReport>,
    /// Fit on the identification log.
    pub training_nrmse: Vec<NrmseReport>,
    /// Floating base: fit of the 6 base rows on the identification log (empty when fixed).
    pub base_rows: Vec<BaseRowReport>,
    /// Fit on a held-out log (`--validate`).
    pub validation_nrmse: Option<Vec<NrmseReport>>,
    /// The held-out log.
    pub validation_log: Option<String>,
    /// Cross-validation candidates tried to choose the cut-off and the friction model (empty
    /// when both were given).
    pub selection: Vec<crate::select::Candidate>,
    /// Per-joint held-out torque NRMSE of the URDF before, the fit and `--compare` models on the
    /// same samples (`None` without held-out data).
    pub held_out: Option<HeldOutTable>,
    /// Each joint's friction and sensor model as written to the `<twin_sysid>` block.
    pub joint_friction: Vec<crate::extension::JointFriction>,
}

/// Held-out torque NRMSE of several models on the same samples.
#[derive(Debug, Clone, Serialize)]
pub struct HeldOutTable {
    /// Where the held-out data came from (a file, or "last 30 % of LOG").
    pub log: String,
    /// Cut-off of the effort the models are scored against, Hz.
    pub effort_cutoff_hz: f64,
    /// Model names (columns): "URDF before", "twin fit", then each `--compare` file.
    pub models: Vec<String>,
    /// Joint names (rows).
    pub joints: Vec<String>,
    /// `nrmse[model][joint]`.
    pub nrmse: Vec<Vec<f64>>,
}

impl HeldOutTable {
    /// Mean over joints of model `m` (finite values only).
    pub fn mean(&self, m: usize) -> f64 {
        let v: Vec<f64> = self.nrmse[m].iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
    }

    /// The table as text.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "
held-out torque NRMSE on {} (effort low-passed at {:.1} Hz for every model)",
            self.log, self.effort_cutoff_hz
        );
        let _ = write!(out, "{:<28}", "joint");
        for m in &self.models {
            let short: String = m.chars().rev().take(22).collect::<Vec<_>>().into_iter().rev().collect();
            let _ = write!(out, " {short:>22}");
        }
        let _ = writeln!(out);
        for (j, name) in self.joints.iter().enumerate() {
            let _ = write!(out, "{name:<28}");
            for m in 0..self.models.len() {
                let _ = write!(out, " {:>21.2}%", 100.0 * self.nrmse[m][j]);
            }
            let _ = writeln!(out);
        }
        let _ = write!(out, "{:<28}", "mean");
        for m in 0..self.models.len() {
            let _ = write!(out, " {:>21.2}%", 100.0 * self.mean(m));
        }
        let _ = writeln!(out);
        out
    }
}

fn ident_label(i: Identifiability) -> &'static str {
    match i {
        Identifiability::Identifiable => "yes",
        Identifiability::Combination => "combined",
        Identifiability::NotIdentifiable => "no",
    }
}

impl Report {
    /// The terminal table: parameter, before, after, ±σ, identifiable.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "robot {} ({}), log {}: {} samples at {:.1} Hz, low-pass {:.1} Hz (order {}), {} rows in {} segment(s)",
            self.robot,
            self.base_description,
            self.log,
            self.log_samples,
            self.rate_hz,
            self.cutoff_hz,
            self.filter_order,
            self.rows,
            self.segments
        );
        let _ = writeln!(
            out,
            "rank {} of {} parameters, condition number {:.3e}, consistent fit in {} iterations, {:.2} s",
            self.rank, self.parameters, self.condition_number, self.fit_iterations, self.wall_secs
        );
        let _ = writeln!(out, "\n{:<40} {:>13} {:>13} {:>11}  identifiable", "parameter", "before", "after", "±σ");
        let mut row = |name: String, p: &ParamReport| {
            let _ = writeln!(
                out,
                "{:<40} {:>13.6e} {:>13.6e} {:>11.2e}  {}",
                name,
                p.before,
                p.after,
                p.std,
                ident_label(p.identifiability)
            );
        };
        for link in &self.links {
            for p in &link.params {
                row(format!("{}.{}", link.name, p.name), p);
            }
        }
        for joint in &self.joints {
            for p in &joint.params {
                row(format!("{}.{}", joint.name, p.name), p);
            }
        }
        let nrmse = |out: &mut String, title: &str, rows: &[NrmseReport]| {
            let _ = writeln!(out, "\n{title}\n{:<40} {:>10} {:>10}", "joint", "before", "after");
            for r in rows {
                let _ = writeln!(out, "{:<40} {:>9.2}% {:>9.2}%", r.joint, 100.0 * r.before, 100.0 * r.after);
            }
        };
        nrmse(&mut out, "torque NRMSE on the identification log", &self.training_nrmse);
        if !self.base_rows.is_empty() {
            let _ = writeln!(
                out,
                "\nfloating-base rows on the identification log (RMS)\n{:<40} {:>10} {:>10} {:>10}",
                "row", "external", "before", "after"
            );
            for r in &self.base_rows {
                let _ = writeln!(
                    out,
                    "{:<40} {:>10.3} {:>10.3} {:>10.3}",
                    r.row, r.rms_external, r.before_rms, r.after_rms
                );
            }
        }
        if !self.selection.is_empty() {
            let _ = write!(out, "\n{}", crate::select::candidates_table(&self.selection));
        }
        if let Some(h) = &self.held_out {
            out.push_str(&h.text());
        }
        if let Some(v) = &self.validation_nrmse {
            let title = format!("torque NRMSE on the held-out log {}", self.validation_log.as_deref().unwrap_or(""));
            nrmse(&mut out, &title, v);
        }
        if !self.warnings.is_empty() {
            let _ = writeln!(out, "\nwarnings:");
            for w in &self.warnings {
                let _ = writeln!(out, "  - {w}");
            }
        }
        out
    }

    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}
