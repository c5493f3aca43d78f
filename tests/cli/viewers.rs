//! `twin sim --foxglove`: the reference Foxglove client (npm `@foxglove/ws-protocol`, installed
//! by the test under the target folder) connects with either subprotocol, decodes /joint_states
//! and the IMU with an independent CDR reader (`@foxglove/rosmsg2-serialization`, from the
//! schema text the server advertises), sees the server time follow the simulation, fetches a
//! package:// mesh, pauses, steps and drives a joint with a published command.

use super::common::{repo_root, twin};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

/// The npm packages of the client, installed once under the target folder (a missing npm or
/// registry fails the test). The tests of this file run in parallel threads of one process:
/// the `OnceLock` makes the second caller wait for the first install instead of running a
/// second `npm install` into the same folder (which removed the first one's packages under it).
fn node_modules() -> PathBuf {
    static MODULES: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    MODULES.get_or_init(install_node_modules).clone()
}

fn install_node_modules() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("foxglove-node");
    let marker = dir.join("node_modules/@foxglove/rosmsg2-serialization/package.json");
    if !marker.is_file() {
        std::fs::create_dir_all(&dir).unwrap();
        let status = Command::new("npm")
            .args([
                "install",
                "--no-audit",
                "--no-fund",
                "--prefix",
                dir.to_str().unwrap(),
                "@foxglove/ws-protocol@0.8.0",
                "ws@8",
                "@foxglove/rosmsg@5.0.5",
                "@foxglove/rosmsg2-serialization@3.1.0",
            ])
            .status()
            .expect("npm runs (node and npm are needed for this test)");
        assert!(status.success(), "npm install of the Foxglove client failed");
    }
    dir.join("node_modules")
}

