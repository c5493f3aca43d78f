//! The walking controller on the shipped humanoid: walking, standing under pushes, turning,
//! and the regressions its metrics and checks must catch.

use std::path::PathBuf;
use twin_core::sim::{self, SimOptions, StepHook};
use twin_core::walk::{GaitMetrics, GaitSummary, GaitTargets, WalkOptions, Walker};

fn humanoid() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/humanoid.urdf")
}

struct Metrics(GaitMetrics);
impl StepHook for Metrics {
    fn after_step(&mut self, data: &twin_core::mj::Data) {
        self.0.update(data);
    }
}

fn robot(armature: f64) -> sim::Robot {
    let opts = twin_core::convert::ConvertOptions { armature, ..Default::default() };
    let model = std::sync::Arc::new(twin_core::mj::Model::from_urdf(humanoid(), &opts).unwrap());
    sim::Robot::from_model(model, "humanoid", &humanoid())
}

fn run(options: WalkOptions, secs: f64) -> GaitSummary {
    let robot = robot(0.01);
    let targets = GaitTargets {
        vx: options.vx,
        vy: options.vy,
        yaw_rate: options.yaw_rate,
        step_length: options.vx * options.step_period,
        step_width: options.step_width,
    };
    let mut walker = Walker::new(&robot.model, options.clone()).unwrap();
    let mut metrics = Metrics(GaitMetrics::for_model(&robot.model, &options.bodies, targets).unwrap());
    sim::simulate_with(&robot, &mut walker, &SimOptions { duration_secs: secs }, None, &mut |_| {}, &mut metrics)
        .unwrap();
    metrics.0.summary()
}

#[test]
#[ignore]
fn probe() {
    let vx: f64 = std::env::var("VX").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
    let secs: f64 = std::env::var("SECS").ok().and_then(|v| v.parse().ok()).unwrap_or(5.0);
    let opts: WalkOptions = toml::from_str(&std::env::var("WALK").unwrap_or_default()).unwrap();
    let s = run(WalkOptions { vx, ..opts }, secs);
    println!("{s}");
}

#[test]
fn kinematics_match_mujoco() {
    use std::sync::Arc;
    use twin_core::walk::kin::{Body, BodyNames, LegIk, Tree};
    let model = Arc::new(twin_core::mj::Model::from_file(humanoid()).unwrap());
    let mut data = twin_core::mj::Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    // A bent configuration.
    for (i, q) in data.qpos_mut().iter_mut().enumerate().skip(7) {
        *q += 0.05 * ((i as f64) * 1.7).sin();
    }
    data.forward().unwrap();
    let tree = Tree::new(&model);
    let mut frames = tree.frames();
    tree.forward(data.qpos(), &mut frames);
    for b in 0..model.nbody() {
        let p = data.xpos()[b];
        assert!((frames.xpos[b] - nalgebra::Vector3::from(p)).norm() < 1e-9, "body {b}");
        let c = data.subtree_com()[b];
        assert!((frames.subtree_com[b] - nalgebra::Vector3::from(c)).norm() < 1e-9, "com {b}");
    }
    let body = Body::find(&model, &tree, data.qpos(), &BodyNames::default()).unwrap();
    for leg in &body.legs {
        let ik = LegIk::new(&model, leg);
        let q: Vec<f64> = (0..ik.len()).map(|k| data.qpos()[ik.qpos_adr(k)]).collect();
        let (p, r) = ik.foot_pose(&q);
        let pel = frames.xrot[body.pelvis].inverse();
        let want = pel * (frames.xpos[leg.foot] - frames.xpos[body.pelvis]);
        assert!((p - want).norm() < 1e-9, "{p} {want}");
        assert!((r.inverse() * pel * frames.xrot[leg.foot]).angle() < 1e-9);
        // IK from the home pose back to this one.
        let mut q0: Vec<f64> = (0..ik.len()).map(|k| model.qpos0()[ik.qpos_adr(k)]).collect();
        let res = ik.solve((p, r), &mut q0, 50, 1e-4);
        assert!(res.position_error_m < 1e-6, "{res:?}");
    }
}

#[test]
#[ignore]
fn trace() {
    use std::sync::Arc;
    use twin_core::control::{Actuation, Controller, Observation};
    let vx: f64 = std::env::var("VX").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
    let secs: f64 = std::env::var("SECS").ok().and_then(|v| v.parse().ok()).unwrap_or(2.0);
    let armature: f64 = std::env::var("ARM").ok().and_then(|v| v.parse().ok()).unwrap_or(0.0);
    let model = Arc::new(
        twin_core::mj::Model::from_urdf(
            humanoid(),
            &twin_core::convert::ConvertOptions { armature, ..Default::default() },
        )
        .unwrap(),
    );
    let mut data = twin_core::mj::Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    let opts: WalkOptions = toml::from_str(&std::env::var("WALK").unwrap_or_default()).unwrap();
    let every: usize = std::env::var("EVERY").ok().and_then(|v| v.parse().ok()).unwrap_or(25);
    let mut w = Walker::new(&model, WalkOptions { vx, ..opts }).unwrap();
    w.reset(&model, &Observation::of(&data)).unwrap();
    let act = Actuation::of(&model);
    let mut cmd = vec![0.0; act.len(&model)];
    let n = (secs / model.timestep_secs()) as usize;
    for i in 0..n {
        data.step1().unwrap();
        w.compute(&model, &Observation::of(&data), &mut cmd);
        act.apply(&mut data, &cmd);
        data.step2().unwrap();
        if i % every == 0 {
            let s = w.state();
            let q = data.qpos();
            println!(
                "t {:.3} com {:.3} {:.3} {:.3} ref {:.3} {:.3} zmp {:.3} {:.3} dcm {:.3} {:.3} dref {:.3} {:.3} base z {:.3} quat {:.3} {:.3} {:.3} ik {:.4} walk {} steps {} cmd {:?}",
                data.time_secs(),
                s.com[0],
                s.com[1],
                s.com[2],
                s.com_ref[0],
                s.com_ref[1],
                s.zmp_ref[0],
                s.zmp_ref[1],
                s.dcm[0],
                s.dcm[1],
                s.dcm_ref[0],
                s.dcm_ref[1],
                q[2],
                q[4],
                q[5],
                q[6],
                s.ik_error_m,
                s.walking,
                s.steps,
                cmd.iter().map(|c| (c * 10.0).round() / 10.0).collect::<Vec<_>>()
            );
        }
    }
}
