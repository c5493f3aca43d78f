//! `twin sim` with a rendered camera from a URDF's Gazebo tags: a `segmentation` camera (RGB,
//! instance and class labels, label table) and a `depth` camera on the same link, looking
//! down at a red box on the floor. The recording, decoded by the independent `mcap` +
//! `mcap-ros2-support` readers, shows the box red where the depth image puts its top and
//! labelled with its link's name; and on a machine without EGL or OSMesa (their library paths
//! hidden) `twin sim` says what to install and still records the depth camera.
//!
//! Python comes from the tests' venv (`test_python.rs`); EGL (Mesa's llvmpipe) must be there.

use super::common::{output_of, repo_root, twin};
use serde_json::Value as Json;
use std::path::Path;
use std::process::Command;

/// The shipped arm bolted to the world, a camera link 1.5 m above the floor at x = 2 m looking
/// straight down (Gazebo: the link's x axis) with a 64 × 48 segmentation camera and a depth
/// camera of the same field of view, and a red 0.2 m box on the floor under it, a little to
/// one side.
fn camera_arm() -> String {
    let arm = std::fs::read_to_string(repo_root().join("models/arm6.urdf")).unwrap();
    let inertial = r#"<inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>"#;
    let camera = r#"<camera><horizontal_fov>1.0</horizontal_fov><image><width>64</width><height>48</height></image>
    <clip><near>0.1</near><far>5</far></clip></camera>"#;
    let extra = format!(
        r#"
  <joint name="camera_mount" type="fixed"><origin xyz="2 0 1.5" rpy="0 1.5707963267948966 0"/>
    <parent link="base_link"/><child link="camera_link"/></joint>
  <link name="camera_link">{inertial}</link>
  <gazebo reference="camera_link">
    <sensor name="seg_cam" type="segmentation"><update_rate>10</update_rate>{camera}</sensor>
    <sensor name="depth_cam" type="depth"><update_rate>10</update_rate>{camera}</sensor>
  </gazebo>
  <joint name="box_mount" type="fixed"><origin xyz="2.1 0.15 0.1"/><parent link="base_link"/><child link="red_box"/></joint>
  <link name="red_box">{inertial}<visual><geometry><box size="0.2 0.2 0.2"/></geometry>
    <material name="red"><color rgba="1 0 0 1"/></material></visual>
    <collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision></link>
</robot>"#
    );
    let bolt = r#"<robot name="arm6">
  <link name="world"/>
  <joint name="world_bolt" type="fixed"><parent link="world"/><child link="base_link"/></joint>"#;
    arm.replace(r#"<robot name="arm6">"#, bolt).replace("</robot>", &extra)
}

const RGB: &str = "/arm6/seg_cam/image_raw";
const INFO: &str = "/arm6/seg_cam/camera_info";
const INSTANCES: &str = "/arm6/seg_cam/segmentation/instances";
const CLASSES: &str = "/arm6/seg_cam/segmentation/classes";
const LABELS: &str = "/arm6/seg_cam/segmentation/labels";
const DEPTH: &str = "/arm6/depth_cam/depth/image_raw";

fn decode(mcap: &Path) -> Json {
    let python = crate::test_python::python();
    let script = repo_root().join("tests/python/camera_check.py");
    let out = Command::new(&python)
        .arg(&script)
        .arg(mcap)
        .args([RGB, INFO, INSTANCES, CLASSES, LABELS, DEPTH])
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", python.display()));
    assert!(out.status.success(), "{} failed:\n{}", script.display(), String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn sim(urdf: &Path, mcap: &Path, hide_gl: bool) -> (bool, String, String) {
    let mut cmd = twin();
    cmd.args(["sim", urdf.to_str().unwrap(), "--duration", "1", "--controller", "hold", "--record"]).arg(mcap);
    if hide_gl {
        cmd.env("TWIN_EGL_LIBRARY", "/nonexistent/libEGL.so.1")
            .env("TWIN_OSMESA_LIBRARY", "/nonexistent/libOSMesa.so.8");
    }
    output_of(cmd.output().expect("twin runs"))
}

#[test]
fn a_segmentation_camera_is_rendered_recorded_and_agrees_with_the_depth_camera() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = super::common::write(dir.path(), "camera_arm.urdf", &camera_arm());
    let mcap = dir.path().join("run.mcap");
    let (ok, stdout, stderr) = sim(&urdf, &mcap, false);
    assert!(ok, "twin sim failed:\n{stderr}\n{stdout}");
    assert!(!stderr.contains("not rendered"), "{stderr}");
    let json = decode(&mcap);

    // 10 Hz for 1 s on every topic, stamped at the frame's time, in the optical frame.
    for topic in [RGB, INFO, INSTANCES, CLASSES, LABELS, DEPTH] {
        assert_eq!(json[topic].as_array().map(Vec::len), Some(10), "{topic}");
    }
    let rgb = &json[RGB][0];
    assert_eq!(
        (rgb["encoding"].as_str(), rgb["width"].as_u64(), rgb["height"].as_u64()),
        (Some("rgb8"), Some(64), Some(48))
    );
    assert_eq!((rgb["step"].as_u64(), rgb["bytes"].as_u64()), (Some(192), Some(64 * 48 * 3)));
    assert_eq!(rgb["frame_id"], "seg_cam_optical_frame");
    for (k, m) in json[RGB].as_array().unwrap().iter().enumerate() {
        assert_eq!(m["log_time"].as_u64(), Some(k as u64 * 100_000_000));
        assert_eq!(m["stamp"], m["log_time"]);
    }
    let info = &json[INFO][0];
    let f = 32.0 / 0.5f64.tan();
    let kk: Vec<f64> = info["k"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((kk[0] - f).abs() < 1e-6 && (kk[4] - f).abs() < 1e-6 && kk[2] == 31.5 && kk[5] == 23.5, "{kk:?}");
    assert_eq!(info["distortion_model"], "plumb_bob");

    // The label table names the box's link; its instance label is one of the box's geoms.
    let table: Json = serde_json::from_str(json[LABELS][0]["text"].as_str().unwrap()).unwrap();
    let box_labels: Vec<u64> = table["instances"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["body"] == "red_box")
        .map(|e| e["label"].as_u64().unwrap())
        .collect();
    assert!(!box_labels.is_empty(), "no instance of red_box in the label table: {table}");
    let box_class =
        table["classes"].as_array().unwrap().iter().find(|e| e["body"] == "red_box").unwrap()["label"].clone();

    // Pixel by pixel: where the depth image sees the box's top (1.3 m, against the floor's
    // 1.5 m), the colour image is red and the labels name the box; elsewhere neither.
    let px = |t: &str| json[t][0]["pixels"].as_array().unwrap().clone();
    let (colour, depth, instances, classes) = (px(RGB), px(DEPTH), px(INSTANCES), px(CLASSES));
    let (mut on_box, mut agree) = (0, 0);
    for i in 0..64 * 48 {
        let z = depth[i].as_f64().expect("every pixel sees the floor or the box");
        let c: Vec<u64> = colour[i].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect();
        let red = c[0] > 100 && c[0] > 3 * c[1] && c[0] > 3 * c[2];
        let labelled = box_labels.contains(&instances[i].as_u64().unwrap()) && classes[i] == box_class;
        let top = (z - 1.3).abs() < 0.005;
        let floor = (z - 1.5).abs() < 0.005;
        on_box += usize::from(top);
        if (top && red && labelled) || (floor && !red && !labelled) {
            agree += 1;
        }
    }
    eprintln!(
        "camera: {on_box} box-top pixels in the depth image; {agree} of {} pixels agree in colour, label and depth",
        64 * 48
    );
    assert!(on_box >= 60, "the box's top covers only {on_box} pixels");
    assert!(agree * 100 >= 64 * 48 * 95, "only {agree} pixels agree");

    // Rendered on the sensors' pool while the simulation goes on: a second run writes the
    // same file, byte for byte.
    let again = dir.path().join("again.mcap");
    let (ok, _, stderr) = sim(&urdf, &again, false);
    assert!(ok, "{stderr}");
    assert!(std::fs::read(&mcap).unwrap() == std::fs::read(&again).unwrap(), "two runs wrote different files");
}

#[test]
fn without_egl_or_osmesa_twin_says_what_to_install_and_records_depth() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = super::common::write(dir.path(), "camera_arm.urdf", &camera_arm());
    let mcap = dir.path().join("run.mcap");
    let (ok, stdout, stderr) = sim(&urdf, &mcap, true);
    assert!(ok, "twin sim failed without OpenGL:\n{stderr}\n{stdout}");
    assert!(
        stderr.contains("camera sensor \"seg_cam\"")
            && stderr.contains("not rendered")
            && stderr.contains("/nonexistent/libEGL.so.1")
            && stderr.contains("apt-get install libegl1"),
        "{stderr}"
    );
    let json = decode(&mcap);
    assert_eq!(json[RGB].as_array().map(Vec::len), Some(0), "an image without OpenGL");
    let depth = json[DEPTH].as_array().unwrap();
    assert_eq!(depth.len(), 10);
    let z: Vec<f64> = depth[0]["pixels"].as_array().unwrap().iter().filter_map(Json::as_f64).collect();
    assert_eq!(z.len(), 64 * 48);
    assert!(z.iter().any(|&z| (z - 1.3).abs() < 0.005) && z.iter().any(|&z| (z - 1.5).abs() < 0.005));
}
