//! Excitation trajectories for identification (`twin excite`): a finite Fourier series per
//! joint (Swevers et al. 1997), starting and ending at rest, optimized for the condition
//! number (or log-determinant) of the base-parameter regressor `twin sysid` will build,
//! within position, velocity, acceleration and torque limits and free of self-collision.
//!
//! ## Trajectory
//! Joint `i` follows, with `ω = 2π·f₀` and period `T = 1/f₀`,
//!
//! ```text
//! q(t) = c + Σ_l [ a_l/(ωl)·sin(ωlt) − b_l/(ωl)·(cos(ωlt) − 1) ]
//! q̇(t) = Σ_l [ a_l·cos(ωlt) + b_l·sin(ωlt) ]
//! ```
//!
//! so `q(0) = q(T) = c`. Rest at both ends (`q̇ = q̈ = 0`) is `Σ a_l = 0` and `Σ l·b_l = 0`,
//! enforced by eliminating `a₁` and `b₁`: the optimizer's variables per joint are `c`,
//! `a₂…a_H`, `b₂…b_H`. The trajectory is periodic: repeated, it stays smooth.
//!
//! ## Criterion
//! The regressor of [`crate::regressor`] (inertial, viscous, Coulomb and armature columns, the
//! rows `twin sysid` would use: joints outside the velocity dead zone) on a grid over one
//! period is compressed as in identification; its base columns (the leading columns of the
//! column-pivoted QR of a generic trajectory, fixed for the whole design so that a degenerate
//! trajectory cannot "improve" by losing rank) are scaled to unit norm, and the criterion is
//! the condition number of that matrix (the figure `twin sysid` reports), or `−(2/n)·Σ ln σᵢ`
//! (log-determinant of `WᵀW`).
//!
//! ## Limits
//! Position (URDF range less a margin), velocity (a fraction of URDF `<limit velocity>`),
//! acceleration (an option: URDF has none), torque (a fraction of URDF `<limit effort>`; the
//! torque is the model's inverse dynamics `Y·π_URDF`, friction included) and self-collision
//! (MuJoCo contacts between the robot's own links; pairs already touching at the rest pose,
//! and each link with its grandparent, whose shapes overlap around the joint between them in
//! most URDFs, excepted). Position, velocity and acceleration are met by construction: each
//! joint's deviation from its rest is shrunk, on a 4× finer grid, where it would leave its box.
//! Torque and collisions enter the search as a penalty; the result is then shrunk (all joints,
//! or only those involved in a violation) until every limit holds on the fine grid.
//!
//! ## Search
//! 20 random 5-harmonic trajectories (`baseline_harmonics`) are drawn and shrunk as a whole to
//! the limits: the best is the comparison figure. The design has 15 harmonics by default (its
//! higher ones zero in those 20): on the arm the binding columns are each joint's viscous and
//! Coulomb pair, which only a velocity that rests near zero and then bursts to the limit tells
//! apart, a shape 5 harmonics can't make. A global stage then draws 1000 more (all harmonics,
//! rest anywhere in the range, so that offsets keeping links apart are tried) and scales each of the 1020 per joint to touch
//! its binding position, velocity or acceleration limit; from the best 3, quasi-Newton
//! searches (BFGS, backtracking line search) minimize smooth
//! surrogates of `ln cond` (soft maximum minus soft minimum of `ln σᵢ`, sharpness 4, 16, 64, then 256:
//! the condition number is not differentiable where singular values cross, and at its optimum
//! many of them do), and the best is polished on `ln cond` itself. The gradient is
//! semi-analytic: each sample's regressor rows are differentiated in that sample's own
//! `(q, q̇, q̈)` and chained through the singular values (`dσᵢ = uᵢᵀ·dW·vᵢ`) and the Fourier
//! series, 3 regressor evaluations per joint and sample instead of a full evaluation per
//! variable. Deterministic for a given seed.

use crate::error::{Error, Result};
use crate::estimate::Accumulator;
use crate::model::RobotModel;
use crate::regressor::{FrictionModel, Regressor};
use faer::Mat;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;
use twin_core::mj::{Data, ObjType};

mod problem;
use problem::*;

/// What the design minimizes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    /// Condition number of the column-scaled base regressor (default).
    #[default]
    Condition,
    /// `−log det(WᵀW)` of the column-scaled base regressor, per parameter.
    LogDet,
}

