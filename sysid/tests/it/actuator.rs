//! Drive identification against an independent ground truth: MuJoCo's own Python package
//! simulates a 7-DOF arm and a humanoid leg held in the air (`tests/python/drive_truth.py`: the
//! URDF through MuJoCo's importer, MuJoCo `position` actuators with its own command `delay`,
//! joint armature) and writes the ROS 2 bag; `identify_drives` reads the bag and must find each
//! joint's delay within 1 ms (delays of 2, 5 and 12 ms), its position-loop gains and armature
//! within 10 %, and, replaying the held-out commands on the twin, a position error at most 0.3×
//! the URDF's before. The write-back changes only the two blocks.

use std::fmt::Write as _;
use std::path::Path;
use sysid::actuator::{CommandLog, DriveOptions, identify_drives, rewrite_drives};
use sysid::log::JointLog;

/// One joint of a serial chain: name, axis, origin from the parent link, limits, link mass,
/// COM, and truth (delay s, kp, kd, armature).
struct J {
    name: &'static str,
    axis: &'static str,
    origin: &'static str,
    lower: f64,
    upper: f64,
    effort: f64,
    mass: f64,
    com: &'static str,
    truth: (f64, f64, f64, f64),
}

fn chain_urdf(robot: &str, joints: &[J]) -> String {
    let mut s = format!("<?xml version=\"1.0\"?>\n<!-- {robot}: a test robot -->\n<robot name=\"{robot}\">\n");
    s.push_str("  <link name=\"base\">\n    <inertial><mass value=\"5\"/><inertia ixx=\"0.1\" ixy=\"0\" ixz=\"0\" iyy=\"0.1\" iyz=\"0\" izz=\"0.1\"/></inertial>\n  </link>\n");
    let mut parent = "base".to_string();
    for j in joints {
        let child = format!("{}_link", j.name);
        let i = j.mass * 0.012;
        let _ = write!(
            s,
            "  <joint name=\"{n}\" type=\"revolute\">\n    <parent link=\"{parent}\"/>\n    <child link=\"{child}\"/>\n    \
             <origin xyz=\"{o}\" rpy=\"0 0 0\"/>\n    <axis xyz=\"{a}\"/>\n    <limit lower=\"{lo}\" upper=\"{up}\" effort=\"{e}\" velocity=\"4\"/>\n    \
             <dynamics damping=\"0.3\" friction=\"0\"/>\n  </joint>\n  <link name=\"{child}\">\n    <inertial><origin xyz=\"{c}\" rpy=\"0 0 0\"/><mass value=\"{m}\"/>\
             <inertia ixx=\"{i}\" ixy=\"0\" ixz=\"0\" iyy=\"{i}\" iyz=\"0\" izz=\"{h}\"/></inertial>\n  </link>\n",
            n = j.name,
            o = j.origin,
            a = j.axis,
            lo = j.lower,
            up = j.upper,
            e = j.effort,
            c = j.com,
            m = j.mass,
            h = i * 0.6,
        );
        parent = child;
    }
    for j in joints {
        let _ = write!(
            s,
            "  <transmission name=\"{n}_tr\">\n    <type>transmission_interface/SimpleTransmission</type>\n    \
             <joint name=\"{n}\"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>\n    \
             <actuator name=\"{n}_motor\"><mechanicalReduction>1</mechanicalReduction></actuator>\n  </transmission>\n",
            n = j.name
        );
    }
    s.push_str("</robot>\n");
    s
}

