//! Gait metrics from the robot's own frames ([`twin_controllers::walk::GaitMetrics`]): the same
//! numbers whatever way the robot's base frame is turned in its file, and the same as an
//! independent reading of the recorded `/odom` (mcap-ros2-support in the tests' Python).

use super::*;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use std::sync::Arc;
use twin_controllers::walk::GaitMetrics;
use twin_core::mj::Data;
use twin_core::sim::{RecordOptions, Recording};

/// Every step's time and `qpos`.
struct Trajectory(Vec<(f64, Vec<f64>)>);

impl Observer for Trajectory {
    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        self.0.push((step.data.time_secs(), step.data.qpos().to_vec()));
        Ok(Flow::Continue)
    }
}

/// The URDF `text` with its root link's frame turned half a turn about its z axis: the root's
/// inertial, visuals and collisions and the origins of the joints it is parent of are turned
/// back by as much, so the robot is the same body, its base frame facing backwards.
fn root_turned_half_about_z(text: &str) -> String {
    let doc = roxmltree::Document::parse(text).unwrap();
    let robot = doc.root_element();
    let children: Vec<&str> = robot
        .children()
        .filter(|n| n.has_tag_name("joint"))
        .filter_map(|j| j.children().find(|c| c.has_tag_name("child")))
        .filter_map(|c| c.attribute("link"))
        .collect();
    let root = robot
        .children()
        .find(|n| n.has_tag_name("link") && !children.contains(&n.attribute("name").unwrap_or_default()))
        .unwrap();
    let root_name = root.attribute("name").unwrap();
    let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
    // (range to replace, replacement): an element's <origin>, or an insertion after its start tag.
    let mut edits: Vec<(std::ops::Range<usize>, String)> = Vec::new();
    let mut turn_origin = |owner: roxmltree::Node| {
        let origin = owner.children().find(|c| c.has_tag_name("origin"));
        let nums = |a: Option<&str>| -> Vec<f64> {
            a.map_or(vec![0.0; 3], |s| s.split_whitespace().map(|x| x.parse().unwrap()).collect())
        };
        let (xyz, rpy) =
            origin.map_or((vec![0.0; 3], vec![0.0; 3]), |o| (nums(o.attribute("xyz")), nums(o.attribute("rpy"))));
        let p = turn * Vector3::new(xyz[0], xyz[1], xyz[2]);
        let (r, pi, y) = (turn * Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2])).euler_angles();
        let new = format!("<origin xyz=\"{} {} {}\" rpy=\"{r} {pi} {y}\"/>", p.x, p.y, p.z);
        match origin {
            Some(o) => edits.push((o.range(), new)),
            None => {
                let start = owner.range().start;
                let end = start + text[start..].find('>').unwrap() + 1;
                edits.push((end..end, new));
            }
        }
    };
    for part in root
        .children()
        .filter(|n| n.has_tag_name("inertial") || n.has_tag_name("visual") || n.has_tag_name("collision"))
    {
        turn_origin(part);
    }
    for joint in robot.children().filter(|n| n.has_tag_name("joint")) {
        let parent = joint.children().find(|c| c.has_tag_name("parent")).and_then(|p| p.attribute("link"));
        if parent == Some(root_name) {
            turn_origin(joint);
        }
    }
    edits.sort_by_key(|e| std::cmp::Reverse(e.0.start));
    let mut out = text.to_string();
    for (range, new) in edits {
        out.replace_range(range, &new);
    }
    out
}

/// `qpos` of the robot as the base-turned model reads it: the free joint's orientation turned
/// half a turn about the base's own z (its position is the root link's origin, unmoved).
fn turned_qpos(q: &[f64], qpos_adr: usize) -> Vec<f64> {
    let mut out = q.to_vec();
    let b = &q[qpos_adr + 3..qpos_adr + 7];
    let rot = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(b[0], b[1], b[2], b[3]));
    let turned = rot * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI);
    out[qpos_adr + 3..qpos_adr + 7].copy_from_slice(&[turned.w, turned.i, turned.j, turned.k]);
    out
}

/// The independent reading of `/odom` (`odom_gait.py`): distance, forward distance and fall time.
fn odom_reading(mcap: &Path) -> (f64, f64, Option<f64>) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/odom_gait.py");
    let v = crate::test_python::script_json(script.to_str().unwrap(), &[mcap.as_os_str()]);
    (v["distance_m"].as_f64().unwrap(), v["forward_m"].as_f64().unwrap(), v["fall_time_secs"].as_f64())
}

/// `path` walks (derived options) for `secs` under the scenario keys `extra` (its command,
/// pushes), recorded; returns the robot, the walker's gait metrics, the trajectory and the
/// recording's odometry reading.
fn walk_recorded(
    path: &Path,
    extra: &str,
    secs: f64,
    dir: &Path,
) -> (twin_core::robot::Robot, GaitSummary, Trajectory, (f64, f64, Option<f64>)) {
    let text = format!("model = {path:?}\nduration = {secs}\n{extra}\n");
    let mut s = Scenario::parse(&scenarios().join("inline.toml"), &text).unwrap();
    let robot = s.robot(path).unwrap();
    s.fit_walk(&robot.model).unwrap();
    let mut controller = s.controller(&robot.model).unwrap();
    let mut check = s.check(&robot.model).unwrap();
    let mcap = dir.join("walk.mcap");
    let mut recording = Recording::with_sinks(
        &robot,
        &RecordOptions { mcap: Some(mcap.clone()), ..RecordOptions::default() },
        Vec::new(),
    )
    .unwrap();
    let mut trajectory = Trajectory(Vec::new());
    let options = SimOptions { duration_secs: s.duration_secs, seed: s.seed };
    let mut pushes = s.disturbances(&robot.model);
    let mut pushes: Vec<&mut dyn Disturbance> = pushes.iter_mut().map(|p| p as &mut dyn Disturbance).collect();
    sim::simulate_with(
        &robot,
        controller.as_mut(),
        &options,
        Some(&mut recording),
        &mut |_| {},
        &mut pushes,
        &mut [&mut check, &mut trajectory],
    )
    .unwrap();
    recording.finish().unwrap();
    let summary = check.metrics.summary();
    (robot, summary, trajectory, odom_reading(&mcap))
}

