//! `twin sim --controller walk` and `twin sim --scenario FILE`: gait metrics, PASS/FAIL checks
//! with numbers, and scenario errors that name the file, the line and the key.

use super::common::{run, write};

#[test]
fn walk_prints_gait_metrics_and_failed_checks_fail_the_command() {
    let dir = tempfile::tempdir().unwrap();
    let model = super::common::repo_root().join("models/humanoid.urdf");
    let file = write(
        dir.path(),
        "short.toml",
        &format!(
            "model = {:?}\nduration = 3.0\n[walk]\nvx = 0.3\n[checks]\nfalls = 0\nmin_forward = 5.0\n",
            model.display().to_string()
        ),
    );
    let (ok, out, err) = run(&["sim", "--scenario", file.to_str().unwrap()]);
    assert!(!ok, "min_forward 5 m in 3 s can't pass:\n{out}");
    assert!(out.contains("gait metrics over 3.00 s") && out.contains("steps"), "{out}");
    assert!(out.contains("PASS falls") && out.contains("FAIL min_forward"), "{out}");
    assert!(err.contains("1 of 2 checks") && err.contains("short.toml"), "{err}");
}

#[test]
fn scenario_errors_name_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "bad.toml", "duration = 5.0\n[walk]\nvx = 0.3\nstep_lenght = 0.2\n");
    let (ok, _, err) = run(&["sim", "--scenario", file.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("bad.toml:4: `step_lenght`") && err.contains("unknown field"), "{err}");
    let file = write(dir.path(), "far.toml", "duration = 5.0\n[walk]\nvx = 0.9\n");
    let (ok, _, err) = run(&["sim", "--scenario", file.to_str().unwrap()]);
    assert!(!ok);
    assert!(err.contains("far.toml:3: `walk.vx`") && err.contains("max_step_length"), "{err}");
}