fn arm7() -> Vec<J> {
    let j = |name, axis, origin, r: f64, effort, mass, com, truth| J {
        name,
        axis,
        origin,
        lower: -r,
        upper: r,
        effort,
        mass,
        com,
        truth,
    };
    vec![
        j("a1", "0 0 1", "0 0 0.33", 2.5, 87.0, 4.0, "0 0.03 -0.05", (0.002, 300.0, 8.0, 0.20)),
        j("a2", "0 1 0", "0 0 0.05", 1.7, 87.0, 4.0, "0.05 0 0.15", (0.005, 300.0, 8.0, 0.20)),
        j("a3", "0 0 1", "0 0 0.31", 2.5, 87.0, 3.0, "0.03 0.02 -0.05", (0.012, 200.0, 5.0, 0.12)),
        j("a4", "0 1 0", "0.08 0 0.05", 1.7, 87.0, 3.0, "-0.04 0 0.12", (0.002, 200.0, 5.0, 0.12)),
        j("a5", "0 0 1", "-0.08 0 0.38", 2.5, 12.0, 2.0, "0 0.04 -0.08", (0.005, 60.0, 1.5, 0.04)),
        j("a6", "0 1 0", "0 0 0.05", 1.7, 12.0, 1.5, "0.06 0 0.01", (0.012, 40.0, 1.0, 0.03)),
        j("a7", "0 0 1", "0.09 0 0", 2.5, 12.0, 0.8, "0 0 0.07", (0.005, 20.0, 0.5, 0.015)),
    ]
}

fn leg6() -> Vec<J> {
    let j = |name, axis, origin, lower, upper, effort, mass, com, truth| J {
        name,
        axis,
        origin,
        lower,
        upper,
        effort,
        mass,
        com,
        truth,
    };
    vec![
        j("hip_yaw", "0 0 1", "0 0.1 -0.05", -0.6, 0.6, 80.0, 1.0, "0 0 -0.03", (0.005, 150.0, 4.0, 0.10)),
        j("hip_roll", "1 0 0", "0 0 -0.06", -0.5, 0.5, 80.0, 1.2, "0 0 -0.03", (0.012, 250.0, 6.0, 0.10)),
        j("hip_pitch", "0 1 0", "0 0 -0.05", -1.5, 0.8, 120.0, 4.0, "0.01 0 -0.18", (0.002, 300.0, 8.0, 0.15)),
        j("knee", "0 1 0", "0 0 -0.4", 0.0, 2.2, 150.0, 2.5, "0 0 -0.2", (0.005, 250.0, 6.0, 0.15)),
        j("ankle_pitch", "0 1 0", "0 0 -0.4", -0.8, 0.8, 60.0, 0.6, "0.02 0 -0.02", (0.012, 80.0, 2.0, 0.04)),
        j("ankle_roll", "1 0 0", "0 0 -0.02", -0.4, 0.4, 30.0, 0.8, "0.04 0 -0.04", (0.002, 60.0, 1.5, 0.03)),
    ]
}

