//! `twin excite`: the designed trajectory is written as CSV and as a ROS 2 JointTrajectory bag,
//! `twin sim --controller replay` plays the bag on the twin, and limits that leave no
//! trajectory are refused naming the limit, with nothing written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn arm_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/arm6.urdf")
}

fn twin(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).current_dir(dir).args(args).output().expect("twin runs")
}

#[test]
fn excite_writes_a_trajectory_that_replay_plays_on_the_twin() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = arm_urdf();
    // One search of 20 iterations a stage: the full default design is the release-profile
    // test in sysid/tests/it/excite.rs.
    let out = twin(
        dir.path(),
        &["excite", urdf.to_str().unwrap(), "--report", "excite.json", "--starts", "1", "--iterations", "20"],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("condition number of the base regressor"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("excite.json")).unwrap()).unwrap();
    let (designed, random) = (report["condition"].as_f64().unwrap(), report["best_random_condition"].as_f64().unwrap());
    assert!(designed < random, "designed {designed} vs best random {random}");

    // The CSV: one period at 100 Hz, starting and ending at rest at the same pose.
    let csv = std::fs::read_to_string(dir.path().join("excite.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv.lines().skip(1).map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 1001);
    let (first, last) = (&rows[0], &rows[rows.len() - 1]);
    for k in (1..first.len()).step_by(2) {
        assert!((first[k] - last[k]).abs() < 1e-6, "column {k}: {} → {}", first[k], last[k]);
        assert!(first[k + 1].abs() < 1e-9 && last[k + 1].abs() < 1e-9, "column {}: not at rest", k + 1);
    }

    // The bag plays on the twin: its joints follow the trajectory.
    let out = twin(
        dir.path(),
        &[
            "sim",
            urdf.to_str().unwrap(),
            "--controller",
            "replay",
            "--trajectory",
            "excite.mcap",
            "--trajectory-topic",
            "/joint_trajectory",
            "--duration",
            "10",
            "--record",
            "run.mcap",
        ],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (log, _) = sysid::JointLog::read_mcap(dir.path().join("run.mcap"), Some("/joint_states")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let t0 = log.t_nanos[0];
    let mut worst: f64 = 0.0;
    let mut span: f64 = 0.0;
    for (j, name) in log.joint_names.iter().enumerate() {
        let col = header.iter().position(|h| h == name).unwrap();
        let (lo, hi) = rows.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| (a.min(r[col]), b.max(r[col])));
        span = span.max(hi - lo);
        for (k, &t) in log.t_nanos.iter().enumerate() {
            let i = (((t - t0) as f64 * 1e-9) * 100.0).round() as usize;
            if i < rows.len() {
                worst = worst.max((log.position[j][k] - rows[i][col]).abs());
            }
        }
    }
    assert!(span > 1.0, "the trajectory barely moves ({span} rad)");
    assert!(worst < 0.1, "the twin is {worst} rad off the trajectory");
}

#[test]
fn excite_refuses_limits_that_leave_no_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = arm_urdf();
    let out = twin(dir.path(), &["excite", urdf.to_str().unwrap(), "--effort-fraction", "0.0001"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no feasible excitation trajectory") && stderr.contains("torque"), "{stderr}");
    assert!(stderr.contains("arm6.urdf"), "{stderr}");
    assert!(!dir.path().join("excite.csv").exists() && !dir.path().join("excite.mcap").exists());
}
