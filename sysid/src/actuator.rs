//! Drive identification (`twin sysid actuator`): per joint, the command delay, the gains of the
//! drive's own position loop and the armature (reflected rotor inertia), from a log of the
//! commands the drives received and what the joints did; scored by replaying held-out commands
//! on the twin; written back into the URDF's `<twin_actuator>` block (delay, gains) and
//! `<twin_sysid>` block (armature), which `twin convert` and every command turn into MuJoCo's
//! own actuator delay, gains and joint armature (see `twin_convert::actuator`).
//!
//! ## Method
//! The robot's rigid-body model (the URDF, inertias as identified by `twin sysid`) gives the
//! torque each joint needed, `τ_rb = M(q)q̈ + c(q, q̇) + b·q̇` (MuJoCo's inverse dynamics, the
//! URDF's joint damping `b` included, its armature left out), from the logged positions and
//! velocities low-passed without phase shift and the acceleration differentiated from them. A
//! position drive delivers `τ = kp·(q*(t − d) − q) − kd·q̇ − a·q̈` seen at the joint (`a` the
//! armature), so for each delay `d` on a grid (0.25 ms) the command held at `t − d`, low-passed
//! like the states, makes the fit linear in `(kp, kd, a)` (least squares); the delay is the one
//! with the smallest residual, refined between grid points by a parabola. An effort drive
//! (`τ = s·τ*(t − d) − a·q̈`) is fitted the same way for its strength `s` and armature.
//!
//! The intervals come from the spread of the same fit on 5 consecutive blocks of the data
//! (each its own delay), which sees the residuals' correlation in time that a least-squares
//! covariance would not. The last `held_out` part of the log is not fitted: the log's commands
//! are replayed open loop on the twin (the converter's MuJoCo model of the URDF, the drives as
//! MuJoCo runs them) before and after, and the position error there is the score; the values
//! written are then fitted on the whole log.
//!
//! ## Limitations
//! Joint Coulomb friction (`frictionloss`) is not in the fitted equation: identify it first
//! (`twin sysid friction`) and expect the gains of a joint with strong friction to absorb it.
//! The torque–speed envelope is not identified (the fit is of the linear drive). Velocity
//! interfaces are refused.

use crate::error::{Error, Result};
use crate::log::JointLog;
use crate::signal::{Butterworth, derivative};
use nalgebra::{DMatrix, DVector};
use std::path::Path;
use std::sync::Arc;
use twin_core::convert::{ConvertOptions, Interface, actuator::DriveModel};
use twin_core::mj::{Data, Model, ObjType};

/// The commands the drives received, per joint, as a zero-order hold between messages.
#[derive(Debug, Clone)]
pub struct CommandLog {
    /// Where they came from (file and topic).
    pub source: String,
    /// URDF joint names, in command order.
    pub joint_names: Vec<String>,
    /// Message times, ns, increasing.
    pub t_nanos: Vec<i64>,
    /// Per joint (in `joint_names` order), one value per message.
    pub values: Vec<Vec<f64>>,
}

