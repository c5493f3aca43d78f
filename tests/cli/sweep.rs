//! `twin randomize --sweep`: one batch per level, the table, CSV and SVG, levels that really
//! change what they name, and shards merged level by level into what one machine writes.

use crate::common::{repo_root, run};
use std::path::Path;

fn ok(args: &[&str]) -> String {
    let (success, stdout, stderr) = run(args);
    assert!(success, "twin {args:?} failed: {stderr}");
    stdout
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn a_terrain_sweep_over_two_shards_merges_to_what_one_machine_writes() {
    let dir = tempfile::tempdir().unwrap();
    let d = |n: &str| dir.path().join(n).display().to_string();
    let scenario = repo_root().join("scenarios/walk_rough.toml").display().to_string();
    let common = [
        "randomize",
        "--scenario",
        &scenario,
        "--episodes",
        "4",
        "--duration",
        "1.5",
        "--sweep",
        "terrain.difficulty=0:1:0.5",
    ];
    let text = ok(&[&common[..], &["--threads", "2", "--out", &d("one")]].concat());
    assert!(text.contains("success first below") || text.contains("success stays"), "{text}");
    ok(&[&common[..], &["--threads", "1", "--shard", "1/2", "--out", &d("s1")]].concat());
    ok(&[&common[..], &["--threads", "2", "--shard", "2/2", "--out", &d("s2")]].concat());
    let merged = ok(&["randomize", "merge", "--out", &d("all"), &d("s1"), &d("s2")]);
    assert!(merged.contains("terrain.difficulty"), "{merged}");
    for f in ["sweep.csv", "sweep.svg", "level-00/episodes.csv", "level-01/summary.json", "level-02/episodes.csv"] {
        assert!(read(&dir.path().join("one").join(f)) == read(&dir.path().join("all").join(f)), "{f} differs");
    }
    let csv = String::from_utf8(read(&dir.path().join("one/sweep.csv"))).unwrap();
    let levels: Vec<&str> = csv.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(levels, ["0", "0.5", "1"]);
    assert!(csv.lines().skip(1).all(|l| l.split(',').nth(1) == Some("4")), "{csv}");
    // Each level's batch says which level it is.
    let summary = String::from_utf8(read(&dir.path().join("one/level-01/summary.json"))).unwrap();
    assert!(summary.contains("[terrain.difficulty = 0.5]"), "{summary}");
}

#[test]
fn a_spec_term_sweep_fixes_the_draw_to_each_level() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("push");
    let model = repo_root().join("randomize/tests/fixtures/humanoid.xml").display().to_string();
    let text = ok(&[
        "randomize",
        &model,
        "--episodes",
        "3",
        "--duration",
        "0.3",
        "--sweep",
        "push.speed_mps=0:0.6:0.3",
        "--out",
        &out.display().to_string(),
    ]);
    assert_eq!(text.matches("== push.speed_mps = ").count(), 3, "{text}");
    for (i, level) in ["0", "0.3", "0.6"].iter().enumerate() {
        let csv = String::from_utf8(read(&out.join(format!("level-{i:02}/episodes.csv")))).unwrap();
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        let col = header.iter().position(|h| *h == "push.speed_mps").expect("a push.speed_mps column");
        for row in csv.lines().skip(1) {
            assert_eq!(row.split(',').nth(col), Some(*level), "level {level}: {row}");
        }
    }
    let svg = String::from_utf8(read(&out.join("sweep.svg"))).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("Success against push.speed_mps"));
    let (success, _, err) = run(&["randomize", &model, "--episodes", "1", "--sweep", "damping=0:1:0.5"]);
    assert!(!success && err.contains("no `damping` term"), "{err}");
    let (success, _, err) = run(&["randomize", &model, "--episodes", "1", "--sweep", "terrain.difficulty=0:1"]);
    assert!(!success && err.contains("NAME=FROM:TO:STEP"), "{err}");
}
