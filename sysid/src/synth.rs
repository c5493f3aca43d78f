//! Synthetic logs: the twin simulates a known robot with MuJoCo under an exciting trajectory
//! and logs what a real robot's `/joint_states` would carry, with sensor imperfections. Used by
//! the benchmark and the tests (and handy to try `twin sysid` without a robot).
//!
//! The true model is the URDF as MuJoCo compiles it (its `<dynamics damping friction>` become
//! viscous damping and dry friction loss) plus an armature per joint. Each joint follows a sum
//! of sines inside its range (or a given reference, e.g. `twin excite`'s design), tracked by
//! computed torque (the full mass matrix, bias and damping forces, a 4 Hz PD on the error; a
//! floating base's free joint unactuated), so that the robot stays inside its joint ranges as
//! identification assumes; the logged effort is the torque applied to the joint, the only one
//! driving it (the model's own actuators are disabled). Every random draw (trajectory phases,
//! wrench waves, sensor noise, the perturbed "CAD") comes from one seeded `ChaCha8Rng`.

use crate::error::Result;
use crate::log::JointLog;
use crate::model::{RobotModel, UrdfSource};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;
use twin_core::mj::Data;

/// Options of a synthetic log.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct SynthOptions {
    /// Duration, seconds (default: 20).
    #[default(20.0)]
    pub duration_secs: f64,
    /// Simulation and log rate, Hz (default: 1000).
    #[default(1000.0)]
    pub rate_hz: f64,
    /// Seed of the trajectory phases and the noise (default: 1).
    #[default(1)]
    pub seed: u64,
    /// Armature of every joint in the true model, kg·m² (default: 0.02).
    #[default(0.02)]
    pub armature: f64,
    /// Encoder resolution in bits per turn; positions are quantised to `2π / 2^bits`
    /// (default: 17).
    #[default(17)]
    pub encoder_bits: u32,
    /// Standard deviation of the velocity noise, rad/s (default: 0.01).
    #[default(0.01)]
    pub velocity_noise: f64,
    /// Effort noise standard deviation as a fraction of each joint's RMS torque (default: 0.01).
    #[default(0.01)]
    pub effort_noise_rel: f64,
    /// Largest amplitude of a joint's trajectory, rad (default: 1.0); at most 80 % of half its
    /// range.
    #[default(1.0)]
    pub max_amplitude: f64,
    /// Lowest trajectory frequency, Hz (default: 0.12).
    #[default(0.12)]
    pub base_frequency_hz: f64,
}

/// A floating-base synthetic log: the robot's root link hangs from nothing (a free joint), and
/// the log carries the base motion (`nav_msgs/msg/Odometry`) and the known external wrenches.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct FloatingSynthOptions {
    /// Gravity on (default: `true`: the robot is in free fall, which for its joints and base
    /// rows is the same as floating in zero gravity: momentum conservation makes the base move
    /// as the joints do. `false` simulates zero gravity, which the identification must then be
    /// told about: its model has the URDF's gravity).
    #[default(true)]
    pub gravity: bool,
    /// Links that receive a known external wrench (a stand-in for measured contact wrenches),
    /// logged as `WrenchStamped` on `/contacts/<link>` with `header.frame_id = <link>`
    /// (default: none).
    pub wrench_links: Vec<String>,
    /// Amplitude of each force component, N (default: 20).
    #[default(20.0)]
    pub wrench_force_n: f64,
    /// Amplitude of each torque component (about the link origin), N·m (default: 2).
    #[default(2.0)]
    pub wrench_torque_nm: f64,
    /// Wrench noise standard deviation as a fraction of its amplitude (default: 0.01).
    #[default(0.01)]
    pub wrench_noise_rel: f64,
    /// Standard deviation of the odometry position noise, m (default: 1e-4).
    #[default(1e-4)]
    pub position_noise_m: f64,
    /// Standard deviation of the odometry orientation noise, rad (default: 1e-4).
    #[default(1e-4)]
    pub orientation_noise_rad: f64,
    /// Standard deviation of the odometry twist noise, m/s and rad/s (default: 0.002; a state
    /// estimator fusing an IMU).
    #[default(0.002)]
    pub twist_noise: f64,
    /// Odometry topic name (default: `/odom`).
    #[default("/odom")]
    pub odom_topic: String,
}

