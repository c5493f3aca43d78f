//! `twin sim` with ray-cast sensors from a URDF's Gazebo tags: a depth camera and a LiDAR
//! publish at their rates; the depth image decodes with the independent `mcap` +
//! `mcap-ros2-support` readers as `32FC1` of the right size and values, the LiDAR's ranges
//! match the analytic ones, and the `.rrd` passes `rerun rrd verify`.
//!
//! Python and `rerun` come from the tests' venv (`test_python.rs`, made from
//! `.ci/requirements.txt` on first use). These cross-checks FAIL when it cannot be made.

use super::common::{repo_root, run};
use serde_json::Value as Json;
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
    let exe = crate::test_python::python();
    let prefix = "/arm6/depth_cam";
    let out = Command::new(&exe)
        .arg(SCRIPT)
        .arg(&mcap)
        .args([format!("{prefix}/depth/image_raw"), format!("{prefix}/depth/camera_info"), format!("{prefix}/points")])
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", exe.display()));
    assert!(out.status.success(), "{} {SCRIPT} failed:\n{}", exe.display(), String::from_utf8_lossy(&out.stderr));
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
    let rerun = crate::test_python::python_tool("rerun", "rerun-sdk");
    let out = Command::new(&rerun).args(["rrd", "verify"]).arg(&rrd).output().expect("rerun runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success() && text.contains("verified without error"), "rerun rrd verify failed:\n{text}");
}

/// Where the ray from the origin `o` along `d` (unscaled: a point is `o + t·d`) first meets
/// the shipped cup of `worlds/table_cup.world` (a cylinder of radius 0.04 m from z = 0.62 to
/// 0.72 m about (0.33, −0.12)): its `t`.
fn cup_hit(o: [f64; 3], d: [f64; 3]) -> Option<f64> {
    let (cx, cy, r, z0, z1) = (0.33, -0.12, 0.04, 0.62, 0.72);
    let (px, py) = (o[0] - cx, o[1] - cy);
    let a = d[0] * d[0] + d[1] * d[1];
    let b = px * d[0] + py * d[1];
    let c = px * px + py * py - r * r;
    let mut best: Option<f64> = None;
    let disc = b * b - a * c;
    if a > 0.0 && disc >= 0.0 {
        let t = (-b - disc.sqrt()) / a;
        let z = o[2] + t * d[2];
        if t > 0.0 && (z0..=z1).contains(&z) {
            best = Some(t);
        }
    }
    // The top disc.
    if d[2] != 0.0 {
        let t = (z1 - o[2]) / d[2];
        let (x, y) = (px + t * d[0], py + t * d[1]);
        if t > 0.0 && x * x + y * y <= r * r && best.is_none_or(|b| t < b) {
            best = Some(t);
        }
    }
    best
}

/// Where the ray meets the table top (z = 0.62 m over x 0.15…0.95, y −0.3…0.3).
fn table_hit(o: [f64; 3], d: [f64; 3]) -> Option<(f64, [f64; 3])> {
    if d[2] >= 0.0 {
        return None;
    }
    let t = (0.62 - o[2]) / d[2];
    let p = [o[0] + t * d[0], o[1] + t * d[1], 0.62];
    ((0.15..=0.95).contains(&p[0]) && (-0.3..=0.3).contains(&p[1])).then_some((t, p))
}