/// Options of [`design`].
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct ExciteOptions {
    /// Joints to excite, by name (default: empty: every revolute and prismatic joint). The
    /// others hold their rest position (0 clamped into their range).
    pub joints: Vec<String>,
    /// Harmonics per joint of the designed trajectory (default: 15: up to 1.5 Hz at the default
    /// 10-s period; more harmonics let a joint's velocity rest near zero and then burst, which
    /// separates its viscous and Coulomb columns, at the cost of a faster trajectory to track).
    #[default(15)]
    pub harmonics: usize,
    /// Harmonics per joint of the random trajectories the design is compared with and starts
    /// from (default: 5, Swevers's choice). At most [`ExciteOptions::harmonics`]: a random
    /// trajectory is a designed one whose higher harmonics are zero.
    #[default(5)]
    pub baseline_harmonics: usize,
    /// Fundamental frequency `f₀`, Hz; the trajectory's period is `1/f₀` (default: 0.1: 10 s).
    #[default(0.1)]
    pub base_frequency_hz: f64,
    /// Kept away from each end of a joint's range, rad or m (default: 0.05).
    #[default(0.05)]
    pub position_margin: f64,
    /// Fraction of the URDF velocity limit used (default: 0.8).
    #[default(0.8)]
    pub velocity_fraction: f64,
    /// Velocity limit of joints whose URDF gives none, rad/s or m/s (default: `None`: such a
    /// joint is an error naming it).
    pub default_velocity_limit: Option<f64>,
    /// Acceleration limit of every joint, rad/s² or m/s² (default: 10).
    #[default(10.0)]
    pub max_acceleration: f64,
    /// Fraction of the URDF effort limit the inverse-dynamics torque may reach (default: 0.8).
    /// Joints without an effort limit are not torque-limited.
    #[default(0.8)]
    pub effort_fraction: f64,
    /// Check self-collision with MuJoCo's contacts (default: true).
    #[default(true)]
    pub self_collision: bool,
    /// What is minimized (default: [`Criterion::Condition`]).
    #[default(Criterion::Condition)]
    pub criterion: Criterion,
    /// Random trajectories tried first; the best is the search's start and the comparison
    /// figure (default: 20).
    #[default(20)]
    pub random_candidates: usize,
    /// Quasi-Newton iterations per stage (default: 150; with the semi-analytic gradient an
    /// iteration costs about 20 evaluations' worth of regressor rows).
    #[default(150)]
    pub max_iterations: usize,
    /// Further random trajectories (rest anywhere in the range) drawn for the global stage
    /// (default: 1000: a draw costs one evaluation, and the search's outcome depends mostly on
    /// its start).
    #[default(1000)]
    pub global_candidates: usize,
    /// Searches started from the best of all random trajectories, each scaled to touch its
    /// limits (default: 3).
    #[default(3)]
    pub starts: usize,
    /// Sharpness of the smooth surrogates of `ln cond` each search goes through before the
    /// polish on `ln cond` itself (default: `[4, 16, 64, 256]`).
    #[default(vec![4.0, 16.0, 64.0, 256.0])]
    pub smoothing: Vec<f64>,
    /// Grid points per period for the criterion and the penalty (default: 100; limits are
    /// checked at the end on a 4× finer grid).
    #[default(100)]
    pub samples: usize,
    /// Seed of the random trajectories (default: 1).
    #[default(1)]
    pub seed: u64,
    /// The Coulomb column is `tanh(q̇/ε)` with this `ε` in the design (rad/s): `twin sysid`'s
    /// `sign(q̇)` with its dead zone made smooth, so that the criterion has a gradient
    /// (default: 0.05, `twin sysid`'s dead zone).
    #[default(0.05)]
    pub velocity_deadzone: f64,
}

/// One joint's Fourier series.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FourierJoint {
    /// Joint name.
    pub name: String,
    /// Index into [`RobotModel::joints`].
    pub index: usize,
    /// Rest position at both ends, rad or m.
    pub rest: f64,
    /// Cosine coefficients of the velocity `a_l`, l = 1…H, rad/s.
    pub a: Vec<f64>,
    /// Sine coefficients of the velocity `b_l`, l = 1…H, rad/s.
    pub b: Vec<f64>,
}

impl FourierJoint {
    /// Scales the motion about the rest position by `s` (the coefficients; rest unchanged).
    fn scale(&mut self, s: f64) {
        self.a.iter_mut().chain(self.b.iter_mut()).for_each(|x| *x *= s);
    }

    /// `(q, q̇, q̈)` at `t` for fundamental `omega` (rad/s).
    pub fn sample(&self, omega: f64, t: f64) -> (f64, f64, f64) {
        let (mut q, mut qd, mut qdd) = (self.rest, 0.0, 0.0);
        for (l, (&a, &b)) in self.a.iter().zip(&self.b).enumerate() {
            let w = omega * (l + 1) as f64;
            let (s, c) = (w * t).sin_cos();
            q += a / w * s - b / w * (c - 1.0);
            qd += a * c + b * s;
            qdd += w * (-a * s + b * c);
        }
        (q, qd, qdd)
    }
}

