//! `twin sysid` with its defaults on a real robot's log: the Franka Emika Panda's exciting
//! trajectory of Gaz et al. 2019 (data/panda_gaz2019), the robot's unchanged public URDF
//! (example-robot-data's panda.urdf, whose finger joints the log does not name), scored on the
//! held-out last 30 % against the model the paper publishes, by twin and by an independent
//! evaluation (tests/python/sysid_heldout.py: mcap-ros2-support, SciPy, MuJoCo's Python
//! package, the paper's own model code).

use std::path::{Path, PathBuf};
use std::process::Command;

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/panda_gaz2019").join(rel)
}

/// Copies the shipped description package into `dir`: the URDF is edited there.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), target).unwrap();
        }
    }
}

/// An element of a URDF as compared: tag, attributes, inside `<inertial>` or `<dynamics>`.
type Element = (String, Vec<(String, String)>, bool);

/// Every element and attribute of `a` and `b` equal except the numbers of `<inertial>` and
/// `<dynamics>`, and `b`'s `<twin_sysid>` block.
fn only_dynamics_numbers_differ(a: &str, b: &str) {
    let da = roxmltree::Document::parse(a).unwrap();
    let db = roxmltree::Document::parse(b).unwrap();
    let elems = |d: &roxmltree::Document<'_>| -> Vec<Element> {
        d.descendants()
            .filter(|n| n.is_element())
            .filter(|n| !n.ancestors().any(|p| p.has_tag_name("twin_sysid")))
            .map(|n| {
                let numeric = n.ancestors().any(|p| p.has_tag_name("inertial") || p.has_tag_name("dynamics"));
                let attrs = n.attributes().map(|a| (a.name().to_string(), a.value().to_string())).collect();
                (n.tag_name().name().to_string(), attrs, numeric)
            })
            .collect()
    };
    let (ea, eb) = (elems(&da), elems(&db));
    assert_eq!(ea.len(), eb.len(), "elements added or removed");
    for (x, y) in ea.iter().zip(&eb) {
        assert_eq!(x.0, y.0);
        if x.2 {
            let names = |v: &Vec<(String, String)>| v.iter().map(|(k, _)| k.clone()).collect::<Vec<_>>();
            assert_eq!(names(&x.1), names(&y.1), "<{}> attributes", x.0);
        } else {
            assert_eq!(x.1, y.1, "<{}> changed", x.0);
        }
    }
}

#[test]
fn sysid_defaults_on_a_real_panda_log_beat_the_published_model_on_held_out_data() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&data("robot"), dir.path());
    let urdf = dir.path().join("example-robot-data/robots/panda_description/urdf/panda.urdf");
    let original = std::fs::read_to_string(&urdf).unwrap();
    let bag = data("panda_exciting_traj.mcap");
    let published = data("gaz2019_model.urdf");
    let out = Command::new(env!("CARGO_BIN_EXE_twin"))
        .current_dir(dir.path())
        .args(["sysid", "--log"])
        .arg(&bag)
        .arg("--update")
        .arg(&urdf)
        .args(["--report", "r.json", "--compare"])
        .arg(&published)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stderr}\n{stdout}");
    assert!(stderr.contains("\"panda_finger_joint1\"") && stderr.contains("\"panda_finger_joint2\""), "{stderr}");
    assert!(stdout.contains("cross-validation") && stdout.contains("held-out torque NRMSE"), "{stdout}");
    let new = std::fs::read_to_string(&urdf).unwrap();
    only_dynamics_numbers_differ(&original, &new);
    assert!(new.contains("<twin_sysid version=\"1\">"), "{new}");

    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("r.json")).unwrap()).unwrap();
    let held = &report["held_out"];
    let col =
        |m: usize| -> Vec<f64> { held["nrmse"][m].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect() };
    let (before, fit, paper_tables) = (col(0), col(1), col(2));
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    // twin's own scoring, against the published model's tables and friction (gaz2019_model.urdf).
    assert!(mean(&fit) <= 0.9 * mean(&paper_tables), "fit {fit:?} vs published {paper_tables:?}");
    assert!(mean(&fit) < 0.5 * mean(&before), "fit {fit:?} vs URDF {before:?}");
    for j in 0..7 {
        assert!(fit[j] <= 1.1 * paper_tables[j], "joint {j}: fit {fit:?} vs published {paper_tables:?}");
    }

    // The independent evaluation: the paper's own code, MuJoCo's inverse dynamics of the fit
    // on the first 70 % (--no-refit writes it), the same held-out samples.
    let urdf = dir.path().join("fit70.urdf");
    std::fs::write(&urdf, &original).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_twin"))
        .current_dir(dir.path().join("example-robot-data/robots/panda_description/urdf"))
        .args(["sysid", "--no-refit", "--log"])
        .arg(&bag)
        .arg("--update")
        .arg(&urdf)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let cutoff = report["cutoff_hz"].as_f64().unwrap().to_string();
    let effort_cutoff = held["effort_cutoff_hz"].as_f64().unwrap().to_string();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/sysid_heldout.py");
    let python = crate::test_python::python();
    let out = Command::new(&python)
        .arg(&script)
        .arg(&bag)
        .arg(&urdf)
        .arg(data("gaz2019_code"))
        .args(["0.3", &cutoff, &effort_cutoff])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let get = |k: &str| -> Vec<f64> { v[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect() };
    let (twin, paper) = (get("twin"), get("paper"));
    eprintln!("independent held-out NRMSE: twin {twin:?}, paper {paper:?}");
    assert!(mean(&twin) <= 0.9 * mean(&paper), "twin {twin:?} vs paper {paper:?}");
    for j in 0..7 {
        assert!(twin[j] <= 1.1 * paper[j], "joint {j}: twin {twin:?} vs paper {paper:?}");
    }
}