impl CommandLog {
    /// The `std_msgs/msg/Float64MultiArray` commands of `topic` (or of the log's only such
    /// topic) in the ROS 2 bag at `path`, entry `i` of each message for `joint_names[i]`, stamped
    /// with the message's log time (when the controller sent it).
    ///
    /// # Errors
    /// [`Error::BadLog`] when the log has no such topic or several (naming them), or a message
    /// whose length is not the number of joints (naming its time); [`Error::Core`] for
    /// unreadable files.
    pub fn read_mcap(path: &Path, topic: Option<&str>, joint_names: &[String]) -> Result<CommandLog> {
        use twin_core::log::{Float64MultiArray, Log, ReadOptions};
        let log = Log::open(path, ReadOptions::default())?;
        let source_name = path.display().to_string();
        let topic = match topic {
            Some(t) => t.to_string(),
            None => {
                let info = log.info()?;
                let found = info.topics_of_type("Float64MultiArray");
                match found.as_slice() {
                    [one] => one.to_string(),
                    [] => {
                        return Err(Error::BadLog {
                            source_name,
                            message: "no std_msgs/msg/Float64MultiArray command topic (a ros2_control forward \
                                      command controller's `commands`): record it, or name it with --command-topic"
                                .into(),
                        });
                    }
                    many => {
                        return Err(Error::BadLog {
                            source_name,
                            message: format!(
                                "several Float64MultiArray topics ({}): name the drives' commands with --command-topic",
                                many.join(", ")
                            ),
                        });
                    }
                }
            }
        };
        let (messages, _report) = log.read_typed::<Float64MultiArray>(&topic)?;
        let mut out = CommandLog {
            source: format!("{} topic {topic}", path.display()),
            joint_names: joint_names.to_vec(),
            t_nanos: Vec::with_capacity(messages.len()),
            values: vec![Vec::with_capacity(messages.len()); joint_names.len()],
        };
        for (t, m) in messages {
            if m.data.len() != joint_names.len() {
                return Err(Error::BadLog {
                    source_name: out.source,
                    message: format!(
                        "the command at log time {:.6} s has {} entries for {} joints ({}): give the joints in \
                         command order with --command-joints",
                        t as f64 * 1e-9,
                        m.data.len(),
                        joint_names.len(),
                        joint_names.join(", ")
                    ),
                });
            }
            if out.t_nanos.last().is_some_and(|&last| (t as i64) < last) {
                continue;
            }
            out.t_nanos.push(t as i64);
            for (v, x) in out.values.iter_mut().zip(&m.data) {
                v.push(*x);
            }
        }
        if out.t_nanos.len() < 2 {
            return Err(Error::BadLog { source_name: out.source, message: "fewer than 2 commands".into() });
        }
        Ok(out)
    }

    /// Joint `j`'s command held at time `t_nanos` (the last one sent at or before it), `None`
    /// before the first.
    fn at(&self, j: usize, t_nanos: i64) -> Option<f64> {
        let i = self.t_nanos.partition_point(|&s| s <= t_nanos);
        i.checked_sub(1).map(|i| self.values[j][i])
    }
}

/// Options of [`identify_drives`].
#[derive(Debug, Clone, smart_default::SmartDefault)]
pub struct DriveOptions {
    /// Longest delay searched, seconds (default 0.03).
    #[default(0.03)]
    pub max_delay_secs: f64,
    /// Delay grid step, seconds (default 0.25 ms; refined between grid points).
    #[default(0.00025)]
    pub delay_step_secs: f64,
    /// Low-pass cut-off of states and commands, Hz (default 20).
    #[default(20.0)]
    pub cutoff_hz: f64,
    /// Fraction of the log (its end) held out for the replay score (default 0.3; 0 turns it off).
    #[default(0.3)]
    pub held_out: f64,
}

/// A value with its 95 % interval.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Estimate {
    /// The estimate.
    pub value: f64,
    /// 95 % interval [low, high].
    pub ci95: [f64; 2],
}

/// One joint's identified drive.
#[derive(Debug, Clone, serde::Serialize)]
pub struct JointDrive {
    /// URDF joint name.
    pub joint: String,
    /// `position` or `effort`.
    pub interface: String,
    /// Command delay, seconds.
    pub delay_secs: Estimate,
    /// Position-loop stiffness (joint space), N·m/rad; for an effort drive, its strength (torque
    /// per unit command).
    pub kp: Estimate,
    /// Position-loop damping beyond the URDF's joint damping, N·m·s/rad (0 for an effort drive).
    pub kd: Estimate,
    /// Armature, kg·m² (or kg).
    pub armature: Estimate,
    /// The URDF joint damping the fit took as known, N·m·s/rad.
    pub urdf_damping: f64,
    /// RMS of the fit's torque residual, N·m.
    pub residual_rms: f64,
    /// Samples fitted.
    pub samples: usize,
}

/// One joint's held-out replay position error.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ReplayError {
    /// URDF joint name.
    pub joint: String,
    /// RMS position error of the URDF as it was, rad (or m).
    pub before_rms: f64,
    /// RMS position error with the identified drive, rad (or m).
    pub after_rms: f64,
}