/// The shipped grasp scenario, recorded as a user would, and its head camera's first depth
/// image decoded by the independent `mcap-ros2-support` reader with the camera's pose from
/// /tf and /tf_static: the cup's pixels read the cup's analytic distance (ray against the
/// cylinder of the world file) within 1 cm, and the table around and behind it its own.
#[test]
fn the_grasp_recording_shows_the_cup_and_the_table_behind_it() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("g.mcap");
    let (ok, stdout, stderr) = run(&["sim", "--scenario", "scenarios/grasp.toml", "--record", mcap.to_str().unwrap()]);
    assert!(ok, "{stdout}\n{stderr}");
    let prefix = "/humanoid/head_depth_plugin/out";
    let script = repo_root().join("tests/python/depth_frame.py");
    let exe = crate::test_python::python();
    let out = Command::new(&exe)
        .arg(&script)
        .arg(&mcap)
        .arg(format!("{prefix}/depth/image_raw"))
        .arg(format!("{prefix}/depth/camera_info"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{} failed:\n{}", script.display(), String::from_utf8_lossy(&out.stderr));
    let frame: Json = serde_json::from_slice(&out.stdout).unwrap();
    let (w, h) = (frame["width"].as_u64().unwrap() as usize, frame["height"].as_u64().unwrap() as usize);
    let k: Vec<f64> = frame["k"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let m: Vec<Vec<f64>> = frame["world_from_optical"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect())
        .collect();
    let depth: Vec<Option<f64>> = frame["depth"].as_array().unwrap().iter().map(Json::as_f64).collect();
    assert_eq!(depth.len(), w * h);
    let finite = depth.iter().flatten().count();
    assert!(finite > w * h / 2, "{finite} finite pixels of {}", w * h);
    let origin = [m[0][3], m[1][3], m[2][3]];
    // Pixel (u, v)'s ray in the world, scaled so that its optical z is 1: t is the depth.
    let ray = |u: f64, v: f64| {
        let o = [(u - k[2]) / k[0], (v - k[5]) / k[4], 1.0];
        std::array::from_fn::<f64, 3, _>(|i| m[i][0] * o[0] + m[i][1] * o[1] + m[i][2] * o[2])
    };
    let (mut cup, mut cup_worst, mut table, mut table_off, mut cup_depth, mut behind) = (0, 0.0f64, 0, 0, 0.0, 0.0);
    let mut behind_n = 0;
    for v in 1..h - 1 {
        for u in 1..w - 1 {
            let (uf, vf) = (u as f64, v as f64);
            let got = depth[v * w + u];
            let around = [(uf - 1.0, vf), (uf + 1.0, vf), (uf, vf - 1.0), (uf, vf + 1.0), (uf, vf)];
            // Pixels well inside the cup's silhouette.
            if around.iter().all(|&(a, b)| cup_hit(origin, ray(a, b)).is_some()) {
                let want = cup_hit(origin, ray(uf, vf)).unwrap();
                let got = got.unwrap_or_else(|| panic!("cup pixel ({u}, {v}) has no depth (expected {want:.3} m)"));
                cup_worst = cup_worst.max((got - want).abs());
                cup += 1;
                cup_depth += got;
                continue;
            }
            // Table pixels clear of the cup (and its edge) within 0.25 m of the cup's axis.
            if around.iter().any(|&(a, b)| cup_hit(origin, ray(a, b)).is_some()) {
                continue;
            }
            let near_cup = |p: [f64; 3]| ((p[0] - 0.33).powi(2) + (p[1] + 0.12).powi(2)).sqrt() < 0.25;
            if around.iter().all(|&(a, b)| table_hit(origin, ray(a, b)).is_some_and(|(_, p)| near_cup(p))) {
                let (want, _) = table_hit(origin, ray(uf, vf)).unwrap();
                table += 1;
                if !got.is_some_and(|g| (g - want).abs() <= 0.01) {
                    table_off += 1;
                }
                // Behind the cup: the table just beyond it (farther from the camera in x).
                let (_, p) = table_hit(origin, ray(uf, vf)).unwrap();
                if p[0] > 0.37 && (p[1] + 0.12).abs() < 0.04 {
                    behind += got.unwrap_or(f64::NAN);
                    behind_n += 1;
                }
            }
        }
    }
    let tf_chain = &frame["tf_chain"];
    assert!(cup >= 30, "only {cup} pixels inside the cup's silhouette (camera chain {tf_chain})");
    assert!(cup_worst <= 0.01, "cup pixels off their analytic depth by up to {cup_worst:.4} m");
    assert!(table >= 500, "only {table} table pixels near the cup");
    assert!(table_off * 100 <= table, "{table_off} of {table} table pixels off by more than 1 cm");
    assert!(behind_n >= 20, "{behind_n} table pixels behind the cup");
    let (cup_mean, behind_mean) = (cup_depth / cup as f64, behind / behind_n as f64);
    assert!(behind_mean > cup_mean + 0.03, "table behind the cup at {behind_mean:.3} m, cup at {cup_mean:.3} m");
    eprintln!(
        "grasp head camera: {cup} cup pixels (worst {:.2} mm off), {table} table pixels ({table_off} off by > 1 cm), \
         cup at {cup_mean:.3} m, table behind it at {behind_mean:.3} m",
        cup_worst * 1e3
    );
}
