//! `twin sim` with ray-cast sensors from a URDF's Gazebo tags: a depth camera and a LiDAR
//! publish at their rates; the depth image decodes with the independent `mcap` +
//! `mcap-ros2-support` readers as `32FC1` of the right size and values, the LiDAR's ranges
//! match the analytic ones, and the `.rrd` passes `rerun rrd verify`.
//!
//! Python comes from `TWIN_PYTHON` (CI: `$HOME/.cache/twin/ci-venv/bin/python`), `rerun` from
//! the same `bin/` folder. These cross-checks FAIL when either is missing.

use super::common::{repo_root, run};
use serde_json::Value as Json;
use std::path::Path;
use std::process::Command;
use twin_core::log::{LaserScan, Log, ReadOptions, TfMessage};

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/sense_check.py");

/// The shipped arm, bolted to the world, with a depth camera 1.5 m above the floor looking straight down (at
/// x = 2 m, clear of the arm), a wall whose face is at x = 4 m, and a LiDAR at x = 3 m facing
/// it at mid-height.
fn sensor_arm() -> String {
    let arm = std::fs::read_to_string(repo_root().join("models/arm6.urdf")).unwrap();
    let inertial = r#"<inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>"#;
    let extra = format!(
        r#"
  <joint name="camera_mount" type="fixed"><origin xyz="2 0 1.5" rpy="0 1.5707963267948966 0"/>
    <parent link="base_link"/><child link="camera_link"/></joint>
  <link name="camera_link">{inertial}</link>
  <gazebo reference="camera_link"><sensor name="depth_cam" type="depth"><update_rate>10</update_rate>
    <camera><horizontal_fov>1.0</horizontal_fov><image><width>64</width><height>48</height></image>
    <clip><near>0.1</near><far>5</far></clip></camera></sensor></gazebo>
  <joint name="wall_mount" type="fixed"><origin xyz="4.05 0 1"/><parent link="base_link"/><child link="wall"/></joint>
  <link name="wall">{inertial}<visual><geometry><box size="0.1 6 2"/></geometry></visual>
    <collision><geometry><box size="0.1 6 2"/></geometry></collision></link>
  <joint name="lidar_mount" type="fixed"><origin xyz="3 0 1"/><parent link="base_link"/><child link="lidar_link"/></joint>
  <link name="lidar_link">{inertial}</link>
  <gazebo reference="lidar_link"><sensor name="front_lidar" type="ray"><update_rate>20</update_rate>
    <ray><scan><horizontal><samples>101</samples><min_angle>-0.5</min_angle><max_angle>0.5</max_angle></horizontal></scan>
    <range><min>0.1</min><max>10</max></range></ray></sensor></gazebo>
</robot>"#
    );
    // Bolted to the world: the sensors must not move.
    let bolt = r#"<robot name="arm6">
  <link name="world"/>
  <joint name="world_bolt" type="fixed"><parent link="world"/><child link="base_link"/></joint>"#;
    arm.replace(r#"<robot name="arm6">"#, bolt).replace("</robot>", &extra)
}

#[test]
fn depth_camera_and_lidar_are_recorded_and_decode_elsewhere() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = super::common::write(dir.path(), "sensor_arm.urdf", &sensor_arm());
    let (mcap, rrd) = (dir.path().join("run.mcap"), dir.path().join("run.rrd"));
    let args = [
        "sim",
        urdf.to_str().unwrap(),
        "--duration",
        "1",
        "--controller",
        "hold",
        "--record",
        mcap.to_str().unwrap(),
        "--rerun",
        rrd.to_str().unwrap(),
    ];
    let (ok, stdout, stderr) = run(&args);
    assert!(ok, "twin {args:?} failed:\n{stderr}\n{stdout}");

    // The LiDAR: 20 Hz for 1 s, each beam at 1 / cos(angle) from the wall, to 1 mm.
    let log = Log::open(&mcap, ReadOptions { strict: true }).unwrap();
    let (scans, report) = log.read_typed::<LaserScan>("/arm6/front_lidar/scan").unwrap();
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    assert_eq!(scans.len(), 20);
    for (k, (t, scan)) in scans.iter().enumerate() {
        assert_eq!(*t, k as u64 * 50_000_000, "scan {k} log time");
        assert_eq!(scan.header.stamp_nanos, *t as i64);
        assert_eq!(scan.ranges.len(), 101);
        for (i, r) in scan.ranges.iter().enumerate() {
            let a = -0.5 + i as f64 * 0.01;
            assert!((f64::from(*r) - 1.0 / a.cos()).abs() < 1e-3, "scan {k} beam {i}: {r} m");
        }
    }

    // The sensor frames are placed on their links once, on /tf_static: the optical frame
    // looks along its link's view axis (Gazebo: the link's x), the LiDAR frame is its link's.
    let (statics, _) = log.read_typed::<TfMessage>("/tf_static").unwrap();
    let transforms = &statics[0].1.transforms;
    let find = |child: &str| transforms.iter().find(|t| t.child_frame_id == child).unwrap_or_else(|| panic!("{child}"));
    // v rotated by the unit quaternion x y z w: v + 2w (u × v) + 2 u × (u × v).
    let rotate = |q: [f64; 4], v: [f64; 3]| -> [f64; 3] {
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
        };
        let u = [q[0], q[1], q[2]];
        let (t, tt) = (cross(u, v), cross(u, cross(u, v)));
        [0, 1, 2].map(|i| v[i] + 2.0 * q[3] * t[i] + 2.0 * tt[i])
    };
    let dist =
        |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    let optical = find("depth_cam_optical_frame");
    let (view, down) = (rotate(optical.rotation_xyzw, [0.0, 0.0, 1.0]), rotate(optical.rotation_xyzw, [0.0, 1.0, 0.0]));
    match optical.header.frame_id.as_str() {
        // The camera link fused into the bolted base (optical z down), or kept as a body
        // (optical z along the link's x, Gazebo's view axis).
        "base_link" => {
            assert!(dist(optical.translation, [2.0, 0.0, 1.5]) < 1e-9, "{:?}", optical.translation);
            assert!(dist(view, [0.0, 0.0, -1.0]) < 1e-9, "{view:?}");
        }
        "camera_link" => {
            assert!(dist(optical.translation, [0.0; 3]) < 1e-9, "{:?}", optical.translation);
            assert!(dist(view, [1.0, 0.0, 0.0]) < 1e-9, "{view:?}");
        }
        other => panic!("optical frame on {other}"),
    }
    assert!((down[0] * view[0] + down[1] * view[1] + down[2] * view[2]).abs() < 1e-9);
    let lidar = find("front_lidar");
    assert!(["base_link", "lidar_link"].contains(&lidar.header.frame_id.as_str()), "{}", lidar.header.frame_id);

    // The depth image, decoded by mcap-ros2-support.
    let exe = std::env::var("TWIN_PYTHON").unwrap_or_else(|_| "python3".into());
    let prefix = "/arm6/depth_cam";
    let out = Command::new(&exe)
        .arg(SCRIPT)
        .arg(&mcap)
        .args([format!("{prefix}/depth/image_raw"), format!("{prefix}/depth/camera_info"), format!("{prefix}/points")])
        .output()
        .unwrap_or_else(|e| panic!("cannot run {exe} (set TWIN_PYTHON to the CI venv's python): {e}"));
    assert!(
        out.status.success(),
        "{exe} {SCRIPT} failed (pip install -r .ci/requirements.txt):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: Json = serde_json::from_slice(&out.stdout).unwrap();
    let images = json["images"].as_array().unwrap();
    assert_eq!(images.len(), 10, "10 Hz for 1 s");
    for (k, im) in images.iter().enumerate() {
        assert_eq!(im["schema"], "sensor_msgs/msg/Image");
        assert_eq!(im["encoding"], "32FC1");
        assert_eq!((im["width"].as_u64(), im["height"].as_u64()), (Some(64), Some(48)));
        assert_eq!((im["step"].as_u64(), im["bytes"].as_u64()), (Some(256), Some(64 * 48 * 4)));
        assert_eq!(im["log_time"].as_u64(), Some(k as u64 * 100_000_000));
        assert_eq!(im["stamp"], im["log_time"]);
        assert_eq!(im["frame_id"], "depth_cam_optical_frame");
        // The floor, 1.5 m below a camera looking straight down: every pixel at depth 1.5 m
        // along the optical axis (the corners' rays are longer).
        assert_eq!(im["finite"].as_u64(), Some(64 * 48));
        for key in ["min", "max"] {
            assert!((im[key].as_f64().unwrap() - 1.5).abs() < 1e-3, "image {k}: {key} {}", im[key]);
        }
    }
    let info = &json["infos"][0];
    assert_eq!(json["infos"].as_array().unwrap().len(), 10);
    let f = 32.0 / 0.5f64.tan();
    let k: Vec<f64> = info["k"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((k[0] - f).abs() < 1e-6 && (k[4] - f).abs() < 1e-6 && k[2] == 31.5 && k[5] == 23.5, "{k:?}");
    assert_eq!(info["distortion_model"], "plumb_bob");
    let cloud = &json["clouds"][0];
    assert_eq!((cloud["width"].as_u64(), cloud["height"].as_u64()), (Some(64), Some(48)));
    assert_eq!((cloud["point_step"].as_u64(), cloud["row_step"].as_u64()), (Some(12), Some(768)));
    assert_eq!(cloud["fields"], serde_json::json!([["x", 0, 7, 1], ["y", 4, 7, 1], ["z", 8, 7, 1]]));

    // Sensors cast on other threads while the simulation goes on: a second run writes the
    // same file, byte for byte.
    let again = dir.path().join("again.mcap");
    let mut args2 = args[..7].to_vec();
    args2.push(again.to_str().unwrap());
    let (ok, _, stderr) = run(&args2);
    assert!(ok, "{stderr}");
    assert!(std::fs::read(&mcap).unwrap() == std::fs::read(&again).unwrap(), "two runs wrote different files");

    // The rerun recording (with the depth image and point clouds) verifies.
    let rerun = Path::new(&exe).parent().map(|d| d.join("rerun")).filter(|p| p.is_file());
    let rerun = rerun.unwrap_or_else(|| panic!("no `rerun` next to {exe} (pip install rerun-sdk==0.36.3)"));
    let out = Command::new(&rerun).args(["rrd", "verify"]).arg(&rrd).output().expect("rerun runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && text.contains("verified without error"), "rerun rrd verify failed:\n{text}");
}