/// What [`identify_drives`] found.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DriveReport {
    /// The state log.
    pub states: String,
    /// The command log.
    pub commands: String,
    /// Per commanded joint: the drive fitted on the whole log (the values written back).
    pub joints: Vec<JointDrive>,
    /// Per commanded joint: the drive fitted without the held-out part (what the replay scores).
    pub fit_without_held_out: Vec<JointDrive>,
    /// Per commanded joint, on the held-out part (empty without one).
    pub held_out: Vec<ReplayError>,
    /// Seconds held out at the end of the log.
    pub held_out_secs: f64,
    /// Anything the caller should know.
    pub warnings: Vec<String>,
}

impl DriveReport {
    /// The report as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }
}

/// The states of the log on a uniform grid, low-passed, with the rigid-body torque.
struct Prepared {
    dt: f64,
    t_nanos: Vec<i64>,
    /// Per model DOF of a commanded joint (in command order): q, q̇, q̈ filtered, τ_rb.
    q: Vec<Vec<f64>>,
    qd: Vec<Vec<f64>>,
    qdd: Vec<Vec<f64>>,
    tau: Vec<Vec<f64>>,
    damping: Vec<f64>,
    /// The joint's effort limit (infinite when unlimited), N·m or N.
    effort: Vec<f64>,
    interface: Vec<Interface>,
    /// First and last sample usable for fitting (commands at t − max delay known, filter edges).
    first: usize,
}

/// The rigid-body model of `urdf` as the fit uses it: fixed base, no floor, the URDF's
/// `<twin_sysid>`/`<twin_actuator>` blocks as they are (armature is subtracted where used).
fn robot(path: &Path, text: &str, timestep_secs: f64) -> Result<twin_core::robot::Robot> {
    let options = ConvertOptions {
        fixed_base: true,
        floor: false,
        visuals: false,
        joint_sensors: false,
        timestep_secs,
        ..ConvertOptions::default()
    };
    Ok(twin_core::robot::Robot::load_str_with_extra(path, text, &options, "")?)
}

