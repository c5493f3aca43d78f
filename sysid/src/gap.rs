//! The reality gap measured (`twin gap --log real.mcap ROBOT.urdf`): the logged efforts are
//! replayed on the twin, open loop, from the logged state, re-synchronized to the log every
//! `resync_secs`; the twin's joint positions and velocities are compared with the log's, and
//! the twin's inverse-dynamics torque along the logged motion with the logged torque. The
//! figure identification and calibration must move.
//!
//! The twin is the URDF as [`crate::synth::simulation_model`] compiles it (fixed base,
//! contacts off, URDF friction as Coulomb friction, timestep = the log's median step). The
//! effort of sample `k` is applied as a joint torque from `t_k` to `t_{k+1}`; a gap in the log
//! (a step over 1.5 median steps) re-synchronizes.

use crate::SysidOptions;
use crate::error::{Error, Result};
use crate::log::JointLog;
use crate::model::RobotModel;
use crate::plot::{COLORS, Plot, stack_svg};
use crate::signal::median_step;
use twin_core::mj::Data;

/// Options of [`measure_gap`].
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct GapOptions {
    /// The twin is reset to the logged state every this many seconds (default: 1.0).
    #[default(1.0)]
    pub resync_secs: f64,
    /// Armature of every joint of the twin, kg·m² (default: 0: URDF has none; a joint's
    /// armature in the URDF's `<twin_sysid>` block wins).
    pub armature: f64,
    /// Refuse a log that lacks some of the robot's joints instead of holding them at their home
    /// position (default: false: held, with a warning, as `twin sysid` does).
    pub strict: bool,
}

/// One joint's gap.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointGap {
    /// Joint name.
    pub name: String,
    /// RMS position error, rad or m.
    pub position_rmse: f64,
    /// Largest position error, rad or m.
    pub position_max: f64,
    /// RMS velocity error, rad/s or m/s.
    pub velocity_rmse: f64,
    /// Torque NRMSE of the twin's inverse dynamics along the logged motion against the logged
    /// torque (as `twin sysid --validate`).
    pub torque_nrmse: f64,
}

/// Result of [`measure_gap`].
#[derive(Debug, Clone, serde::Serialize)]
pub struct GapReport {
    /// The URDF.
    pub urdf: String,
    /// The log.
    pub log: String,
    /// Re-synchronization period, seconds.
    pub resync_secs: f64,
    /// Log duration, seconds.
    pub duration_secs: f64,
    /// Per joint.
    pub joints: Vec<JointGap>,
    /// Mean of the joints' RMS position errors, rad.
    pub mean_position_rmse: f64,
    /// What the reader should know (joints held because the log lacks them).
    pub warnings: Vec<String>,
    /// Mean of the joints' RMS velocity errors, rad/s.
    pub mean_velocity_rmse: f64,
    /// Mean of the joints' torque NRMSE.
    pub mean_torque_nrmse: f64,
    /// Time (s from the log's start), twin position and logged position per joint
    /// (decimated to at most 2000 points), for the plot.
    #[serde(skip)]
    pub traces: Vec<Vec<(f64, f64, f64)>>,
}

impl GapReport {
    /// Human-readable table.
    pub fn table(&self) -> String {
        let w = self.joints.iter().map(|j| j.name.len()).max().unwrap_or(5).max(5);
        let mut s = format!(
            "reality gap of {} on {} ({:.1} s, open loop, re-synchronized every {} s)\n{:<w$}  {:>12}  {:>12}  {:>12}  {:>12}\n",
            self.urdf,
            self.log,
            self.duration_secs,
            self.resync_secs,
            "joint",
            "pos rmse",
            "pos max",
            "vel rmse",
            "torque nrmse"
        );
        for j in &self.joints {
            s.push_str(&format!(
                "{:<w$}  {:>12.3e}  {:>12.3e}  {:>12.3e}  {:>11.1}%\n",
                j.name,
                j.position_rmse,
                j.position_max,
                j.velocity_rmse,
                100.0 * j.torque_nrmse
            ));
        }
        s.push_str(&format!(
            "{:<w$}  {:>12.3e}  {:>12}  {:>12.3e}  {:>11.1}%\n",
            "mean",
            self.mean_position_rmse,
            "",
            self.mean_velocity_rmse,
            100.0 * self.mean_torque_nrmse
        ));
        s
    }

    /// The report as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// One panel per joint: logged and twin position over time.
    pub fn svg(&self) -> String {
        let panels: Vec<Plot> = self
            .joints
            .iter()
            .zip(&self.traces)
            .map(|(j, tr)| {
                let mut p =
                    Plot::new(&format!("{} (rmse {:.2e})", j.name, j.position_rmse), "time (s)", "position (rad)");
                p.line("log", tr.iter().map(|&(t, _, l)| (t, l)).collect(), COLORS[0]);
                p.line("twin", tr.iter().map(|&(t, s, _)| (t, s)).collect(), COLORS[1]);
                p
            })
            .collect();
        stack_svg(&panels)
    }
}