/// Simulates the robot of `urdf` (contacts off: a robot bolted down or on a gantry, moving in
/// free space) and returns its log.
///
/// # Errors
/// Loading errors of the URDF; [`crate::Error::Core`] if MuJoCo fails.
pub fn simulate(urdf: &Path, opts: &SynthOptions) -> Result<JointLog> {
    simulate_impl(urdf, opts, None, None)
}

/// A joint-space reference: `(q, q̇, q̈)` of joint `j` ([`RobotModel::joints`] order) at time
/// `t` seconds.
pub type Reference<'a> = &'a dyn Fn(usize, f64) -> (f64, f64, f64);

/// As [`simulate`], the robot tracking `reference` instead of the built-in sum of sines (e.g.
/// an excitation trajectory of [`crate::excite`]); the options' trajectory fields
/// (`max_amplitude`, `base_frequency_hz`) are then unused.
///
/// # Errors
/// As [`simulate`].
pub fn simulate_tracking(urdf: &Path, opts: &SynthOptions, reference: Reference<'_>) -> Result<JointLog> {
    simulate_impl(urdf, opts, None, Some(reference))
}

/// Simulates the robot of `urdf` with a floating base (contacts off) and returns its log with
/// [`JointLog::base`] and [`JointLog::wrenches`] filled ([`JointLog::write_mcap`] writes them
/// as `/odom` and `/contacts/<link>`).
///
/// # Errors
/// As [`simulate`]; [`crate::Error::Urdf`] for a wrench link the robot lacks.
pub fn simulate_floating(urdf: &Path, opts: &SynthOptions, floating: &FloatingSynthOptions) -> Result<JointLog> {
    simulate_impl(urdf, opts, Some(floating), None)
}