fn prepare(
    path: &Path,
    text: &str,
    states: &JointLog,
    commands: &CommandLog,
    opts: &DriveOptions,
    warnings: &mut Vec<String>,
) -> Result<Prepared> {
    let bad = |message: String| Error::BadLog { source_name: states.source.clone(), message };
    let n = states.len();
    if n < 100 {
        return Err(bad(format!("{n} joint-state samples: too few to identify drives")));
    }
    let t: Vec<f64> = states.t_nanos.iter().map(|&x| (x - states.t_nanos[0]) as f64 * 1e-9).collect();
    let dt = crate::signal::median_step(&t).ok_or_else(|| bad("no time step in the joint states".into()))?;
    if t.windows(2).any(|w| ((w[1] - w[0]) - dt).abs() > 0.25 * dt) {
        warnings.push(format!(
            "the joint states are not evenly spaced ({:.3} ms median step): they are taken as sampled on it",
            dt * 1e3
        ));
    }
    let robot = robot(path, text, dt)?;
    let model = robot.model.clone();
    let bw = Butterworth::low_pass(2, opts.cutoff_hz.min(0.4 / dt), 1.0 / dt);
    let pad = (0.2 / dt) as usize;
    // Every 1-DOF joint of the model at its logged (filtered) state, or held at qpos0.
    let mut q_all = Vec::new();
    for j in 0..model.njnt() {
        let name = model.name(ObjType::Joint, j);
        let (qa, va) = (model.jnt_qposadr()[j] as usize, model.jnt_dofadr()[j] as usize);
        if !matches!(model.joint_type(j), twin_core::mj::JointType::Hinge | twin_core::mj::JointType::Slide) {
            continue;
        }
        match states.joint_index(name) {
            Some(k) => {
                let q = bw.filtfilt(&states.position[k], pad);
                let qd = if states.velocity[k].iter().any(|v| v.is_nan()) {
                    derivative(&q, dt)
                } else {
                    bw.filtfilt(&states.velocity[k], pad)
                };
                let qdd = derivative(&qd, dt);
                q_all.push((name.to_string(), qa, va, Some((q, qd, qdd))));
            }
            None => {
                if commands.joint_names.iter().any(|c| c == name) {
                    return Err(bad(format!("joint \"{name}\" is commanded but has no joint state in the log")));
                }
                warnings.push(format!("joint \"{name}\" is not in the log: held at its default position"));
                q_all.push((name.to_string(), qa, va, None));
            }
        }
    }
    // Inverse dynamics, armature left out.
    let mut data = Data::new(model.clone())?;
    let mut tau_all = vec![vec![0.0; n]; model.nv()];
    for k in 0..n {
        data.qvel_mut().fill(0.0);
        data.qacc_mut().fill(0.0);
        for (_, qa, va, s) in &q_all {
            if let Some((q, qd, qdd)) = s {
                data.qpos_mut()[*qa] = q[k];
                data.qvel_mut()[*va] = qd[k];
                data.qacc_mut()[*va] = qdd[k];
            }
        }
        data.inverse()?;
        for (dof, row) in tau_all.iter_mut().enumerate() {
            row[k] = data.qfrc_inverse()[dof] - model.dof_armature()[dof] * data.qacc()[dof];
        }
    }
    let mut out = Prepared {
        dt,
        t_nanos: states.t_nanos.clone(),
        q: Vec::new(),
        qd: Vec::new(),
        qdd: Vec::new(),
        tau: Vec::new(),
        damping: Vec::new(),
        effort: Vec::new(),
        interface: Vec::new(),
        first: 0,
    };
    for name in &commands.joint_names {
        let Some((_, _, va, Some((q, qd, qdd)))) = q_all.iter().find(|(n, ..)| n == name) else {
            return Err(Error::Urdf {
                path: path.to_path_buf(),
                message: format!("commanded joint \"{name}\" is not a 1-DOF joint of the URDF"),
            });
        };
        let jid = model.dof_jntid()[*va] as usize;
        let Some(act) = robot.actuators.iter().find(|a| a.joint == Some(jid)) else {
            return Err(Error::Urdf {
                path: path.to_path_buf(),
                message: format!(
                    "commanded joint \"{name}\" has no actuator in the URDF (a <transmission> or ros2_control \
                     entry with its command interface): twin could not apply its commands"
                ),
            });
        };
        if act.interface == Interface::Velocity {
            return Err(Error::Urdf {
                path: path.to_path_buf(),
                message: format!(
                    "joint \"{name}\" has a velocity interface: only position and effort drives are identified"
                ),
            });
        }
        out.q.push(q.clone());
        out.qd.push(qd.clone());
        out.qdd.push(qdd.clone());
        out.tau.push(tau_all[*va].clone());
        out.damping.push(model.dof_damping()[*va]);
        let [lo, hi] = model.jnt_actfrcrange()[jid];
        out.effort.push(if model.jnt_actfrclimited()[jid] { lo.abs().min(hi.abs()) } else { f64::INFINITY });
        out.interface.push(act.interface);
    }
    let start = commands.t_nanos[0] + (opts.max_delay_secs * 1e9) as i64;
    out.first = out.t_nanos.partition_point(|&x| x < start).max(pad.min(n / 10));
    Ok(out)
}

/// Normal equations of one delay: per block, `XᵀX`, `Xᵀy`, `yᵀy`, count.
#[derive(Clone)]
struct Normal {
    xtx: DMatrix<f64>,
    xty: DVector<f64>,
    yty: f64,
    count: usize,
}

impl Normal {
    fn new(p: usize) -> Normal {
        Normal { xtx: DMatrix::zeros(p, p), xty: DVector::zeros(p), yty: 0.0, count: 0 }
    }
    fn add(&mut self, other: &Normal) {
        self.xtx += &other.xtx;
        self.xty += &other.xty;
        self.yty += other.yty;
        self.count += other.count;
    }
    /// Coefficients and residual sum of squares.
    fn solve(&self) -> Option<(DVector<f64>, f64)> {
        let beta = self.xtx.clone().cholesky()?.solve(&self.xty);
        let sse = self.yty - 2.0 * beta.dot(&self.xty) + (beta.transpose() * &self.xtx * &beta)[(0, 0)];
        Some((beta, sse.max(0.0)))
    }
}