/// An excitation trajectory: one period, starting and ending at rest.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Excitation {
    /// Fundamental frequency, Hz.
    pub base_frequency_hz: f64,
    /// The excited joints.
    pub joints: Vec<FourierJoint>,
    /// Position of every joint of the robot ([`RobotModel::joints`] order) when not excited.
    pub hold: Vec<f64>,
    /// Names of every joint of the robot.
    pub joint_names: Vec<String>,
}

impl Excitation {
    /// Duration of one period, seconds.
    pub fn period_secs(&self) -> f64 {
        1.0 / self.base_frequency_hz
    }

    /// `(q, q̇, q̈)` of robot joint `j` ([`RobotModel::joints`] order) at `t` seconds (periodic).
    pub fn reference(&self, j: usize, t: f64) -> (f64, f64, f64) {
        match self.joints.iter().find(|f| f.index == j) {
            Some(f) => f.sample(2.0 * PI * self.base_frequency_hz, t),
            None => (self.hold[j], 0.0, 0.0),
        }
    }

    /// CSV `time_sec,<joint>,<joint>_vel,…` of the excited joints at `rate_hz` over one
    /// period (both ends included): what `twin sim --controller replay --trajectory` reads.
    pub fn to_csv(&self, rate_hz: f64) -> String {
        let mut s = String::from("time_sec");
        for f in &self.joints {
            s.push_str(&format!(",{0},{0}_vel", f.name));
        }
        s.push('\n');
        let omega = 2.0 * PI * self.base_frequency_hz;
        for t in self.times(rate_hz) {
            s.push_str(&format!("{t:.6}"));
            for f in &self.joints {
                let (q, qd, _) = f.sample(omega, t);
                s.push_str(&format!(",{q:.9},{qd:.9}"));
            }
            s.push('\n');
        }
        s
    }

    fn times(&self, rate_hz: f64) -> Vec<f64> {
        let n = (self.period_secs() * rate_hz).round().max(1.0) as usize;
        (0..=n).map(|k| k as f64 * self.period_secs() / n as f64).collect()
    }

    /// The trajectory as one ROS 2 `trajectory_msgs/msg/JointTrajectory` message (positions,
    /// velocities, accelerations at `rate_hz`; header stamp 0: start on receipt).
    pub fn to_message(&self, rate_hz: f64) -> twin_core::log::JointTrajectory {
        let omega = 2.0 * PI * self.base_frequency_hz;
        let points = self
            .times(rate_hz)
            .into_iter()
            .map(|t| {
                let s: Vec<(f64, f64, f64)> = self.joints.iter().map(|f| f.sample(omega, t)).collect();
                twin_core::log::JointTrajectoryPoint {
                    positions: s.iter().map(|x| x.0).collect(),
                    velocities: s.iter().map(|x| x.1).collect(),
                    accelerations: s.iter().map(|x| x.2).collect(),
                    effort: Vec::new(),
                    time_from_start_nanos: (t * 1e9).round() as i64,
                }
            })
            .collect();
        twin_core::log::JointTrajectory {
            header: twin_core::log::Header::default(),
            joint_names: self.joints.iter().map(|f| f.name.clone()).collect(),
            points,
        }
    }

    /// Writes [`Excitation::to_message`] to an MCAP file on `topic` (an existing file is kept as
    /// a numbered backup).
    ///
    /// # Errors
    /// [`Error::Core`] if the file can't be written.
    pub fn write_mcap(&self, path: &Path, topic: &str, rate_hz: f64) -> Result<()> {
        // The log writer checks the path and keeps an existing file as a numbered backup, as
        // every bag twin writes.
        let mut writer = twin_core::log::LogWriter::create(path, &twin_core::log::WriterOptions::default())?;
        let t = writer.add_topic::<twin_core::log::JointTrajectory>(topic)?;
        writer.write(t, 0, &self.to_message(rate_hz))?;
        writer.finish()?;
        Ok(())
    }
}

/// One joint's limits as the design uses them.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointLimits {
    /// Joint name.
    pub name: String,
    /// Lowest position allowed (range less the margin).
    pub lower: f64,
    /// Highest position allowed.
    pub upper: f64,
    /// Velocity limit used.
    pub velocity: f64,
    /// Acceleration limit used.
    pub acceleration: f64,
    /// Torque limit used (`None`: not limited).
    pub torque: Option<f64>,
}

/// How much of each limit the trajectory uses (1 = at the limit).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointUse {
    /// Joint name.
    pub name: String,
    /// Position span over the period, rad or m.
    pub span: f64,
    /// Largest |q̇| / velocity limit.
    pub velocity: f64,
    /// Largest |q̈| / acceleration limit.
    pub acceleration: f64,
    /// Largest |τ| / torque limit (0 when not limited).
    pub torque: f64,
}

