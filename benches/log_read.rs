//! Log reading and writing speed.
//!
//! `cargo bench --bench log_read` (env: `TWIN_PYTHON` = a Python with `mcap` and
//! `mcap-ros2-support` for the comparison, default `python3`; `TWIN_BENCH_MB` = bag size in MB,
//! default 100).
//!
//! 1. Write throughput: 23-joint humanoid JointStates through [`LogWriter`] (zstd chunks), in
//!    messages/s and µs per message, against the humanoid's own MuJoCo step time at 500 Hz
//!    logging (the ≤ 10 % budget of `twin sim --record`).
//! 2. Read speed: a ~100 MB ROS 2 bag (JointState, IMU, odometry, TF, wrenches, commands at
//!    500 Hz) decoded for `/joint_states` by twin and by `mcap-ros2-support`, same file, same run.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::time::Instant;
use twin_core::log::*;

fn humanoid_joint_names() -> Vec<String> {
    let urdf = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf"))
        .expect("models/humanoid.urdf");
    urdf.split("<joint ")
        .skip(1)
        .filter(|j| j.contains("type=\"revolute\""))
        .filter_map(|j| j.split("name=\"").nth(1)?.split('"').next().map(String::from))
        .collect()
}

/// Deterministic joint-like signals (no RNG dependency): smooth motion plus a small
/// pseudo-random jitter so the data compresses like real sensor values.
struct Signals {
    rng: ChaCha8Rng,
}

impl Signals {
    fn noise(&mut self) -> f64 {
        self.rng.random_range(-0.5..0.5)
    }

    fn joint_state(&mut self, names: &[String], i: u64, js: &mut JointState) {
        let t = i as f64 * 0.002;
        js.header.stamp_nanos = (i * 2_000_000) as i64;
        js.name.clone_from_slice(names);
        for k in 0..names.len() {
            let phase = t * (1.0 + k as f64 * 0.1);
            js.position[k] = 0.5 * phase.sin() + 1e-4 * self.noise();
            js.velocity[k] = 0.5 * phase.cos() + 1e-3 * self.noise();
            js.effort[k] = 10.0 * phase.sin() + 0.05 * self.noise();
        }
    }
}

fn new_joint_state(names: &[String]) -> JointState {
    JointState {
        header: Header::default(),
        name: names.to_vec(),
        position: vec![0.0; names.len()],
        velocity: vec![0.0; names.len()],
        effort: vec![0.0; names.len()],
    }
}

fn write_throughput(dir: &Path, names: &[String]) -> f64 {
    let path = dir.join("throughput.mcap");
    let n = 200_000u64;
    let mut sig = Signals { rng: ChaCha8Rng::seed_from_u64(1) };
    let mut js = new_joint_state(names);
    let mut w = LogWriter::create(&path, &WriterOptions::default()).unwrap();
    let topic = w.add_topic::<JointState>("/joint_states").unwrap();
    // Signal generation is timed separately and subtracted: it stands in for the simulation.
    let gen_start = Instant::now();
    for i in 0..n {
        sig.joint_state(names, i, &mut js);
    }
    let gen_secs = gen_start.elapsed().as_secs_f64();
    let start = Instant::now();
    for i in 0..n {
        sig.joint_state(names, i, &mut js);
        w.write(topic, i * 2_000_000, &js).unwrap();
    }
    let summary = w.finish().unwrap();
    // Until the file is closed: encoding, compression and I/O together (writer thread bound).
    let secs = start.elapsed().as_secs_f64() - gen_secs;
    let us = secs / n as f64 * 1e6;
    println!(
        "write: {n} JointState (23 joints) back to back, file closed after {secs:.3} s -> {:.0} \
         messages/s, {us:.2} µs/message end to end, {:.1} MB file ({} chunks)",
        n as f64 / secs,
        summary.bytes as f64 / 1e6,
        summary.chunks
    );
    us
}

