//! The regressor `Y·π` equals MuJoCo's own inverse dynamics of the same parameters.

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
fn lcg(state: &mut u64) -> f64 {
    *state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    ((*state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
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
    let mut params = vec![0.0; layout.ncols()];
    for (l, link) in robot.links.iter().enumerate() {
        params[layout.link_col(l)..layout.link_col(l) + 10].copy_from_slice(&link.cad);
    }
    for (j, joint) in robot.joints.iter().enumerate() {
        let c = layout.joint_col(j);
        params[c] = joint.damping;
        params[c + 1] = 0.0;
        params[c + 2] = joint.armature;
    }
    let mut data = Data::new(model.clone()).unwrap();
    let mut rng = 7u64;
    let nj = robot.joints.len();
    let mut rows = Vec::new();
    let mut worst = 0.0f64;
    for _ in 0..20 {
        let q: Vec<f64> = (0..nj).map(|_| lcg(&mut rng) * 1.5).collect();
        let qd: Vec<f64> = (0..nj).map(|_| lcg(&mut rng) * 3.0).collect();
        let qdd: Vec<f64> = (0..nj).map(|_| lcg(&mut rng) * 10.0).collect();
        let tau = reg.torques(&q, &qd, &qdd, &params, &mut rows).unwrap();
        for (j, joint) in robot.joints.iter().enumerate() {
            data.qpos_mut()[joint.qpos_adr] = q[j];
            data.qvel_mut()[joint.dof] = qd[j];
            data.qacc_mut()[joint.dof] = qdd[j];
        }
        data.inverse().unwrap();
        for (j, joint) in robot.joints.iter().enumerate() {
            let expected = data.qfrc_inverse()[joint.dof];
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
    let mut params = vec![0.0; layout.ncols()];
    for (l, link) in robot.links.iter().enumerate() {
        params[layout.link_col(l)..layout.link_col(l) + 10].copy_from_slice(&link.cad);
    }
    for (j, joint) in robot.joints.iter().enumerate() {
        params[layout.joint_col(j)] = joint.damping;
        params[layout.joint_col(j) + 2] = joint.armature;
    }
    let mut data = Data::new(model.clone()).unwrap();
    let (q, qd, qdd) = ([0.4, -1.1], [1.3, -0.7], [-2.0, 5.0]);
    let mut rows = Vec::new();
    let tau = reg.torques(&q, &qd, &qdd, &params, &mut rows).unwrap();
    for (j, joint) in robot.joints.iter().enumerate() {
        data.qpos_mut()[joint.qpos_adr] = q[j];
        data.qvel_mut()[joint.dof] = qd[j];
        data.qacc_mut()[joint.dof] = qdd[j];
    }
    data.inverse().unwrap();
    for (j, joint) in robot.joints.iter().enumerate() {
        let expected = data.qfrc_inverse()[joint.dof];
        assert!((tau[j] - expected).abs() < 1e-9 * (1.0 + expected.abs()), "{}: {} vs {expected}", joint.name, tau[j]);
    }
}