/// Result of [`design`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExciteReport {
    /// The designed trajectory.
    pub trajectory: Excitation,
    /// Criterion minimized.
    pub criterion: Criterion,
    /// Condition number of the base regressor `W_b` (SI units, the figure Swevers and
    /// Gautier optimize) along the designed trajectory.
    pub condition: f64,
    /// Condition number of the column-scaled base regressor (the figure `twin sysid` reports).
    pub scaled_condition: f64,
    /// The same for the best random trajectory.
    pub best_random_scaled_condition: f64,
    /// The same for each random trajectory (scaled to the same limits).
    pub random_conditions: Vec<f64>,
    /// The best of them.
    pub best_random_condition: f64,
    /// Harmonics per joint of the random trajectories.
    pub baseline_harmonics: usize,
    /// The best random trajectory (the search's start).
    pub best_random: Excitation,
    /// The median random trajectory by condition number (the lower median of an even count):
    /// what a random draw typically gives, the baseline a design is fairly compared with (the
    /// best of a few draws is itself a lucky draw).
    pub median_random: Excitation,
    /// Its condition number.
    pub median_random_condition: f64,
    /// Base parameters (columns of the base regressor).
    pub base_parameters: usize,
    /// Limits used.
    pub limits: Vec<JointLimits>,
    /// Use of each limit by the designed trajectory.
    pub usage: Vec<JointUse>,
    /// Criterion evaluations.
    pub evaluations: usize,
    /// Wall time of the design, seconds.
    pub design_secs: f64,
    /// Things the user should know.
    pub notes: Vec<String>,
}

impl ExciteReport {
    /// Human-readable summary.
    pub fn table(&self) -> String {
        let mut s = format!(
            "excitation: {} joints, {} harmonics, period {:.2} s, {} base parameters\n\
             condition number of the base regressor: designed {:.3e}, best of {} random {}-harmonic {:.3e} ({:.1}× lower), \
             median random {:.3e} ({:.1}× lower)\n\
             column-scaled (as twin sysid reports it): designed {:.2}, best random {:.2}\n\
             design time {:.2} s ({} evaluations)\n",
            self.trajectory.joints.len(),
            self.trajectory.joints.first().map_or(0, |f| f.a.len()),
            self.trajectory.period_secs(),
            self.base_parameters,
            self.condition,
            self.random_conditions.len(),
            self.baseline_harmonics,
            self.best_random_condition,
            self.best_random_condition / self.condition,
            self.median_random_condition,
            self.median_random_condition / self.condition,
            self.scaled_condition,
            self.best_random_scaled_condition,
            self.design_secs,
            self.evaluations
        );
        let w = self.usage.iter().map(|u| u.name.len()).max().unwrap_or(5).max(5);
        s.push_str(&format!("{:<w$}  {:>8}  {:>8}  {:>8}  {:>8}\n", "joint", "span", "vel use", "acc use", "torque"));
        for u in &self.usage {
            let torque = if u.torque > 0.0 { format!("{:>7.0}%", 100.0 * u.torque) } else { "      -".into() };
            s.push_str(&format!(
                "{:<w$}  {:>8.3}  {:>7.0}%  {:>7.0}%  {torque}\n",
                u.name,
                u.span,
                100.0 * u.velocity,
                100.0 * u.acceleration
            ));
        }
        for n in &self.notes {
            s.push_str(&format!("note: {n}\n"));
        }
        s
    }

    /// The report as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }
}

fn sorted(b: [usize; 2]) -> [usize; 2] {
    if b[0] <= b[1] { b } else { [b[1], b[0]] }
}

fn option_error(name: &'static str, message: String) -> Error {
    Error::Option { name, message }
}

