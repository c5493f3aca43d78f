//! `twin sim --ros` against an independent DDS implementation: a Cyclone DDS peer in Python
//! (`tests/python/ros_peer.py`, PyPI `cyclonedds`) on loopback only.
//!
//! Network: both sides use loopback only with unicast discovery to 127.0.0.1 and no
//! multicast (twin: `--ros-interface lo`; Cyclone: `tests/python/cyclonedds-loopback.xml`), a
//! domain id of their own per test, and every wait is bounded (the peer's `--timeout`, twin's
//! `--lockstep-timeout` / `--wait-for-subscriber`, [`wait`] here).
//!
//! Python comes from `TWIN_PYTHON` (default `python3`) and must have `cyclonedds` (see
//! `.ci/requirements.txt`): without it these tests FAIL.

use super::common::{output_of, repo_root, twin};
use serde_json::{Value as Json, json};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};
use twin_core::log::{
    Float64MultiArray, Imu, JointState, Log, Odometry, ReadOptions, RosMessage, TfMessage, WrenchStamped,
};

const PEER: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/ros_peer.py");
const CYCLONE_XML: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/python/cyclonedds-loopback.xml");
const MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf");
const ELBOW: &str = "left_elbow_joint";
/// The elbow target, rad: 0.3 rad of flexion. The humanoid's elbows flex towards negative
/// angles (range [-2.4, 0.05] rad), so +0.3 rad would be beyond the joint limit.
const ELBOW_TARGET: f64 = -0.3;
const PERIOD_NANOS: u64 = 10_000_000;

/// A domain id for test `k` (0..5) unlikely to meet another test binary's.
fn domain(k: u32) -> u32 {
    10 + (std::process::id() % 40) * 5 + k
}