const BLOCKS: usize = 5;
/// Student t, 97.5 % quantile, 4 degrees of freedom.
const T4: f64 = 2.776;

/// Per delay on the grid, the normal equations of joint `j` over `BLOCKS` blocks of
/// `range`.
fn normals(
    p: &Prepared,
    commands: &CommandLog,
    j: usize,
    range: std::ops::Range<usize>,
    used: &[bool],
    opts: &DriveOptions,
) -> Vec<(f64, Vec<Normal>)> {
    let n = p.t_nanos.len();
    let bw = Butterworth::low_pass(2, opts.cutoff_hz.min(0.4 / p.dt), 1.0 / p.dt);
    let pad = (0.2 / p.dt) as usize;
    let steps = (opts.max_delay_secs / opts.delay_step_secs).round() as usize;
    let position = p.interface[j] == Interface::Position;
    let np = if position { 3 } else { 2 };
    let block_len = range.len().div_ceil(BLOCKS);
    (0..=steps)
        .map(|s| {
            let d = s as f64 * opts.delay_step_secs;
            let dn = (d * 1e9).round() as i64;
            let first_cmd = commands.values[j][0];
            let held: Vec<f64> = (0..n).map(|k| commands.at(j, p.t_nanos[k] - dn).unwrap_or(first_cmd)).collect();
            let c = bw.filtfilt(&held, pad);
            let mut blocks = vec![Normal::new(np); BLOCKS];
            for k in range.clone().filter(|&k| used[k]) {
                let b = ((k - range.start) / block_len).min(BLOCKS - 1);
                let x: [f64; 3] =
                    if position { [c[k] - p.q[j][k], -p.qd[j][k], -p.qdd[j][k]] } else { [c[k], -p.qdd[j][k], 0.0] };
                let y = p.tau[j][k];
                let nb = &mut blocks[b];
                for r in 0..np {
                    for cc in 0..np {
                        nb.xtx[(r, cc)] += x[r] * x[cc];
                    }
                    nb.xty[r] += x[r] * y;
                }
                nb.yty += y * y;
                nb.count += 1;
            }
            (d, blocks)
        })
        .collect()
}

/// `mask` with every `false` widened by `margin` samples each side.
fn dilate_false(mask: Vec<bool>, margin: usize) -> Vec<bool> {
    let n = mask.len();
    let mut out = mask.clone();
    for (k, ok) in mask.iter().enumerate() {
        if !ok {
            out[k.saturating_sub(margin)..(k + margin + 1).min(n)].fill(false);
        }
    }
    out
}

/// Per delay, the normal equations of all blocks together.
fn sum_blocks(grid: &[(f64, Vec<Normal>)]) -> Vec<(f64, Normal)> {
    grid.iter()
        .map(|(d, blocks)| {
            let mut all = Normal::new(blocks[0].xty.len());
            for b in blocks {
                all.add(b);
            }
            (*d, all)
        })
        .collect()
}

/// The delay with the least residual (refined by a parabola through its neighbours) and the
/// coefficients there, from per-delay normal equations.
fn best(grid: &[(f64, Normal)]) -> Option<(f64, DVector<f64>, f64)> {
    let sse: Vec<Option<(DVector<f64>, f64)>> = grid.iter().map(|(_, n)| n.solve()).collect();
    let (i, _) =
        sse.iter().enumerate().filter_map(|(i, s)| s.as_ref().map(|s| (i, s.1))).min_by(|a, b| a.1.total_cmp(&b.1))?;
    let mut d = grid[i].0;
    if i > 0
        && i + 1 < grid.len()
        && let (Some(a), Some(c)) = (&sse[i - 1], &sse[i + 1])
    {
        let (ya, yb, yc) = (a.1, sse[i].as_ref().map_or(0.0, |s| s.1), c.1);
        let den = ya - 2.0 * yb + yc;
        if den > 0.0 {
            let h = grid[i + 1].0 - grid[i].0;
            d += (0.5 * (ya - yc) / den).clamp(-0.5, 0.5) * h;
        }
    }
    let (beta, s) = sse[i].clone()?;
    Some((d, beta, s))
}