/// A random trajectory: rest inside the middle half of each range, each velocity coefficient
/// uniform in `±v_max/H` (so that the velocity reaches about its limit), as drawn in practice
/// (Gaz et al. 2019); [`Problem::fit_to_limits`] then shrinks it as a whole where it exceeds a
/// limit.
/// A random `h`-harmonic trajectory (each velocity coefficient uniform in ±v_max/h, the rest in
/// the middle half of the range), its harmonics above `h` zero up to the template's.
fn random_joints(
    template: &[FourierJoint],
    limits: &[JointLimits],
    h: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<FourierJoint> {
    let nv = vars_per_joint(h);
    let mut x = Vec::with_capacity(template.len() * nv);
    for lim in limits {
        let mid = 0.5 * (lim.lower + lim.upper);
        let half = 0.5 * (lim.upper - lim.lower);
        x.push(mid + half * 0.5 * (2.0 * rng.random::<f64>() - 1.0));
        for _ in 0..2 * (h - 1) {
            x.push(lim.velocity / h as f64 * (2.0 * rng.random::<f64>() - 1.0));
        }
    }
    let mut js = joints_from_vars(&x, h, template);
    for (f, t) in js.iter_mut().zip(template) {
        f.a.resize(t.a.len(), 0.0);
        f.b.resize(t.b.len(), 0.0);
    }
    js
}

/// As [`random_joints`], the rest position uniform over the whole range (the global stage's
/// draw: offsets that keep links apart are part of the search).
fn random_joints_anywhere(
    template: &[FourierJoint],
    limits: &[JointLimits],
    h: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<FourierJoint> {
    let mut js = random_joints(template, limits, h, rng);
    for (f, lim) in js.iter_mut().zip(limits) {
        f.rest = lim.lower + (lim.upper - lim.lower) * rng.random::<f64>();
    }
    js
}

/// The starting inverse Hessian of [`bfgs`]: the step scales squared (variables of different
/// units).
fn initial_hinv(steps: &[f64]) -> Vec<Vec<f64>> {
    let n = steps.len();
    (0..n).map(|i| (0..n).map(|j| if i == j { 1e-2 * steps[i] * steps[i] } else { 0.0 }).collect()).collect()
}

/// Minimizes `f` from `x0` by BFGS with a backtracking line search; returns the best point
/// found. `f(x, true)` gives the value and its gradient, `f(x, false)` the value alone (the
/// line search's). (Small dense updates keep index loops.)
#[allow(clippy::needless_range_loop)]
fn bfgs(
    mut f: impl FnMut(&[f64], bool) -> Result<(f64, Vec<f64>)>,
    x0: &[f64],
    steps: &[f64],
    max_iter: usize,
) -> Result<Vec<f64>> {
    let n = x0.len();
    let mut x = x0.to_vec();
    let (mut fx, mut g) = f(&x, true)?;
    let mut hinv = initial_hinv(steps);
    let mut restarted = false;
    for _ in 0..max_iter {
        let d: Vec<f64> = (0..n).map(|i| -(0..n).map(|j| hinv[i][j] * g[j]).sum::<f64>()).collect();
        let slope: f64 = d.iter().zip(&g).map(|(a, b)| a * b).sum();
        if slope >= 0.0 {
            // Not a descent direction: restart from the scaled steepest descent.
            hinv = initial_hinv(steps);
            continue;
        }
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..12 {
            let xn: Vec<f64> = x.iter().zip(&d).map(|(a, b)| a + alpha * b).collect();
            let fnew = f(&xn, false)?.0;
            if fnew <= fx + 1e-4 * alpha * slope {
                accepted = Some((xn, fnew));
                break;
            }
            alpha *= 0.4;
        }
        let Some((xn, fnew)) = accepted else {
            if restarted {
                break;
            }
            // The quasi-Newton model went stale (the criterion is not smooth where two
            // singular values cross): start again from the scaled steepest descent once.
            restarted = true;
            hinv = initial_hinv(steps);
            continue;
        };
        restarted = false;
        let gn = f(&xn, true)?.1;
        let s: Vec<f64> = xn.iter().zip(&x).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy: f64 = s.iter().zip(&y).map(|(a, b)| a * b).sum();
        if sy > 1e-12 {
            let hy: Vec<f64> = (0..n).map(|i| (0..n).map(|j| hinv[i][j] * y[j]).sum()).collect();
            let yhy: f64 = y.iter().zip(&hy).map(|(a, b)| a * b).sum();
            for i in 0..n {
                for j in 0..n {
                    hinv[i][j] += (sy + yhy) * s[i] * s[j] / (sy * sy) - (hy[i] * s[j] + s[i] * hy[j]) / sy;
                }
            }
        }
        let improved = fx - fnew;
        x = xn;
        fx = fnew;
        g = gn;
        if improved < 1e-7 * fx.abs().max(1.0) {
            break;
        }
    }
    Ok(x)
}

/// Designs an excitation trajectory for `urdf`.
///
/// # Errors
/// Loading errors; [`Error::Option`] for bad options or an unknown joint;
/// [`Error::Urdf`] naming the joint and the limit when the limits leave no feasible
/// trajectory (no range, no velocity limit, a torque limit below what holding still needs, a
/// self-collision at rest, or no room to move).
pub fn design(urdf: &Path, opts: &ExciteOptions) -> Result<ExciteReport> {
    let started = Instant::now();
    faer::set_global_parallelism(faer::Par::Seq);
    let h = opts.harmonics;
    if !(1..=20).contains(&h) {
        return Err(option_error("harmonics", format!("{h}: must be 1 to 20")));
    }
    let hb = opts.baseline_harmonics;
    if !(1..=h).contains(&hb) {
        return Err(option_error(
            "baseline_harmonics",
            format!("{hb}: must be 1 to the designed trajectory's {h} harmonics"),
        ));
    }
    if !(opts.base_frequency_hz > 0.0 && opts.base_frequency_hz <= 10.0) {
        return Err(option_error(
            "base_frequency_hz",
            format!("{}: must be above 0 and at most 10 Hz", opts.base_frequency_hz),
        ));
    }
    for (name, v) in [
        ("velocity_fraction", opts.velocity_fraction),
        ("effort_fraction", opts.effort_fraction),
        ("max_acceleration", opts.max_acceleration),
    ] {
        if !(v > 0.0 && v.is_finite()) {
            return Err(option_error(name, format!("{v}: must be positive (a zero limit leaves nothing to move)")));
        }
    }
    if !(opts.position_margin >= 0.0 && opts.position_margin.is_finite()) {
        return Err(option_error("position_margin", format!("{}: must be ≥ 0", opts.position_margin)));
    }
    if opts.starts == 0 || opts.max_iterations == 0 {
        return Err(option_error("starts", "at least 1 search of at least 1 iteration".into()));
    }
    if let Some(b) = opts.smoothing.iter().find(|b| !(**b > 0.0 && b.is_finite())) {
        return Err(option_error("smoothing", format!("{b}: each sharpness must be positive")));
    }
    if opts.samples < 10 || opts.random_candidates == 0 {
        return Err(option_error("samples", "at least 10 grid samples and 1 random candidate".into()));
    }
    let source = crate::model::UrdfSource::read(urdf)?;
    let twin = source.robot("", false, opts.self_collision)?;
    let model: Arc<twin_core::mj::Model> = twin.model.clone();
    let robot = RobotModel::of_urdf(&source, model.clone(), false)?;
    let nj = robot.joints.len();
    let selected: Vec<usize> = if opts.joints.is_empty() {
        (0..nj).collect()
    } else {
        opts.joints
            .iter()
            .map(|name| {
                robot.joint_index(name).ok_or_else(|| {
                    option_error(
                        "joints",
                        format!(
                            "\"{name}\" is not a revolute or prismatic joint of {}; its joints: {}",
                            urdf.display(),
                            crate::condition::quote_list(
                                &robot.joints.iter().map(|j| j.name.clone()).collect::<Vec<_>>()
                            )
                        ),
                    )
                })
            })
            .collect::<Result<_>>()?
    };
    let urdf_err = |message: String| Error::Urdf { path: urdf.to_path_buf(), message };
    let mut hold = vec![0.0; nj];
    let mut limits = Vec::new();
    let mut notes = Vec::new();
    for (j, joint) in robot.joints.iter().enumerate() {
        let tj = twin.joints.iter().find(|t| t.name == joint.name);
        let range = tj.and_then(|t| t.range);
        if let Some([lo, hi]) = range {
            hold[j] = 0.0f64.clamp(lo, hi);
        }
        if !selected.contains(&j) {
            continue;
        }
        let [lo, hi] = range.unwrap_or([-PI, PI]);
        if range.is_none() {
            notes.push(format!("joint \"{}\" has no position limits: kept within ±π", joint.name));
        }
        let (lower, upper) = (lo + opts.position_margin, hi - opts.position_margin);
        if upper <= lower {
            return Err(urdf_err(format!(
                "joint \"{}\": its range [{lo}, {hi}] leaves no room to move inside the {} margin at each end; \
                 widen <limit lower/upper> or lower the position margin",
                joint.name, opts.position_margin
            )));
        }
        let velocity = match (tj.and_then(|t| t.velocity_limit).filter(|v| *v > 0.0), opts.default_velocity_limit) {
            (Some(v), _) => v * opts.velocity_fraction,
            (None, Some(v)) if v > 0.0 => v,
            _ => {
                return Err(urdf_err(format!(
                    "joint \"{}\" has no velocity limit (<limit velocity=\"…\"> is missing or 0): add one, or give \
                     a default velocity limit (--max-velocity)",
                    joint.name
                )));
            }
        };
        let torque = tj.and_then(|t| t.effort_limit).filter(|e| *e > 0.0).map(|e| e * opts.effort_fraction);
        if torque.is_none() {
            notes.push(format!("joint \"{}\" has no effort limit: its torque is not limited", joint.name));
        }
        limits.push(JointLimits {
            name: joint.name.clone(),
            lower,
            upper,
            velocity,
            acceleration: opts.max_acceleration,
            torque,
        });
    }
    let friction =
        FrictionModel { coulomb_smoothing: Some(opts.velocity_deadzone.max(1e-3)), offset: false, asymmetry: false };
    let reg = Regressor::new(&robot, friction)?;
    let layout = reg.layout();
    let cad = crate::identify::cad_params(&robot, &layout);
    let cols: Vec<Vec<usize>> = selected.iter().map(|&j| crate::identify::joint_columns(&robot, &layout, j)).collect();
    let collide = if opts.self_collision {
        let mut data = Data::new(model.clone())?;
        for (j, joint) in robot.joints.iter().enumerate() {
            data.qpos_mut()[joint.qpos_adr] = hold[j];
        }
        data.forward()?;
        let mut allowed: Vec<[usize; 2]> = data
            .contacts()
            .iter()
            .map(|(_, g)| {
                sorted([model.geom_bodyid()[g[0] as usize] as usize, model.geom_bodyid()[g[1] as usize] as usize])
            })
            .collect();
        // Links two joints apart (a link and its grandparent) overlap around the joint between
        // them in most URDFs' collision shapes; MuJoCo already skips parent and child.
        let parent = model.body_parentid();
        for b in 1..model.nbody() {
            let p = parent[b] as usize;
            if p > 0 {
                allowed.push(sorted([b, parent[p] as usize]));
            }
        }
        allowed.sort_unstable();
        allowed.dedup();
        let grandparents: Vec<[usize; 2]> = (1..model.nbody())
            .filter(|&b| parent[b] > 0)
            .map(|b| sorted([b, parent[parent[b] as usize] as usize]))
            .collect();
        for p in allowed.iter().filter(|p| !grandparents.contains(p)) {
            notes.push(format!(
                "links \"{}\" and \"{}\" already touch at the rest pose: their contacts are not counted as collisions",
                model.name(ObjType::Body, p[0]),
                model.name(ObjType::Body, p[1])
            ));
        }
        Some((data, allowed))
    } else {
        None
    };
    let body_joints: Vec<Vec<usize>> = (0..model.nbody())
        .map(|b| {
            let mut out = Vec::new();
            let mut k = b;
            while k != 0 {
                let (adr, num) = (model.body_dofadr()[k], model.body_dofnum()[k]);
                for d in 0..num.max(0) {
                    let dof = (adr + d) as usize;
                    if let Some(s) = selected.iter().position(|&j| robot.joints[j].dof == dof) {
                        out.push(s);
                    }
                }
                k = model.body_parentid()[k] as usize;
            }
            out
        })
        .collect();
    let mut problem = Problem {
        robot: &robot,
        reg,
        collide,
        limits,
        selected: selected.clone(),
        cad,
        cols,
        ncols: layout.ncols(),
        base_cols: Vec::new(),
        opts: opts.clone(),
        hold,
        evaluations: 0,
        body_joints,
        involved: Vec::new(),
        beta: None,
        searching: false,
        touching_scaled: false,
    };
    let template: Vec<FourierJoint> = selected
        .iter()
        .map(|&j| FourierJoint {
            name: robot.joints[j].name.clone(),
            index: j,
            rest: 0.0,
            a: vec![0.0; h],
            b: vec![0.0; h],
        })
        .collect();

    // Random candidates, each scaled to the limits; the first feasible one fixes the base columns.
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let mut candidates = Vec::new();
    let mut last_violation = None;
    for _ in 0..opts.random_candidates {
        let raw = random_joints(&template, &problem.limits, hb, &mut rng);
        match problem.fit_to_limits(&raw, false)? {
            Ok((js, _)) => candidates.push(js),
            Err(v) => last_violation = Some(v),
        }
    }
    if candidates.is_empty() {
        let v = last_violation.map_or_else(String::new, |v| v.what);
        return Err(urdf_err(format!(
            "the limits leave no feasible excitation trajectory: even holding still at rest, {v}; raise that \
             limit (the URDF's <limit>, or the effort/velocity fraction) or choose another rest pose"
        )));
    }
    if let (Some(v), true) = (&last_violation, candidates.len() < opts.random_candidates) {
        notes.push(format!(
            "{} of {} random trajectories were infeasible even at their rest pose (e.g. {})",
            opts.random_candidates - candidates.len(),
            opts.random_candidates,
            v.what
        ));
    }
    {
        let (rz, _, _) = problem.assess(&candidates[0], 4 * opts.samples, false)?;
        let ba = crate::estimate::base_analysis(&rz, 4 * opts.samples * selected.len())?;
        problem.base_cols = ba.base.iter().map(|b| b.lead).collect();
    }
    let mut random_conditions = Vec::new();
    let mut best: Option<(f64, Eval, Vec<FourierJoint>)> = None;
    let kept = candidates.clone();
    for js in candidates {
        let e = problem.evaluate(&js)?;
        random_conditions.push(e.condition);
        if best.as_ref().is_none_or(|b| e.cost < b.0) {
            best = Some((e.cost, e, js));
        }
    }
    let (_, best_eval, best_random) = best.expect("at least one candidate");
    let best_random_condition = best_eval.condition;
    let mut by_condition: Vec<usize> = (0..kept.len()).collect();
    by_condition.sort_by(|&a, &b| random_conditions[a].total_cmp(&random_conditions[b]));
    let median_index = by_condition[(kept.len() - 1) / 2];
    let (median_random, median_random_condition) = (kept[median_index].clone(), random_conditions[median_index]);

    // Global stage: more random trajectories (the same draw, but the rest position anywhere in
    // the range) and the 20 above, each scaled per joint to touch its position, velocity or
    // acceleration room; the best few start quasi-Newton searches on a smooth surrogate of the
    // condition number, and the best result is polished on the condition number itself.
    let steps: Vec<f64> = problem
        .limits
        .iter()
        .flat_map(|l| {
            let mut s = vec![0.5 * (l.upper - l.lower)];
            s.extend(std::iter::repeat_n(l.velocity, 2 * (h - 1)));
            s
        })
        .collect();
    problem.searching = true;
    let mut pool: Vec<(f64, Vec<FourierJoint>)> = Vec::new();
    for js in &kept {
        let t = problem.box_fit(js, true);
        pool.push((problem.evaluate(&t)?.cost, t));
    }
    for _ in 0..opts.global_candidates {
        let raw = random_joints_anywhere(&template, &problem.limits, h, &mut rng);
        let t = problem.box_fit(&raw, true);
        pool.push((problem.evaluate(&t)?.cost, t));
    }
    pool.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut joints, mut condition, mut scaled_condition, mut cost) =
        (best_random.clone(), best_random_condition, best_eval.scaled_condition, best_eval.cost);
    let mut binding_note = None;
    let mut results: Vec<(f64, Vec<f64>, bool)> = Vec::new();
    for (_, start) in pool.iter().take(opts.starts) {
        for touching_scaled in [false, true] {
            problem.touching_scaled = touching_scaled;
            let mut x = vars_from_joints(start, h);
            for &beta in &opts.smoothing {
                problem.beta = Some(beta);
                x = bfgs(
                    |x, with_gradient| problem.cost(x, &template, with_gradient),
                    &x,
                    &steps,
                    opts.max_iterations,
                )?;
            }
            problem.beta = None;
            let js = problem.box_fit(&joints_from_vars(&x, h, &template), false);
            results.push((problem.evaluate(&js)?.cost, x, touching_scaled));
        }
    }
    results.sort_by(|a, b| a.0.total_cmp(&b.0));
    if let Some((_, x0, touching_scaled)) = results.first() {
        problem.touching_scaled = *touching_scaled;
        let x = bfgs(|x, with_gradient| problem.cost(x, &template, with_gradient), x0, &steps, opts.max_iterations)?;
        problem.searching = false;
        // The fine grid (4 points per sample) can miss a 15-harmonic peak by up to
        // 1 − cos(π·15/400) ≈ 0.7 %: the design is shrunk per joint to fit its position,
        // velocity and acceleration limits on a grid 100 points per harmonic.
        let designed: Vec<FourierJoint> = problem
            .box_fit(&joints_from_vars(&x, h, &template), false)
            .iter()
            .zip(&problem.limits)
            .map(|(f, lim)| {
                let (mut f, room) = problem.room_on(f, lim, (100 * h).max(4 * opts.samples));
                if room < 1.0 {
                    f.scale(room);
                }
                f
            })
            .collect();
        let mut options = Vec::new();
        let (_, pen, _) = problem.assess(&designed, 4 * opts.samples, opts.self_collision)?;
        if pen == 0.0 {
            options.push((designed.clone(), None));
        } else {
            for per_joint in [false, true] {
                if let Ok(fitted) = problem.fit_to_limits(&designed, per_joint)? {
                    options.push(fitted);
                }
            }
        }
        for (fitted, binding) in options {
            let e = problem.evaluate(&fitted)?;
            if e.penalty == 0.0 && e.cost < cost {
                (joints, condition, scaled_condition, cost) = (fitted, e.condition, e.scaled_condition, e.cost);
                binding_note = binding.map(|b: Violation| {
                    format!("the designed trajectory was shrunk to fit the limits; the binding one: {}", b.what)
                });
            }
        }
    }
    problem.searching = false;
    notes.extend(binding_note);
    if condition >= best_random_condition {
        notes.push("the search found nothing better than the best random trajectory".into());
    }
    let usage = problem.usage(&joints)?;
    let report = ExciteReport {
        trajectory: problem.excitation(joints),
        criterion: opts.criterion,
        condition,
        scaled_condition,
        best_random_scaled_condition: best_eval.scaled_condition,
        random_conditions,
        best_random_condition,
        baseline_harmonics: hb,
        best_random: problem.excitation(best_random),
        median_random: problem.excitation(median_random),
        median_random_condition,
        base_parameters: problem.base_cols.len(),
        limits: problem.limits.clone(),
        usage,
        evaluations: problem.evaluations,
        design_secs: started.elapsed().as_secs_f64(),
        notes,
    };
    Ok(report)
}