/// Replays `log` on the twin of `urdf` and measures the gap.
///
/// # Errors
/// [`Error::BadLog`] for a log without efforts or with joints the URDF lacks (as `twin
/// sysid`); loading errors; [`Error::Option`] for a bad re-synchronization period;
/// [`Error::Numerical`] if the twin diverges.
pub fn measure_gap(urdf: &std::path::Path, log: &JointLog, opts: &GapOptions) -> Result<GapReport> {
    if !(opts.resync_secs > 0.0 && opts.resync_secs.is_finite()) {
        return Err(Error::Option { name: "resync_secs", message: format!("{}: must be positive", opts.resync_secs) });
    }
    log.check_shape()?;
    let n = log.len();
    if n < 10 {
        return Err(log.bad(format!("only {n} samples: a log of at least a few seconds is needed")));
    }
    let t: Vec<f64> = log.t_nanos.iter().map(|&x| (x - log.t_nanos[0]) as f64 * 1e-9).collect();
    let dt = median_step(&t).ok_or_else(|| log.bad("all timestamps are equal".into()))?;
    let source = crate::model::UrdfSource::read(urdf)?;
    // Joints the log lacks are held at home, as `twin sysid` holds them.
    let (text, held) = crate::hold::hold_joints(&source, &log.joint_names)?;
    let mut warnings = Vec::new();
    if !held.is_empty() {
        let names: Vec<String> = held.iter().map(|(n, _)| n.clone()).collect();
        if opts.strict {
            return Err(log.bad(format!(
                "the robot's joint(s) {} are not in the log (which has {}); without --strict they are held at \
                 their home position",
                crate::condition::quote_list(&names),
                crate::condition::quote_list(&log.joint_names)
            )));
        }
        warnings.push(format!(
            "joint(s) {} of {} are not in the log: held at their home position",
            crate::condition::quote_list(&names),
            urdf.display()
        ));
    }
    // The friction and sensor model beyond <dynamics>: a torque sensor's offset is not torque
    // on the joint, the asymmetry term is friction MuJoCo's frictionloss does not hold.
    let block = crate::extension::read_block(urdf, &source.text)?;
    let source = crate::model::UrdfSource { path: source.path.clone(), text };
    let model = crate::synth::simulation_model_of(&source, dt, opts.armature)?;
    let robot = RobotModel::of_urdf(&source, model.clone(), false)?;
    let (map, _) = crate::condition::match_joints(log, &robot)?;
    let nj = robot.joints.len();
    for (joint, &i) in robot.joints.iter().zip(&map) {
        if let Some(k) = (0..n).find(|&k| !log.effort[i][k].is_finite() || !log.position[i][k].is_finite()) {
            return Err(log.bad(format!(
                "joint \"{}\" has no effort or position at t = {:.3} s: the gap replays the logged efforts \
                 (JointState.effort) and compares positions",
                joint.name, t[k]
            )));
        }
    }
    let mut data = Data::new(model.clone())?;
    let resync_every = (opts.resync_secs / dt).round().max(1.0) as usize;
    let (mut e_pos, mut e_vel, mut e_max) = (vec![0.0; nj], vec![0.0; nj], vec![0.0f64; nj]);
    let decimate = n.div_ceil(2000).max(1);
    let mut traces = vec![Vec::new(); nj];
    let mut since = 0usize;
    let vel = |i: usize, k: usize| -> f64 {
        let v = log.velocity[i][k];
        if v.is_finite() {
            v
        } else if k + 1 < n {
            (log.position[i][k + 1] - log.position[i][k]) / (t[k + 1] - t[k]).max(1e-9)
        } else {
            0.0
        }
    };
    for k in 0..n {
        let gap = k > 0 && t[k] - t[k - 1] > 1.5 * dt;
        if k == 0 || since >= resync_every || gap {
            for (joint, &i) in robot.joints.iter().zip(&map) {
                data.qpos_mut()[joint.qpos_adr] = log.position[i][k];
                data.qvel_mut()[joint.dof] = vel(i, k);
            }
            since = 0;
        }
        for (j, (joint, &i)) in robot.joints.iter().zip(&map).enumerate() {
            let dq = data.qpos()[joint.qpos_adr] - log.position[i][k];
            let dv = data.qvel()[joint.dof] - vel(i, k);
            e_pos[j] += dq * dq;
            e_vel[j] += dv * dv;
            e_max[j] = e_max[j].max(dq.abs());
            if k % decimate == 0 {
                traces[j].push((t[k], data.qpos()[joint.qpos_adr], log.position[i][k]));
            }
            let extra = block.iter().find(|b| b.name == joint.name).map_or(0.0, |b| {
                let bump = b.smoothing.map_or(0.0, |eps| 1.0 / (data.qvel()[joint.dof] / eps).cosh().powi(2));
                b.offset + b.asymmetry * bump
            });
            data.qfrc_applied_mut()[joint.dof] = log.effort[i][k] - extra;
        }
        data.step()?;
        since += 1;
        if data.diverged() {
            return Err(Error::Numerical(format!(
                "the twin of {} diverged at t = {:.3} s of the replay",
                urdf.display(),
                t[k]
            )));
        }
    }
    // Torque: the twin's inverse dynamics along the logged motion (as `twin sysid --validate`).
    let sysid_opts = SysidOptions::default();
    let torque =
        crate::select::models_nrmse(&robot, log, &sysid_opts, &[crate::select::ScoredModel::of_urdf(&robot, &block)])?;
    let joints: Vec<JointGap> = robot
        .joints
        .iter()
        .enumerate()
        .map(|(j, joint)| JointGap {
            name: joint.name.clone(),
            position_rmse: (e_pos[j] / n as f64).sqrt(),
            position_max: e_max[j],
            velocity_rmse: (e_vel[j] / n as f64).sqrt(),
            torque_nrmse: torque[0][j],
        })
        .collect();
    let mean = |f: &dyn Fn(&JointGap) -> f64| joints.iter().map(f).sum::<f64>() / nj as f64;
    Ok(GapReport {
        urdf: urdf.display().to_string(),
        log: log.source.clone(),
        resync_secs: opts.resync_secs,
        duration_secs: t[n - 1],
        mean_position_rmse: mean(&|j| j.position_rmse),
        mean_velocity_rmse: mean(&|j| j.velocity_rmse),
        mean_torque_nrmse: mean(&|j| j.torque_nrmse),
        warnings,
        joints,
        traces,
    })
}
