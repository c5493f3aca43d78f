//! `twin sim` and `twin view`: what `--record` writes is read identically by twin and by the
//! independent Python readers (`mcap` + `mcap-ros2-support`, `rosbags`), carries the physics of
//! a standing humanoid, and a replay reproduces a recorded trajectory; the `.rrd` files pass the
//! rerun SDK's own `rerun rrd verify`.
//!
//! Python and the `rerun` executable come from the tests' venv (`test_python.rs`, made from
//! `.ci/requirements.txt` on first use); the cross-checks fail when it cannot be made.

use super::common::{repo_root, run};
use serde_json::Value as Json;
use std::path::{Path, PathBuf};
use std::process::Command;
use twin_core::control::JointTrajectory;
use twin_core::log::{
    Float64MultiArray, Imu, JointState, Log, Odometry, ReadOptions, RosMessage, TfMessage, WrenchStamped,
};

const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/data/humanoid_joint_states.mcap");
const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/twin-core/tests/python/log_interop.py");
/// Accelerometer and gyro noise of the shipped humanoid's IMU (models/humanoid.urdf).
const ACCEL_STD: f64 = 0.017;
const GYRO_STD: f64 = 0.002;

/// Every message of `file` decoded by the Python readers (the tests' venv, `test_python.rs`).
fn python_decode(file: &Path) -> Json {
    crate::test_python::script_json(SCRIPT, &["decode".as_ref(), file.as_os_str()])
}

