//! Sensor noise from still logs: known white noise, bias instability and bias random walk
//! recovered from synthetic IMUs (hours of data generated here), encoder σ and quantization,
//! refusals of moving and short logs, and the URDF write-back.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use sysid::noise::{AxisTruth, ImuLog, NoiseOptions, analyze_encoders, analyze_imu, imu_noise_updates, synth_imu};

fn truth(offset: f64, n: f64, b: f64, k: f64) -> AxisTruth {
    AxisTruth { offset, white_density: n, bias_instability: b, bias_random_walk: k }
}

/// Gyro (rad/s) and accelerometer (m/s²) axes whose white noise dominates below ≈ 0.25 s, bias
/// instability from there to ≈ 8 s and bias random walk above: every term visible, as the
/// tools' users need (N of a consumer MEMS IMU, bias terms raised so that the 3 h show each
/// over a decade or more: B = 3·N, K = 0.41·B).
fn gyro_truth() -> [AxisTruth; 3] {
    [truth(0.001, 1.5e-4, 4.5e-4, 1.85e-4), truth(-0.002, 2.0e-4, 6.0e-4, 2.5e-4), truth(0.0, 1.0e-4, 3.0e-4, 1.2e-4)]
}
fn accel_truth() -> [AxisTruth; 3] {
    [truth(0.05, 3.0e-3, 9.0e-3, 3.7e-3), truth(-0.03, 2.5e-3, 7.5e-3, 3.1e-3), truth(9.81, 4.0e-3, 1.2e-2, 4.9e-3)]
}

fn check_within(what: &str, got: f64, want: f64, tol: f64) {
    let rel = got / want - 1.0;
    assert!(rel.abs() <= tol, "{what}: got {got:.4e}, want {want:.4e} ({:+.1} %)", 100.0 * rel);
}

#[test]
fn allan_fit_recovers_white_noise_bias_instability_and_random_walk_within_10_percent() {
    // 3 h at 200 Hz per axis (2.16 M samples), six axes.
    let imu = synth_imu("/imu", "imu_link", gyro_truth(), accel_truth(), 200.0, 10800.0, 11);
    let noise = analyze_imu(&imu, &NoiseOptions::default()).unwrap();
    let truths: Vec<AxisTruth> = gyro_truth().into_iter().chain(accel_truth()).collect();
    let mut failures = Vec::new();
    for (axis, t) in noise.axes.iter().zip(&truths) {
        let name = format!("{} {}", axis.sensor, axis.axis);
        let f = &axis.fit;
        eprintln!(
            "{name}: N {:.3e}/{:.3e} B {:.3e}/{:.3e} K {:.3e}/{:.3e} rel {:?} rms {:.3}",
            f.white_density,
            t.white_density,
            f.bias_instability,
            t.bias_instability,
            f.bias_random_walk,
            t.bias_random_walk,
            f.rel_std,
            f.log_rms_residual
        );
        for (what, got, want) in [
            ("N", f.white_density, t.white_density),
            ("B", f.bias_instability, t.bias_instability),
            ("K", f.bias_random_walk, t.bias_random_walk),
        ] {
            if (got / want - 1.0).abs() > 0.10 {
                failures.push(format!("{name} {what}: got {got:.4e}, want {want:.4e}"));
            }
        }
        // The model describes the curve: residuals in units of each point's own relative
        // standard error 1/√(2·edf) stay of order one.
        let z: Vec<f64> =
            axis.points.iter().map(|p| (p.adev / f.adev_at(p.tau_secs)).ln() * (2.0 * p.edf).sqrt()).collect();
        let z_rms = (z.iter().map(|r| r * r).sum::<f64>() / z.len() as f64).sqrt();
        assert!(z_rms < 2.0, "{name}: normalised residual {z_rms}");
        // The band contains the model over most of the curve (95 % band).
        let inside = axis.points.iter().filter(|p| (p.adev_low..=p.adev_high).contains(&f.adev_at(p.tau_secs))).count();
        assert!(inside as f64 >= 0.8 * axis.points.len() as f64, "{name}: {inside}/{}", axis.points.len());
        // White noise alone at τ = 1 s is the density.
        let tau_max = axis.points.last().unwrap().tau_secs;
        assert!(tau_max > 2000.0 && tau_max <= 2700.0, "{tau_max}");
    }
    assert!(failures.is_empty(), "outside 10 %:\n{}", failures.join("\n"));
}

