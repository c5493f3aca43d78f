//! `cargo bench --bench sysid`: identification wall time and accuracy on synthetic logs.
//!
//! - a 30-DOF robot (a trunk with five 6-joint limbs) with 10⁵ samples (100 s at 1 kHz);
//! - the 6-DOF arm (`models/arm6.urdf`) and the humanoid on a gantry (`models/humanoid.urdf`),
//!   20 s each, starting from URDFs off by 20–40 %, validated on a held-out log.
//!
//! Simulation (generating the logs) is not timed; `identify` (conditioning, regressor,
//! compression, base parameters, weighted least squares, consistent fit, statistics) is.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;
use sysid::synth::{SynthOptions, perturbed_urdf, simulate};
use sysid::{RobotModel, SysidOptions, identify, validate};

/// A trunk with five limbs of six revolute joints: 30 DOF, 31 links.
fn thirty_dof_urdf() -> String {
    let mut s = String::from("<?xml version=\"1.0\"?>\n<robot name=\"thirty\">\n");
    s.push_str("  <link name=\"trunk\"><inertial><mass value=\"10\"/><inertia ixx=\"0.2\" ixy=\"0\" ixz=\"0\" iyy=\"0.2\" iyz=\"0\" izz=\"0.2\"/></inertial></link>\n");
    let axes = ["0 0 1", "0 1 0", "0 1 0", "1 0 0", "0 0 1", "0 1 0"];
    for limb in 0..5 {
        let yaw = limb as f64 * 2.0 * std::f64::consts::PI / 5.0;
        let mut parent = "trunk".to_string();
        for (k, axis) in axes.iter().enumerate() {
            let name = format!("l{limb}_{k}");
            let origin = if k == 0 {
                format!("xyz=\"{:.4} {:.4} 0\" rpy=\"0 0 {yaw:.4}\"", 0.2 * yaw.cos(), 0.2 * yaw.sin())
            } else {
                "xyz=\"0.12 0 0\" rpy=\"0 0 0\"".to_string()
            };
            let m = 2.0 - 0.25 * k as f64;
            let _ = writeln!(
                s,
                "  <joint name=\"{name}_joint\" type=\"revolute\"><origin {origin}/><parent link=\"{parent}\"/><child link=\"{name}\"/><axis xyz=\"{}\"/><limit lower=\"-2\" upper=\"2\" effort=\"100\" velocity=\"5\"/><dynamics damping=\"{:.2}\" friction=\"{:.2}\"/></joint>",
                axis,
                1.0 - 0.1 * k as f64,
                0.3 - 0.03 * k as f64
            );
            let _ = writeln!(
                s,
                "  <link name=\"{name}\"><inertial><origin xyz=\"0.06 0.005 -0.004\" rpy=\"0 0 0\"/><mass value=\"{m}\"/><inertia ixx=\"{:.6}\" ixy=\"0.00001\" ixz=\"0\" iyy=\"{:.6}\" iyz=\"0\" izz=\"{:.6}\"/></inertial></link>",
                0.002 * m,
                0.004 * m,
                0.0045 * m
            );
            parent = name;
        }
    }
    s.push_str("</robot>\n");
    s
}

fn bench_robot(label: &str, truth: &Path, secs: f64, dir: &Path, opts: &SysidOptions) {
    let start = dir.join(format!("start-{label}.urdf"));
    perturbed_urdf(truth, &start, 3).expect("perturbed URDF");
    let train = simulate(truth, &SynthOptions { duration_secs: secs, ..Default::default() }).expect("simulation");
    let held_out =
        simulate(truth, &SynthOptions { duration_secs: 10.0, seed: 2, ..Default::default() }).expect("simulation");
    let robot = RobotModel::from_urdf(&start).expect("robot");
    let t = Instant::now();
    let ident = identify(&robot, &train, opts).expect("identification");
    let identify_secs = t.elapsed().as_secs_f64();
    let nrmse = validate(&robot, &held_out, opts, &[&ident.before, &ident.after]).expect("validation");
    let truth_robot = RobotModel::from_urdf(truth).expect("truth");
    let worst = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let mut friction_err: f64 = 0.0;
    for (j, joint) in truth_robot.joints.iter().enumerate() {
        let (viscous, coulomb, _) = ident.joint_friction(j);
        friction_err =
            friction_err.max((viscous / joint.damping - 1.0).abs()).max((coulomb / joint.friction - 1.0).abs());
    }
    let r = &ident.report;
    println!(
        "{label:<10} dof {:>2}  samples {:>6}  regressor rows {:>6}  params {:>3}  rank {:>3}  cond {:>7.1}  identify {:>6.3} s  held-out NRMSE worst before {:>5.1} %  after {:>4.2} %  friction worst error {:>4.1} %",
        robot.joints.len(),
        train.len(),
        r.rows,
        r.parameters,
        r.rank,
        r.condition_number,
        identify_secs,
        100.0 * worst(&nrmse[0]),
        100.0 * worst(&nrmse[1]),
        100.0 * friction_err
    );
}

fn main() {
    // `cargo bench` passes --bench; any other argument filters by robot label.
    let filter: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let wanted = |l: &str| filter.is_empty() || filter.iter().any(|f| l.contains(f.as_str()));
    let dir = tempfile::tempdir().expect("temp dir");
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    if wanted("arm6") {
        bench_robot("arm6", &models.join("arm6.urdf"), 20.0, dir.path(), &SysidOptions::default());
    }
    if wanted("humanoid") {
        bench_robot("humanoid", &models.join("humanoid.urdf"), 20.0, dir.path(), &SysidOptions::default());
    }
    let urdf = dir.path().join("thirty.urdf");
    std::fs::write(&urdf, thirty_dof_urdf()).expect("write URDF");
    if wanted("30dof") {
        bench_robot("30dof", &urdf, 100.0, dir.path(), &SysidOptions::default());
    }
    // Every one of the 10⁵ filtered samples in the regressor (no decimation): 3·10⁶ rows.
    if filter.iter().any(|f| f == "30dof-all") {
        let mut opts = SysidOptions::default();
        opts.condition.regressor_rate_hz = Some(1000.0);
        bench_robot("30dof-all", &urdf, 100.0, dir.path(), &opts);
    }
}