/// `rerun rrd verify FILE` with the `rerun` of the tests' venv (rerun-sdk).
pub fn rerun_verify(file: &Path) {
    let rerun = crate::test_python::python_tool("rerun", "rerun-sdk");
    let out = Command::new(&rerun).args(["rrd", "verify"]).arg(file).output().expect("rerun runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "rerun rrd verify {} failed:\n{text}", file.display());
    assert!(text.contains("verified without error"), "{text}");
}

fn sim(args: &[&str]) -> String {
    let (ok, stdout, stderr) = run(args);
    assert!(ok, "twin {args:?} failed:\n{stderr}");
    stdout
}

fn read<T: RosMessage>(file: &Path, topic: &str) -> Vec<(u64, T)> {
    let log = Log::open(file, ReadOptions { strict: true }).unwrap();
    let (msgs, report) = log.read_typed::<T>(topic).unwrap();
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    msgs
}

fn tmp(dir: &tempfile::TempDir, name: &str) -> PathBuf {
    dir.path().join(name)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn std_dev(v: &[f64]) -> f64 {
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

#[test]
fn sim_hold_records_standing_physics_stamped_in_sim_time() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = tmp(&dir, "run.mcap");
    let stdout = sim(&["sim", "--duration", "1", "--controller", "hold", "--record", s(&mcap), "--seed", "3"]);
    assert!(stdout.contains("500 steps"), "{stdout}");
    assert!(stdout.contains("real-time factor"), "{stdout}");

    // JointState: duration × rate exactly, header stamp = log time = k · 2 ms.
    let js = read::<JointState>(&mcap, "/joint_states");
    assert_eq!(js.len(), 500);
    for (k, (log_time, m)) in js.iter().enumerate() {
        assert_eq!(*log_time, k as u64 * 2_000_000);
        assert_eq!(m.header.stamp_nanos, *log_time as i64);
        assert_eq!(m.name.len(), 23);
        assert_eq!((m.position.len(), m.velocity.len(), m.effort.len()), (23, 23, 23));
    }
    // Holding still at the home pose (straight legs, feet on the Gazebo-stiff contact the URDF
    // declares): the weight goes through the straight legs' structure (the feet's wrenches carry
    // m·g, checked below), so the joints need only the small torques of a static stance.
    let last = &js.last().unwrap().1;
    let effort = |name: &str| last.effort[last.name.iter().position(|n| n == name).unwrap()];
    assert!(last.effort.iter().all(|e| e.is_finite() && e.abs() < 5.0), "{:?}", last.effort);
    assert!(effort("left_knee_joint").abs() < 1.0, "{:?}", last.effort);
    assert!((effort("left_ankle_pitch_joint") - effort("right_ankle_pitch_joint")).abs() < 1e-6, "symmetric stance");

    // IMU at its 200 Hz update rate; specific force ≈ +g on z, gyro noise ≈ its configured σ.
    let imu = read::<Imu>(&mcap, "/humanoid/imu/data");
    assert_eq!(imu.len(), 200);
    assert!(imu.iter().all(|(t, m)| m.header.stamp_nanos == *t as i64 && m.header.frame_id == "imu_link"));
    let az: Vec<f64> = imu.iter().map(|(_, m)| m.linear_acceleration[2]).collect();
    let gx: Vec<f64> = imu.iter().map(|(_, m)| m.angular_velocity[0]).collect();
    // 4σ of the mean of 200 noisy samples is 0.005; the hold's own sway adds a little.
    assert!((mean(&az) - 9.81).abs() < 0.03, "mean a_z {}", mean(&az));
    // Standing still, the gyro's spread is its noise (the accelerometer also feels contact
    // vibration: its noise is checked below against a run with another seed).
    assert!((std_dev(&gx) / GYRO_STD - 1.0).abs() < 0.3, "gyro x std {} vs σ {GYRO_STD}", std_dev(&gx));
    assert_eq!(imu[0].1.linear_acceleration_covariance[0], ACCEL_STD * ACCEL_STD);

    // Odometry: pelvis at the nominal 0.71 m, twist in the pelvis frame, nearly still.
    let odom = read::<Odometry>(&mcap, "/odom");
    assert_eq!(odom.len(), 500);
    for (_, o) in &odom {
        assert_eq!((o.header.frame_id.as_str(), o.child_frame_id.as_str()), ("odom", "pelvis"));
        assert!((o.position[2] - 0.71).abs() < 0.01, "pelvis z {}", o.position[2]);
    }
    assert!(odom.last().unwrap().1.linear_velocity.iter().all(|v| v.abs() < 0.05));

    // Contacts: the feet carry the robot's weight (35.7 kg · 9.81), in their own frames.
    let total_mass = twin_core::mj::Model::from_file(repo_root().join("models/humanoid.urdf")).unwrap().total_mass_kg();
    let left = read::<WrenchStamped>(&mcap, "/contacts/left_foot_link");
    let right = read::<WrenchStamped>(&mcap, "/contacts/right_foot_link");
    assert_eq!((left.len(), right.len()), (500, 500));
    let (l, r) = (&left.last().unwrap().1, &right.last().unwrap().1);
    assert_eq!(l.header.frame_id, "left_foot_link");
    let weight = total_mass * 9.81;
    assert!(((l.force[2] + r.force[2]) / weight - 1.0).abs() < 0.02, "{} + {} vs {weight}", l.force[2], r.force[2]);
    assert!((l.force[2] - r.force[2]).abs() < 0.05 * weight, "symmetric stance");

    // Commands: one entry per actuator, as sent.
    let cmd = read::<Float64MultiArray>(&mcap, "/humanoid/joint_commands");
    assert_eq!(cmd.len(), 500);
    assert!(cmd.iter().all(|(_, c)| c.data.len() == 23));

    // TF: odom → pelvis equals the odometry pose; every body is in the tree.
    let tf = read::<TfMessage>(&mcap, "/tf");
    assert_eq!(tf.len(), 100);
    let (t_tf, first) = &tf[0];
    assert_eq!(*t_tf, 0);
    let base = first.transforms.iter().find(|t| t.child_frame_id == "pelvis").unwrap();
    assert_eq!(base.header.frame_id, "odom");
    assert_eq!(base.translation, odom[0].1.position);
    assert!(first.transforms.iter().any(|t| t.header.frame_id == "torso_link" && t.child_frame_id == "imu_link"));
    assert!(first.transforms.len() >= 24, "{}", first.transforms.len());

    // Same seed: same bytes; another seed: other IMU noise.
    let again = tmp(&dir, "again.mcap");
    sim(&["sim", "--duration", "1", "--record", s(&again), "--seed", "3"]);
    assert_eq!(std::fs::read(&mcap).unwrap(), std::fs::read(&again).unwrap());
    let other = tmp(&dir, "other.mcap");
    sim(&["sim", "--duration", "1", "--record", s(&other), "--seed", "4"]);
    let imu4 = read::<Imu>(&other, "/humanoid/imu/data");
    // Same physics, other noise draws: the difference of the two runs is noise only, σ·√2.
    for (axis, sigma) in [(0, ACCEL_STD), (2, ACCEL_STD)] {
        let d: Vec<f64> =
            imu.iter().zip(&imu4).map(|(a, b)| a.1.linear_acceleration[axis] - b.1.linear_acceleration[axis]).collect();
        let ratio = std_dev(&d) / (sigma * 2f64.sqrt());
        assert!((ratio - 1.0).abs() < 0.2, "accel axis {axis}: noise std ratio {ratio}");
        assert!(mean(&d).abs() < 4.0 * sigma * (2.0 / d.len() as f64).sqrt(), "zero-mean noise");
    }
    let d: Vec<f64> = imu.iter().zip(&imu4).map(|(a, b)| a.1.angular_velocity[1] - b.1.angular_velocity[1]).collect();
    assert!((std_dev(&d) / (GYRO_STD * 2f64.sqrt()) - 1.0).abs() < 0.2, "gyro noise {}", std_dev(&d));
    let js4 = read::<JointState>(&other, "/joint_states");
    assert_eq!(js4.last().unwrap().1.position, js.last().unwrap().1.position, "noise does not touch the physics");
}

fn xyz(v: &Json) -> [f64; 3] {
    [v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap(), v["z"].as_f64().unwrap()]
}

fn xyzw(v: &Json) -> [f64; 4] {
    [v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap(), v["z"].as_f64().unwrap(), v["w"].as_f64().unwrap()]
}

fn nums(v: &Json) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

fn stamp(v: &Json) -> i64 {
    v["header"]["stamp"]["sec"].as_i64().unwrap() * 1_000_000_000 + v["header"]["stamp"]["nanosec"].as_i64().unwrap()
}

#[test]
fn sim_record_decodes_identically_in_mcap_ros2_support_and_rosbags() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = tmp(&dir, "run.mcap");
    sim(&["sim", "--duration", "0.2", "--record", s(&mcap), "--seed", "1"]);
    let out = python_decode(&mcap);
    assert_eq!(out["profile"], "ros2");

    let js = read::<JointState>(&mcap, "/joint_states");
    let imu = read::<Imu>(&mcap, "/humanoid/imu/data");
    let odom = read::<Odometry>(&mcap, "/odom");
    let tf = read::<TfMessage>(&mcap, "/tf");
    let wrench = read::<WrenchStamped>(&mcap, "/contacts/left_foot_link");
    let cmd = read::<Float64MultiArray>(&mcap, "/humanoid/joint_commands");
    let total = js.len() + imu.len() + odom.len() + tf.len() + cmd.len() + 2 * wrench.len();

    for reader in ["mcap_ros2", "rosbags"] {
        let msgs = out[reader].as_array().unwrap();
        assert_eq!(msgs.len(), total, "{reader}: message count");
        let topic = |name: &str| -> Vec<&Json> { msgs.iter().filter(|m| m["topic"] == name).collect() };

        let p_js = topic("/joint_states");
        assert_eq!(p_js.len(), js.len(), "{reader}");
        for (p, (t, m)) in p_js.iter().zip(&js) {
            assert_eq!(p["log_time"].as_u64().unwrap(), *t, "{reader}");
            let v = &p["msg"];
            assert_eq!(stamp(v), m.header.stamp_nanos);
            let names: Vec<&str> = v["name"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
            assert_eq!(names, m.name);
            assert_eq!(nums(&v["position"]), m.position, "{reader}");
            assert_eq!(nums(&v["velocity"]), m.velocity, "{reader}");
            assert_eq!(nums(&v["effort"]), m.effort, "{reader}");
        }
        let p_imu = topic("/humanoid/imu/data");
        assert_eq!(p_imu.len(), imu.len(), "{reader}");
        for (p, (_, m)) in p_imu.iter().zip(&imu) {
            let v = &p["msg"];
            assert_eq!(v["header"]["frame_id"], "imu_link");
            assert_eq!(xyzw(&v["orientation"]), m.orientation_xyzw);
            assert_eq!(xyz(&v["angular_velocity"]), m.angular_velocity);
            assert_eq!(xyz(&v["linear_acceleration"]), m.linear_acceleration);
            assert_eq!(nums(&v["linear_acceleration_covariance"]), m.linear_acceleration_covariance);
        }
        let p_odom = topic("/odom");
        assert_eq!(p_odom.len(), odom.len(), "{reader}");
        for (p, (_, m)) in p_odom.iter().zip(&odom) {
            let v = &p["msg"];
            assert_eq!(v["child_frame_id"], "pelvis");
            assert_eq!(xyz(&v["pose"]["pose"]["position"]), m.position);
            assert_eq!(xyzw(&v["pose"]["pose"]["orientation"]), m.orientation_xyzw);
            assert_eq!(xyz(&v["twist"]["twist"]["linear"]), m.linear_velocity);
            assert_eq!(xyz(&v["twist"]["twist"]["angular"]), m.angular_velocity);
        }
        let p_tf = topic("/tf");
        assert_eq!(p_tf.len(), tf.len(), "{reader}");
        for (p, (_, m)) in p_tf.iter().zip(&tf) {
            let ts = p["msg"]["transforms"].as_array().unwrap();
            assert_eq!(ts.len(), m.transforms.len());
            for (a, b) in ts.iter().zip(&m.transforms) {
                assert_eq!(a["header"]["frame_id"].as_str().unwrap(), b.header.frame_id);
                assert_eq!(a["child_frame_id"].as_str().unwrap(), b.child_frame_id);
                assert_eq!(xyz(&a["transform"]["translation"]), b.translation);
                assert_eq!(xyzw(&a["transform"]["rotation"]), b.rotation_xyzw);
            }
        }
        let p_wr = topic("/contacts/left_foot_link");
        assert_eq!(p_wr.len(), wrench.len(), "{reader}");
        for (p, (_, m)) in p_wr.iter().zip(&wrench) {
            assert_eq!(xyz(&p["msg"]["wrench"]["force"]), m.force);
            assert_eq!(xyz(&p["msg"]["wrench"]["torque"]), m.torque);
        }
        let p_cmd = topic("/humanoid/joint_commands");
        assert_eq!(p_cmd.len(), cmd.len(), "{reader}");
        for (p, (_, m)) in p_cmd.iter().zip(&cmd) {
            assert_eq!(nums(&p["msg"]["data"]), m.data);
        }
    }
}

/// Joints that carry no body weight while standing: tracked by PD + velocity feed-forward alone.
const FREE_JOINTS: &[&str] = &[
    "waist_yaw_joint",
    "neck_yaw_joint",
    "left_shoulder_roll_joint",
    "left_shoulder_yaw_joint",
    "left_elbow_joint",
    "right_shoulder_roll_joint",
    "right_shoulder_yaw_joint",
    "right_elbow_joint",
];

#[test]
fn replay_of_a_recorded_log_tracks_its_trajectory() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = tmp(&dir, "replay.mcap");
    let stdout =
        sim(&["sim", "--duration", "1.5", "--controller", "replay", "--trajectory", FIXTURE, "--record", s(&mcap)]);
    assert!(stdout.contains("controller replay"), "{stdout}");
    let reference = JointTrajectory::from_log(Path::new(FIXTURE), "/joint_states").unwrap();
    let js = read::<JointState>(&mcap, "/joint_states");
    assert_eq!(js.len(), 750);
    // Tracking error per joint against the log interpolated at the same times.
    let mut errors: Vec<(String, f64, f64)> = Vec::new(); // (joint, sum of squares, worst)
    let mut swing = 0.0f64;
    for rj in &reference.joints {
        let k = js[0].1.name.iter().position(|n| *n == rj.name).unwrap();
        let (mut sum_sq, mut worst) = (0.0, 0.0f64);
        for (_, m) in &js {
            let (q_ref, _) = rj.sample(m.header.stamp_nanos as f64 * 1e-9);
            let e = m.position[k] - q_ref;
            sum_sq += e * e;
            worst = worst.max(e.abs());
            swing = swing.max((q_ref - rj.position[0]).abs());
        }
        errors.push((rj.name.clone(), sum_sq, worst));
    }
    let rms = |free: bool| {
        let sel: Vec<_> = errors.iter().filter(|(n, ..)| FREE_JOINTS.contains(&n.as_str()) == free).collect();
        (sel.iter().map(|e| e.1).sum::<f64>() / (sel.len() * js.len()) as f64).sqrt()
    };
    let worst = errors.iter().map(|e| e.2).fold(0.0, f64::max);
    eprintln!(
        "replay tracking over a ±{swing:.3} rad log: unloaded joints rms {:.4} rad, loaded joints rms {:.4} rad, worst {worst:.4} rad",
        rms(true),
        rms(false)
    );
    assert!(swing > 0.09, "the reference moves");
    // Unloaded joints follow within a few mrad (PD + feed-forward, no inverse dynamics).
    assert!(rms(true) < 0.005, "unloaded joints rms {} rad", rms(true));
    // Legs: the log moves each leg joint independently, which a robot standing on both feet can't
    // do (closed chain); they follow as far as the contacts allow and the robot stays up.
    assert!(rms(false) < 0.04 && worst < 0.12, "loaded joints rms {} rad, worst {worst} rad", rms(false));
    let odom = read::<Odometry>(&mcap, "/odom");
    assert!(odom.iter().all(|(_, o)| o.position[2] > 0.65), "the robot stays standing");
}

#[test]
fn replay_errors_name_the_file_and_the_joint() {
    let dir = tempfile::tempdir().unwrap();
    let csv = tmp(&dir, "traj.csv");
    std::fs::write(&csv, "time_sec,left_knee_joint,tail_joint\n0,0.1,0\n0.1,0.2,0\n").unwrap();
    let (ok, _, stderr) = run(&["sim", "--duration", "0.1", "--controller", "replay", "--trajectory", s(&csv)]);
    assert!(!ok);
    assert!(stderr.contains("traj.csv") && stderr.contains("\"tail_joint\" is not a joint of the model"), "{stderr}");
    assert!(stderr.contains("left_knee_joint"), "lists the joints that exist: {stderr}");

    std::fs::write(&csv, "time_sec,left_knee_joint\n0,0.1\n0.1,abc\n").unwrap();
    let (ok, _, stderr) = run(&["sim", "--duration", "0.1", "--controller", "replay", "--trajectory", s(&csv)]);
    assert!(!ok);
    assert!(stderr.contains("traj.csv:3") && stderr.contains("`abc` is not a finite number"), "{stderr}");

    let (ok, _, stderr) = run(&["sim", "--duration", "0.1", "--controller", "replay"]);
    assert!(!ok && stderr.contains("--trajectory"), "{stderr}");

    // A CSV that moves one knee is followed.
    std::fs::write(&csv, "time_sec,left_knee_joint\n0,0.2\n0.5,0.4\n").unwrap();
    let mcap = tmp(&dir, "csv.mcap");
    sim(&["sim", "--duration", "0.5", "--controller", "replay", "--trajectory", s(&csv), "--record", s(&mcap)]);
    let js = read::<JointState>(&mcap, "/joint_states");
    let k = js[0].1.name.iter().position(|n| n == "left_knee_joint").unwrap();
    let (_, last) = js.last().unwrap();
    let t = last.header.stamp_nanos as f64 * 1e-9;
    let expected = 0.2 + 0.2 * t / 0.5;
    // The knee bends under the robot's weight: PD without gravity compensation lags ~0.02 rad.
    assert!((last.position[k] - expected).abs() < 0.03, "{} vs {expected}", last.position[k]);
    assert!(last.position[k] > 0.35, "the knee followed the ramp from 0.2 rad: {}", last.position[k]);
}

#[test]
fn rerun_recordings_of_sim_and_view_verify() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = tmp(&dir, "run.rrd");
    let stdout = sim(&["sim", "--duration", "0.3", "--rerun", s(&rrd)]);
    assert!(stdout.contains("run.rrd"), "{stdout}");
    assert!(std::fs::metadata(&rrd).unwrap().len() > 10_000);

    let view = tmp(&dir, "view.rrd");
    let stdout = sim(&["view", FIXTURE, "-o", s(&view)]);
    // 1.99 s of log at 50 frames/s; all 23 joints of the humanoid animated.
    assert!(stdout.contains("100 frames, 23 joints animated"), "{stdout}");
    assert!(stdout.contains("4600 scalars"), "one scalar per joint sample: {stdout}");

    let (ok, _, stderr) = run(&["view", FIXTURE]);
    assert!(!ok && stderr.contains("-o LOG.rrd"), "{stderr}");
    let (ok, _, stderr) = run(&["view", s(&tmp(&dir, "missing.mcap")), "-o", s(&view)]);
    assert!(!ok && stderr.contains("missing.mcap"), "{stderr}");

    rerun_verify(&rrd);
    rerun_verify(&view);
}

