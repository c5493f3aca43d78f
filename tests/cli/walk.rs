//! `twin sim --controller walk` and `twin sim --scenario FILE`: gait metrics, PASS/FAIL checks
//! with numbers, and scenario errors that name the file, the line and the key.

use super::common::{run, write};
use std::path::{Path, PathBuf};

/// Writes `dir/name`: a scenario of the shipped humanoid with the TOML `rest` after its model.
fn humanoid_scenario(dir: &Path, name: &str, rest: &str) -> PathBuf {
    let model = super::common::repo_root().join("models/humanoid.urdf");
    write(dir, name, &format!("model = {:?}\n{rest}", model.display().to_string()))
}

#[test]
fn walk_prints_gait_metrics_and_failed_checks_fail_the_command() {
    let dir = tempfile::tempdir().unwrap();
    let file = humanoid_scenario(
        dir.path(),
        "short.toml",
        "duration = 3.0\n[walk]\nvx = 0.3\n[checks]\nfalls = 0\nmin_forward = 5.0\n",
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

/// `twin randomize --scenario`: the scenario's model, duration and walker drive the batch, and
/// its checks decide each episode's success.
#[test]
fn randomize_scenario_checks_decide_success() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = |name: &str, checks: &str| {
        humanoid_scenario(dir.path(), name, &format!("duration = 1.5\n[walk]\nvx = 0.0\n[checks]\n{checks}"))
    };
    let stand = scenario("stand.toml", "falls = 0\nmax_distance = 0.5\n");
    let out_dir = dir.path().join("out");
    let (ok, out, err) = run(&[
        "randomize",
        "--scenario",
        stand.to_str().unwrap(),
        "--episodes",
        "2",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("success: 2/2"), "standing still for 1.5 s passes:\n{out}");
    let csv = std::fs::read_to_string(out_dir.join("episodes.csv")).unwrap();
    assert_eq!(csv.matches("scenario=PASS").count(), 2, "{csv}");
    // Standing, the soles' contacts flicker but no foot leaves the ground: no steps.
    let steps = csv.lines().next().unwrap().split(',').position(|h| h == "steps_taken").unwrap();
    for row in csv.lines().skip(1) {
        assert_eq!(row.split(',').nth(steps), Some("0"), "steps_taken standing: {row}");
    }
    let summary = std::fs::read_to_string(out_dir.join("summary.json")).unwrap();
    assert!(summary.contains("\"controller\": \"walk\"") && summary.contains("\"duration_secs\": 1.5"), "{summary}");
    // Standing can't cover 5 m: every episode fails its check, though none falls.
    let far = scenario("far.toml", "min_forward = 5.0\n");
    let (ok, out, err) = run(&["randomize", "--scenario", far.to_str().unwrap(), "--episodes", "2"]);
    assert!(ok, "{err}");
    assert!(out.contains("success: 0/2") && out.contains("fell 0"), "{out}");
    // The scenario's scripted pushes act in every episode too: 1000 N for 0.1 s (2.8 m/s of
    // the whole robot, a capture point 0.7 m ahead) fells both, where the same standing passed.
    let pushed = humanoid_scenario(
        dir.path(),
        "pushed.toml",
        "duration = 2.5\n[walk]\nvx = 0.0\n[[push]]\ntime = 0.5\nforce = [1000.0, 0.0, 0.0]\n[checks]\nfalls = 0\n",
    );
    let (ok, out, err) = run(&["randomize", "--scenario", pushed.to_str().unwrap(), "--episodes", "2"]);
    assert!(ok, "{err}");
    assert!(out.contains("success: 0/2") && out.contains("fell 2"), "{out}");
}

/// `twin randomize --scenario` tabulates the scenario's gait metrics per episode (CSV columns
/// `metric:scenario.*`, quantiles in the summary), counts a walking foot's landings as steps
/// (not its sole's contact flicker), and shards of such a batch merge into the same bytes.
#[test]
fn randomize_scenario_summarizes_gait_metrics_and_shards_merge() {
    let dir = tempfile::tempdir().unwrap();
    // 1 s crouch, then 0.5-s steps from 1.3 s: about 5 landings in 4 s.
    let walk = humanoid_scenario(
        dir.path(),
        "walk.toml",
        "duration = 4.0\n[walk]\nvx = 0.3\nstep_period = 0.5\n[checks]\nfalls = 0\n",
    );
    let w = walk.to_str().unwrap();
    let out_of = |name: &str| dir.path().join(name);
    let whole = out_of("whole");
    let (ok, out, err) = run(&["randomize", "--scenario", w, "--episodes", "2", "--out", whole.to_str().unwrap()]);
    assert!(ok, "{out}\n{err}");
    for metric in ["scenario.slip_mean_m", "scenario.velocity_rms_error_mps", "scenario.cost_of_transport"] {
        assert!(out.contains(metric), "the summary tabulates {metric}:\n{out}");
    }
    let csv = std::fs::read_to_string(whole.join("episodes.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name}: {header:?}"));
    let (steps, gait_steps, slip) =
        (col("steps_taken"), col("metric:scenario.steps"), col("metric:scenario.slip_mean_m"));
    for line in lines {
        let row: Vec<&str> = line.split(',').collect();
        let n: f64 = row[steps].parse().unwrap();
        assert!((3.0..=8.0).contains(&n), "about 5 landings in 2.7 s of 0.5-s steps, got {n}: {line}");
        assert_eq!(row[gait_steps].parse::<f64>().unwrap(), n, "the engine and the gait metrics count alike");
        let slip_m: f64 = row[slip].parse().unwrap();
        assert!((0.0..0.02).contains(&slip_m), "{slip_m}");
    }
    for k in 1..=2 {
        let shard = out_of(&format!("shard-{k}"));
        let shard_arg = format!("{k}/2");
        let args =
            ["randomize", "--scenario", w, "--episodes", "2", "--shard", &shard_arg, "--out", shard.to_str().unwrap()];
        let (ok, out, err) = run(&args);
        assert!(ok, "{out}\n{err}");
    }
    let merged = out_of("merged");
    let (s1, s2) = (out_of("shard-1"), out_of("shard-2"));
    let args = ["randomize", "merge", s1.to_str().unwrap(), s2.to_str().unwrap(), "--out", merged.to_str().unwrap()];
    let (ok, out, err) = run(&args);
    assert!(ok, "{out}\n{err}");
    for name in ["episodes.csv", "summary.json"] {
        let (a, b) = (std::fs::read(whole.join(name)).unwrap(), std::fs::read(merged.join(name)).unwrap());
        assert!(a == b, "{name}: merged shards differ from the single run");
    }
}

/// `--topics` may name the walker's own topics (`/walk/*`): they are its diagnostics, recorded
/// whatever `--topics` says; a topic neither the table nor the controller has is still refused.
#[test]
fn sim_topics_accepts_the_controllers_topics() {
    let dir = tempfile::tempdir().unwrap();
    let model = super::common::repo_root().join("models/humanoid.urdf");
    let m = model.to_str().unwrap();
    let mcap = dir.path().join("w.mcap");
    let mcap = mcap.to_str().unwrap();
    let args = ["sim", m, "--controller", "walk", "--duration", "0.2", "--record", mcap, "--topics"];
    let (ok, out, err) = run(&[&args[..], &["/walk/com,/joint_states"]].concat());
    assert!(ok, "{out}\n{err}");
    let (ok, info, err) = run(&["log", "info", mcap]);
    assert!(ok, "{err}");
    let count = |topic: &str| -> u64 {
        let line = info.lines().find(|l| l.trim_start().starts_with(&format!("{topic} "))).unwrap_or("");
        line.split_whitespace().nth(3).and_then(|n| n.parse().ok()).unwrap_or(0)
    };
    // 100 Hz diagnostics and 500 Hz joint states over 0.2 s; nothing of the table's other topics.
    assert!((19..=21).contains(&count("/walk/com")), "{info}");
    assert!((99..=101).contains(&count("/joint_states")), "{info}");
    assert_eq!(count("/tf"), 0, "{info}");
    let (ok, _, err) = run(&[&args[..], &["/walk/nope"]].concat());
    assert!(!ok && err.contains("/walk/nope") && err.contains("/walk/com"), "{err}");
}

/// `twin randomize` on a robot whose legs can't reach the shipped humanoid's steps: the batch's
/// walker is built on the options derived for this robot, never on the defaults. Romeo (from
/// example-robot-data) was refused before its first episode — "the left leg can't reach a step
/// of max_step_length 0.2 m" — by a check of the default walker, though `twin sim` walks it.
/// Each episode walks here: steps counted from its feet's landings, the CoM carried forward.
/// Six episodes: the fifth's copy of Romeo (masses drawn ±10 %) was refused by the walker's
/// reach check at its reset, and the batch stopped with it; the options are checked against the
/// robot once, and that copy walks (5 steps, 0.77 m).
#[test]
fn randomize_walks_a_robot_that_the_default_steps_do_not_fit() {
    let romeo = crate::example_robot_data::example_robot_data().join("romeo_description/urdf/romeo.urdf");
    let dir = tempfile::tempdir().unwrap();
    let file = write(
        dir.path(),
        "romeo_walk.toml",
        &format!("model = {:?}\nduration = 5.0\n[walk]\nvx = 0.2\n[checks]\nfalls = 0\n", romeo.display().to_string()),
    );
    let out_dir = dir.path().join("out");
    let args =
        ["randomize", "--scenario", file.to_str().unwrap(), "--episodes", "6", "--out", out_dir.to_str().unwrap()];
    let (ok, out, err) = run(&args);
    assert!(ok, "{out}\n{err}");
    let csv = std::fs::read_to_string(out_dir.join("episodes.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(csv.lines().count(), 7, "{csv}");
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name}: {header:?}"));
    let (steps, forward) = (col("steps_taken"), col("metric:scenario.forward_m"));
    for line in lines {
        let row: Vec<&str> = line.split(',').collect();
        let n: f64 = row[steps].parse().unwrap();
        let forward_m: f64 = row[forward].parse().unwrap();
        // 0.2 m/s from the first step (after the 1-s crouch): about 0.8 m in 4 s.
        assert!(n >= 5.0 && forward_m > 0.4, "{n} steps, {forward_m} m: {line}");
    }
    // Without a scenario, `--controller walk` stands Romeo on its derived options too.
    let (ok, out, err) =
        run(&["randomize", romeo.to_str().unwrap(), "--controller", "walk", "--episodes", "1", "--duration", "2"]);
    assert!(ok && out.contains("success:"), "{out}\n{err}");
    // MODEL replaces a scenario's own `model`, as in `twin sim`: the episodes draw Romeo's link
    // masses, not the shipped humanoid's (`scenarios/stand.toml`'s model), which they did while
    // the summary named Romeo.
    let replaced = dir.path().join("replaced");
    let (ok, out, err) = run(&[
        "randomize",
        romeo.to_str().unwrap(),
        "--scenario",
        "scenarios/stand.toml",
        "--episodes",
        "1",
        "--duration",
        "1",
        "--out",
        replaced.to_str().unwrap(),
    ]);
    assert!(ok, "{out}\n{err}");
    let csv = std::fs::read_to_string(replaced.join("episodes.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(header.contains("mass:LHipYawLink") && !header.contains("mass:waist_yaw_link"), "{header}");
}