fn identify_and_check(robot: &str, joints: &[J]) {
    let dir = tempfile::tempdir().unwrap();
    let urdf_path = dir.path().join(format!("{robot}.urdf"));
    let urdf = chain_urdf(robot, joints);
    std::fs::write(&urdf_path, &urdf).unwrap();
    let bag = dir.path().join("drives.mcap");
    // In command order (a list: JSON objects have none).
    let truth: Vec<serde_json::Value> = joints
        .iter()
        .map(|j| {
            let (d, kp, kd, a) = j.truth;
            serde_json::json!({"name": j.name, "delay": d, "kp": kp, "kd": kd, "armature": a})
        })
        .collect();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/python/drive_truth.py");
    let used = crate::test_python::script_json(
        script.to_str().unwrap(),
        &[
            urdf_path.as_os_str(),
            bag.as_os_str(),
            serde_json::Value::Array(truth).to_string().as_ref(),
            "16".as_ref(),
            "7".as_ref(),
        ],
    );
    // MuJoCo's importer read the URDF's damping, and the truth is what it simulated.
    for j in joints {
        let u = &used[j.name];
        assert_eq!(u["damping"].as_f64(), Some(0.3), "{robot} {}: {u}", j.name);
        assert!((u["delay"].as_f64().unwrap() - j.truth.0).abs() < 1e-12, "{u}");
    }
    let (states, _) = JointLog::read_mcap(&bag, Some("/joint_states")).unwrap();
    let names: Vec<String> = joints.iter().map(|j| j.name.to_string()).collect();
    let commands = CommandLog::read_mcap(&bag, None, &names).unwrap();
    let report = identify_drives(&urdf_path, &states, &commands, &DriveOptions::default()).unwrap();
    let mut failures = Vec::new();
    for (j, got) in joints.iter().zip(&report.joints) {
        let (d, kp, kd, a) = j.truth;
        eprintln!(
            "{robot} {}: delay {:.2} ms [{:.2}, {:.2}] (truth {:.1}) kp {:.1} [{:.1}, {:.1}] ({kp}) kd {:.3} ({kd}) armature {:.4} [{:.4}, {:.4}] ({a}) residual {:.3} N·m",
            j.name,
            got.delay_secs.value * 1e3,
            got.delay_secs.ci95[0] * 1e3,
            got.delay_secs.ci95[1] * 1e3,
            d * 1e3,
            got.kp.value,
            got.kp.ci95[0],
            got.kp.ci95[1],
            got.kd.value,
            got.armature.value,
            got.armature.ci95[0],
            got.armature.ci95[1],
            got.residual_rms
        );
        if (got.delay_secs.value - d).abs() > 0.001 {
            failures.push(format!("{} delay {:.2} ms, truth {} ms", j.name, got.delay_secs.value * 1e3, d * 1e3));
        }
        for (what, g, t) in [("kp", got.kp.value, kp), ("kd", got.kd.value, kd), ("armature", got.armature.value, a)] {
            if (g / t - 1.0).abs() > 0.10 {
                failures.push(format!("{} {what} {g:.4}, truth {t}", j.name));
            }
        }
    }
    let (mut before, mut after) = (0.0, 0.0);
    for r in &report.held_out {
        eprintln!(
            "{robot} {} held-out RMS position error: before {:.5} rad, after {:.5} rad",
            r.joint, r.before_rms, r.after_rms
        );
        before += r.before_rms.powi(2);
        after += r.after_rms.powi(2);
        if r.after_rms > 0.3 * r.before_rms {
            failures.push(format!("{} held-out error {:.5} after vs {:.5} before", r.joint, r.after_rms, r.before_rms));
        }
    }
    assert_eq!(report.held_out.len(), joints.len());
    assert!(after.sqrt() <= 0.3 * before.sqrt(), "{robot}: {} vs {}", after.sqrt(), before.sqrt());
    assert!(failures.is_empty(), "{robot}:\n{}", failures.join("\n"));

    // Written back: the two blocks, every other byte as it was; read back by the converter.
    let new = rewrite_drives(&urdf_path, &urdf, &report.joints).unwrap();
    let start = new.find("  <!-- twin actuator").expect("actuator block");
    let end = new.rfind("</robot>").unwrap();
    assert_eq!(format!("{}{}", &new[..start], &new[end..]), urdf, "only the blocks are added");
    let doc = roxmltree::Document::parse(&new).unwrap();
    let models = twin_core::convert::actuator::read_block(&urdf_path, &doc).unwrap();
    let friction = sysid::extension::read_block(&urdf_path, &new).unwrap();
    for (j, got) in joints.iter().zip(&report.joints) {
        let m = models.iter().find(|m| m.joint == j.name).unwrap();
        assert!((m.delay_secs - got.delay_secs.value).abs() < 1e-9 && m.kp.is_some(), "{m:?}");
        let f = friction.iter().find(|f| f.name == j.name).unwrap();
        assert!((f.armature / got.armature.value - 1.0).abs() < 1e-6 && f.viscous == 0.3, "{f:?}");
    }
}

#[test]
fn seven_dof_arm_drives_identified_from_an_independent_mujoco_log() {
    identify_and_check("arm7", &arm7());
}

#[test]
fn humanoid_leg_drives_identified_from_an_independent_mujoco_log() {
    identify_and_check("leg6", &leg6());
}
