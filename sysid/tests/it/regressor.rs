//! The regressor `Y·π` equals MuJoCo's own inverse dynamics of the same parameters.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::sync::Arc;
use sysid::RobotModel;
use sysid::model::load_urdf_in_mujoco;
use sysid::regressor::{FrictionModel, Regressor};
use twin_core::mj::Data;

fn models_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../models"))
}

/// Deterministic pseudo-random numbers in [-1, 1).
fn uniform(rng: &mut ChaCha8Rng) -> f64 {
    rng.random_range(-1.0..1.0)
}

/// The model's own parameters in `layout`'s columns: each link's CAD, each joint's damping and
/// Coulomb friction, and its armature (`armature`, when given, for every joint).
fn model_params(robot: &RobotModel, layout: &sysid::regressor::Layout, armature: Option<f64>) -> Vec<f64> {
    let mut params = vec![0.0; layout.ncols()];
    for (l, link) in robot.links.iter().enumerate() {
        params[layout.link_col(l)..layout.link_col(l) + 10].copy_from_slice(&link.cad);
    }
    for (j, joint) in robot.joints.iter().enumerate() {
        let c = layout.joint_col(j);
        params[c] = joint.damping;
        params[c + 1] = joint.friction;
        params[c + 2] = armature.unwrap_or(joint.armature);
    }
    params
}

/// MuJoCo's inverse dynamics (`qfrc_inverse`) of each of the robot's joints at `q`, `qd`, `qdd`
/// (one entry a joint, in joint order): what the regressor's `Y·π` must equal.
fn joint_inverse_dynamics(robot: &RobotModel, data: &mut Data, q: &[f64], qd: &[f64], qdd: &[f64]) -> Vec<f64> {
    for (j, joint) in robot.joints.iter().enumerate() {
        data.qpos_mut()[joint.qpos_adr] = q[j];
        data.qvel_mut()[joint.dof] = qd[j];
        data.qacc_mut()[joint.dof] = qdd[j];
    }
    data.inverse().unwrap();
    robot.joints.iter().map(|joint| data.qfrc_inverse()[joint.dof]).collect()
}