/// `--effort-scale`: a log whose drives report 10× the joint torque (motor current through a
/// torque constant, say) gives, scaled back by 0.1, the URDF the torque log gives; unscaled,
/// the effort-semantics diagnosis flags it.
#[test]
fn effort_scale_turns_a_current_like_log_into_the_torque_log_fit() {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&data("robot"), dir.path());
    let urdf_dir = dir.path().join("example-robot-data/robots/panda_description/urdf");
    let original = std::fs::read_to_string(urdf_dir.join("panda.urdf")).unwrap();
    let (mut log, _) = sysid::JointLog::read_mcap(data("panda_exciting_traj.mcap"), None).unwrap();
    for e in &mut log.effort {
        e.iter_mut().for_each(|x| *x *= 10.0);
    }
    let scaled = dir.path().join("current.mcap");
    log.write_mcap(&scaled, "/joint_states").unwrap();
    let run = |name: &str, bag: &Path, extra: &[&str]| -> (String, String) {
        let urdf = urdf_dir.join(name);
        std::fs::write(&urdf, &original).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_twin"))
            .args(["sysid", "--log"])
            .arg(bag)
            .arg("--update")
            .arg(&urdf)
            .args(["--cutoff-hz", "6", "--offset", "--held-out", "0"])
            .args(extra)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stderr}");
        (std::fs::read_to_string(&urdf).unwrap(), String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let (torque, _) = run("a.urdf", &data("panda_exciting_traj.mcap"), &[]);
    let (current, report) = run("b.urdf", &scaled, &["--effort-scale", "0.1"]);
    assert!(report.contains("multiplied by 0.1 (--effort-scale)"), "{report}");
    let masses = |text: &str| -> Vec<f64> {
        roxmltree::Document::parse(text)
            .unwrap()
            .descendants()
            .filter(|n| n.has_tag_name("mass"))
            .map(|n| n.attribute("value").unwrap().parse().unwrap())
            .collect()
    };
    let (a, b) = (masses(&torque), masses(&current));
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() <= 1e-5 * x.abs().max(1e-3), "{a:?} vs {b:?}");
    }
    let pairs = (1..=7).map(|i| format!("panda_joint{i}=0.1")).collect::<Vec<_>>().join(",");
    let (per_joint, _) = run("c.urdf", &scaled, &["--effort-scale", &pairs]);
    assert_eq!(masses(&per_joint), b);
    let (_, unscaled) = run("d.urdf", &scaled, &[]);
    assert!(unscaled.contains("is it motor current or motor-side torque"), "{unscaled}");
}