fn python() -> String {
    let exe = std::env::var("TWIN_PYTHON").unwrap_or_else(|_| "python3".into());
    let ok = Command::new(&exe).args(["-c", "import cyclonedds.domain"]).output();
    match ok {
        Ok(o) if o.status.success() => exe,
        Ok(o) => panic!(
            "{exe} has no cyclonedds ({}): pip install -r .ci/requirements.txt and set TWIN_PYTHON",
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => panic!("cannot run {exe} ({e}): set TWIN_PYTHON to a Python with cyclonedds"),
    }
}

/// Waits for `child` at most `limit`, killing it after that.
fn wait(mut child: Child, limit: Duration, what: &str) -> Output {
    let deadline = Instant::now() + limit;
    loop {
        match child.try_wait().expect("try_wait") {
            Some(_) => return child.wait_with_output().expect("output"),
            None if Instant::now() > deadline => {
                let _ = child.kill();
                let out = child.wait_with_output().expect("output");
                panic!(
                    "{what} still running after {limit:?}; killed.\nstdout:\n{}\nstderr:\n{}",
                    String::from_utf8_lossy(&out.stdout),
                    String::from_utf8_lossy(&out.stderr)
                );
            }
            None => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

fn spawn_twin(domain: u32, args: &[&str]) -> Child {
    twin()
        .args(["sim", MODEL, "--ros", "--ros-interface", "lo"])
        .args(args)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("twin starts")
}

fn spawn_peer(domain: u32, out: &Path, args: &[String]) -> Child {
    Command::new(python())
        .arg(PEER)
        .arg("--out")
        .arg(out)
        .args(["--domain", &domain.to_string(), "--command-topic", "/humanoid/joint_commands"])
        .args(["--contact-topics", "/contacts/left_foot_link,/contacts/right_foot_link"])
        .args(args)
        .env("CYCLONEDDS_URI", format!("file://{CYCLONE_XML}"))
        .current_dir(repo_root())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the peer starts")
}

/// The position command: the home pose with the left elbow at [`ELBOW_TARGET`], in command
/// order.
fn elbow_command() -> Vec<f64> {
    let robot = twin_core::robot::Robot::load(MODEL).unwrap();
    let c = twin_core::live::Commander::new(&robot.model, twin_core::live::CommandInterface::Position);
    let home = twin_core::control::nominal_pose(&robot.model);
    let names = c.joint_names();
    names
        .iter()
        .map(|n| {
            let j = robot.model.id(twin_core::mj::ObjType::Joint, n).unwrap();
            if n == ELBOW { ELBOW_TARGET } else { home[robot.model.jnt_qposadr()[j] as usize] }
        })
        .collect()
}

fn read<T: RosMessage>(file: &Path, topic: &str) -> Vec<(u64, T)> {
    let log = Log::open(file, ReadOptions { strict: true }).unwrap();
    let (msgs, report) = log.read_typed::<T>(topic).unwrap();
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    msgs
}

fn peer_json(file: &Path, out: &Output) -> Json {
    let text = std::fs::read_to_string(file).unwrap_or_default();
    serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!(
            "peer wrote no JSON ({e}):\n{}\nstderr:\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn header(stamp: i64, frame: &str) -> Json {
    json!({"stamp": stamp, "frame_id": frame})
}

/// twin's messages as the peer writes them.
fn js_json(m: &JointState) -> Json {
    json!({"header": header(m.header.stamp_nanos, &m.header.frame_id), "name": m.name,
           "position": m.position, "velocity": m.velocity, "effort": m.effort})
}
fn imu_json(m: &Imu) -> Json {
    json!({"header": header(m.header.stamp_nanos, &m.header.frame_id), "orientation": m.orientation_xyzw,
           "angular_velocity": m.angular_velocity, "linear_acceleration": m.linear_acceleration,
           "angular_velocity_covariance": m.angular_velocity_covariance,
           "linear_acceleration_covariance": m.linear_acceleration_covariance})
}
fn odom_json(m: &Odometry) -> Json {
    json!({"header": header(m.header.stamp_nanos, &m.header.frame_id), "child_frame_id": m.child_frame_id,
           "position": m.position, "orientation": m.orientation_xyzw,
           "linear": m.linear_velocity, "angular": m.angular_velocity})
}
fn tf_json(m: &TfMessage) -> Json {
    json!({"transforms": m.transforms.iter().map(|t| json!({
        "header": header(t.header.stamp_nanos, &t.header.frame_id), "child_frame_id": t.child_frame_id,
        "translation": t.translation, "rotation": t.rotation_xyzw})).collect::<Vec<_>>()})
}
fn wrench_json(m: &WrenchStamped) -> Json {
    json!({"header": header(m.header.stamp_nanos, &m.header.frame_id), "force": m.force, "torque": m.torque})
}

/// Every message the peer got on `topic` equals the MCAP message of the same stamp; returns
/// how many were compared.
fn compare<T: RosMessage>(mcap: &Path, peer: &Json, topic: &str, to_json: fn(&T) -> Json) -> usize {
    let recorded: std::collections::HashMap<u64, Json> =
        read::<T>(mcap, topic).iter().map(|(t, m)| (*t, to_json(m))).collect();
    let got = peer["received"][topic].as_array().unwrap_or_else(|| panic!("peer has no {topic}"));
    for m in got {
        let stamp = m["header"]["stamp"]
            .as_u64()
            .or_else(|| m["transforms"][0]["header"]["stamp"].as_u64())
            .unwrap_or_else(|| panic!("{topic}: no stamp in {m}"));
        let want = recorded.get(&stamp).unwrap_or_else(|| panic!("{topic}: stamp {stamp} not in the MCAP"));
        assert_eq!(m, want, "{topic} at {stamp} ns: the peer decoded something else than the MCAP holds");
    }
    got.len()
}

fn elbow_at_end(mcap: &Path) -> (u64, f64) {
    let js = read::<JointState>(mcap, "/joint_states");
    let (t, last) = js.last().unwrap();
    let i = last.name.iter().position(|n| n == ELBOW).unwrap();
    (*t, last.position[i])
}

fn tmp(dir: &tempfile::TempDir, name: &str) -> PathBuf {
    dir.path().join(name)
}

#[test]
fn ros_lockstep_with_a_cyclone_peer_reaches_the_elbow_target_and_matches_the_recording() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = tmp(&dir, "live.mcap");
    let d = domain(0);
    let command = serde_json::to_string(&elbow_command()).unwrap();
    let peer_file = tmp(&dir, "peer.json");
    let peer = spawn_peer(
        d,
        &peer_file,
        &[
            "--mode".into(),
            "lockstep".into(),
            "--command".into(),
            command,
            "--until-clock".into(),
            "0.99".into(),
            "--timeout".into(),
            "90".into(),
        ],
    );
    let twin = spawn_twin(
        d,
        &[
            "--lockstep",
            "--duration",
            "1.0",
            "--control-rate",
            "100",
            "--wait-for-subscriber",
            "30",
            "--lockstep-timeout",
            "20",
            "--record",
            mcap.to_str().unwrap(),
        ],
    );
    let twin_out = wait(twin, Duration::from_secs(120), "twin sim --ros --lockstep");
    let peer_out = wait(peer, Duration::from_secs(120), "the Cyclone peer");
    let (ok, stdout, stderr) = output_of(twin_out);
    assert!(ok, "twin failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains("command order (") && stdout.contains(ELBOW), "{stdout}");
    assert!(peer_out.status.success(), "peer:\n{}", String::from_utf8_lossy(&peer_out.stderr));
    let peer = peer_json(&peer_file, &peer_out);

    // Sim time advances exactly one control period per command: the peer saw /clock at every
    // period, twin took one command at each, stamped with that period's time.
    let mut clocks: Vec<u64> =
        peer["received"]["/clock"].as_array().unwrap().iter().map(|c| c["clock"].as_u64().unwrap()).collect();
    // While it waits, twin says the same time again (a reader that matched late gets it too).
    assert!(clocks.windows(2).all(|w| w[0] <= w[1]), "/clock went backwards");
    clocks.dedup();
    let expected: Vec<u64> = (0..100).map(|k| k * PERIOD_NANOS).collect();
    assert_eq!(clocks, expected, "the peer's /clock");
    let commands = read::<Float64MultiArray>(&mcap, "/humanoid/joint_commands");
    let times: Vec<u64> = commands.iter().map(|(t, _)| *t).collect();
    assert_eq!(times, expected, "commands recorded at each period");
    assert_eq!(peer["sent"].as_u64(), Some(100));
    assert!(commands.iter().all(|(_, c)| c.data == elbow_command()));
    let recorded_clock: Vec<u64> = read::<twin_core::log::Clock>(&mcap, "/clock").iter().map(|(t, _)| *t).collect();
    assert_eq!(recorded_clock, expected);

    // The elbow reaches its target (0.3 rad of flexion) within 0.02 rad in 1 s of simulated time.
    let (t, q) = elbow_at_end(&mcap);
    assert!(t <= 1_000_000_000, "{t}");
    assert!((q - ELBOW_TARGET).abs() < 0.02, "left elbow at {q} rad after {t} ns");

    // The peer decodes every topic to the values of the recording.
    let n_js = compare(&mcap, &peer, "/joint_states", js_json);
    let n_imu = compare(&mcap, &peer, "/humanoid/imu/data", imu_json);
    let n_odom = compare(&mcap, &peer, "/odom", odom_json);
    let n_tf = compare(&mcap, &peer, "/tf", tf_json);
    let n_contacts = compare(&mcap, &peer, "/contacts/left_foot_link", wrench_json)
        + compare(&mcap, &peer, "/contacts/right_foot_link", wrench_json);
    // The peer joined before the first period, so (reliable) it got nearly everything.
    assert!(
        n_js >= 450 && n_imu >= 180 && n_odom >= 450 && n_tf >= 90 && n_contacts >= 900,
        "{n_js} {n_imu} {n_odom} {n_tf} {n_contacts}"
    );
    // The humanoid's IMU frame is a link of its own: /tf carries it, there is no /tf_static.
    assert_eq!(peer["received"]["/tf_static"].as_array().map(Vec::len), Some(0));
    let description = &peer["received"]["/robot_description"][0];
    let urdf = std::fs::read_to_string(MODEL).unwrap();
    assert_eq!(description["data_len"].as_u64(), Some(urdf.len() as u64));
    assert_eq!(description["data_head"].as_str(), Some(&urdf[..200]));
}

#[test]
fn ros_rejects_bad_commands_and_holds_the_last_good_one() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = tmp(&dir, "bad.mcap");
    let d = domain(1);
    let command = serde_json::to_string(&elbow_command()).unwrap();
    let peer_file = tmp(&dir, "peer.json");
    let peer = spawn_peer(
        d,
        &peer_file,
        &[
            "--mode".into(),
            "bad".into(),
            "--command".into(),
            command,
            "--until-clock".into(),
            "0.99".into(),
            "--timeout".into(),
            "90".into(),
        ],
    );
    let twin = spawn_twin(
        d,
        &[
            "--lockstep",
            "--duration",
            "1.0",
            "--wait-for-subscriber",
            "30",
            "--lockstep-timeout",
            "20",
            "--record",
            mcap.to_str().unwrap(),
        ],
    );
    let (ok, stdout, stderr) = output_of(wait(twin, Duration::from_secs(120), "twin"));
    let peer_out = wait(peer, Duration::from_secs(120), "the peer");
    assert!(ok, "twin failed:\n{stdout}\n{stderr}");
    assert!(peer_out.status.success(), "{}", String::from_utf8_lossy(&peer_out.stderr));
    // Wrong length (short and long) and NaN: each rejected with a warning naming the topic.
    for k in 1..=3 {
        assert!(stderr.contains(&format!("rejected command #{k} on /humanoid/joint_commands")), "{stderr}");
    }
    assert!(stderr.contains("is NaN") && stderr.contains("values, expected"), "{stderr}");
    assert!(stdout.contains("3 rejected"), "{stdout}");
    // All 100 taken commands are recorded, bad ones included; the good ones still bring the
    // elbow to its target within the second.
    let commands = read::<Float64MultiArray>(&mcap, "/humanoid/joint_commands");
    assert_eq!(commands.len(), 100);
    assert!(commands[1].1.data[0].is_nan());
    let (_, q) = elbow_at_end(&mcap);
    assert!((q - ELBOW_TARGET).abs() < 0.02, "elbow at {q}");
    // Before the first good command (three periods) the home pose was held.
    assert_eq!(read::<JointState>(&mcap, "/joint_states").len(), 500);
}

#[test]
fn ros_survives_a_flood_a_peer_that_leaves_and_a_second_twin_in_the_domain() {
    python(); // before starting any twin: fail at once without cyclonedds
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (tmp(&dir, "a.mcap"), tmp(&dir, "b.mcap"));
    let d = domain(2);
    let command = serde_json::to_string(&elbow_command()).unwrap();
    let args = |file: &Path| -> Vec<String> {
        ["--rtf", "1", "--duration", "6", "--silence-timeout", "0.5", "--wait-for-subscriber", "30", "--record"]
            .iter()
            .map(|s| s.to_string())
            .chain([file.to_str().unwrap().to_string()])
            .collect()
    };
    let args_a = args(&a);
    let args_b = args(&b);
    let twin_a = spawn_twin(d, &args_a.iter().map(String::as_str).collect::<Vec<_>>());
    let twin_b = spawn_twin(d, &args_b.iter().map(String::as_str).collect::<Vec<_>>());
    // 10 000 good commands at up to 10 kHz (as fast as Python manages on a loaded machine), then
    // the peer leaves mid-run.
    let peer_file = tmp(&dir, "peer.json");
    let peer = spawn_peer(
        d,
        &peer_file,
        &["--mode", "flood", "--flood-hz", "10000", "--flood-count", "10000", "--until-clock", "0", "--timeout", "60"]
            .iter()
            .map(|s| s.to_string())
            .chain(["--command".to_string(), command])
            .collect::<Vec<_>>(),
    );
    let peer_out = wait(peer, Duration::from_secs(90), "the flooding peer");
    for (child, file) in [(twin_a, &a), (twin_b, &b)] {
        let (ok, stdout, stderr) = output_of(wait(child, Duration::from_secs(90), "twin"));
        assert!(ok, "twin failed:\n{stdout}\n{stderr}");
        // The flood was taken (the last good command wins), then the silence led to a safe hold.
        let commands = read::<Float64MultiArray>(file, "/humanoid/joint_commands");
        assert!(commands.len() > 1000, "{} commands recorded\n{stdout}", commands.len());
        assert!(stderr.contains("holding the current pose"), "{stderr}");
        // Nothing lost from the recording: 6 s of /joint_states at 500 Hz, /clock at 100 Hz.
        assert_eq!(read::<JointState>(file, "/joint_states").len(), 3000, "{stdout}");
        assert_eq!(read::<twin_core::log::Clock>(file, "/clock").len(), 600);
    }
    let peer = peer_json(&peer_file, &peer_out);
    assert_eq!(peer["sent"].as_u64(), Some(10_000));
    eprintln!("flood: 10 000 commands at {:.0} Hz", peer["flood_rate_hz"].as_f64().unwrap());
}