#[test]
fn white_noise_density_of_a_1000_hz_imu() {
    // 1 h at 1000 Hz, white noise and random walk only (no floor): N within 10 %, B not seen.
    let g = [truth(0.0, 1.5e-4, 0.0, 2.7e-6); 3];
    let a = [truth(9.81, 6.3e-3, 0.0, 1.2e-4); 3];
    let imu = synth_imu("/imu", "imu_link", g, a, 1000.0, 3600.0, 4);
    let noise = analyze_imu(&imu, &NoiseOptions::default()).unwrap();
    for (axis, t) in noise.axes.iter().zip(g.iter().chain(&a)) {
        check_within(&format!("{} {} N", axis.sensor, axis.axis), axis.fit.white_density, t.white_density, 0.10);
        // No bias instability in the data: the fitted floor stays far below the white noise at
        // the longest τ.
        let f = &axis.fit;
        let tau = axis.points.last().unwrap().tau_secs;
        assert!(
            0.664 * f.bias_instability
                < 0.3 * f.white_density / tau.sqrt() + 0.3 * t.bias_random_walk * (tau / 3.0).sqrt(),
            "{f:?}"
        );
    }
}

fn still_imu(seconds: f64) -> ImuLog {
    let g = [truth(0.0, 1.5e-4, 0.0, 0.0); 3];
    let a = [truth(0.0, 6.0e-3, 0.0, 0.0), truth(0.0, 6.0e-3, 0.0, 0.0), truth(9.81, 6.0e-3, 0.0, 0.0)];
    synth_imu("/imu", "imu_link", g, a, 200.0, seconds, 2)
}

#[test]
fn a_moving_imu_is_refused_naming_the_sensor_axis_and_time() {
    let mut imu = still_imu(300.0);
    // Someone turns the robot about z between 100 and 103 s.
    for (k, t) in imu.t_nanos.iter().enumerate() {
        let s = (*t - imu.t_nanos[0]) as f64 * 1e-9;
        if (100.0..103.0).contains(&s) {
            imu.gyro[2][k] += 0.3;
        }
    }
    let err = analyze_imu(&imu, &NoiseOptions::default()).unwrap_err().to_string();
    assert!(err.contains("/imu") && err.contains("the robot moved: gyro z"), "{err}");
    assert!(err.contains("t = 100.0–10"), "{err}");
}

#[test]
fn a_log_too_short_for_the_asked_tau_is_refused() {
    let imu = still_imu(300.0);
    let opts = NoiseOptions { tau_max_secs: Some(1000.0), ..Default::default() };
    let err = analyze_imu(&imu, &opts).unwrap_err().to_string();
    assert!(err.contains("too short for τ up to 1000 s") && err.contains("4000 s"), "{err}");
    let err = analyze_imu(&still_imu(30.0), &NoiseOptions::default()).unwrap_err().to_string();
    assert!(err.contains("at least 60 s"), "{err}");
}

#[test]
fn encoder_sigma_and_quantization_step() {
    // A 17-bit encoder (Δ = 2π/2¹⁷) with σ = 3Δ of analog noise before quantization, and a
    // 12-bit one that reads one value.
    let step17 = 2.0 * std::f64::consts::PI / f64::from(1u32 << 17);
    let step12 = 2.0 * std::f64::consts::PI / 4096.0;
    let mut log = sysid::JointLog::new(vec!["a".into(), "b".into()], "mem");
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    for k in 0..60_000 {
        let a = ((0.7 + 3.0 * step17 * rng.sample::<f64, _>(StandardNormal)) / step17).round() * step17;
        let b = ((-0.2 + 0.01 * step12 * rng.sample::<f64, _>(StandardNormal)) / step12).round() * step12;
        log.push(k * 5_000_000, &[a, b], &[], &[]);
    }
    let enc = analyze_encoders(&log, &NoiseOptions::default()).unwrap();
    let q = enc[0].quantization_step.unwrap();
    check_within("17-bit step", q, step17, 0.001);
    // σ of a quantized Gaussian: √(σ² + Δ²/12).
    check_within("17-bit σ", enc[0].sigma, (9.0 * step17 * step17 + step17 * step17 / 12.0).sqrt(), 0.03);
    assert_eq!(enc[1].distinct_values, 1);
    assert!(enc[1].quantization_step.is_none() && enc[1].sigma < 1e-12, "{:?}", enc[1]);

    // A joint that moves 0.05 rad at 20 s is refused.
    for k in 4000..4400 {
        log.position[1][k] += 0.05;
    }
    let err = analyze_encoders(&log, &NoiseOptions::default()).unwrap_err().to_string();
    assert!(err.contains("joint \"b\"") && err.contains("t = 20.0–"), "{err}");
}