/// Simulates the humanoid with and without logging a JointState every step (500 Hz at its
/// 2 ms timestep); returns (µs per step without, with logging, timestep).
fn sim_with_logging(dir: &Path, names: &[String]) -> Option<(f64, f64, f64)> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf");
    let model = Arc::new(twin_core::mj::Model::from_file(path).ok()?);
    let dt = model.timestep_secs();
    let steps_per_log = ((1.0 / 500.0) / dt).round().max(1.0) as u64;
    let n = 20_000u64;
    let run = |log: Option<&mut LogWriter>| -> Option<f64> {
        let mut data = twin_core::mj::Data::new(model.clone()).ok()?;
        let mut js = new_joint_state(names);
        let mut log = log.map(|w| (w.add_topic::<JointState>("/joint_states").unwrap(), w));
        let start = Instant::now();
        for i in 0..n {
            if data.step().is_err() || data.diverged() {
                data.reset().ok()?;
            }
            if let Some((topic, w)) = &mut log
                && i % steps_per_log == 0
            {
                // The 23 hinge joints come last (after a free joint's 7/6 coordinates, if any).
                let (q, v) = (data.qpos(), data.qvel());
                let (qo, vo) = (q.len() - names.len(), v.len() - names.len());
                js.header.stamp_nanos = (data.time_secs() * 1e9) as i64;
                for k in 0..names.len() {
                    js.position[k] = q[qo + k];
                    js.velocity[k] = v[vo + k];
                    js.effort[k] = data.qfrc_actuator()[vo + k];
                }
                w.write(*topic, js.header.stamp_nanos as u64, &js).unwrap();
            }
        }
        Some(start.elapsed().as_secs_f64() / n as f64 * 1e6)
    };
    let plain = run(None)?;
    let mut w = LogWriter::create(dir.join("sim.mcap"), &WriterOptions::default()).unwrap();
    let logged = run(Some(&mut w))?;
    w.finish().unwrap();
    // Repeat the plain run: the first one also warmed caches.
    let plain = plain.min(run(None)?);
    Some((plain, logged, dt))
}

fn write_bag(path: &Path, names: &[String], target_bytes: u64) -> u64 {
    let mut w = LogWriter::create(path, &WriterOptions::default()).unwrap();
    let t_js = w.add_topic::<JointState>("/joint_states").unwrap();
    let t_imu = w.add_topic::<Imu>("/humanoid/imu/data").unwrap();
    let t_odom = w.add_topic::<Odometry>("/odom").unwrap();
    let t_tf = w.add_topic::<TfMessage>("/tf").unwrap();
    let t_lw = w.add_topic::<WrenchStamped>("/left_foot/wrench").unwrap();
    let t_rw = w.add_topic::<WrenchStamped>("/right_foot/wrench").unwrap();
    let t_cmd = w.add_topic::<Float64MultiArray>("/humanoid/joint_commands").unwrap();
    let mut sig = Signals { rng: ChaCha8Rng::seed_from_u64(42) };
    let mut js = new_joint_state(names);
    let mut imu = Imu::default();
    let mut odom = Odometry::default();
    let mut tf = TfMessage {
        transforms: vec![TransformStamped {
            header: Header { stamp_nanos: 0, frame_id: "odom".into() },
            child_frame_id: "pelvis".into(),
            translation: [0.0, 0.0, 0.71],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        }],
    };
    let mut wrench = WrenchStamped::default();
    let mut cmd = Float64MultiArray { data: vec![0.0; names.len()], ..Default::default() };
    let mut i = 0u64;
    let mut joint_states = 0;
    loop {
        let t = i * 2_000_000;
        sig.joint_state(names, i, &mut js);
        w.write(t_js, t, &js).unwrap();
        joint_states += 1;
        imu.header.stamp_nanos = t as i64;
        imu.angular_velocity = [sig.noise(), sig.noise(), sig.noise()];
        imu.linear_acceleration = [sig.noise(), sig.noise(), 9.81 + sig.noise()];
        w.write(t_imu, t, &imu).unwrap();
        odom.header.stamp_nanos = t as i64;
        odom.position = [i as f64 * 1e-4, sig.noise() * 1e-3, 0.71];
        w.write(t_odom, t, &odom).unwrap();
        tf.transforms[0].header.stamp_nanos = t as i64;
        tf.transforms[0].translation = odom.position;
        w.write(t_tf, t, &tf).unwrap();
        wrench.header.stamp_nanos = t as i64;
        wrench.force = [sig.noise(), sig.noise(), 170.0 + sig.noise()];
        w.write(t_lw, t, &wrench).unwrap();
        w.write(t_rw, t, &wrench).unwrap();
        cmd.data.copy_from_slice(&js.position);
        w.write(t_cmd, t, &cmd).unwrap();
        i += 1;
        if i.is_multiple_of(5000) && std::fs::metadata(path).map(|m| m.len()).unwrap_or(0) >= target_bytes {
            break;
        }
    }
    w.finish().unwrap();
    joint_states
}

