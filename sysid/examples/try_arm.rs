use std::path::Path;
fn main() {
    let which = std::env::args().nth(1).unwrap_or("arm6".into());
    let secs: f64 = std::env::args().nth(2).map(|s| s.parse().unwrap()).unwrap_or(20.0);
    let truth = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../models/{which}.urdf"));
    let dir = tempfile::tempdir().unwrap();
    let start = dir.path().join("start.urdf");
    sysid::synth::perturbed_urdf(&truth, &start, 3).unwrap();
    let t = std::time::Instant::now();
    let log = sysid::synth::simulate(&truth, &sysid::synth::SynthOptions { duration_secs: secs, ..Default::default() }).unwrap();
    let val = sysid::synth::simulate(&truth, &sysid::synth::SynthOptions { duration_secs: 10.0, seed: 2, ..Default::default() }).unwrap();
    eprintln!("sim {:.2}s", t.elapsed().as_secs_f64());
    let robot = sysid::RobotModel::from_urdf(&start).unwrap();
    let opts = sysid::SysidOptions::default();
    let t = std::time::Instant::now();
    let mut id = sysid::identify(&robot, &log, &opts).unwrap();
    eprintln!("identify {:.2}s", t.elapsed().as_secs_f64());
    let truth_robot0 = sysid::RobotModel::from_urdf(&truth).unwrap();
    let mut truep = sysid::identify::cad_params(&truth_robot0, &id.layout);
    for j in 0..truth_robot0.joints.len() { truep[id.layout.joint_col(j)+2] = 0.02; }
    let vt = sysid::validate(&robot, &val, &opts, &[&truep]).unwrap();
    eprintln!("true params on held-out: {:?}", vt[0].iter().map(|x| format!("{:.2}%", 100.0*x)).collect::<Vec<_>>());
    for dz in [0.05, 0.1, 0.2, 0.5] {
        let mut o2 = opts.clone(); o2.velocity_deadzone = dz;
        let vt = sysid::validate(&robot, &val, &o2, &[&truep]).unwrap();
        eprintln!("dz {dz} true params on held-out: {:?}", vt[0].iter().map(|x| format!("{:.2}%", 100.0*x)).collect::<Vec<_>>());
        o2.friction.coulomb_smoothing = Some(dz);
        let vt = sysid::validate(&robot, &val, &o2, &[&truep]).unwrap();
        eprintln!("tanh {dz} true params on held-out: {:?}", vt[0].iter().map(|x| format!("{:.2}%", 100.0*x)).collect::<Vec<_>>());
    }
    let vt = sysid::validate(&robot, &log, &opts, &[&truep]).unwrap();
    eprintln!("true params on training: {:?}", vt[0].iter().map(|x| format!("{:.2}%", 100.0*x)).collect::<Vec<_>>());
    let v = sysid::validate(&robot, &val, &opts, &[&id.before, &id.after]).unwrap();
    id.report.validation_nrmse = Some(robot.joints.iter().enumerate().map(|(j, jn)| sysid::report::NrmseReport { joint: jn.name.clone(), before: v[0][j], after: v[1][j] }).collect());
    println!("{}", id.report.table());
    let truth_robot = sysid::RobotModel::from_urdf(&truth).unwrap();
    for (j, jt) in truth_robot.joints.iter().enumerate() {
        let (v, c, a) = id.joint_friction(j);
        println!("{}: viscous {:.4} (true {:.4}, {:+.1}%) coulomb {:.4} (true {:.4}, {:+.1}%) arm {:.4}", jt.name, v, jt.damping, 100.0*(v/jt.damping-1.0), c, jt.friction, 100.0*(c/jt.friction-1.0), a);
    }
}
