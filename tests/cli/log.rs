//! `twin log info` on the shipped humanoid fixture, a truncated copy, and a non-MCAP file.

use std::path::Path;
use std::process::{Command, Output};

const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/humanoid_joint_states.mcap");

fn twin(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).args(args).current_dir(dir).output().expect("twin runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn log_info_lists_topics_counts_rates_and_gaps() {
    let dir = tempfile::tempdir().unwrap();
    let out = twin(&["log", "info", FIXTURE], dir.path());
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(out.stderr.is_empty(), "{}", text(&out.stderr));
    let line = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("/joint_states"))
        .unwrap_or_else(|| panic!("no /joint_states line:\n{stdout}"));
    let cols: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(
        cols,
        ["/joint_states", "sensor_msgs/msg/JointState", "cdr", "200", "100.00", "0.0100", "1700000000.010000"],
        "{stdout}"
    );
    assert!(stdout.contains("messages: 200"), "{stdout}");
    assert!(stdout.contains("duration 1.990 s"), "{stdout}");
    assert!(stdout.contains("profile: ros2"), "{stdout}");
}

#[test]
fn log_info_on_cut_file_warns_what_was_lost_and_strict_refuses() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(FIXTURE).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();

    let out = twin(&["log", "info", "cut.mcap"], dir.path());
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("warning:") && stderr.contains("cut.mcap"), "{stderr}");
    assert!(stderr.contains("cut off") && stderr.contains("bytes lost"), "{stderr}");
    let stdout = text(&out.stdout);
    let count: u64 = stdout
        .lines()
        .find(|l| l.trim_start().starts_with("/joint_states"))
        .and_then(|l| l.split_whitespace().nth(3)?.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(count > 0 && count < 200, "{count} messages recovered");

    let out = twin(&["log", "info", "--strict", "cut.mcap"], dir.path());
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.starts_with("error:") && stderr.contains("--strict"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn log_info_on_a_non_mcap_file_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("notes.mcap"), "hello").unwrap();
    let out = twin(&["log", "info", "notes.mcap"], dir.path());
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("notes.mcap") && stderr.contains("not an MCAP file"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
