//! `twin calibrate noise` and `twin sysid friction`: still and sweep logs through ROS 2 bags,
//! URDF write-back with backup, plots, spec fragment, and refusals that leave the URDF alone.

use super::common::assert_untouched;
use std::path::Path;
use std::process::{Command, Output};
use sysid::noise::{AxisTruth, synth_imu};

fn twin(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).current_dir(dir).args(args).output().expect("twin runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A still humanoid IMU (frame `imu_link`, the URDF's) at 200 Hz: gyro N = 1.5e-4, accel
/// N = 6e-3, nothing else.
/// A temporary folder holding a copy of `models/<name>`, and the copy's bytes (what a refused
/// or dry run must leave untouched).
fn copy_of(name: &str) -> (tempfile::TempDir, Vec<u8>) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(root().join("models").join(name), dir.path().join(name)).unwrap();
    let original = std::fs::read(dir.path().join(name)).unwrap();
    (dir, original)
}

fn write_still_bag(path: &Path, seconds: f64, moved_at: Option<f64>) {
    let t =
        |off: f64, n: f64| AxisTruth { offset: off, white_density: n, bias_instability: 0.0, bias_random_walk: 0.0 };
    let mut imu = synth_imu(
        "/humanoid/imu/data",
        "imu_link",
        [t(0.0, 1.5e-4); 3],
        [t(0.0, 6e-3), t(0.0, 6e-3), t(9.81, 6e-3)],
        200.0,
        seconds,
        3,
    );
    if let Some(at) = moved_at {
        for (k, &tn) in imu.t_nanos.clone().iter().enumerate() {
            let s = (tn - imu.t_nanos[0]) as f64 * 1e-9;
            if (at..at + 2.0).contains(&s) {
                imu.accel[0][k] += 1.5;
            }
        }
    }
    let mut w = twin_core::log::LogWriter::create(path, &twin_core::log::WriterOptions::default()).unwrap();
    imu.write_to(&mut w).unwrap();
    w.finish().unwrap();
}