fn fit_joint(
    p: &Prepared,
    commands: &CommandLog,
    j: usize,
    range: std::ops::Range<usize>,
    opts: &DriveOptions,
) -> Result<JointDrive> {
    let name = &commands.joint_names[j];
    // Where the drive is at its effort limit the linear drive equation does not hold: those
    // samples are left out, first by the rigid-body torque, then with the armature's too.
    // The low-pass spreads a clip over its impulse response: a margin of one cut-off period
    // around each saturated sample goes too.
    let effort = p.effort[j];
    let margin = (1.0 / (opts.cutoff_hz * p.dt)).ceil() as usize;
    let mut used = dilate_false(p.tau[j].iter().map(|t| t.abs() < 0.85 * effort).collect(), margin);
    let first = normals(p, commands, j, range.clone(), &used, opts);
    if let Some((_, beta, _)) = best(&sum_blocks(&first)) {
        let a = beta[beta.len() - 1];
        let within = p.tau[j].iter().zip(&p.qdd[j]).map(|(t, qdd)| (t + a * qdd).abs() < 0.95 * effort).collect();
        used = dilate_false(within, margin);
    }
    let saturated = range.clone().filter(|&k| !used[k]).count();
    if saturated * 2 > range.len() {
        return Err(Error::NotExcited {
            source_name: commands.source.clone(),
            problems: vec![format!(
                "joint \"{name}\": the drive is at its {effort} effort limit in {saturated} of {} samples: \
                 command smaller steps for identification",
                range.len()
            )],
        });
    }
    let grid = normals(p, commands, j, range.clone(), &used, opts);
    let whole = sum_blocks(&grid);
    let not_excited = || Error::NotExcited {
        source_name: commands.source.clone(),
        problems: vec![format!("joint \"{name}\": its commands and motion do not determine the drive (singular fit)")],
    };
    let (delay, beta, sse) = best(&whole).ok_or_else(not_excited)?;
    let position = p.interface[j] == Interface::Position;
    let params = |b: &DVector<f64>| -> [f64; 3] { if position { [b[0], b[1], b[2]] } else { [b[0], 0.0, b[1]] } };
    let whole_params = params(&beta);
    // Block fits, each its own delay.
    let mut per_block: Vec<[f64; 4]> = Vec::new();
    for b in 0..BLOCKS {
        let g: Vec<(f64, Normal)> = grid.iter().map(|(d, blocks)| (*d, blocks[b].clone())).collect();
        if let Some((d, beta, _)) = best(&g) {
            let [a, bb, c] = params(&beta);
            per_block.push([d, a, bb, c]);
        }
    }
    let interval = |i: usize, value: f64| -> Estimate {
        if per_block.len() < 3 {
            return Estimate { value, ci95: [f64::NAN, f64::NAN] };
        }
        let m = per_block.len() as f64;
        let mean = per_block.iter().map(|b| b[i]).sum::<f64>() / m;
        let sd = (per_block.iter().map(|b| (b[i] - mean).powi(2)).sum::<f64>() / (m - 1.0)).sqrt();
        // The delay is found on a grid: never narrower than half its step.
        let floor = if i == 0 { 0.5 * opts.delay_step_secs } else { 0.0 };
        let half = (T4 * sd / m.sqrt()).max(floor);
        Estimate { value, ci95: [value - half, value + half] }
    };
    let count = whole.first().map_or(0, |w| w.1.count);
    // The fitted damping is the drive's plus the URDF joint's, which the inverse dynamics holds:
    // the fit's kd is the drive's alone.
    Ok(JointDrive {
        joint: name.clone(),
        interface: if position { "position" } else { "effort" }.into(),
        delay_secs: interval(0, delay),
        kp: interval(1, whole_params[0]),
        kd: interval(2, whole_params[1]),
        armature: interval(3, whole_params[2]),
        urdf_damping: p.damping[j],
        residual_rms: (sse / count.max(1) as f64).sqrt(),
        samples: count,
    })
}