fn check_against_inverse_dynamics(urdf: &Path) {
    // Damping and armature are part of MuJoCo's inverse dynamics; constraint forces (friction
    // loss, joint limits at random poses, self-contacts) are not part of the rigid-body model.
    let base = load_urdf_in_mujoco(urdf, r#"<option><flag constraint="disable"/></option>"#).unwrap();
    let mut edit = base.edit().unwrap();
    for dof in 0..base.nv() {
        edit.set_dof_frictionloss(dof, 0.0).unwrap();
        edit.set_dof_armature(dof, 0.01 + 0.003 * dof as f64).unwrap();
        edit.set_dof_damping(dof, 0.5 + 0.1 * dof as f64).unwrap();
    }
    let model = Arc::new(edit.finish().unwrap());
    let robot = RobotModel::from_model(urdf, model.clone()).unwrap();
    assert_eq!(robot.joints.len(), model.nv(), "fixed base: every DOF is a joint");
    let fm = FrictionModel::default();
    let mut reg = Regressor::new(&robot, fm).unwrap();
    let layout = reg.layout();
    // Friction loss is zeroed above: the Coulomb columns are 0.
    let params = model_params(&robot, &layout, None);
    let mut data = Data::new(model.clone()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let nj = robot.joints.len();
    let mut rows = Vec::new();
    let mut worst = 0.0f64;
    for _ in 0..20 {
        let q: Vec<f64> = (0..nj).map(|_| uniform(&mut rng) * 1.5).collect();
        let qd: Vec<f64> = (0..nj).map(|_| uniform(&mut rng) * 3.0).collect();
        let qdd: Vec<f64> = (0..nj).map(|_| uniform(&mut rng) * 10.0).collect();
        let tau = reg.torques(None, &q, &qd, &qdd, &params, &mut rows).unwrap();
        let inverse = joint_inverse_dynamics(&robot, &mut data, &q, &qd, &qdd);
        for (j, (joint, &expected)) in robot.joints.iter().zip(&inverse).enumerate() {
            let err = (tau[j] - expected).abs() / (1.0 + expected.abs());
            worst = worst.max(err);
            assert!(
                err < 1e-9,
                "{}: joint {}: Y·π = {} but MuJoCo's inverse dynamics gives {}",
                urdf.display(),
                joint.name,
                tau[j],
                expected
            );
        }
    }
    eprintln!("{}: worst relative error {worst:e}", urdf.display());
}

#[test]
fn regressor_matches_mujoco_inverse_dynamics_on_the_arm() {
    check_against_inverse_dynamics(&models_dir().join("arm6.urdf"));
}

#[test]
fn regressor_matches_mujoco_inverse_dynamics_on_the_humanoid() {
    check_against_inverse_dynamics(&models_dir().join("humanoid.urdf"));
}

/// Models compiled with a free base (what the URDF converter produces by default) identify as a
/// fixed base: the free joint stays at its default pose, at rest, and only the 1-DOF joints
/// have rows.
#[test]
fn regressor_on_a_free_base_model_matches_inverse_dynamics_of_the_joints() {
    let xml = r#"<mujoco><option><flag constraint="disable"/></option><worldbody>
      <body name="base" pos="0 0 1"><freejoint/><inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>
        <body name="a" pos="0.1 0 0"><joint name="ja" axis="0 1 0" damping="0.3" armature="0.01"/>
          <inertial pos="0.1 0.02 0" mass="1.5" fullinertia="0.01 0.02 0.015 0.001 0 0.002"/>
          <body name="b" pos="0.3 0 0"><joint name="jb" axis="1 0 1" damping="0.1"/>
            <inertial pos="0.05 0 -0.03" quat="0.9 0.1 0.3 0" mass="0.7" diaginertia="0.004 0.003 0.002"/>
          </body></body></body></worldbody></mujoco>"#;
    let model = Arc::new(twin_core::mj::Model::from_xml_str(xml).unwrap());
    let robot = RobotModel::from_model(Path::new("free.xml"), model.clone()).unwrap();
    assert_eq!(robot.joints.len(), 2);
    assert_eq!(robot.links.iter().map(|l| l.name.as_str()).collect::<Vec<_>>(), ["a", "b"]);
    let mut reg = Regressor::new(&robot, FrictionModel::default()).unwrap();
    let layout = reg.layout();
    let params = model_params(&robot, &layout, None);
    let mut data = Data::new(model.clone()).unwrap();
    let (q, qd, qdd) = ([0.4, -1.1], [1.3, -0.7], [-2.0, 5.0]);
    let mut rows = Vec::new();
    let tau = reg.torques(None, &q, &qd, &qdd, &params, &mut rows).unwrap();
    let inverse = joint_inverse_dynamics(&robot, &mut data, &q, &qd, &qdd);
    for (j, (joint, &expected)) in robot.joints.iter().zip(&inverse).enumerate() {
        assert!((tau[j] - expected).abs() < 1e-9 * (1.0 + expected.abs()), "{}: {} vs {expected}", joint.name, tau[j]);
    }
}

/// Floating base: with MuJoCo's free joint moving (random pose, twist and acceleration) and
/// known external wrenches applied through `xfrc_applied`, the regressor's rows (6 base rows
/// included) equal MuJoCo's inverse dynamics, and `Y·π − Jᵀ·w` equals the applied joint torques
/// and zero on the base: the equation `twin sysid --base floating` fits.
#[test]
fn floating_base_rows_match_mujoco_inverse_dynamics_with_external_wrenches() {
    use sysid::regressor::BaseSample;
    use sysid::synth::xfrc_from_body_wrench;
    let urdf = models_dir().join("humanoid.urdf");
    let base =
        sysid::model::load_urdf_in_mujoco_floating(&urdf, r#"<option><flag constraint="disable"/></option>"#).unwrap();
    let mut edit = base.edit().unwrap();
    for dof in 0..base.nv() {
        edit.set_dof_frictionloss(dof, 0.0).unwrap();
        edit.set_dof_armature(dof, if dof < 6 { 0.0 } else { 0.01 + 0.003 * dof as f64 }).unwrap();
        edit.set_dof_damping(dof, if dof < 6 { 0.0 } else { 0.5 + 0.1 * dof as f64 }).unwrap();
    }
    let model = Arc::new(edit.finish().unwrap());
    let robot = RobotModel::from_model_floating(&urdf, model.clone()).unwrap();
    let fb = robot.floating.clone().unwrap();
    assert_eq!(fb.name, "pelvis");
    assert_eq!(robot.joints.len() + 6, model.nv());
    assert!(robot.links.iter().any(|l| l.name == "pelvis" && l.floating && l.ancestor_joints.is_empty()));
    let mut reg = Regressor::new(&robot, FrictionModel::default()).unwrap();
    assert_eq!(reg.nrows(), model.nv());
    let layout = reg.layout();
    // Friction loss is zeroed above: the Coulomb columns are 0.
    let params = model_params(&robot, &layout, None);
    let wrench_bodies: Vec<usize> = ["left_foot_link", "right_foot_link", "left_forearm_link", "pelvis"]
        .iter()
        .filter_map(|n| model.id(twin_core::mj::ObjType::Body, n))
        .collect();
    assert!(wrench_bodies.len() >= 2, "humanoid bodies renamed?");
    let mut data = Data::new(model.clone()).unwrap();
    let nj = robot.joints.len();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (mut rows, mut ext) = (Vec::new(), vec![0.0; reg.nrows()]);
    let mut worst = 0.0f64;
    for _ in 0..10 {
        let q: Vec<f64> = (0..nj).map(|_| uniform(&mut rng) * 1.2).collect();
        let qd: Vec<f64> = (0..nj).map(|_| uniform(&mut rng) * 3.0).collect();
        let tau_joint: Vec<f64> = (0..nj).map(|_| uniform(&mut rng) * 20.0).collect();
        let mut quat = [1.0 + uniform(&mut rng), uniform(&mut rng), uniform(&mut rng), uniform(&mut rng)];
        let norm = quat.iter().map(|x| x * x).sum::<f64>().sqrt();
        quat.iter_mut().for_each(|x| *x /= norm);
        let mut base_qpos = [uniform(&mut rng), uniform(&mut rng), 1.0 + uniform(&mut rng), 0.0, 0.0, 0.0, 0.0];
        base_qpos[3..].copy_from_slice(&quat);
        let base_qvel: [f64; 6] = std::array::from_fn(|_| uniform(&mut rng) * 2.0);
        data.qpos_mut()[fb.qpos_adr..fb.qpos_adr + 7].copy_from_slice(&base_qpos);
        data.qvel_mut()[fb.dof..fb.dof + 6].copy_from_slice(&base_qvel);
        data.qfrc_applied_mut().fill(0.0);
        for (j, joint) in robot.joints.iter().enumerate() {
            data.qpos_mut()[joint.qpos_adr] = q[j];
            data.qvel_mut()[joint.dof] = qd[j];
            data.qfrc_applied_mut()[joint.dof] = tau_joint[j];
        }
        // Wrenches in body frames (torque about the body origin), applied as MuJoCo's
        // xfrc_applied (world frame, at the CoM) at this pose.
        data.kinematics_with_velocity().unwrap();
        let wrenches: Vec<(usize, [f64; 6])> = wrench_bodies
            .iter()
            .map(|&b| (b, std::array::from_fn(|k| uniform(&mut rng) * if k < 3 { 50.0 } else { 5.0 })))
            .collect();
        data.xfrc_applied_mut().iter_mut().for_each(|x| *x = [0.0; 6]);
        for &(b, w) in &wrenches {
            let x = xfrc_from_body_wrench(w, data.xmat()[b], data.xpos()[b], data.xipos()[b]);
            data.xfrc_applied_mut()[b] = x;
        }
        data.forward().unwrap();
        let qacc = data.qacc().to_vec();
        let qdd: Vec<f64> = robot.joints.iter().map(|j| qacc[j.dof]).collect();
        let sample = BaseSample { qpos: base_qpos, qvel: base_qvel, qacc: std::array::from_fn(|k| qacc[fb.dof + k]) };
        let tau = reg.torques(Some(&sample), &q, &qd, &qdd, &params, &mut rows).unwrap();
        reg.external_forces(&wrenches, &mut ext).unwrap();
        data.inverse().unwrap();
        let dof_of_row = |r: usize| if r < nj { robot.joints[r].dof } else { fb.dof + r - nj };
        for r in 0..reg.nrows() {
            let d = dof_of_row(r);
            let inverse = data.qfrc_inverse()[d];
            let applied = if r < nj { tau_joint[r] } else { 0.0 };
            let e1 = (tau[r] - inverse).abs() / (1.0 + inverse.abs());
            let e2 = (tau[r] - ext[r] - applied).abs() / (1.0 + tau[r].abs());
            worst = worst.max(e1).max(e2);
            assert!(e1 < 1e-9, "row {r} (dof {d}): Y·π = {} but qfrc_inverse = {inverse}", tau[r]);
            assert!(e2 < 1e-9, "row {r} (dof {d}): Y·π − Jᵀw = {} but applied {applied}", tau[r] - ext[r]);
        }
        // The wrench term matters: without it the base rows would not balance.
        assert!((nj..reg.nrows()).any(|r| ext[r].abs() > 1.0));
    }
    eprintln!("floating humanoid: worst relative error {worst:e}");
}

/// The UR5 of example-robot-data, compiled by twin's converter (`package://` STL and Collada
/// meshes, massless `ee_link`/`tool0` frames welded to the wrist): `Y·π` with its CAD
/// parameters is MuJoCo's inverse dynamics.
#[test]
fn regressor_matches_mujoco_inverse_dynamics_on_the_ur5() {
    check_against_inverse_dynamics(
        &crate::example_robot_data::example_robot_data().join("ur_description/urdf/ur5_robot.urdf"),
    );
}

/// The synthetic UR5 log's torques are the inverse dynamics of its logged motion: `Y·π` of the
/// URDF's parameters (and the synthetic armature) at each sample's position, velocity and
/// acceleration (the next velocity's difference: MuJoCo's Euler step) is the logged effort.
/// The converter gives the UR5 position servos (its `PositionJointInterface`); they must not
/// add torques the log does not carry.
#[test]
fn synthetic_ur5_torques_are_the_inverse_dynamics_of_its_logged_motion() {
    use sysid::synth::{SynthOptions, simulate};
    let ur5 = crate::example_robot_data::example_robot_data().join("ur_description/urdf/ur5_robot.urdf");
    let opts = SynthOptions {
        duration_secs: 1.0,
        encoder_bits: 50,
        velocity_noise: 0.0,
        effort_noise_rel: 0.0,
        ..SynthOptions::default()
    };
    let log = simulate(&ur5, &opts).unwrap();
    let robot = RobotModel::from_urdf(&ur5).unwrap();
    let mut reg = Regressor::new(&robot, FrictionModel::default()).unwrap();
    let layout = reg.layout();
    let params = model_params(&robot, &layout, Some(opts.armature));
    let dt = 1.0 / opts.rate_hz;
    let nj = robot.joints.len();
    let mut rows = Vec::new();
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    for k in 0..log.t_nanos.len() - 1 {
        let q: Vec<f64> = (0..nj).map(|j| log.position[j][k]).collect();
        let qd: Vec<f64> = (0..nj).map(|j| log.velocity[j][k]).collect();
        let qdd: Vec<f64> = (0..nj).map(|j| (log.velocity[j][k + 1] - log.velocity[j][k]) / dt).collect();
        let tau = reg.torques(None, &q, &qd, &qdd, &params, &mut rows).unwrap();
        for (t, effort) in tau.iter().zip(&log.effort) {
            worst = worst.max((t - effort[k]).abs());
            largest = largest.max(effort[k].abs());
        }
    }
    assert!(largest > 1.0, "the UR5 needs torque to move: largest {largest} N·m");
    assert!(worst < 1e-6 * largest, "Y·π differs from the logged effort by up to {worst} N·m (largest {largest} N·m)");
}