fn agrees_with_odom(who: &str, s: &GaitSummary, odom: (f64, f64, Option<f64>)) {
    println!(
        "{who}: metrics distance {:.4} m, forward {:.4} m, fall {:?}, steps {}; /odom {odom:?}",
        s.distance_m, s.forward_m, s.fall_time_secs, s.steps
    );
    assert!(
        (s.distance_m - odom.0).abs() <= 0.02 * odom.0.max(0.05),
        "{who}: distance {} m, /odom {} m",
        s.distance_m,
        odom.0
    );
    match (s.fall_time_secs, odom.2) {
        (None, None) => {}
        (Some(a), Some(b)) => assert!((a - b).abs() <= 0.05, "{who}: fell at {a} s, /odom at {b} s"),
        (a, b) => panic!("{who}: metrics fall {a:?}, /odom fall {b:?}"),
    }
}

/// The G1 walks 6 s at 0.25 m/s; its gait metrics equal the recorded `/odom`'s (distance within
/// 2 %, no fall in either). The same trajectory on a G1 whose base frame is turned half a turn
/// about z in its URDF (its x axis backwards) gives the same metrics: steps, distance, heading
/// change, no fall; forward and lateral, along the turned base's own axes, change sign.
#[test]
fn g1_metrics_agree_with_odom_and_hold_on_a_base_frame_turned_half_about_z() {
    let dir = tempfile::tempdir().unwrap();
    let g1 = example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf");
    let (_, s, trajectory, odom) = walk_recorded(&g1, "[walk]\nvx = 0.25", 6.0, dir.path());
    agrees_with_odom("G1", &s, odom);
    assert!(!s.fell && s.steps >= 6 && s.forward_m > 0.8, "{s:?}");

    // The base-turned G1 beside the original (its package:// meshes resolve from there).
    let text = std::fs::read_to_string(&g1).unwrap();
    let turned_file = tempfile::Builder::new().suffix(".urdf").tempfile_in(g1.parent().unwrap()).unwrap();
    std::fs::write(turned_file.path(), root_turned_half_about_z(&text)).unwrap();
    let turned = twin_core::robot::Robot::load(turned_file.path()).unwrap();
    let model = Arc::new(turned.model.try_clone().unwrap());
    let free = model.free_joint().unwrap();
    let mut metrics = GaitMetrics::for_model(&model, &Default::default(), Default::default()).unwrap();
    let mut data = Data::new(model.clone()).unwrap();
    for (t, q) in &trajectory.0 {
        data.qpos_mut().copy_from_slice(&turned_qpos(q, free.qpos_adr));
        data.set_time_secs(*t);
        data.forward().unwrap();
        metrics.update(&data);
    }
    let r = metrics.summary();
    println!("turned G1: {r:?}");
    assert_eq!((r.fell, r.steps), (s.fell, s.steps), "turned: {r:?}");
    // Forward is along the base's own forward axis (the walker's +x, the side of its +y foot on
    // the left): on the turned base the same path runs along its −x.
    for (what, a, b) in [
        ("distance", r.distance_m, s.distance_m),
        ("forward", -r.forward_m, s.forward_m),
        ("lateral", -r.lateral_m, s.lateral_m),
        ("heading", r.yaw_change_rad, s.yaw_change_rad),
    ] {
        assert!((a - b).abs() < 1e-3, "{what}: turned {a}, original {b}");
    }
}

/// Gait metrics equal to the recorded `/odom` read by another tool (distance within 2 %, fall
/// time within 0.05 s) on the shipped humanoid, Talos (its own servos) and Romeo walking 6 s, and
/// on the G1 pushed over sideways while walking (60 N·s at 2 s).
#[test]
fn gait_metrics_agree_with_odom_on_humanoid_talos_romeo_and_a_pushed_g1() {
    let dir = tempfile::tempdir().unwrap();
    for (who, path, extra, falls) in [
        ("humanoid", humanoid(), "[walk]\nvx = 0.3", false),
        ("Talos", example_robot("talos_data/robots/talos_full_v2.urdf"), "[walk]\nvx = 0.25", false),
        ("Romeo", example_robot("romeo_description/urdf/romeo.urdf"), "[walk]\nvx = 0.2", false),
        (
            "G1 pushed",
            example_robot("g1_description/urdf/g1_29dof_rev_1_0.urdf"),
            "[walk]\nvx = 0.25\n[[push]]\ntime = 2.0\nduration = 0.1\nforce = [0.0, 600.0, 0.0]",
            true,
        ),
    ] {
        let (_, s, _, odom) = walk_recorded(&path, extra, 6.0, dir.path());
        agrees_with_odom(who, &s, odom);
        assert_eq!(s.fell, falls, "{who}: {s:?}");
        assert!(s.distance_m > if falls { 0.1 } else { 0.8 }, "{who}: {s:?}");
    }
}