/// Identifies each commanded joint's drive (see the module docs) of the robot `urdf` from the
/// joint `states` and the `commands` its drives received, and scores it on the held-out end of
/// the log by replaying the commands on the twin before and after.
///
/// # Errors
/// [`Error::BadLog`] for a log too short or missing a commanded joint; [`Error::Urdf`] for a
/// commanded joint without an actuator (or with a velocity interface); [`Error::NotExcited`]
/// when a joint's fit is singular; the converter's and MuJoCo's errors.
pub fn identify_drives(
    urdf: &Path,
    states: &JointLog,
    commands: &CommandLog,
    opts: &DriveOptions,
) -> Result<DriveReport> {
    let text = twin_core::fsio::read_to_string(urdf)?;
    let mut warnings = Vec::new();
    let p = prepare(urdf, &text, states, commands, opts, &mut warnings)?;
    let n = p.t_nanos.len();
    let trim_end = n.saturating_sub((0.2 / p.dt) as usize);
    let held_out = opts.held_out.clamp(0.0, 0.9);
    let split = p.first + (((trim_end - p.first) as f64) * (1.0 - held_out)) as usize;
    let mut joints = Vec::new();
    let mut fit_part = Vec::new();
    for j in 0..commands.joint_names.len() {
        joints.push(fit_joint(&p, commands, j, p.first..trim_end, opts)?);
        if held_out > 0.0 {
            fit_part.push(fit_joint(&p, commands, j, p.first..split, opts)?);
        }
    }
    let mut report = DriveReport {
        states: states.source.clone(),
        commands: commands.source.clone(),
        joints,
        fit_without_held_out: fit_part,
        held_out: Vec::new(),
        held_out_secs: 0.0,
        warnings,
    };
    if held_out > 0.0 {
        let after_text = rewrite_drives(urdf, &text, &report.fit_without_held_out)?;
        let before = replay(urdf, &text, states, commands, p.dt)?;
        let after = replay(urdf, &after_text, states, commands, p.dt)?;
        report.held_out_secs = (trim_end - split) as f64 * p.dt;
        for (j, name) in commands.joint_names.iter().enumerate() {
            let k = states.joint_index(name).expect("checked by prepare");
            let rms = |sim: &[Vec<f64>]| {
                let e: f64 = (split..trim_end).map(|i| (sim[j][i] - states.position[k][i]).powi(2)).sum();
                (e / (trim_end - split).max(1) as f64).sqrt()
            };
            report.held_out.push(ReplayError { joint: name.clone(), before_rms: rms(&before), after_rms: rms(&after) });
        }
    }
    Ok(report)
}

/// The log's commands replayed open loop on the twin of URDF `text` (the converter's MuJoCo
/// model, stepped at the log's `dt`), from the logged state at the first sample: per commanded
/// joint, its position at each joint-state sample.
fn replay(path: &Path, text: &str, states: &JointLog, commands: &CommandLog, dt: f64) -> Result<Vec<Vec<f64>>> {
    let robot = robot(path, text, dt)?;
    let model: Arc<Model> = robot.model.clone();
    let mut data = Data::new(model.clone())?;
    let joint = |name: &str| model.id(ObjType::Joint, name);
    for (k, name) in states.joint_names.iter().enumerate() {
        if let Some(j) = joint(name) {
            data.qpos_mut()[model.jnt_qposadr()[j] as usize] = states.position[k][0];
        }
    }
    // Actuator of each commanded joint; the others hold their logged position (or zero torque).
    let mut drive: Vec<(usize, Option<usize>, Option<usize>)> = Vec::new();
    for a in &robot.actuators {
        let Some(j) = a.joint else { continue };
        let name = model.name(ObjType::Joint, j);
        let cmd = commands.joint_names.iter().position(|c| c == name);
        let logged = states.joint_index(name).filter(|_| a.interface == Interface::Position);
        drive.push((a.id, cmd, logged));
    }
    let out_index: Vec<usize> = commands
        .joint_names
        .iter()
        .map(|n| joint(n).map(|j| model.jnt_qposadr()[j] as usize).expect("checked by prepare"))
        .collect();
    let mut out = vec![Vec::with_capacity(states.len()); commands.joint_names.len()];
    for k in 0..states.len() {
        for (o, &adr) in out.iter_mut().zip(&out_index) {
            o.push(data.qpos()[adr]);
        }
        let t = states.t_nanos[k];
        for &(a, cmd, logged) in &drive {
            data.ctrl_mut()[a] = match (cmd, logged) {
                (Some(c), _) => commands.at(c, t).unwrap_or(commands.values[c][0]),
                (None, Some(l)) => states.position[l][k],
                (None, None) => 0.0,
            };
        }
        data.step()?;
    }
    Ok(out)
}