fn main() {
    // `cargo test --benches` runs this with --bench absent; keep that quick.
    if !std::env::args().any(|a| a == "--bench") {
        println!("log_read: run with `cargo bench --bench log_read`");
        return;
    }
    let names = humanoid_joint_names();
    assert_eq!(names.len(), 23);
    let dir = tempfile::tempdir().unwrap();

    write_throughput(dir.path(), &names);
    match sim_with_logging(dir.path(), &names) {
        Some((plain_us, logged_us, dt)) => println!(
            "sim: humanoid step {plain_us:.2} µs without logging, {logged_us:.2} µs with a \
             JointState every 500 Hz tick (timestep {dt} s) -> logging costs {:.1} % of \
             simulation time",
            (logged_us - plain_us) / plain_us * 100.0
        ),
        None => println!("sim: skipped (humanoid model did not load)"),
    }

    let mb: u64 = std::env::var("TWIN_BENCH_MB").ok().and_then(|s| s.parse().ok()).unwrap_or(100);
    let bag = dir.path().join("bag.mcap");
    let start = Instant::now();
    let written = write_bag(&bag, &names, mb * 1_000_000);
    let size = std::fs::metadata(&bag).unwrap().len();
    println!(
        "bag: {:.1} MB, {written} JointState among 7 topics at 500 Hz, written in {:.2} s",
        size as f64 / 1e6,
        start.elapsed().as_secs_f64()
    );

    // twin: best of 3 (file in page cache for both sides).
    let mut best = f64::INFINITY;
    let mut count = 0;
    let mut position_sum = 0.0;
    for _ in 0..3 {
        let start = Instant::now();
        let log = Log::open(&bag, ReadOptions::default()).unwrap();
        let series = log.joint_states("/joint_states").unwrap();
        let secs = start.elapsed().as_secs_f64();
        best = best.min(secs);
        count = series.joints[0].len();
        // Same sum order as the Python side: per message, then over messages.
        position_sum = (0..count).map(|i| series.joints.iter().map(|j| j.position[i]).sum::<f64>()).sum();
    }
    println!(
        "twin: {count} JointState decoded into per-joint series in {best:.3} s ({:.0} MB/s, {:.2} µs/message)",
        size as f64 / 1e6 / best,
        best / count as f64 * 1e6
    );

    let python = std::env::var("TWIN_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/log_read.py");
    match Command::new(&python).arg(script).arg(&bag).output() {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            let field = |k: &str| -> f64 {
                text.split(&format!("\"{k}\": "))
                    .nth(1)
                    .and_then(|s| s.split([',', '}']).next())
                    .and_then(|s| s.trim().parse().ok())
                    .unwrap_or(f64::NAN)
            };
            let (py_count, py_sum, py_secs) = (field("count"), field("position_sum"), field("secs"));
            assert_eq!(py_count as usize, count, "both read every JointState");
            assert!((py_sum - position_sum).abs() <= 1e-9 * position_sum.abs().max(1.0));
            println!(
                "mcap-ros2-support: {py_count} JointState in {py_secs:.3} s ({:.2} µs/message)",
                py_secs / py_count * 1e6
            );
            println!("speedup: twin is {:.1}x faster", py_secs / best);
        }
        Ok(out) => {
            println!("mcap-ros2-support: skipped ({}): {}", out.status, String::from_utf8_lossy(&out.stderr).trim())
        }
        Err(e) => println!("mcap-ros2-support: skipped, cannot run {python}: {e}"),
    }
}
