//! Every legged robot of example-robot-data 6.0.0 and icub-models 3.2.0 (PyPI), converted with
//! no option, stands under `twin check`'s physics step ([`twin_core::check::physics`]: 5 s of
//! PD hold of the home pose; base tilt under 0.25 rad, height drift under 5 cm, penetration under
//! 1 cm). The home pose is the SRDF's named standing or home pose where the package ships one
//! (Unitree Go1, Go2, A1 and B1 from "standing"), else the zero pose clamped into the joint
//! ranges (Laikago: its package ships no SRDF; the humanoids, whose SRDFs name "half_sitting",
//! not a default: see `twin_convert::srdf`). Prints the table (`-- --nocapture`).
//!
//! Robots that do not stand are listed with why in [`FALLS_KNOWN`]; the test fails when one of
//! them stands (remove it there) or when any other falls.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use twin_core::check::{CheckOptions, physics};
use twin_core::convert::{ConvertOptions, convert_urdf};
use twin_core::mj::Model;

use crate::example_robot_data::{example_robot_data, icub_models};

/// example-robot-data's legged robots (floating base, legs with collision geometry), with the
/// SRDF pose their home pose must come from (`None`: zero clamped into the ranges).
const EXAMPLE_ROBOT_DATA: &[(&str, Option<&str>)] = &[
    ("a1_description/urdf/a1.urdf", Some("standing")),
    ("anymal_b_simple_description/robots/anymal.urdf", Some("standing")),
    ("anymal_b_simple_description/robots/anymal-kinova.urdf", Some("standing_with_arm_up")),
    ("anymal_c_simple_description/urdf/anymal.urdf", Some("standing")),
    ("b1_description/urdf/b1.urdf", Some("standing")),
    ("b1_description/urdf/b1-z1.urdf", Some("standing_with_arm_up")),
    ("bolt_description/robots/bolt.urdf", Some("standing")),
    ("centauro_description/urdf/centauro.urdf", Some("homing_nominal")),
    ("g1_description/urdf/g1_29dof_rev_1_0.urdf", None),
    ("g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf", None),
    ("go1_description/urdf/go1.urdf", Some("standing")),
    ("go2_description/urdf/go2.urdf", Some("standing")),
    ("hyq_description/robots/hyq_no_sensors.urdf", Some("standing")),
    ("icub_description/robots/icub.urdf", None),
    ("icub_description/robots/icub_reduced.urdf", None),
    ("laikago_description/urdf/laikago.urdf", None),
    ("quadruped_description/urdf/quadruped.urdf", None),
    ("romeo_description/urdf/romeo.urdf", None),
    ("romeo_description/urdf/romeo_laas_small.urdf", None),
    ("romeo_description/urdf/romeo_small.urdf", None),
    ("simple_humanoid_description/urdf/simple_humanoid.urdf", None),
    ("solo_description/robots/solo.urdf", Some("standing")),
    ("solo_description/robots/solo12.urdf", Some("standing")),
    ("talos_data/robots/talos_full_v2.urdf", None),
    ("talos_data/robots/talos_full_v2_box.urdf", None),
    ("talos_data/robots/talos_reduced.urdf", None),
    ("talos_data/robots/talos_reduced_box.urdf", None),
    ("talos_data/robots/talos_reduced_corrected.urdf", None),
];

/// example-robot-data's legged robots without any `<collision>`: nothing of them can touch the
/// floor, so no hold can stand them (checked: the URDF has no collision element).
const NO_COLLISION: &[&str] = &[
    "alexander_description/urdf/alexander_v1.lowerBodyOnly.urdf",
    "human_description/robots/human.urdf",
    "simple_humanoid_description/urdf/simple_humanoid_classical.urdf",
];

/// icub-models' full-body iCubs (`iCub/robots/NAME/model.urdf`); no SRDF: zero pose.
const ICUB_MODELS: &[&str] = &[
    "iCubDarmstadt01",
    "iCubErzelli02",
    "iCubGazeboV2_5",
    "iCubGazeboV2_5_KIT_007",
    "iCubGazeboV2_6",
    "iCubGazeboV2_7",
    "iCubGenova01",
    "iCubGenova02",
    "iCubGenova03",
    "iCubGenova04",
    "iCubGenova11",
    "iCubLisboa01",
    "iCubNancy01",
    "iCubWaterloo01",
];

