//! `twin sim --scenario scenarios/grasp.toml`: the cup seen by the depth camera, lifted and held
//! with every grasp check passing; a cup out of reach refused before moving.

use super::common::{repo_root, run, write};

#[test]
fn grasp_scenario_lifts_the_cup_and_an_unreachable_cup_is_refused() {
    let scenario = repo_root().join("scenarios/grasp.toml");
    let (ok, out, err) = run(&["sim", "--scenario", scenario.to_str().unwrap()]);
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("grasp: cup seen at (0.3"), "{out}");
    for check in
        ["max_slip_m", "min_grip_force_n", "min_com_margin_m", "min_lift_m", "min_hold_secs", "min_clearance_m"]
    {
        assert!(out.contains(&format!("PASS {check}")), "{check}:\n{out}");
    }
    // The same scenario with the cup at the table's far end.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&scenario)
        .unwrap()
        .replace("\"../", &format!("\"{}/", repo_root().display()))
        .replace("grasp_randomize.toml", &repo_root().join("scenarios/grasp_randomize.toml").display().to_string())
        .replace("position = [0.33, -0.12]", "position = [0.75, -0.1]");
    let far = write(dir.path(), "far.toml", &text);
    let (ok, out, err) = run(&["sim", "--scenario", far.to_str().unwrap(), "--duration", "3"]);
    assert!(!ok, "{out}");
    assert!(out.contains("grasp: refused before moving: the cup seen at (0.750"), "{out}");
    assert!(out.contains("FAIL min_lift_m"), "{out}");
    assert!(err.contains("checks of") && err.contains("failed"), "{err}");
}