#[test]
fn calibrate_noise_writes_the_imu_noise_into_the_urdf_plot_and_spec() {
    let (dir, original) = copy_of("humanoid.urdf");
    let d = dir.path();
    let original = String::from_utf8(original).unwrap();
    write_still_bag(&d.join("still.mcap"), 300.0, None);
    let out = twin(
        d,
        &[
            "calibrate",
            "noise",
            "--log",
            "still.mcap",
            "--update",
            "humanoid.urdf",
            "--plot",
            "allan.svg",
            "--spec",
            "noise.toml",
            "--report",
            "noise.json",
            "--rerun",
            "allan.rrd",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    // The Allan plot in the rerun recording is a valid .rrd.
    super::sim::rerun_verify(&d.join("allan.rrd"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("IMU /humanoid/imu/data (frame imu_link)") && stdout.contains("gyro x"), "{stdout}");
    assert_eq!(std::fs::read_to_string(d.join("humanoid.urdf.bak")).unwrap(), original);
    let new = std::fs::read_to_string(d.join("humanoid.urdf")).unwrap();
    let doc = roxmltree::Document::parse(&new).unwrap();
    let stddevs: Vec<f64> =
        doc.descendants().filter(|n| n.has_tag_name("stddev")).map(|n| n.text().unwrap().parse().unwrap()).collect();
    assert_eq!(stddevs.len(), 6);
    // Per-sample stddev = N·√200 within 10 % of the simulated one.
    for (k, s) in stddevs.iter().enumerate() {
        let want = if k < 3 { 1.5e-4 } else { 6e-3 } * 200f64.sqrt();
        assert!((s / want - 1.0).abs() < 0.1, "axis {k}: {s} vs {want}");
    }
    // Only <noise> lines changed.
    let changed: Vec<&str> = original.lines().zip(new.lines()).filter(|(a, b)| a != b).map(|(a, _)| a).collect();
    assert!(changed.iter().all(|l| l.contains("<stddev>")), "{changed:?}");
    // The spec fragment is a valid `twin randomize` spec.
    let spec = std::fs::read_to_string(d.join("noise.toml")).unwrap();
    let parsed = randomize::spec::Spec::from_toml_str(&spec).unwrap();
    assert!(parsed.imu_noise_std.is_some(), "{spec}");
    assert!(roxmltree::Document::parse(&std::fs::read_to_string(d.join("allan.svg")).unwrap()).is_ok());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("noise.json")).unwrap()).unwrap();
    assert_eq!(report["imus"][0]["axes"].as_array().unwrap().len(), 6);
}

#[test]
fn calibrate_noise_refuses_a_moving_robot_and_a_short_log_leaving_the_urdf_untouched() {
    let (dir, original) = copy_of("humanoid.urdf");
    let d = dir.path();
    write_still_bag(&d.join("moved.mcap"), 200.0, Some(50.0));
    let out = twin(d, &["calibrate", "noise", "--log", "moved.mcap", "--update", "humanoid.urdf"]);
    let err = stderr(&out);
    assert!(!out.status.success());
    assert!(err.contains("humanoid.urdf was not changed") && err.contains("the robot moved: accelerometer x"), "{err}");
    assert!(err.contains("/humanoid/imu/data") && err.contains("t = 50.0–"), "{err}");
    write_still_bag(&d.join("short.mcap"), 100.0, None);
    let out = twin(d, &["calibrate", "noise", "--log", "short.mcap", "--update", "humanoid.urdf", "--tau-max", "100"]);
    let err = stderr(&out);
    assert!(!out.status.success() && err.contains("too short for τ up to 100 s"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_untouched(&d.join("humanoid.urdf"), &original);
}

#[test]
fn sysid_friction_fits_sweeps_and_writes_the_dynamics() {
    use sysid::friction::{Stribeck, SweepOptions, synth_sweep};
    let (dir, original) = copy_of("arm6.urdf");
    let d = dir.path();
    let original = String::from_utf8(original).unwrap();
    let arm = root().join("models/arm6.urdf");
    let truth: Vec<Stribeck> = (0..6)
        .map(|j| Stribeck {
            coulomb: 2.0 / (1.0 + j as f64),
            breakaway: 3.0 / (1.0 + j as f64),
            stribeck_velocity: 0.05,
            exponent: 1.0,
            viscous: 0.5 / (1.0 + j as f64),
        })
        .collect();
    let opts = SweepOptions { rate_hz: 200.0, ..Default::default() };
    synth_sweep(&arm, &truth, &opts).unwrap().write_mcap(d.join("sweeps.mcap"), "/joint_states").unwrap();
    let out = twin(
        d,
        &[
            "sysid",
            "friction",
            "--log",
            "sweeps.mcap",
            "--update",
            "arm6.urdf",
            "--plot",
            "f.svg",
            "--report",
            "f.json",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(std::fs::read_to_string(d.join("arm6.urdf.bak")).unwrap(), original);
    let new = std::fs::read_to_string(d.join("arm6.urdf")).unwrap();
    let doc = roxmltree::Document::parse(&new).unwrap();
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("f.json")).unwrap()).unwrap();
    for (j, t) in truth.iter().enumerate() {
        let joint = doc
            .descendants()
            .filter(|n| n.has_tag_name("joint") && n.attribute("type") != Some("fixed"))
            .nth(j)
            .unwrap();
        let dynamics = joint.children().find(|c| c.has_tag_name("dynamics")).unwrap();
        let friction: f64 = dynamics.attribute("friction").unwrap().parse().unwrap();
        let damping: f64 = dynamics.attribute("damping").unwrap().parse().unwrap();
        // Within 10 % here (200 Hz, light wrist friction against 0.05 N·m effort noise); the 5 %
        // figures are sysid/tests/it/friction.rs's.
        assert!((friction / t.coulomb - 1.0).abs() < 0.1, "joint {j}: friction {friction} vs {}", t.coulomb);
        assert!((damping / t.viscous - 1.0).abs() < 0.1, "joint {j}: damping {damping} vs {}", t.viscous);
        // What is written is what the report says.
        let fit = &report["joints"][j]["fit"];
        assert!((friction / fit["coulomb"].as_f64().unwrap() - 1.0).abs() < 1e-6, "{fit}");
        assert!((damping / fit["viscous"].as_f64().unwrap() - 1.0).abs() < 1e-6, "{fit}");
    }
    assert!(d.join("f.svg").is_file() && d.join("f.json").is_file());
}

#[test]
fn sysid_friction_refuses_a_log_without_constant_velocity_and_leaves_the_urdf_untouched() {
    let (dir, original) = copy_of("arm6.urdf");
    let d = dir.path();
    let arm = root().join("models/arm6.urdf");
    let log =
        sysid::synth::simulate(&arm, &sysid::synth::SynthOptions { duration_secs: 6.0, ..Default::default() }).unwrap();
    log.write_mcap(d.join("sines.mcap"), "/joint_states").unwrap();
    let out = twin(d, &["sysid", "friction", "--log", "sines.mcap", "--update", "arm6.urdf"]);
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("arm6.urdf was not changed") && err.contains("no constant-velocity segment"), "{err}");
    assert!(err.contains("joint \"shoulder_pan_joint\""), "{err}");
    assert_untouched(&d.join("arm6.urdf"), &original);
}

/// `twin sim --friction-fit`: the fitted Stribeck curves of `twin sysid friction --report`
/// run on their joints; a fit naming a joint the robot lacks is refused naming it.
#[test]
fn sim_runs_the_fitted_stribeck_curves_and_refuses_unknown_joints() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let arm = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/arm6.urdf");
    let fit = |joint: &str| {
        format!(
            r#"{{"log": "sweeps.mcap", "joints": [{{"joint": "{joint}", "fit": {{"coulomb": 2.0, "breakaway": 3.5,
            "stribeck_velocity": 0.1, "exponent": 1.5, "viscous": 1.0}}, "ci95": [0,0,0,0,0], "rms_residual": 0.01,
            "points": [], "segments": 10}}]}}"#
        )
    };
    std::fs::write(d.join("friction.json"), fit("elbow_joint")).unwrap();
    let out = twin(d, &["sim", arm.to_str().unwrap(), "--friction-fit", "friction.json", "--duration", "0.5"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    std::fs::write(d.join("bad.json"), fit("no_such_joint")).unwrap();
    let out = twin(d, &["sim", arm.to_str().unwrap(), "--friction-fit", "bad.json", "--duration", "0.5"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.json") && err.contains("\"no_such_joint\" is not a joint"), "{err}");
}

/// A block welded to the world with a 100 Hz IMU and no noise yet: the twin's IMU reads the
/// bare physics (0 rad/s, +9.81 m/s² on z) plus whatever `<noise>` says.
const IMU_BLOCK_URDF: &str = r#"<robot name="imu_block">
  <link name="world"/>
  <link name="block"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="mount" type="fixed"><parent link="world"/><child link="block"/><origin xyz="0 0 0.5"/></joint>
  <gazebo reference="block">
    <sensor name="imu" type="imu">
      <update_rate>100</update_rate>
      <plugin name="imu" filename="libgazebo_ros_imu_sensor.so"><ros><namespace>/block</namespace><remapping>~/out:=imu/data</remapping></ros><frame_name>imu_link</frame_name></plugin>
    </sensor>
  </gazebo>
</robot>
"#;

/// Issue 14's noise must-show end to end: a synthetic IMU with known white noise N, bias
/// instability B and bias random walk K (1 h at 100 Hz) → `twin calibrate noise --update`
/// writes the `<noise>` tags → `twin sim` of that URDF (1 h) records an IMU whose Allan
/// deviation is the original's within 10 % where each term dominates. The terms (B = 3·N,
/// K = 0.41·B, as in sysid's noise tests) put white noise below τ₁ = N²/(0.664·B)² = 0.25 s,
/// the floor around √3·N/K ≈ 1.4 s and the random walk above τ₂ = 3·(0.664·B)²/K² ≈ 8 s: all
/// three regions fit inside 0.01–120 s, so one hour (not the many hours a real IMU's terms
/// need) resolves each with ≥ 30 clusters; the 6 axes are averaged to shrink the scatter.
#[test]
fn calibrated_noise_tags_make_the_simulated_imu_reproduce_the_allan_deviation() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("imu.urdf"), IMU_BLOCK_URDF).unwrap();
    let t = |off: f64, n: f64| AxisTruth {
        offset: off,
        white_density: n,
        bias_instability: 3.0 * n,
        bias_random_walk: 0.41 * 3.0 * n,
    };
    let gyro = [t(0.0, 2.0e-4); 3];
    let accel = [t(0.0, 3.0e-3), t(0.0, 3.0e-3), t(9.81, 3.0e-3)];
    let (rate_hz, seconds) = (100.0, 3600.0);
    let imu = synth_imu("/block/imu/data", "imu_link", gyro, accel, rate_hz, seconds, 11);
    let mut w =
        twin_core::log::LogWriter::create(d.join("still.mcap"), &twin_core::log::WriterOptions::default()).unwrap();
    imu.write_to(&mut w).unwrap();
    w.finish().unwrap();

    let out = twin(d, &["calibrate", "noise", "--log", "still.mcap", "--update", "imu.urdf"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let urdf = std::fs::read_to_string(d.join("imu.urdf")).unwrap();
    for tag in ["<stddev>", "<dynamic_bias_stddev>", "<dynamic_bias_correlation_time>", "<bias_random_walk>"] {
        assert_eq!(urdf.matches(tag).count(), 6, "{tag} per axis in\n{urdf}");
    }
    let out = twin(
        d,
        &[
            "sim",
            "imu.urdf",
            "--duration",
            "3600",
            "--record",
            "sim.mcap",
            "--topics",
            "/block/imu/data",
            "--seed",
            "4",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let (logs, _) = sysid::noise::read_imus(&d.join("sim.mcap"), None).unwrap();
    let sim = &logs[0];
    assert!(sim.rate_hz() > 99.0 && sim.duration_secs() > 3590.0, "{} Hz, {} s", sim.rate_hz(), sim.duration_secs());

    // Allan deviation of each simulated axis over the original's (the truth curve), averaged
    // over the 6 axes and over the τ of each region.
    let ms = sysid::allan::cluster_sizes(12_000, 10);
    let truths: Vec<AxisTruth> = gyro.into_iter().chain(accel).collect();
    let series: Vec<&Vec<f64>> = sim.gyro.iter().chain(sim.accel.iter()).collect();
    let mut ratios: Vec<(f64, f64)> = Vec::new();
    for (x, truth) in series.iter().zip(&truths) {
        let floor = sysid::allan::BIAS_INSTABILITY_FLOOR * truth.bias_instability;
        for p in sysid::allan::overlapping_adev(x, rate_hz, &ms) {
            let tau = p.tau_secs;
            let want =
                (truth.white_density.powi(2) / tau + floor * floor + truth.bias_random_walk.powi(2) * tau / 3.0).sqrt();
            ratios.push((tau, p.adev / want));
        }
    }
    let n = gyro[0].white_density;
    let (b, k) = (gyro[0].bias_instability, gyro[0].bias_random_walk);
    let floor = sysid::allan::BIAS_INSTABILITY_FLOOR * b;
    let (tau_white, tau_walk, tau_min) = ((n / floor).powi(2), 3.0 * (floor / k).powi(2), 3f64.sqrt() * n / k);
    for (what, lo, hi) in [
        // Below τ₁/5: the Gauss–Markov peak that stands for the floor has faded there, and
        // the original's flat floor still adds a few % to its white line.
        ("white noise", 0.01, tau_white / 5.0),
        ("bias instability", tau_min / 2.0, tau_min * 2.0),
        ("random walk", tau_walk * 3.0, seconds / 30.0),
    ] {
        let inside: Vec<f64> = ratios.iter().filter(|(tau, _)| (lo..=hi).contains(tau)).map(|r| r.1).collect();
        assert!(inside.len() >= 6 * 3, "{what}: only {} points in {lo:.3}–{hi:.1} s", inside.len());
        let mean = inside.iter().sum::<f64>() / inside.len() as f64;
        eprintln!("{what} ({lo:.3}–{hi:.1} s): simulated / original Allan deviation = {mean:.3}");
        assert!((mean - 1.0).abs() < 0.10, "{what} ({lo:.3}–{hi:.1} s): simulated/original = {mean:.3}");
    }
}

/// The twin's IMU bias model term by term: Gazebo's turn-on bias (`bias_mean`, random sign,
/// constant) and its first-order Gauss–Markov dynamic bias, whose stationary deviation is
/// σ_b·√(τ/2) and whose autocorrelation at lag L is e^(−L/τ); same seed, same samples.
#[test]
fn sim_imu_turn_on_and_gauss_markov_bias_have_gazebos_statistics() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let noise = |inner: &str| format!("<x>{inner}</x><y>{inner}</y><z>{inner}</z>");
    let imu = format!(
        "<imu><angular_velocity>{}</angular_velocity><linear_acceleration>{}</linear_acceleration></imu>",
        noise("<noise type=\"gaussian\"><stddev>0</stddev><bias_mean>0.5</bias_mean></noise>"),
        noise(
            "<noise type=\"gaussian\"><stddev>0</stddev><dynamic_bias_stddev>0.2</dynamic_bias_stddev>\
             <dynamic_bias_correlation_time>2</dynamic_bias_correlation_time></noise>"
        ),
    );
    let urdf =
        IMU_BLOCK_URDF.replace("<update_rate>100</update_rate>", &format!("<update_rate>100</update_rate>{imu}"));
    std::fs::write(d.join("imu.urdf"), urdf).unwrap();
    for (file, seed) in [("a.mcap", "1"), ("b.mcap", "1"), ("c.mcap", "2")] {
        let out = twin(
            d,
            &["sim", "imu.urdf", "--duration", "1200", "--record", file, "--topics", "/block/imu/data", "--seed", seed],
        );
        assert!(out.status.success(), "{}", stderr(&out));
    }
    let read = |f: &str| sysid::noise::read_imus(&d.join(f), None).unwrap().0.remove(0);
    let (a, b, c) = (read("a.mcap"), read("b.mcap"), read("c.mcap"));
    assert_eq!(a.gyro, b.gyro);
    assert_eq!(a.accel, b.accel);
    assert_ne!(a.accel, c.accel);
    // Turn-on bias: ±0.5 rad/s on each axis, constant.
    for x in &a.gyro {
        assert!(x.iter().all(|v| (v.abs() - 0.5).abs() < 1e-9 && v.signum() == x[0].signum()), "{:?}", &x[..3]);
    }
    // Gauss–Markov: stationary σ = 0.2·√(2/2) = 0.2, lag-1 s autocorrelation e^(−1/2).
    let (mut var, mut cov, mut count) = (0.0, 0.0, 0.0);
    for x in &a.accel {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let y: Vec<f64> = x.iter().map(|v| v - mean).collect();
        var += y.iter().map(|v| v * v).sum::<f64>();
        cov += y.iter().zip(&y[100..]).map(|(p, q)| p * q).sum::<f64>();
        count += y.len() as f64;
    }
    let sigma = (var / count).sqrt();
    let rho = cov / var;
    assert!((sigma / 0.2 - 1.0).abs() < 0.1, "stationary σ {sigma}");
    assert!((rho - (-0.5f64).exp()).abs() < 0.06, "lag-1 s autocorrelation {rho}");
}

/// A sweep bag made without twin (`tests/python/friction_sweep.py`: three pendulum joints under
/// PD + feed-forward tracking, Stribeck friction, `nspeeds` speeds from 0.03 to 1.2 rad/s per
/// direction, 1 s settle before each sweep) in `dir/sweep`; returns the script's truth.
fn independent_sweep(dir: &Path, nspeeds: usize, stribeck: bool) -> serde_json::Value {
    let script = root().join("tests/python/friction_sweep.py");
    let mut cmd = Command::new(crate::test_python::python());
    cmd.arg(&script).arg(dir.join("sweep")).arg(nspeeds.to_string());
    if !stribeck {
        cmd.arg("--no-stribeck");
    }
    let out = cmd.output().unwrap();
    assert!(out.status.success(), "{} failed:\n{}", script.display(), stderr(&out));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `twin sysid friction` on an [`independent_sweep`] of `nspeeds` speeds: (the script's truth,
/// twin's stdout, its report's joints).
fn friction_of_sweep(nspeeds: usize, stribeck: bool) -> (serde_json::Value, String, Vec<serde_json::Value>) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let truth = independent_sweep(d, nspeeds, stribeck);
    let out = twin(d, &["sysid", "friction", "--log", "sweep", "--report", "f.json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("f.json")).unwrap()).unwrap();
    (truth, String::from_utf8_lossy(&out.stdout).into_owned(), report["joints"].as_array().unwrap().clone())
}

/// The line `twin sysid friction` printed for joint `name` (its segments and model).
fn segments_line<'a>(stdout: &'a str, name: &str) -> &'a str {
    stdout.lines().find(|l| l.starts_with(&format!("{name}: "))).expect("a segments line per joint")
}

#[test]
fn sysid_friction_pairs_all_8_speeds_of_an_independent_sweep_and_fits_stribeck() {
    let (truth, stdout, joints) = friction_of_sweep(8, true);
    assert_eq!(joints.len(), 3, "{stdout}");
    for j in &joints {
        let name = j["joint"].as_str().unwrap();
        let t = &truth["joints"][name];
        let points = j["points"].as_array().unwrap();
        assert_eq!(points.len(), 8, "{name}: paired speeds\n{stdout}");
        // The pairs are the swept speeds, within 2 %.
        for (p, v) in points.iter().zip(truth["speeds"].as_array().unwrap()) {
            let (got, want) = (p["speed"].as_f64().unwrap(), v.as_f64().unwrap());
            assert!((got / want - 1.0).abs() < 0.02, "{name}: speed {got} vs {want}");
        }
        assert_eq!(j["model"], "stribeck", "{name}\n{stdout}");
        let line = segments_line(&stdout, name);
        assert!(line.ends_with("segment(s), 8 paired speed(s) → Stribeck"), "{line}");
        let fit = &j["fit"];
        for (what, tol) in [("coulomb", 0.1), ("viscous", 0.1), ("breakaway", 0.15)] {
            let (got, want) = (fit[what].as_f64().unwrap(), t[what].as_f64().unwrap());
            assert!((got / want - 1.0).abs() < tol, "{name} {what}: {got} vs {want}\n{stdout}");
        }
    }
    // The segments used are printed with their times.
    assert!(stdout.contains(" rad/s: +v ") && stdout.contains(" s, −v "), "{stdout}");
}

#[test]
fn sysid_friction_with_4_speeds_fits_coulomb_and_viscous_and_says_so() {
    let (truth, stdout, joints) = friction_of_sweep(4, false);
    for j in &joints {
        let name = j["joint"].as_str().unwrap();
        let t = &truth["joints"][name];
        assert_eq!(j["points"].as_array().unwrap().len(), 4, "{name}\n{stdout}");
        assert_eq!(j["model"], "coulomb_viscous", "{name}\n{stdout}");
        let line = segments_line(&stdout, name);
        assert!(line.contains("segment(s), 4 paired speed(s) → Coulomb + viscous ("), "{line}");
        let fit = &j["fit"];
        for what in ["coulomb", "viscous"] {
            let (got, want) = (fit[what].as_f64().unwrap(), t[what].as_f64().unwrap());
            assert!((got / want - 1.0).abs() < 0.05, "{name} {what}: {got} vs {want}\n{stdout}");
        }
        // Intervals for what was fitted, none for the hump.
        assert!(j["ci95"][0].as_f64().unwrap() > 0.0 && j["ci95"][1].is_null(), "{}", j["ci95"]);
    }
    assert!(stdout.contains("Coulomb + viscous (Stribeck needs 6)"), "{stdout}");
}

/// A 4-joint arm simulated by MuJoCo's own Python package (`tests/python/arm_sweep.py`): a
/// heavy turret on a vertical-axis base joint (≈ 4.9 kg m² about yaw with the arm stretched
/// out) whose drive is tuned for a third of that, three pitch joints, 8 speeds per direction
/// from 0.03 to 1.2 rad/s, MuJoCo's `frictionloss` and `damping` plus a Stribeck hump. Every
/// joint's Coulomb and viscous friction come out within 10 %, the yaw joint's too (Coulomb 1.01
/// and viscous −0.23 against 0.8 and 0.35 before the ±v pairs took out the inertia torque of
/// the speed changes still ringing in them).
#[test]
fn sysid_friction_of_a_mujoco_arm_sweep_with_a_heavy_yaw_joint_is_within_10_percent() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let script = root().join("tests/python/arm_sweep.py");
    let out = Command::new(crate::test_python::python()).arg(&script).arg(d.join("sweep")).arg("8").output().unwrap();
    assert!(out.status.success(), "{} failed:\n{}", script.display(), stderr(&out));
    let truth: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let fit = twin(d, &["sysid", "friction", "--log", "sweep", "--report", "f.json"]);
    assert!(fit.status.success(), "{}", stderr(&fit));
    let stdout = String::from_utf8_lossy(&fit.stdout);
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(d.join("f.json")).unwrap()).unwrap();
    let joints = report["joints"].as_array().unwrap();
    assert_eq!(joints.len(), 4, "{stdout}");
    for j in joints {
        let name = j["joint"].as_str().unwrap();
        assert_eq!(j["points"].as_array().unwrap().len(), 8, "{name}: paired speeds\n{stdout}");
        for what in ["coulomb", "viscous"] {
            let (got, want) = (j["fit"][what].as_f64().unwrap(), truth["joints"][name][what].as_f64().unwrap());
            assert!((got / want - 1.0).abs() < 0.1, "{name} {what}: {got} vs {want}\n{stdout}");
        }
    }
}