/// Robots that do not stand under the check's hold, with what was measured and why.
const FALLS_KNOWN: &[(&str, &str)] = &[
    ("bolt_description/robots/bolt.urdf", "point feet: no support polygon for a PD hold to balance on"),
    ("romeo_description/urdf/romeo_laas_small.urdf", "feet slide 0.10 m at its zero pose (no SRDF for this variant)"),
    // Romeo's zero pose slides 5.3 cm (tilt 0.07 rad, drift 2 mm); from its SRDF's half_sitting
    // (`--pose half_sitting`, not a default: see twin_convert::srdf) it stands: tilt 0.06 rad,
    // drift 7 mm, slide under 5 cm.
    ("romeo_description/urdf/romeo.urdf", "feet slide 5.3 cm at its zero pose; stands from --pose half_sitting"),
    ("romeo_description/urdf/romeo_small.urdf", "feet slide 5.3 cm at its zero pose; stands from --pose half_sitting"),
    (
        "simple_humanoid_description/urdf/simple_humanoid.urdf",
        "stands (tilt 0.000 rad, drift 0.2 mm) but a joint rings under the check's servo gains at its zero pose (RMS 0.071 → 0.212 rad/s); not at half_sitting",
    ),
    // These four are one model (same numbers): the robot stands (tilt 0.016 rad, drift 1.1 mm,
    // penetration 0.3 mm) but a joint under the check's servo gains rings ever more (joint speed
    // RMS 0.047 → 0.186 rad/s): the check's gains, not the stance; not investigated.
    ("icub-models/iCubErzelli02", "stands, but a joint rings under the check's servo gains"),
    ("icub-models/iCubGenova04", "stands, but a joint rings under the check's servo gains"),
    ("icub-models/iCubGenova11", "stands, but a joint rings under the check's servo gains"),
    ("icub-models/iCubWaterloo01", "stands, but a joint rings under the check's servo gains"),
    ("icub-models/iCubLisboa01", "diverges (NaN) under the check's servo gains; not investigated"),
];

struct Row {
    robot: String,
    home: String,
    tilt_rad: f64,
    drift_m: f64,
    penetration_m: f64,
    passed: bool,
    cause: String,
}

fn check_one(urdf: &Path, label: &str, package_paths: &[PathBuf]) -> Row {
    let opts = ConvertOptions { package_paths: package_paths.to_vec(), ..ConvertOptions::default() };
    let c = convert_urdf(urdf, &opts).unwrap_or_else(|e| panic!("{label}: conversion failed: {e}"));
    let model = Model::from_xml_str(&c.mjcf).unwrap_or_else(|e| panic!("{label}: does not load: {e}"));
    let report = physics(&model, &CheckOptions::default()).unwrap_or_else(|e| panic!("{label}: {e}"));
    let metric = |name: &str| report.metrics.iter().find(|m| m.name == name).map_or(f64::NAN, |m| m.value);
    Row {
        robot: label.to_string(),
        home: c.meta.home_pose.clone(),
        tilt_rad: metric("base tilt"),
        drift_m: metric("base height drift"),
        penetration_m: metric("deepest penetration"),
        passed: report.passed,
        cause: report.cause.clone().unwrap_or_default(),
    }
}

#[test]
fn every_legged_robot_of_example_robot_data_and_icub_models_stands_under_twin_check() {
    let erd = example_robot_data();
    let icub = icub_models();
    for rel in NO_COLLISION {
        let text = std::fs::read_to_string(erd.join(rel)).unwrap();
        assert!(!text.contains("<collision"), "{rel} has collision geometry now: list it in EXAMPLE_ROBOT_DATA");
    }
    let mut jobs: Vec<(PathBuf, String, Vec<PathBuf>)> =
        EXAMPLE_ROBOT_DATA.iter().map(|(rel, _)| (erd.join(rel), rel.to_string(), Vec::new())).collect();
    for name in ICUB_MODELS {
        jobs.push((
            icub.join("iCub/robots").join(name).join("model.urdf"),
            format!("icub-models/{name}"),
            vec![icub.clone()],
        ));
    }
    let rows = Mutex::new(Vec::new());
    let next = Mutex::new(jobs.into_iter());
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get()).min(8);
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                loop {
                    let job = next.lock().unwrap().next();
                    let Some((path, label, packages)) = job else { break };
                    let row = check_one(&path, &label, &packages);
                    rows.lock().unwrap().push(row);
                }
            });
        }
    });
    let mut rows = rows.into_inner().unwrap();
    rows.sort_by(|a, b| a.robot.cmp(&b.robot));
    println!("| robot | stands | base tilt, rad | height drift, mm | penetration, mm | home pose |");
    println!("|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {} | {:.4} | {:.1} | {:.2} | {} |",
            r.robot,
            if r.passed { "yes".to_string() } else { format!("no: {}", r.cause) },
            r.tilt_rad,
            r.drift_m * 1e3,
            r.penetration_m * 1e3,
            r.home.split(" of ").next().unwrap_or_default()
        );
    }
    let mut failures = Vec::new();
    for r in &rows {
        let known = FALLS_KNOWN.iter().find(|(k, _)| *k == r.robot);
        match (r.passed, known) {
            (true, Some(_)) => failures.push(format!("{} stands now: remove it from FALLS_KNOWN", r.robot)),
            (false, None) => failures.push(format!(
                "{} does not stand: {} (tilt {:.3} rad, drift {:.4} m, penetration {:.4} m)",
                r.robot, r.cause, r.tilt_rad, r.drift_m, r.penetration_m
            )),
            _ => {}
        }
        if let Some((_, pose)) = EXAMPLE_ROBOT_DATA.iter().find(|(rel, _)| *rel == r.robot) {
            let expected = match pose {
                Some(p) => format!("SRDF pose \"{p}\""),
                None => "zero pose clamped".to_string(),
            };
            if !r.home.starts_with(&expected) {
                failures.push(format!("{}: home pose is {}, expected {expected}", r.robot, r.home));
            }
        } else if !r.home.starts_with("zero pose clamped") {
            failures.push(format!("{}: home pose is {}, expected the zero pose clamped", r.robot, r.home));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