/// A binary STL tetrahedron (4 facets).
fn stl() -> Vec<u8> {
    let v = [[0.0f32, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.05]];
    let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&(faces.len() as u32).to_le_bytes());
    for f in faces {
        b.extend_from_slice(&[0u8; 12]);
        for i in f {
            for c in v[i] {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    b
}

/// The humanoid as a description package with one mesh (on the pelvis).
fn package(dir: &Path) -> (PathBuf, usize) {
    let pkg = dir.join("twin_view_description");
    std::fs::create_dir_all(pkg.join("urdf")).unwrap();
    std::fs::create_dir_all(pkg.join("meshes")).unwrap();
    std::fs::write(pkg.join("package.xml"), "<package><name>twin_view_description</name></package>").unwrap();
    let mesh = stl();
    std::fs::write(pkg.join("meshes/marker.stl"), &mesh).unwrap();
    let urdf = std::fs::read_to_string(repo_root().join("models/humanoid.urdf")).unwrap();
    let urdf = urdf.replacen(
        "<link name=\"pelvis\">",
        "<link name=\"pelvis\">\n    <visual><geometry><mesh filename=\"package://twin_view_description/meshes/marker.stl\"/>\
         </geometry></visual>",
        1,
    );
    let path = pkg.join("urdf/humanoid.urdf");
    std::fs::write(&path, urdf).unwrap();
    (path, mesh.len())
}

fn client(modules: &Path, args: &[&str]) -> serde_json::Value {
    let script = repo_root().join("tests/js/foxglove_client.js");
    let out = Command::new("node").arg(script).args(args).env("NODE_PATH", modules).output().expect("node runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_str(stdout.lines().last().unwrap_or("")).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

/// Starts `twin ARGS` and reads its output until a line that starts with `prefix` says where it
/// listens (the first word after `marker`), waiting at most `limit` for each line (`what` names
/// what it waits for); returns the running child and that address.
fn spawn_listening(args: &[&str], prefix: &str, marker: &str, limit: Duration, what: &str) -> (Child, String) {
    let mut child = twin().args(args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    loop {
        let Ok(line) = rx.recv_timeout(limit) else {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what}");
        };
        let after = line.strip_prefix(prefix).and_then(|l| l.split_once(marker)).map(|(_, a)| a);
        if let Some(word) = after.and_then(|a| a.split_whitespace().next()) {
            return (child, word.to_string());
        }
    }
}

/// [`spawn_listening`] for a Foxglove server (`twin sim|view … --foxglove`): its
/// `foxglove: ws://ADDRESS` line, waited for at most `limit_secs` a line.
fn spawn_foxglove(args: &[&str], limit_secs: u64) -> (Child, String) {
    let what = format!("twin {} says where the server listens", args[0]);
    spawn_listening(args, "foxglove: ", "ws://", Duration::from_secs(limit_secs), &what)
}

#[test]
fn foxglove_client_subscribes_decodes_fetches_pauses_steps_and_commands() {
    let modules = node_modules();
    let dir = tempfile::tempdir().unwrap();
    let (urdf, mesh_bytes) = package(dir.path());
    let (mut sim, address) =
        spawn_foxglove(&["sim", urdf.to_str().unwrap(), "--duration", "120", "--foxglove", "0"], 120);
    let url = format!("ws://{address}");
    assert!(url.starts_with("ws://127.0.0.1:"), "loopback by default: {url}");

    // The SDK's subprotocol name: subscribe and decode.
    let a = client(&modules, &[&url, "foxglove.sdk.v1", "watch"]);
    assert_eq!(a["subprotocol"], "foxglove.sdk.v1", "{a:#}");
    assert_eq!(a["end"], "done", "{a:#}");
    let first = &a["firstJointState"];
    assert_eq!(first["name"].as_array().unwrap().len(), 23, "{a:#}");
    // The message's receive time is its stamp: the server time is the simulation's.
    let (stamp, receive) = (first["stamp"].as_f64().unwrap(), first["receive"].as_f64().unwrap());
    assert!((stamp - receive).abs() < 1e-9, "{a:#}");
    // The IMU: a unit quaternion, upright.
    let q = &a["firstImu"]["orientation"];
    let n: f64 = ["x", "y", "z", "w"].iter().map(|k| q[k].as_f64().unwrap().powi(2)).sum();
    assert!((n - 1.0).abs() < 1e-6 && q["w"].as_f64().unwrap().abs() > 0.99, "{a:#}");

    // The spec's name: everything.
    let b = client(
        &modules,
        &[
            &url,
            "foxglove.websocket.v1",
            "full",
            "package://twin_view_description/meshes/marker.stl",
            "/humanoid/joint_commands",
            "neck_yaw_joint",
            "0.5",
        ],
    );
    let _ = Command::new("kill").args(["-INT", &sim.id().to_string()]).status();
    let status = sim.wait().unwrap();
    assert_eq!(b["subprotocol"], "foxglove.websocket.v1", "{b:#}");
    assert_eq!(b["end"], "done", "{b:#}");
    for s in ["/twin/pause", "/twin/resume", "/twin/step", "/twin/reset"] {
        assert!(b["services"].as_array().unwrap().iter().any(|x| x == s), "{s}: {b:#}");
    }
    assert!(b["channels"].as_array().unwrap().iter().any(|c| c["topic"] == "/robot_description"), "{b:#}");
    assert_eq!(b["asset"]["status"], 0, "{b:#}");
    assert_eq!(b["asset"]["bytes"].as_u64(), Some(mesh_bytes as u64), "{b:#}");
    // Time advances with the simulation, and not while paused.
    let times: Vec<f64> = b["times"].as_array().unwrap().iter().map(|t| t.as_f64().unwrap()).collect();
    assert!(times.windows(2).all(|w| w[1] >= w[0]) && times.last() > times.first(), "{b:#}");
    let paused_at = b["calls"]["pause"]["time_secs"].as_f64().unwrap();
    assert!(b["calls"]["pause"]["ok"].as_bool().unwrap());
    for t in b["timeWhilePaused"].as_array().unwrap() {
        assert!(t.as_f64().unwrap() <= paused_at + 1e-9, "time moved while paused: {b:#}");
    }
    // 50 steps of 2 ms.
    let stepped = b["calls"]["step"]["time_secs"].as_f64().unwrap() - paused_at;
    assert!((stepped - 0.1).abs() < 1e-9, "{stepped}: {b:#}");
    // The published command turned the neck to 0.5 rad.
    let moved = b["moved"]["position"].as_f64().unwrap_or(f64::NAN);
    assert!((moved - 0.5).abs() < 0.05, "{b:#}");
    // Ctrl-C ends the run cleanly (status 130).
    assert_eq!(status.code(), Some(130), "{status:?}");
}

/// `twin sim --unity`: a client framed like Unity's ROS-TCP-Connector (tests/python, messages
/// through rclpy's serializer) gets the handshake and the topic list, subscribes to
/// /joint_states, decodes it, and publishes a Float64MultiArray that turns the neck.
#[test]
fn unity_client_handshakes_subscribes_and_moves_a_joint() {
    let python = crate::test_python::python().to_string_lossy().into_owned();
    let (mut sim, addr) = spawn_listening(
        &["sim", "--duration", "120", "--unity", "0"],
        "unity: ",
        " on ",
        Duration::from_secs(120),
        "twin sim says where the endpoint listens",
    );
    let (host, port) = addr.rsplit_once(':').unwrap();
    assert_eq!(host, "127.0.0.1", "loopback by default");
    let out = Command::new(&python)
        .arg(repo_root().join("tests/python/unity_client.py"))
        .args([host, port, "/humanoid/joint_commands", "neck_yaw_joint", "0.5"])
        .output()
        .unwrap_or_else(|e| panic!("{python} (TWIN_PYTHON) with rclpy runs the Unity client: {e}"));
    let _ = Command::new("kill").args(["-INT", &sim.id().to_string()]).status();
    let status = sim.wait().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    // An empty frame, then the handshake, as the endpoint sends them.
    assert_eq!(v["frames"][0], "", "{v:#}");
    assert_eq!(v["frames"][1], "__handshake", "{v:#}");
    assert_eq!(v["handshake"]["version"], "v0.7.0", "{v:#}");
    let topics = v["topic_list"]["topics"].as_array().unwrap();
    let types = v["topic_list"]["types"].as_array().unwrap();
    let i = topics.iter().position(|t| t == "/joint_states").unwrap();
    assert_eq!(types[i], "sensor_msgs/JointState", "{v:#}");
    assert!(v["errors"].as_array().unwrap().is_empty(), "{v:#}");
    assert_eq!(v["first"]["names"].as_array().unwrap().len(), 23, "{v:#}");
    let moved = v["moved"]["position"].as_f64().unwrap_or(f64::NAN);
    assert!((moved - 0.5).abs() < 0.05, "{v:#}");
    assert_eq!(status.code(), Some(130), "{status:?}");
}

/// `twin view LOG --foxglove`: a recorded run played to the reference client, which decodes
/// its /joint_states and IMU with the schemas the log carries; the receive times are the log's.
#[test]
fn foxglove_client_plays_a_recorded_log() {
    let modules = node_modules();
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("run.mcap");
    let (ok, out, err) = super::common::run(&["sim", "--duration", "1", "--record", mcap.to_str().unwrap()]);
    assert!(ok, "{out}\n{err}");
    let (mut view, address) = spawn_foxglove(&["view", mcap.to_str().unwrap(), "--foxglove", "0", "--wait", "60"], 60);
    let a = client(&modules, &[&format!("ws://{address}"), "foxglove.websocket.v1", "watch"]);
    let status = view.wait().unwrap();
    assert!(status.success(), "{status:?}");
    assert_eq!(a["end"], "done", "{a:#}");
    assert_eq!(a["firstJointState"]["name"].as_array().unwrap().len(), 23, "{a:#}");
    // Played from the log's start: stamps (simulation time) are the receive times.
    let first = &a["firstJointState"];
    assert!((first["stamp"].as_f64().unwrap() - first["receive"].as_f64().unwrap()).abs() < 1e-9, "{a:#}");
    assert!(first["stamp"].as_f64().unwrap() < 0.05, "{a:#}");
}
