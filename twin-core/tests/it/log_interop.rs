//! Round trips with independent readers and writers: what twin writes is decoded by the Python
//! `mcap` + `mcap-ros2-support` packages and opened by `rosbags` with the same field values, and
//! bags written by `rosbags` (ROS 2 folder layout) are read by twin with the same values.
//!
//! Python is the tests' venv (`test_python.rs`, from `.ci/requirements.txt`); without it the tests
//! fail.

use serde_json::Value as Json;
use std::path::Path;
use twin_core::log::*;

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/log_interop.py");

/// Runs the helper script with the tests' Python.
fn python(args: &[&str]) -> Json {
    let args: Vec<&std::ffi::OsStr> = args.iter().map(std::ffi::OsStr::new).collect();
    crate::test_python::script_json(SCRIPT, &args)
}

fn humanoid_joint_names() -> Vec<String> {
    let urdf = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap();
    let doc = roxmltree::Document::parse(&urdf).unwrap();
    doc.descendants()
        .filter(|n| n.has_tag_name("joint") && n.attribute("type") == Some("revolute"))
        .map(|n| n.attribute("name").unwrap().to_string())
        .collect()
}

fn nums(v: &Json) -> Vec<f64> {
    v.as_array().unwrap_or_else(|| panic!("not an array: {v}")).iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect()
}

fn stamp(v: &Json) -> i64 {
    v["header"]["stamp"]["sec"].as_i64().unwrap() * 1_000_000_000 + v["header"]["stamp"]["nanosec"].as_i64().unwrap()
}

fn xyz(v: &Json) -> [f64; 3] {
    [v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap(), v["z"].as_f64().unwrap()]
}

fn xyzw(v: &Json) -> [f64; 4] {
    [v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap(), v["z"].as_f64().unwrap(), v["w"].as_f64().unwrap()]
}

struct Written {
    joint_states: Vec<JointState>,
    imus: Vec<Imu>,
    odoms: Vec<Odometry>,
    tfs: Vec<TfMessage>,
    wrenches: Vec<WrenchStamped>,
    cmds: Vec<Float64MultiArray>,
}

fn write_all_types(path: &Path) -> Written {
    let names = humanoid_joint_names();
    assert_eq!(names.len(), 23);
    let mut w = LogWriter::create(path, &WriterOptions::default()).unwrap();
    let t_js = w.add_topic::<JointState>("/joint_states").unwrap();
    let t_imu = w.add_topic::<Imu>("/humanoid/imu/data").unwrap();
    let t_odom = w.add_topic::<Odometry>("/odom").unwrap();
    let t_tf = w.add_topic::<TfMessage>("/tf").unwrap();
    let t_wr = w.add_topic::<WrenchStamped>("/left_foot/wrench").unwrap();
    let t_cmd = w.add_topic::<Float64MultiArray>("/humanoid/joint_commands").unwrap();
    let mut out =
        Written { joint_states: vec![], imus: vec![], odoms: vec![], tfs: vec![], wrenches: vec![], cmds: vec![] };
    for i in 0..40 {
        let t = 5_000_000_000i64 + i * 2_000_000;
        let x = i as f64 * 0.01;
        let header = |frame: &str| Header { stamp_nanos: t, frame_id: frame.into() };
        let js = JointState {
            header: header(""),
            name: names.clone(),
            position: (0..23).map(|k| (x + k as f64).sin()).collect(),
            velocity: (0..23).map(|k| (x * k as f64).cos()).collect(),
            effort: if i % 3 == 0 { vec![] } else { (0..23).map(|k| k as f64 - x).collect() },
        };
        let imu = Imu {
            header: header("imu_link"),
            orientation_xyzw: [0.0, 0.0, x.sin(), x.cos()],
            orientation_covariance: [1e-4; 9],
            angular_velocity: [x, -x, 0.5],
            angular_velocity_covariance: [0.0; 9],
            linear_acceleration: [0.1, 0.2, 9.81 - x],
            linear_acceleration_covariance: [2e-3; 9],
        };
        let mut odom = Odometry {
            header: header("odom"),
            child_frame_id: "pelvis".into(),
            position: [x, 0.0, 0.71],
            linear_velocity: [0.5, 0.0, -x],
            ..Default::default()
        };
        odom.pose_covariance[7] = x;
        let tf = TfMessage {
            transforms: vec![
                TransformStamped {
                    header: header("odom"),
                    child_frame_id: "pelvis".into(),
                    translation: [x, 0.0, 0.71],
                    rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
                },
                TransformStamped {
                    header: header("pelvis"),
                    child_frame_id: "torso".into(),
                    translation: [0.0, 0.0, 0.2],
                    rotation_xyzw: [0.0, x.sin(), 0.0, x.cos()],
                },
            ],
        };
        let wr = WrenchStamped { header: header("left_foot"), force: [1.0, -2.0, 170.0 + x], torque: [0.1, 0.2, x] };
        let cmd = Float64MultiArray {
            dim: vec![MultiArrayDimension { label: "joints".into(), size: 23, stride: 23 }],
            data_offset: 0,
            data: (0..23).map(|k| k as f64 * x).collect(),
        };
        let lt = t as u64;
        w.write(t_js, lt, &js).unwrap();
        w.write(t_imu, lt, &imu).unwrap();
        w.write(t_odom, lt, &odom).unwrap();
        w.write(t_tf, lt, &tf).unwrap();
        w.write(t_wr, lt, &wr).unwrap();
        w.write(t_cmd, lt, &cmd).unwrap();
        out.joint_states.push(js);
        out.imus.push(imu);
        out.odoms.push(odom);
        out.tfs.push(tf);
        out.wrenches.push(wr);
        out.cmds.push(cmd);
    }
    w.finish().unwrap();
    out
}

