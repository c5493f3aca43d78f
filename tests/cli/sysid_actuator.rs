//! `twin sysid actuator`: a two-joint arm whose drives MuJoCo's Python package simulates with its
//! own command delay (`tests/python/drive_truth.py`), identified from the bag through the CLI;
//! the URDF gains exactly the two blocks (the original kept byte for byte as the backup), and
//! `twin info` then shows the identified delay on each joint.

use crate::common::{run, write};

const URDF: &str = r#"<?xml version="1.0"?>
<robot name="pair">
  <link name="base"><inertial><mass value="3"/><inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" effort="60" velocity="4"/><dynamics damping="0.2"/></joint>
  <link name="upper"><inertial><origin xyz="0.15 0 0"/><mass value="2"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="30" velocity="4"/><dynamics damping="0.1"/></joint>
  <link name="fore"><inertial><origin xyz="0.12 0 0"/><mass value="1"/><inertia ixx="0.005" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="shoulder"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <transmission name="t2"><type>transmission_interface/SimpleTransmission</type>
    <joint name="elbow"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>
    <actuator name="m2"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
</robot>
"#;

#[test]
fn sysid_actuator_identifies_delays_and_writes_only_the_blocks() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = write(dir.path(), "pair.urdf", URDF);
    let bag = dir.path().join("drives.mcap");
    let truth = r#"[{"name": "shoulder", "delay": 0.005, "kp": 150, "kd": 4, "armature": 0.08},
                    {"name": "elbow", "delay": 0.012, "kp": 60, "kd": 1.5, "armature": 0.03}]"#;
    let script = crate::common::repo_root().join("tests/python/drive_truth.py");
    crate::test_python::script_json(
        script.to_str().unwrap(),
        &[urdf.as_os_str(), bag.as_os_str(), truth.as_ref(), "8".as_ref(), "3".as_ref()],
    );
    let report = dir.path().join("actuator.json");
    let (ok, out, err) = run(&[
        "sysid",
        "actuator",
        "--log",
        bag.to_str().unwrap(),
        "--update",
        urdf.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("held-out replay") && err.contains("original kept as"), "{out}\n{err}");
    let backup = std::fs::read_to_string(dir.path().join("pair.urdf.bak")).unwrap();
    assert_eq!(backup, URDF);
    let new = std::fs::read_to_string(&urdf).unwrap();
    let start = new.find("  <!-- twin actuator").expect("actuator block");
    let end = new.rfind("</robot>").unwrap();
    assert_eq!(format!("{}{}", &new[..start], &new[end..]), URDF, "only the blocks are added");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    for (joint, delay, kp) in [("shoulder", 0.005, 150.0), ("elbow", 0.012, 60.0)] {
        let j = json["joints"].as_array().unwrap().iter().find(|j| j["joint"] == joint).unwrap();
        let got = j["delay_secs"]["value"].as_f64().unwrap();
        assert!((got - delay).abs() <= 0.001, "{joint}: delay {got}");
        let got_kp = j["kp"]["value"].as_f64().unwrap();
        assert!((got_kp / kp - 1.0).abs() <= 0.1, "{joint}: kp {got_kp}");
        let h = json["held_out"].as_array().unwrap().iter().find(|h| h["joint"] == joint).unwrap();
        assert!(h["after_rms"].as_f64().unwrap() <= 0.3 * h["before_rms"].as_f64().unwrap(), "{h}");
    }
    // The converter reads the blocks back: `twin info` shows each joint's identified delay.
    let (ok, info, err) = run(&["info", urdf.to_str().unwrap()]);
    assert!(ok, "{err}");
    for (joint, delay_ms) in [("shoulder", 5.0), ("elbow", 12.0)] {
        let line =
            info.lines().find(|l| l.trim_start().starts_with(&format!("{joint} ")) && l.contains("drive:")).unwrap();
        let ms: f64 = line.split("delay ").nth(1).and_then(|r| r.split(' ').next()).unwrap().parse().unwrap();
        assert!((ms - delay_ms).abs() <= 1.0 && line.contains("position loop kp"), "{line}");
    }
    // A log without commands is refused, naming what is missing, and the file stays as it is.
    let (ok, _, err) = run(&[
        "sysid",
        "actuator",
        "--log",
        bag.to_str().unwrap(),
        "--update",
        urdf.to_str().unwrap(),
        "--command-topic",
        "/nope",
    ]);
    assert!(!ok && err.contains("/nope"), "{err}");
    assert_eq!(std::fs::read_to_string(&urdf).unwrap(), new);
}
