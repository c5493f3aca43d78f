//! `twin gap`: on a synthetic "real" arm (the shipped arm's masses, inertias and friction off by
//! 20–40 %), the twin built from the CAD URDF drifts from the logged motion when the logged
//! efforts are replayed open loop; after `twin sysid --update` (inertias, damping and friction
//! written back) the gap is more than 5× smaller.

use std::path::{Path, PathBuf};
use sysid::gap::{GapOptions, measure_gap};
use sysid::synth::{SynthOptions, perturbed_urdf, simulate};
use sysid::{RobotModel, SysidOptions, identify, urdf_updates};

fn models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

#[test]
fn gap_shrinks_more_than_5x_after_identification() {
    let dir = tempfile::tempdir().unwrap();
    let cad = models_dir().join("arm6.urdf");
    let real = dir.path().join("real.urdf");
    perturbed_urdf(&cad, &real, 11).unwrap();
    let twin = dir.path().join("arm6.urdf");
    std::fs::copy(&cad, &twin).unwrap();
    // The "real" robot's logs: one to identify from, one to measure the gap on.
    let synth = SynthOptions { armature: 0.0, ..Default::default() };
    let train = simulate(&real, &SynthOptions { duration_secs: 20.0, seed: 1, ..synth.clone() }).unwrap();
    let real_log = simulate(&real, &SynthOptions { duration_secs: 8.0, seed: 2, ..synth }).unwrap();
    let path = dir.path().join("real.mcap");
    real_log.write_mcap(&path, "/joint_states").unwrap();
    let (real_log, _) = sysid::JointLog::read_mcap(&path, Some("/joint_states")).unwrap();

    let opts = GapOptions::default();
    let before = measure_gap(&twin, &real_log, &opts).unwrap();
    eprintln!("{}", before.table());

    let robot = RobotModel::from_urdf(&twin).unwrap();
    let ident = identify(&robot, &train, &SysidOptions::default()).unwrap();
    let (links, joints) = urdf_updates(&robot, &ident);
    sysid::writeback::update_urdf_file(&twin, &links, &joints, false).unwrap();

    let after = measure_gap(&twin, &real_log, &opts).unwrap();
    eprintln!("{}", after.table());
    assert!(
        after.mean_position_rmse * 5.0 <= before.mean_position_rmse,
        "position gap {:.3e} → {:.3e} rad: not 5× smaller",
        before.mean_position_rmse,
        after.mean_position_rmse
    );
    assert!(after.mean_velocity_rmse * 5.0 <= before.mean_velocity_rmse);
    assert!(after.mean_torque_nrmse * 5.0 <= before.mean_torque_nrmse);
    // The gap of the true robot's own URDF is the floor the identified one approaches.
    let floor = measure_gap(&real, &real_log, &opts).unwrap();
    assert!(floor.mean_position_rmse <= after.mean_position_rmse * 1.5 + 1e-4, "{}", floor.table());
    let svg = after.svg();
    assert!(svg.starts_with("<svg") && svg.matches("<polyline").count() >= 12, "{}", &svg[..200.min(svg.len())]);
    let json: serde_json::Value = serde_json::from_str(&after.to_json()).unwrap();
    assert_eq!(json["joints"].as_array().unwrap().len(), 6);
}