/// Checks one decoder's messages against what was written.
fn check_decoded(reader: &str, msgs: &[Json], written: &Written) {
    let of = |topic: &str| -> Vec<&Json> { msgs.iter().filter(|m| m["topic"] == topic).map(|m| &m["msg"]).collect() };
    let js = of("/joint_states");
    assert_eq!(js.len(), written.joint_states.len(), "{reader}");
    for (m, w) in js.iter().zip(&written.joint_states) {
        assert_eq!(stamp(m), w.header.stamp_nanos, "{reader}");
        let names: Vec<&str> = m["name"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
        assert_eq!(names, w.name, "{reader}");
        assert_eq!(nums(&m["position"]), w.position, "{reader}");
        assert_eq!(nums(&m["velocity"]), w.velocity, "{reader}");
        assert_eq!(nums(&m["effort"]), w.effort, "{reader}");
    }
    let imu = of("/humanoid/imu/data");
    assert_eq!(imu.len(), written.imus.len(), "{reader}");
    for (m, w) in imu.iter().zip(&written.imus) {
        assert_eq!(m["header"]["frame_id"], "imu_link");
        assert_eq!(xyzw(&m["orientation"]), w.orientation_xyzw, "{reader}");
        assert_eq!(nums(&m["orientation_covariance"]), w.orientation_covariance);
        assert_eq!(xyz(&m["angular_velocity"]), w.angular_velocity, "{reader}");
        assert_eq!(xyz(&m["linear_acceleration"]), w.linear_acceleration);
        assert_eq!(nums(&m["linear_acceleration_covariance"]), w.linear_acceleration_covariance);
    }
    let odom = of("/odom");
    assert_eq!(odom.len(), written.odoms.len(), "{reader}");
    for (m, w) in odom.iter().zip(&written.odoms) {
        assert_eq!(m["child_frame_id"], "pelvis");
        assert_eq!(xyz(&m["pose"]["pose"]["position"]), w.position, "{reader}");
        assert_eq!(xyzw(&m["pose"]["pose"]["orientation"]), w.orientation_xyzw);
        assert_eq!(nums(&m["pose"]["covariance"]), w.pose_covariance);
        assert_eq!(xyz(&m["twist"]["twist"]["linear"]), w.linear_velocity);
    }
    let tf = of("/tf");
    assert_eq!(tf.len(), written.tfs.len(), "{reader}");
    for (m, w) in tf.iter().zip(&written.tfs) {
        let ts = m["transforms"].as_array().unwrap();
        assert_eq!(ts.len(), 2);
        for (t, wt) in ts.iter().zip(&w.transforms) {
            assert_eq!(t["child_frame_id"], wt.child_frame_id.as_str());
            assert_eq!(t["header"]["frame_id"], wt.header.frame_id.as_str());
            assert_eq!(xyz(&t["transform"]["translation"]), wt.translation);
            assert_eq!(xyzw(&t["transform"]["rotation"]), wt.rotation_xyzw);
        }
    }
    let wr = of("/left_foot/wrench");
    assert_eq!(wr.len(), written.wrenches.len(), "{reader}");
    for (m, w) in wr.iter().zip(&written.wrenches) {
        assert_eq!(xyz(&m["wrench"]["force"]), w.force, "{reader}");
        assert_eq!(xyz(&m["wrench"]["torque"]), w.torque, "{reader}");
    }
    let cmd = of("/humanoid/joint_commands");
    assert_eq!(cmd.len(), written.cmds.len(), "{reader}");
    for (m, w) in cmd.iter().zip(&written.cmds) {
        assert_eq!(nums(&m["data"]), w.data, "{reader}");
        assert_eq!(m["layout"]["dim"][0]["label"], "joints");
        assert_eq!(m["layout"]["dim"][0]["size"], 23);
    }
}

#[test]
fn twin_written_log_decodes_identically_in_mcap_ros2_support_and_rosbags() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let written = write_all_types(&path);
    let out = python(&["decode", path.to_str().unwrap()]);
    assert_eq!(out["profile"], "ros2");
    assert_eq!(out["library"], twin_core::log::writer::LIBRARY_IDENTIFIER);
    for reader in ["mcap_ros2", "rosbags"] {
        let msgs = out[reader].as_array().unwrap();
        assert_eq!(msgs.len(), 240, "{reader}");
        check_decoded(reader, msgs, &written);
    }
    // And twin's own reader agrees.
    let log = Log::open(&path, ReadOptions::default()).unwrap();
    let (odoms, _) = log.read_typed::<Odometry>("/odom").unwrap();
    assert_eq!(odoms.into_iter().map(|(_, m)| m).collect::<Vec<_>>(), written.odoms);
    let (tfs, _) = log.read_typed::<TfMessage>("/tf").unwrap();
    assert_eq!(tfs.into_iter().map(|(_, m)| m).collect::<Vec<_>>(), written.tfs);
}

