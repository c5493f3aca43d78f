//! `twin gap`: table, JSON and plot of the reality gap of the CAD arm on a log of a perturbed
//! "real" arm; the true robot's URDF shows a far smaller gap; a log of another robot is refused
//! naming the missing joints.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use sysid::synth::{SynthOptions, perturbed_urdf, simulate};

fn arm_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/arm6.urdf")
}

fn twin(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).current_dir(dir).args(args).output().expect("twin runs")
}

fn mean_gap(dir: &Path, urdf: &Path) -> f64 {
    let out =
        twin(dir, &["gap", urdf.to_str().unwrap(), "--log", "real.mcap", "--report", "gap.json", "--plot", "gap.svg"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("pos rmse"));
    assert!(std::fs::read_to_string(dir.join("gap.svg")).unwrap().starts_with("<svg"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("gap.json")).unwrap()).unwrap();
    json["mean_position_rmse"].as_f64().unwrap()
}

#[test]
fn gap_reports_the_cad_twin_far_off_a_perturbed_robot() {
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.urdf");
    perturbed_urdf(&arm_urdf(), &real, 11).unwrap();
    let log =
        simulate(&real, &SynthOptions { duration_secs: 5.0, armature: 0.0, seed: 2, ..Default::default() }).unwrap();
    log.write_mcap(dir.path().join("real.mcap"), "/joint_states").unwrap();
    let cad = mean_gap(dir.path(), &arm_urdf());
    let truth = mean_gap(dir.path(), &real);
    assert!(cad > 0.05 && truth * 10.0 < cad, "CAD twin {cad} rad, true robot {truth} rad");

    let other = dir.path().join("other.mcap");
    let mut renamed = log.clone();
    renamed.joint_names[0] = "not_a_joint".into();
    renamed.write_mcap(&other, "/joint_states").unwrap();
    let out = twin(dir.path(), &["gap", arm_urdf().to_str().unwrap(), "--log", "other.mcap", "--strict"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("shoulder_pan_joint") && stderr.contains("not in the log"), "{stderr}");
}