#[test]
fn imu_noise_is_written_into_the_gazebo_noise_tags_byte_preservingly() {
    let urdf = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap();
    let path = std::path::Path::new("humanoid.urdf");
    let imu = still_imu(600.0);
    let mut noise = analyze_imu(&imu, &NoiseOptions::default()).unwrap();
    for a in &mut noise.axes {
        a.fit.bias_instability = 0.0;
        a.fit.bias_random_walk = 0.0;
    }
    noise.axes[0].fit.bias_instability = 2e-4;
    noise.axes[0].fit.bias_random_walk = 2e-5;
    let (updates, warnings) = imu_noise_updates(path, &urdf, &[noise.clone()]).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    // humanoid.urdf: <update_rate>200</update_rate>, the log's rate too.
    assert_eq!(updates[0].rate_hz, 200.0);
    let out = sysid::writeback::rewrite_imu_noise(path, &urdf, &updates).unwrap();
    let diff = sysid::writeback::unified_diff(path, &urdf, &out);
    // Six stddev lines changed, three bias lines added on gyro x; nothing else.
    let added = diff.lines().filter(|l| l.starts_with('+') && !l.starts_with("+++")).count();
    let removed = diff.lines().filter(|l| l.starts_with('-') && !l.starts_with("---")).count();
    assert_eq!((added, removed), (9, 6), "{diff}");
    let doc = roxmltree::Document::parse(&out).unwrap();
    let stddevs: Vec<f64> =
        doc.descendants().filter(|n| n.has_tag_name("stddev")).map(|n| n.text().unwrap().parse().unwrap()).collect();
    for (k, s) in stddevs.iter().enumerate() {
        let n = noise.axes[k].fit.white_density;
        check_within("stddev = N·√200", *s, n * 200f64.sqrt(), 1e-6);
    }
    // The written per-sample stddev is the simulated one (1.5e-4·√200, 6e-3·√200) within 10 %.
    check_within("gyro stddev", stddevs[0], 1.5e-4 * 200f64.sqrt(), 0.1);
    check_within("accel stddev", stddevs[5], 6e-3 * 200f64.sqrt(), 0.1);
    let corr: f64 = doc
        .descendants()
        .find(|n| n.has_tag_name("dynamic_bias_correlation_time"))
        .and_then(|n| n.text())
        .unwrap()
        .parse()
        .unwrap();
    let num = |tag: &str| -> f64 {
        doc.descendants().find(|n| n.has_tag_name(tag)).and_then(|n| n.text()).unwrap().parse().unwrap()
    };
    // The Gauss–Markov peak (at 1.89·τc, 0.617 of σ_b·√(τc/2)) sits at the fitted curve's
    // minimum √3·N/K with the floor's height 0.664·B; the random walk is K.
    let n = noise.axes[0].fit.white_density;
    check_within("correlation time", corr * 1.8926, 3f64.sqrt() * n / 2e-5, 1e-3);
    check_within(
        "Gauss–Markov peak",
        0.6174 * num("dynamic_bias_stddev") * (corr / 2.0).sqrt(),
        0.664_283 * 2e-4,
        1e-3,
    );
    check_within("random walk", num("bias_random_walk"), 2e-5, 1e-9);
    // Rewriting with the same values changes nothing.
    assert_eq!(sysid::writeback::rewrite_imu_noise(path, &out, &updates).unwrap(), out);
    // An IMU whose frame the URDF lacks, with two IMUs measured: a clear error.
    let mut other = noise.clone();
    other.frame_id = "chest_imu".into();
    let err = imu_noise_updates(path, &urdf, &[noise, other]).unwrap_err().to_string();
    assert!(err.contains("chest_imu") && err.contains("imu_link"), "{err}");
}

#[test]
fn still_log_through_a_ros2_bag_and_spec_fragment() {
    let dir = tempfile::tempdir().unwrap();
    let bag = dir.path().join("still.mcap");
    let imu = still_imu(120.0);
    let mut joints = sysid::JointLog::new(vec!["j1".into()], "mem");
    let step = 2.0 * std::f64::consts::PI / 65536.0;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for &t in imu.t_nanos.iter().step_by(2) {
        joints.push(t, &[((0.3 + 2.0 * step * rng.sample::<f64, _>(StandardNormal)) / step).round() * step], &[], &[]);
    }
    {
        let mut w = twin_core::log::LogWriter::create(&bag, &twin_core::log::WriterOptions::default()).unwrap();
        imu.write_to(&mut w).unwrap();
        let js = w.add_topic::<twin_core::log::JointState>("/joint_states").unwrap();
        for k in 0..joints.len() {
            let msg = twin_core::log::JointState {
                header: twin_core::log::Header { stamp_nanos: joints.t_nanos[k], frame_id: String::new() },
                name: vec!["j1".into()],
                position: vec![joints.position[0][k]],
                ..Default::default()
            };
            w.write(js, joints.t_nanos[k] as u64, &msg).unwrap();
        }
        w.finish().unwrap();
    }
    let (report, warnings) = sysid::noise::calibrate_noise(&bag, None, None, &NoiseOptions::default()).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(report.imus.len(), 1);
    assert_eq!(report.imus[0].frame_id, "imu_link");
    check_within("N over the bag", report.imus[0].axes[0].fit.white_density, 1.5e-4, 0.1);
    check_within("encoder step", report.encoders[0].quantization_step.unwrap(), step, 0.001);
    let fragment = report.spec_fragment();
    assert!(fragment.contains("[imu_noise_std]") && fragment.contains("[encoder_noise_std]"), "{fragment}");
    let svg = report.svg();
    let doc = roxmltree::Document::parse(&svg).unwrap();
    assert_eq!(doc.descendants().filter(|n| n.has_tag_name("polyline")).count(), 6);
    assert!(report.table().contains("gyro z"));
}