#[test]
fn rosbags_written_bag_reads_identically_in_twin() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("bag");
    let expected = python(&["write", bag.to_str().unwrap()]);
    let log = Log::open(&bag, ReadOptions::default()).unwrap();
    let info = log.info().unwrap();
    assert_eq!(info.message_count, 200);
    assert!(info.read.warnings().is_empty(), "{:?}", info.read.warnings());

    let names: Vec<String> =
        expected["names"].as_array().unwrap().iter().map(|n| n.as_str().unwrap().to_string()).collect();
    let msgs = expected["messages"].as_array().unwrap();
    let of = |topic: &str| -> Vec<&Json> { msgs.iter().filter(|m| m["topic"] == topic).collect() };

    let series = log.joint_states("/joint_states").unwrap();
    assert_eq!(series.names().collect::<Vec<_>>(), names);
    let js = of("/joint_states");
    for (k, name) in names.iter().enumerate() {
        let j = series.joint(name).unwrap();
        assert_eq!(j.len(), js.len());
        for (i, m) in js.iter().enumerate() {
            assert_eq!(j.time_nanos[i], m["t"].as_i64().unwrap());
            assert_eq!(j.position[i], nums(&m["position"])[k]);
            match nums(&m["velocity"]).get(k) {
                Some(&v) => assert_eq!(j.velocity[i], v),
                None => assert!(j.velocity[i].is_nan()),
            }
            assert_eq!(j.effort[i], nums(&m["effort"])[k]);
        }
    }
    assert_eq!(series.report.empty_velocity, 25);

    let (imus, _) = log.read_typed::<Imu>("/imu").unwrap();
    let exp = of("/imu");
    assert_eq!(imus.len(), exp.len());
    for ((t, imu), e) in imus.iter().zip(&exp) {
        assert_eq!(*t, e["t"].as_u64().unwrap());
        assert_eq!(imu.orientation_xyzw[2], e["z"].as_f64().unwrap());
        assert_eq!(imu.linear_acceleration.to_vec(), nums(&e["acc"]));
        assert_eq!(imu.angular_velocity[2], e["wz"].as_f64().unwrap());
        assert_eq!(imu.angular_velocity_covariance, [0.5; 9]);
        assert_eq!(imu.header.frame_id, "imu_link");
    }
    let (wr, _) = log.read_typed::<WrenchStamped>("/ft").unwrap();
    let exp = of("/ft");
    assert_eq!(wr.len(), exp.len());
    for ((_, w), e) in wr.iter().zip(&exp) {
        assert_eq!(w.force[2], e["fz"].as_f64().unwrap());
        assert_eq!(w.torque, [-1.0, 0.0, 0.5]);
    }
    let (cmd, _) = log.read_typed::<Float64MultiArray>("/cmd").unwrap();
    let exp = of("/cmd");
    assert_eq!(cmd.len(), exp.len());
    for ((_, c), e) in cmd.iter().zip(&exp) {
        assert_eq!(c.data, nums(&e["data"]));
        assert_eq!(c.dim[0].label, "joints");
        assert_eq!((c.dim[0].size, c.dim[0].stride), (3, 3));
    }
    // The generic decoder reads rosbags' schema text as well.
    let mut n = 0;
    log.for_each_value("/imu", |_, _, v| {
        assert_eq!(v.get("header.frame_id").and_then(Value::as_str), Some("imu_link"));
        n += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(n, 50);
}