/// A JointState log of the humanoid's left knee: one message per stamp of `stamps_nanos`.
fn knee_log(path: &Path, stamps_nanos: &[i64]) {
    let mut w = twin_core::log::LogWriter::create(path, &twin_core::log::WriterOptions::default()).unwrap();
    let topic = w.add_topic::<JointState>("/joint_states").unwrap();
    for (k, &t) in stamps_nanos.iter().enumerate() {
        let msg = JointState {
            header: twin_core::log::Header { stamp_nanos: t, frame_id: String::new() },
            name: vec!["left_knee_joint".into()],
            position: vec![0.2 + 1e-4 * k as f64],
            velocity: Vec::new(),
            effort: Vec::new(),
        };
        w.write(topic, 1_000_000_000 + k as u64 * 10_000_000, &msg).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn replay_and_view_warn_when_time_goes_backwards_or_stands_still() {
    let dir = tempfile::tempdir().unwrap();
    // 30 s at 100 Hz whose clock jumps 15 s back after 20 s.
    let back = tmp(&dir, "back.mcap");
    let stamps: Vec<i64> =
        (0..3000).map(|k| 100_000_000_000 + k * 10_000_000 - if k >= 2000 { 15_000_000_000 } else { 0 }).collect();
    knee_log(&back, &stamps);
    // Replayed by `twin sim` and shown by `twin view`, both warn naming the file: sim's stderr.
    let replayed_with_warning = |log: &Path, name: &str, warning: &str| {
        let (ok, _, stderr) = run(&["sim", "--duration", "0.1", "--controller", "replay", "--trajectory", s(log)]);
        assert!(ok && stderr.contains(name) && stderr.contains(warning), "{stderr}");
        let rrd = log.with_extension("rrd");
        let (ok, stdout, view_stderr) = run(&["view", s(log), "-o", s(&rrd)]);
        assert!(ok && view_stderr.contains(warning), "{stdout}{view_stderr}");
        stderr
    };
    let stderr = replayed_with_warning(&back, "back.mcap", "time goes backwards");
    assert!(stderr.contains("1000 samples") && stderr.contains("14.99"), "{stderr}");

    // 10 000 samples sharing one stamp.
    let still = tmp(&dir, "still.mcap");
    knee_log(&still, &vec![5_000_000_000; 10_000]);
    let stderr = replayed_with_warning(&still, "still.mcap", "time stands still");
    assert!(stderr.contains("9999 samples") && stderr.contains("10000 samples at one instant"), "{stderr}");
}

/// `--seed` seeds the run's one sensor model: another seed, another IMU noise in what is
/// recorded, and (the walker balances on its IMU) other joint motion; the same seed, the same
/// bytes.
#[test]
fn sim_seed_sets_the_observed_imu_noise_and_through_the_walker_the_joint_states() {
    let dir = tempfile::tempdir().unwrap();
    let record = |seed: &str| {
        let file = dir.path().join(format!("seed{seed}-{}.mcap", std::process::id()));
        let (ok, out, err) = run(&[
            "sim",
            "--controller",
            "walk",
            "--duration",
            "0.5",
            "--seed",
            seed,
            "--topics",
            "/joint_states,/humanoid/imu/data",
            "--record",
            file.to_str().unwrap(),
        ]);
        assert!(ok, "{out}\n{err}");
        let log = Log::open(&file, ReadOptions { strict: true }).unwrap();
        let imu: Vec<Imu> = log.read_typed::<Imu>("/humanoid/imu/data").unwrap().0.into_iter().map(|m| m.1).collect();
        let js: Vec<JointState> =
            log.read_typed::<JointState>("/joint_states").unwrap().0.into_iter().map(|m| m.1).collect();
        std::fs::remove_file(&file).unwrap();
        (imu, js)
    };
    let (imu1, js1) = record("1");
    let (imu2, js2) = record("2");
    assert_eq!((imu1.len(), js1.len()), (100, 250));
    let gyro = |m: &Imu| m.angular_velocity;
    assert!(imu1.iter().zip(&imu2).all(|(a, b)| gyro(a) != gyro(b)), "every IMU sample differs between seeds");
    assert!(js1.last().unwrap().position != js2.last().unwrap().position, "the walker's joints differ");
    assert!(record("1") == (imu1, js1), "the same seed, the same recording");
}

/// `--controller` takes only the registered names: anything else is clap's usage error (exit
/// 2) listing them, before any model is loaded.
#[test]
fn an_unknown_controller_is_a_usage_error_listing_the_names() {
    let out = super::common::twin().args(["sim", "--controller", "bogus"]).output().expect("twin runs");
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("invalid value 'bogus' for '--controller <CONTROLLER>'"), "{stderr}");
    assert!(stderr.contains("[possible values: pd-hold, passive, replay, walk, grasp, ros]"), "{stderr}");
}
