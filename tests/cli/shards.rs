//! Shards of `twin randomize` as a scheduler runs them: progress while running, a shard killed
//! mid-run, shards that don't belong together, reruns of finished shards.

use crate::common::{output_of, run, twin};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn fixture() -> String {
    crate::common::repo_root().join("randomize/tests/fixtures/humanoid.xml").display().to_string()
}

fn ok(args: &[&str]) -> String {
    let (success, stdout, stderr) = run(args);
    assert!(success, "twin {args:?} failed: {stderr}");
    stdout
}

fn fails(args: &[&str]) -> String {
    let (success, _, stderr) = run(args);
    assert!(!success, "twin {args:?} should have failed");
    stderr
}

fn same_files(a: &Path, b: &Path) {
    for file in ["episodes.csv", "summary.json", "spec.toml"] {
        let (x, y) = (std::fs::read(a.join(file)).unwrap(), std::fs::read(b.join(file)).unwrap());
        assert!(x == y, "{file} of {} and {} differ", a.display(), b.display());
    }
}

/// The `twin randomize merge --status` line of shard `k`: (done, total, state).
fn status_of(dirs: &[&Path], k: u64) -> (u64, u64, String) {
    let mut args = vec!["randomize".to_string(), "merge".into(), "--status".into()];
    args.extend(dirs.iter().map(|d| d.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let text = ok(&args);
    let prefix = format!("shard {k}/");
    let line = text.lines().find(|l| l.starts_with(&prefix)).unwrap_or_else(|| panic!("no shard {k} in\n{text}"));
    // shard K/N  DONE/TOTAL  STATE  FOLDER
    let words: Vec<&str> = line.split_whitespace().collect();
    let (done, total) = words[2].split_once('/').unwrap();
    let state = ["done", "running (or killed)", "interrupted", "missing"]
        .into_iter()
        .find(|s| line.contains(&format!(" {s} ")) || line.ends_with(&format!(" {s}")))
        .unwrap_or_else(|| panic!("no state in {line:?}"))
        .to_string();
    (done.parse().unwrap(), total.trim().parse().unwrap(), state)
}

#[test]
fn a_killed_shard_is_refused_with_its_rerun_command_and_rerunning_it_completes_the_merge() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let d = |name: &str| p(name).display().to_string();
    let model = fixture();
    // Shard 2 has 60 episodes; on one thread they finish in chunks of 32, so it is stopped
    // after the first chunk reached the disk and before the last.
    let common = ["randomize", &model, "--episodes", "120", "--duration", "0.25", "--seed", "5"];
    ok(&[&common[..], &["--threads", "1", "--shard", "1/2", "--out", &d("s1")]].concat());
    assert_eq!(status_of(&[&p("s1")], 1), (60, 60, "done".into()));
    assert_eq!(status_of(&[&p("s1")], 2), (0, 60, "missing".into()));

    let mut child = twin()
        .args([&common[..], &["--threads", "1", "--shard", "2/2", "--out", &d("s2")]].concat())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    let progress = loop {
        assert!(started.elapsed() < Duration::from_secs(300), "shard 2 wrote no progress in 300 s");
        if p("s2/shard.json").exists() {
            let (done, total, state) = status_of(&[&p("s1"), &p("s2")], 2);
            assert_eq!(total, 60);
            if done > 0 {
                assert_eq!(state, "running (or killed)");
                break done;
            }
        }
        assert!(child.try_wait().unwrap().is_none(), "shard 2 ended before it could be killed");
        std::thread::sleep(Duration::from_millis(20));
    };
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(progress < 60, "the first chunk is 32 episodes, got {progress}");
    let (done, _, state) = status_of(&[&p("s1"), &p("s2")], 2);
    assert!((progress..60).contains(&done) && state == "running (or killed)", "{done} {state}");

    let err = fails(&["randomize", "merge", &d("s1"), &d("s2"), "--out", &d("merged")]);
    assert!(err.contains("1 of 2 shards not finished") && err.contains("shard 2/2 is running (or killed)"), "{err}");
    assert!(!p("merged").exists(), "a refused merge writes nothing");
    let rerun = err
        .lines()
        .skip_while(|l| !l.contains("rerun only it"))
        .nth(1)
        .unwrap_or_else(|| panic!("no rerun command in {err}"))
        .trim()
        .to_string();
    assert!(rerun.contains("--shard 2/2") && rerun.contains(&d("s2")) && !rerun.contains("1/2"), "{rerun}");
    let status = std::process::Command::new("sh").arg("-c").arg(&rerun).current_dir(dir.path()).output().unwrap();
    assert!(output_of(status).0, "{rerun}");

    let merged = ok(&["randomize", "merge", &d("s2"), &d("s1"), "--out", &d("merged")]);
    let whole = ok(&[&common[..], &["--threads", "2", "--out", &d("all")]].concat());
    assert_eq!(merged, whole);
    same_files(&p("all"), &p("merged"));
    assert!(
        ok(&["randomize", "merge", "--status", &d("s1"), &d("s2")])
            .contains("total: 120/120 episodes (100.0 %), 2 of 2 shards done")
    );
}

#[test]
fn shards_of_another_spec_seed_or_binary_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let d = |name: &str| p(name).display().to_string();
    let model = fixture();
    let common = ["randomize", &model, "--episodes", "4", "--duration", "0.2", "--threads", "1"];
    ok(&[&common[..], &["--seed", "1", "--shard", "1/2", "--out", &d("s1")]].concat());
    ok(&[&common[..], &["--seed", "2", "--shard", "2/2", "--out", &d("seed2")]].concat());
    let err = fails(&["randomize", "merge", &d("s1"), &d("seed2")]);
    assert!(err.contains("ran with seed 2") && err.contains("--seed 1") && err.contains("--shard 2/2"), "{err}");

    let spec = p("spec.toml");
    std::fs::write(&spec, "[friction]\nmode = \"scale\"\ndist = \"uniform\"\nlow = 0.5\nhigh = 1.5\n").unwrap();
    let spec = spec.display().to_string();
    ok(&[&common[..], &["--seed", "1", "--config", &spec, "--shard", "2/2", "--out", &d("spec2")]].concat());
    let err = fails(&["randomize", "merge", &d("s1"), &d("spec2")]);
    assert!(err.contains("different randomization spec"), "{err}");

    ok(&[&common[..], &["--seed", "1", "--shard", "2/2", "--out", &d("s2")]].concat());
    ok(&["randomize", "merge", &d("s1"), &d("s2")]);
    let manifest = p("s2/shard.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&manifest).unwrap()).unwrap();
    let version = json["twin_version"].as_str().unwrap();
    assert!(version.starts_with(env!("CARGO_PKG_VERSION")) && version.contains("MuJoCo"), "{version}");
    json["twin_version"] = "0.0.9 (MuJoCo 3.3.0)".into();
    std::fs::write(&manifest, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    let err = fails(&["randomize", "merge", &d("s1"), &d("s2")]);
    assert!(err.contains("made by twin \"0.0.9 (MuJoCo 3.3.0)\""), "{err}");

    let err = fails(&["randomize", "merge", &d("s1"), &d("s1")]);
    assert!(err.contains("shard 1/2 is also in"), "{err}");
    let err = fails(&["randomize", "merge", &d("nothing-here")]);
    assert!(err.contains("nothing-here") && err.contains("shard.json"), "{err}");
}

#[test]
fn rerunning_a_finished_shard_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out: PathBuf = dir.path().join("s1");
    let model = fixture();
    let args = ["randomize", &model, "--episodes", "5", "--duration", "0.2", "--seed", "3", "--shard", "1/2"];
    let o = out.display().to_string();
    let first = ok(&[&args[..], &["--threads", "1", "--out", &o]].concat());
    let files = |dir: &Path| {
        let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap())
            .filter(|e| e.file_type().unwrap().is_file())
            .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
            .collect();
        v.sort();
        v
    };
    let before = files(&out);
    // Another thread count is the same work.
    let (success, again, stderr) = run(&[&args[..], &["--threads", "2", "--out", &o]].concat());
    assert!(success && stderr.contains("already complete"), "{stderr}");
    assert_eq!(again, first, "the stored summary is printed");
    assert_eq!(files(&out), before, "no file rewritten, no backup made");
    // Another batch in the same folder runs (and the merge sees the new batch).
    let (success, _, stderr) = run(&[
        "randomize",
        &model,
        "--episodes",
        "5",
        "--duration",
        "0.2",
        "--seed",
        "4",
        "--shard",
        "1/2",
        "--out",
        &o,
    ]);
    assert!(success && !stderr.contains("already complete"), "{stderr}");
    assert!(std::fs::read_to_string(out.join("shard.json")).unwrap().contains("\"seed\": 4"));
}