/// `text` (the URDF at `path`) with the identified `drives` written into its `<twin_actuator>`
/// block (delay and, for position drives, kp and kd; other joints' entries kept) and their
/// armature into its `<twin_sysid>` block (other terms kept; a joint without an entry gets one
/// with its URDF `<dynamics>`). Every other byte is kept.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML or blocks.
pub fn rewrite_drives(path: &Path, text: &str, drives: &[JointDrive]) -> Result<String> {
    use crate::extension::{self, JointFriction};
    let urdf_err =
        |e: twin_core::convert::actuator::Error| Error::Urdf { path: path.to_path_buf(), message: e.to_string() };
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: e.to_string() })?;
    let mut models = twin_core::convert::actuator::read_block(path, &doc).map_err(urdf_err)?;
    for d in drives {
        let position = d.interface == "position";
        let m = DriveModel {
            joint: d.joint.clone(),
            delay_secs: d.delay_secs.value.max(0.0),
            kp: position.then_some(d.kp.value.max(0.0)),
            kd: position.then_some(d.kd.value.max(0.0)),
            ..DriveModel::default()
        };
        match models.iter_mut().find(|x| x.joint == d.joint) {
            Some(old) => {
                *old = DriveModel { stall_torque: old.stall_torque, no_load_speed: old.no_load_speed, ..m };
            }
            None => models.push(m),
        }
    }
    let block = twin_core::convert::actuator::block_text(
        &models,
        "command delay and drive-loop gains (joint space), identified by `twin sysid actuator`",
    );
    let text = extension::splice_element(path, text, twin_core::convert::actuator::BLOCK, "twin actuator", &block)?;
    let mut friction = extension::read_block(path, &text)?;
    let dynamics = urdf_dynamics(&text);
    for d in drives {
        let a = d.armature.value.max(0.0);
        match friction.iter_mut().find(|f| f.name == d.joint) {
            Some(f) => f.armature = a,
            None => {
                let (damping, coulomb) = dynamics.iter().find(|x| x.0 == d.joint).map_or((0.0, 0.0), |x| (x.1, x.2));
                friction.push(JointFriction::from_dynamics(&d.joint, damping, coulomb, a));
            }
        }
    }
    let block = extension::block_text(&friction, "armature identified by `twin sysid actuator`.");
    extension::splice_block(path, &text, &block)
}

/// `(joint, damping, friction)` of each URDF joint's `<dynamics>`.
fn urdf_dynamics(text: &str) -> Vec<(String, f64, f64)> {
    let Ok(doc) = roxmltree::Document::parse(text) else { return Vec::new() };
    doc.root_element()
        .children()
        .filter(|n| n.has_tag_name("joint"))
        .filter_map(|j| {
            let dyn_ = j.children().find(|n| n.has_tag_name("dynamics"))?;
            let num = |a: &str| dyn_.attribute(a).and_then(|v| v.trim().parse::<f64>().ok()).unwrap_or(0.0);
            Some((j.attribute("name")?.to_string(), num("damping"), num("friction")))
        })
        .collect()
}