fn simulate_impl(
    urdf: &Path,
    opts: &SynthOptions,
    floating: Option<&FloatingSynthOptions>,
    custom: Option<Reference<'_>>,
) -> Result<JointLog> {
    let dt = 1.0 / opts.rate_hz;
    let gravity = if floating.is_some_and(|f| !f.gravity) { r#" gravity="0 0 0""# } else { "" };
    // The joints are driven by the logged torques alone (`qfrc_applied`): the converter's
    // actuators (position servos for a URDF's `PositionJointInterface`, as on the UR5) would add
    // forces that no log entry carries.
    let extra = format!(r#"<option timestep="{dt}"{gravity}><flag contact="disable" actuation="disable"/></option>"#);
    let source = UrdfSource::read(urdf)?;
    let base = source.model(&extra, floating.is_some())?;
    let free_dofs = if floating.is_some() { 6 } else { 0 };
    let model = stiff_friction(&base, free_dofs, dt, opts.armature)?;
    let robot = RobotModel::of_urdf(&source, model.clone(), floating.is_some())?;
    let nj = robot.joints.len();
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    // Known external wrenches: per link and component, 3 sines between 0.2 and 1.5 Hz.
    let wrench_links: Vec<(String, usize)> = match floating {
        Some(f) => f
            .wrench_links
            .iter()
            .map(|name| {
                model.id(twin_core::mj::ObjType::Body, name).map(|b| (name.clone(), b)).ok_or_else(|| {
                    crate::Error::Urdf { path: urdf.to_path_buf(), message: format!("no link \"{name}\" for a wrench") }
                })
            })
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    let wrench_waves: Vec<[[(f64, f64, f64); 3]; 6]> = wrench_links
        .iter()
        .map(|_| {
            std::array::from_fn(|k| {
                let amp = floating.map_or(0.0, |f| if k < 3 { f.wrench_force_n } else { f.wrench_torque_nm });
                std::array::from_fn(|_| (amp / 3.0, 0.2 + 1.3 * rng.random::<f64>(), 2.0 * PI * rng.random::<f64>()))
            })
        })
        .collect();
    let wrench_at = |i: usize, t: f64| -> [f64; 6] {
        std::array::from_fn(|k| wrench_waves[i][k].iter().map(|&(a, f, p)| a * (2.0 * PI * f * t + p).sin()).sum())
    };
    let mut base_log = crate::log::BaseTrajectory {
        topic: floating.map_or(String::new(), |f| f.odom_topic.clone()),
        ..Default::default()
    };
    let mut wrench_log: Vec<crate::log::WrenchSeries> = wrench_links
        .iter()
        .map(|(name, _)| crate::log::WrenchSeries {
            topic: format!("/contacts/{name}"),
            body: name.clone(),
            ..Default::default()
        })
        .collect();

    // Trajectory: per joint centre, 5 harmonics with random phases, amplitudes within range.
    const HARMONICS: [f64; 5] = [1.0, 2.0, 3.0, 5.0, 7.0];
    let mut centre = vec![0.0; nj];
    let mut amp = vec![[0.0; 5]; nj];
    let mut phase = vec![[0.0; 5]; nj];
    let mut freq = vec![[0.0; 5]; nj];
    for (j, joint) in robot.joints.iter().enumerate() {
        let jid = model.dof_jntid()[joint.dof] as usize;
        let (lo, hi) = if model.jnt_limited()[jid] {
            let r = model.jnt_range()[jid];
            (r[0], r[1])
        } else {
            (-PI, PI)
        };
        centre[j] = 0.5 * (lo + hi);
        let total = (0.8 * 0.5 * (hi - lo)).min(opts.max_amplitude);
        let f0 = opts.base_frequency_hz * (1.0 + 0.13 * j as f64 + 0.2 * rng.random::<f64>());
        let weights: Vec<f64> = HARMONICS.iter().map(|h| 1.0 / h).collect();
        let wsum: f64 = weights.iter().sum();
        for k in 0..5 {
            amp[j][k] = total * weights[k] / wsum;
            phase[j][k] = 2.0 * PI * rng.random::<f64>();
            freq[j][k] = f0 * HARMONICS[k];
        }
    }
    let sines = |j: usize, t: f64| -> (f64, f64, f64) {
        let (mut q, mut qd, mut qdd) = (centre[j], 0.0, 0.0);
        for k in 0..5 {
            let w = 2.0 * PI * freq[j][k];
            let a = w * t + phase[j][k];
            q += amp[j][k] * a.sin();
            qd += amp[j][k] * w * a.cos();
            qdd -= amp[j][k] * w * w * a.sin();
        }
        (q, qd, qdd)
    };
    let reference: Reference<'_> = custom.unwrap_or(&sines);

    let mut data = Data::new(model.clone())?;
    for (j, joint) in robot.joints.iter().enumerate() {
        let (q, qd, _) = reference(j, 0.0);
        data.qpos_mut()[joint.qpos_adr] = q;
        data.qvel_mut()[joint.dof] = qd;
    }
    // Computed-torque tracking: each joint's acceleration command is the reference's plus a
    // critically damped PD on the error (about 4 Hz), and the torques that realise it come from
    // the full mass matrix (armature included), bias and damping forces, the unactuated DOFs
    // (a floating base's free joint) taking whatever acceleration their own equations give.
    // The robot then stays on its reference, inside its joint ranges (whose limit forces no
    // log carries), however strongly the joints and the base are coupled.
    let wn = 2.0 * PI * 4.0;
    let nv = model.nv();
    let joint_dofs: Vec<usize> = robot.joints.iter().map(|j| j.dof).collect();
    let free: Vec<usize> = (0..nv).filter(|d| !joint_dofs.contains(d)).collect();
    let mut qacc = vec![0.0; nv];
    // Per-step buffers: the mass matrix and the generalised forces besides the command.
    let (mut mass, mut other) = (Vec::with_capacity(nv * nv), vec![0.0; nv]);

    let steps = (opts.duration_secs * opts.rate_hz).round() as usize;
    let names: Vec<String> = robot.joints.iter().map(|j| j.name.clone()).collect();
    let mut log = JointLog::new(names, format!("synthetic log of {}", urdf.display()));
    let resolution = 2.0 * PI / (1u64 << opts.encoder_bits) as f64;
    let (mut p, mut v, mut e) = (vec![0.0; nj], vec![0.0; nj], vec![0.0; nj]);
    let mut qfrc_ext = vec![0.0; nv];
    let (mut jacp, mut jacr, mut jacp_dot, mut jacr_dot) =
        (vec![0.0; 3 * nv], vec![0.0; 3 * nv], vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
    for step in 0..steps {
        let t = step as f64 * dt;
        data.step1()?;
        let t_nanos = (t * 1e9).round() as i64;
        // The controller cancels the known wrenches' joint torques (feedforward `−Jᵀ·w`), so
        // that a light joint such as an ankle is not pushed into its limits (joint-limit forces
        // are not in the identified model).
        qfrc_ext.fill(0.0);
        for (i, &(_, body)) in wrench_links.iter().enumerate() {
            let w = wrench_at(i, t);
            let x = data.xmat()[body];
            data.xfrc_applied_mut()[body] = xfrc_from_body_wrench(w, x, data.xpos()[body], data.xipos()[body]);
            data.body_jacobian_dot(body, &mut jacp, &mut jacr, &mut jacp_dot, &mut jacr_dot)?;
            let rot = |v: [f64; 3]| [0, 1, 2].map(|r| x[3 * r] * v[0] + x[3 * r + 1] * v[1] + x[3 * r + 2] * v[2]);
            let (f, n) = (rot([w[0], w[1], w[2]]), rot([w[3], w[4], w[5]]));
            for (d, q) in qfrc_ext.iter_mut().enumerate() {
                *q += (0..3).map(|r| jacp[r * nv + d] * f[r] + jacr[r * nv + d] * n[r]).sum::<f64>();
            }
            wrench_log[i].t_nanos.push(t_nanos);
            wrench_log[i].wrench.push(w);
        }
        if let (Some(f), Some(fb)) = (floating, &robot.floating) {
            let qpos = &data.qpos()[fb.qpos_adr..fb.qpos_adr + 7];
            let p = [qpos[0], qpos[1], qpos[2]].map(|x| x + f.position_noise_m * rng.sample::<f64, _>(StandardNormal));
            // Orientation noise: a small random rotation (half-angles in the vector part).
            let e: [f64; 3] =
                std::array::from_fn(|_| 0.5 * f.orientation_noise_rad * rng.sample::<f64, _>(StandardNormal));
            let mut q = [qpos[3], qpos[4], qpos[5], qpos[6]];
            let dq = [1.0, e[0], e[1], e[2]];
            q = [
                q[0] * dq[0] - q[1] * dq[1] - q[2] * dq[2] - q[3] * dq[3],
                q[0] * dq[1] + q[1] * dq[0] + q[2] * dq[3] - q[3] * dq[2],
                q[0] * dq[2] - q[1] * dq[3] + q[2] * dq[0] + q[3] * dq[1],
                q[0] * dq[3] + q[1] * dq[2] - q[2] * dq[1] + q[3] * dq[0],
            ];
            let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            // REP-105 twist: linear velocity in the base frame (MuJoCo's is in the world frame).
            let qvel = &data.qvel()[fb.dof..fb.dof + 6];
            let r = data.xmat()[fb.body];
            let v_base = [0, 1, 2].map(|i| r[i] * qvel[0] + r[3 + i] * qvel[1] + r[6 + i] * qvel[2]);
            let twist = [v_base[0], v_base[1], v_base[2], qvel[3], qvel[4], qvel[5]]
                .map(|x| x + f.twist_noise * rng.sample::<f64, _>(StandardNormal));
            base_log.twist.push(twist);
            base_log.t_nanos.push(t_nanos);
            base_log.position.push(p);
            base_log.orientation_wxyz.push(q.map(|x| x / n));
        }
        // Generalised forces besides the command: bias less damping and the known wrenches.
        let (qvel, bias, damping) = (data.qvel(), data.qfrc_bias(), model.dof_damping());
        for (d, o) in other.iter_mut().enumerate() {
            *o = bias[d] + damping[d] * qvel[d] - qfrc_ext[d];
        }
        for (j, joint) in robot.joints.iter().enumerate() {
            let (qr, qdr, qddr) = reference(j, t);
            let (q, qd) = (data.qpos()[joint.qpos_adr], data.qvel()[joint.dof]);
            qacc[joint.dof] = qddr + wn * wn * (qr - q) + 2.0 * wn * (qdr - qd);
            p[j] = (q / resolution).round() * resolution;
            v[j] = qd + opts.velocity_noise * rng.sample::<f64, _>(StandardNormal);
        }
        data.full_mass_matrix_into(&mut mass);
        if !free.is_empty() {
            // M_ff·a_f = −(M_fj·a_j + other_f): no command acts on the free DOFs.
            let a = nalgebra::DMatrix::from_fn(free.len(), free.len(), |r, c| mass[free[r] * nv + free[c]]);
            let b = nalgebra::DVector::from_fn(free.len(), |r, _| {
                -other[free[r]] - joint_dofs.iter().map(|&d| mass[free[r] * nv + d] * qacc[d]).sum::<f64>()
            });
            let a_free = a.lu().solve(&b).ok_or_else(|| {
                crate::Error::Numerical(format!("the free DOFs' mass matrix of {} is singular", urdf.display()))
            })?;
            for (k, &d) in free.iter().enumerate() {
                qacc[d] = a_free[k];
            }
        }
        for (j, joint) in robot.joints.iter().enumerate() {
            let d = joint.dof;
            let tau = other[d] + (0..nv).map(|c| mass[d * nv + c] * qacc[c]).sum::<f64>();
            data.qfrc_applied_mut()[d] = tau;
            e[j] = tau;
        }
        log.push((t * 1e9).round() as i64, &p, &v, &e);
        data.step2()?;
        if data.diverged() {
            return Err(crate::Error::Numerical(format!(
                "the simulation of {} diverged at t = {t:.3} s",
                urdf.display()
            )));
        }
    }
    if let Some(f) = floating {
        for series in &mut wrench_log {
            for w in &mut series.wrench {
                for (k, x) in w.iter_mut().enumerate() {
                    *x += f.wrench_noise_rel
                        * if k < 3 { f.wrench_force_n } else { f.wrench_torque_nm }
                        * rng.sample::<f64, _>(StandardNormal);
                }
            }
        }
        log.base = Some(base_log);
        log.wrenches = wrench_log;
    }
    // Effort noise relative to each joint's RMS torque.
    for j in 0..nj {
        let rms = (log.effort[j].iter().map(|x| x * x).sum::<f64>() / steps.max(1) as f64).sqrt();
        for x in &mut log.effort[j] {
            *x += opts.effort_noise_rel * rms * rng.sample::<f64, _>(StandardNormal);
        }
    }
    Ok(log)
}

/// `base` with armature `armature` on every DOF from `first_dof` on and a stiff friction-loss
/// constraint: MuJoCo's friction loss is a soft constraint; with its defaults the friction of
/// a light joint ramps up over ~0.1 rad/s. A time constant of two steps makes it the Coulomb
/// friction the URDF's `friction` stands for.
fn stiff_friction(
    base: &twin_core::mj::Model,
    first_dof: usize,
    dt: f64,
    armature: f64,
) -> Result<Arc<twin_core::mj::Model>> {
    let mut edit = base.edit()?;
    for dof in first_dof..base.nv() {
        // An armature the URDF carries (its `<twin_sysid>` block, which the converter reads) wins.
        let own = base.dof_armature()[dof];
        edit.set_dof_armature(dof, if own > 0.0 { own } else { armature })?;
        edit.set_dof_friction_solver(dof, [2.0 * dt, 1.0], [0.99, 0.999, 0.001, 0.5, 2.0])?;
    }
    Ok(Arc::new(edit.finish()?))
}

/// The fixed-base model [`simulate`] runs `urdf` with (timestep `dt_secs`, contacts off,
/// `armature` on every joint, friction loss as Coulomb friction): also the twin `twin gap`
/// replays a log on.
///
/// # Errors
/// Loading errors of the URDF; [`crate::Error::Core`] if MuJoCo fails.
pub fn simulation_model(urdf: &Path, dt_secs: f64, armature: f64) -> Result<Arc<twin_core::mj::Model>> {
    simulation_model_of(&UrdfSource::read(urdf)?, dt_secs, armature)
}

/// [`simulation_model`] of a URDF already read.
///
/// # Errors
/// As [`simulation_model`].
pub fn simulation_model_of(source: &UrdfSource, dt_secs: f64, armature: f64) -> Result<Arc<twin_core::mj::Model>> {
    let extra = format!(r#"<option timestep="{dt_secs}"><flag contact="disable"/></option>"#);
    stiff_friction(&source.model(&extra, false)?, 0, dt_secs, armature)
}

/// Writes to `dst` a copy of the URDF `src` whose link inertials and joint friction are off by
/// 20–40 % (random signs and sizes from `seed`): the "CAD" of the synthetic benchmark. Masses,
/// inertias about the centre of mass, centre-of-mass offsets, damping and friction are scaled;
/// the copy stays physically valid.
///
/// # Errors
/// Loading or writing errors.
pub fn perturbed_urdf(src: &Path, dst: &Path, seed: u64) -> Result<()> {
    let robot = RobotModel::from_urdf(src)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let factor = |rng: &mut ChaCha8Rng| {
        let size = 0.2 + 0.2 * rng.random::<f64>();
        if rng.random::<f64>() < 0.5 { 1.0 - size } else { 1.0 + size }
    };
    let links: Vec<crate::writeback::LinkUpdate> = robot
        .links
        .iter()
        .filter_map(|link| {
            let mp = crate::model::MassProperties::from_params(&link.own_params(&link.cad))?;
            Some(crate::writeback::LinkUpdate {
                name: link.name.clone(),
                mass_kg: mp.mass_kg * factor(&mut rng),
                com_link: mp.com_link * factor(&mut rng),
                inertia_com: mp.inertia_com * factor(&mut rng),
            })
        })
        .collect();
    let joints: Vec<crate::writeback::JointUpdate> = robot
        .joints
        .iter()
        .map(|j| crate::writeback::JointUpdate {
            name: j.name.clone(),
            damping: j.damping * factor(&mut rng),
            friction: j.friction * factor(&mut rng),
        })
        .collect();
    let text = twin_core::fsio::read_to_string(src)?;
    let new = crate::writeback::rewrite_urdf(src, &text, &links, &joints)?;
    twin_core::fsio::write_atomic(dst, new.as_bytes(), twin_core::fsio::Backup::None)?;
    Ok(())
}

/// MuJoCo's `xfrc_applied` entry (world frame, force then torque about the body's centre of
/// mass) of a wrench `[f; n]` expressed in the body frame, torque about the body origin.
/// `world_from_body` is the body's row-major `xmat`, `origin` its `xpos`, `com` its `xipos`.
pub fn xfrc_from_body_wrench(
    wrench_body: [f64; 6],
    world_from_body: [f64; 9],
    origin: [f64; 3],
    com: [f64; 3],
) -> [f64; 6] {
    let r = world_from_body;
    let rot = |v: [f64; 3]| {
        [
            r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
            r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
            r[6] * v[0] + r[7] * v[1] + r[8] * v[2],
        ]
    };
    let f = rot([wrench_body[0], wrench_body[1], wrench_body[2]]);
    let n = rot([wrench_body[3], wrench_body[4], wrench_body[5]]);
    // Torque about the CoM = torque about the origin + (origin − com) × f.
    let d = [origin[0] - com[0], origin[1] - com[1], origin[2] - com[2]];
    let c = [d[1] * f[2] - d[2] * f[1], d[2] * f[0] - d[0] * f[2], d[0] * f[1] - d[1] * f[0]];
    [f[0], f[1], f[2], n[0] + c[0], n[1] + c[1], n[2] + c[2]]
}

/// The body-frame wrench (torque about the body origin) of an `xfrc_applied`-style world
/// wrench at the centre of mass: the inverse of [`xfrc_from_body_wrench`].
pub fn body_wrench_from_xfrc(xfrc: [f64; 6], world_from_body: [f64; 9], origin: [f64; 3], com: [f64; 3]) -> [f64; 6] {
    let r = world_from_body;
    let f = [xfrc[0], xfrc[1], xfrc[2]];
    let d = [com[0] - origin[0], com[1] - origin[1], com[2] - origin[2]];
    let c = [d[1] * f[2] - d[2] * f[1], d[2] * f[0] - d[0] * f[2], d[0] * f[1] - d[1] * f[0]];
    let n = [xfrc[3] + c[0], xfrc[4] + c[1], xfrc[5] + c[2]];
    let rot_t = |v: [f64; 3]| {
        [
            r[0] * v[0] + r[3] * v[1] + r[6] * v[2],
            r[1] * v[0] + r[4] * v[1] + r[7] * v[2],
            r[2] * v[0] + r[5] * v[1] + r[8] * v[2],
        ]
    };
    let (fb, nb) = (rot_t(f), rot_t(n));
    [fb[0], fb[1], fb[2], nb[0], nb[1], nb[2]]
}
