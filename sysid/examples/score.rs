//! Scores identified parameters with twin's held-out metric, for the comparison with
//! `mujoco.sysid` (benches/sysid_mujoco.py):
//! `cargo run --release -p sysid --example score -- START.urdf TRAIN.csv HELDOUT.csv TRUTH.urdf [OTHER.json]`.
//! Runs twin's own identification on TRAIN.csv (timed) and, with OTHER.json, scores those values
//! too: per-joint held-out torque NRMSE (worst, mean) and viscous/Coulomb error against the truth.
use nalgebra::{Matrix3, Vector3};
use sysid::model::MassProperties;
use sysid::{JointLog, RobotModel, SysidOptions};

fn score(label: &str, robot: &RobotModel, truth: &RobotModel, held: &JointLog, params: &[f64], secs: f64) {
    let opts = SysidOptions::default();
    let layout =
        sysid::regressor::Layout { links: robot.links.len(), joints: robot.joints.len(), friction: opts.friction };
    let nrmse = sysid::validate(robot, held, &opts, &[params]).expect("validation");
    let worst = nrmse[0].iter().copied().fold(0.0, f64::max);
    let mean = nrmse[0].iter().sum::<f64>() / nrmse[0].len() as f64;
    let (mut fv, mut fc): (f64, f64) = (0.0, 0.0);
    for (j, t) in truth.joints.iter().enumerate() {
        let c = layout.joint_col(j);
        fv = fv.max((params[c] / t.damping - 1.0).abs());
        fc = fc.max((params[c + 1] / t.friction - 1.0).abs());
    }
    println!(
        "{label:<14} wall {secs:>8.3} s  held-out NRMSE worst {:>6.2} %  mean {:>6.2} %  viscous worst error {:>6.1} %  Coulomb worst error {:>6.1} %",
        100.0 * worst,
        100.0 * mean,
        100.0 * fv,
        100.0 * fc
    );
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let robot = RobotModel::from_urdf(&a[1]).expect("start URDF");
    let train = JointLog::read_csv(&a[2]).expect("training log");
    let held = JointLog::read_csv(&a[3]).expect("held-out log");
    let truth = RobotModel::from_urdf(&a[4]).expect("truth URDF");
    let opts = SysidOptions::default();
    let t = std::time::Instant::now();
    let ident = sysid::identify(&robot, &train, &opts).expect("identify");
    let secs = t.elapsed().as_secs_f64();
    score("start URDF", &robot, &truth, &held, &ident.before, 0.0);
    score("twin sysid", &robot, &truth, &held, &ident.after, secs);
    if let Some(path) = a.get(5) {
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).expect("json")).expect("json");
        let mut p = ident.before.clone();
        for (l, link) in robot.links.iter().enumerate() {
            let Some(x) = v["links"].get(&link.name) else {
                continue;
            };
            let f = |k: &str, i: usize| x[k][i].as_f64().unwrap();
            let i = &x["inertia_com"];
            let m = Matrix3::from_fn(|r, c| i[r][c].as_f64().unwrap());
            let mp = MassProperties {
                mass_kg: x["mass"].as_f64().unwrap(),
                com_link: Vector3::new(f("com", 0), f("com", 1), f("com", 2)),
                inertia_com: m,
            };
            let c = ident.layout.link_col(l);
            p[c..c + 10].copy_from_slice(&mp.to_params());
        }
        for (j, joint) in robot.joints.iter().enumerate() {
            let x = &v["joints"][&joint.name];
            let c = ident.layout.joint_col(j);
            p[c] = x["damping"].as_f64().unwrap();
            p[c + 1] = x["frictionloss"].as_f64().unwrap();
            p[c + 2] = x["armature"].as_f64().unwrap();
        }
        score("mujoco.sysid", &robot, &truth, &held, &p, v["wall_secs"].as_f64().unwrap());
    }
}
