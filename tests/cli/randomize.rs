//! `twin randomize` and `twin randomize merge`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("randomize/tests/fixtures/humanoid.xml")
}

fn twin(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).args(args).output().expect("twin runs")
}

fn ok(args: &[&str]) -> String {
    let out = twin(args);
    assert!(out.status.success(), "twin {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn shards_merged_equal_the_unsharded_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).display().to_string();
    let model = fixture().display().to_string();
    let common = ["randomize", &model, "--episodes", "7", "--duration", "0.6", "--seed", "9"];
    let whole = ok(&[&common[..], &["--threads", "2", "--out", &d("all")]].concat());
    ok(&[&common[..], &["--threads", "1", "--shard", "1/2", "--out", &d("s1")]].concat());
    ok(&[&common[..], &["--threads", "2", "--shard", "2/2", "--out", &d("s2")]].concat());
    let merged = ok(&["randomize", "merge", &d("s2"), &d("s1"), "--out", &d("merged")]);
    assert_eq!(merged, whole, "merge prints exactly the single-machine summary");
    for file in ["episodes.csv", "summary.json", "spec.toml"] {
        let a = std::fs::read(dir.path().join("all").join(file)).unwrap();
        let b = std::fs::read(dir.path().join("merged").join(file)).unwrap();
        assert_eq!(a, b, "{file} differs");
    }
    let csv = std::fs::read_to_string(dir.path().join("s1/episodes.csv")).unwrap();
    let episodes: Vec<&str> = csv.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(episodes, ["0", "2", "4", "6"]);
    assert!(whole.contains("episodes: 7 of 7"), "{whole}");

    // A missing shard is an error naming it.
    let out = twin(&["randomize", "merge", &d("s1")]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("shard 2/2 is missing"), "{err}");
}

#[test]
fn bad_inputs_get_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let model = fixture().display().to_string();
    let spec = dir.path().join("spec.toml");
    std::fs::write(
        &spec,
        "[mass]\nmode = \"scale\"\ndist = \"uniform\"\nlow = 0.9\nhigh = 1.1\nselect = [\"elbow*\"]\n",
    )
    .unwrap();
    let out = twin(&["randomize", &model, "--config", spec.to_str().unwrap(), "--episodes", "1"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("spec.toml") && err.contains("[mass]") && err.contains("elbow*"), "{err}");
    assert!(!err.contains("panicked"), "{err}");

    std::fs::write(&spec, "[friction]\nmode = \"scale\"\ndist = \"unifrom\"\n").unwrap();
    let out = twin(&["randomize", &model, "--config", spec.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("line 3") && err.contains("unifrom"), "{err}");

    let out = twin(&["randomize", &model, "--shard", "3/2"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--shard"), "{err}");

    let out = twin(&["randomize", &model, "--controller", "dance"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("pd-hold"), "{err}");
}

#[test]
fn print_config_is_a_valid_spec() {
    let dir = tempfile::tempdir().unwrap();
    let text = ok(&["randomize", "--print-config"]);
    assert!(text.contains("[friction]") && text.contains("[push.speed_mps]"), "{text}");
    let spec = dir.path().join("default.toml");
    std::fs::write(&spec, &text).unwrap();
    let model = fixture().display().to_string();
    let out = ok(&["randomize", &model, "--config", spec.to_str().unwrap(), "--episodes", "2", "--duration", "0.2"]);
    assert!(out.contains("success: 2/2"), "{out}");
}
