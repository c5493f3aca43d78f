//! Friction curves from velocity sweeps: a sweep log simulated on the arm (gravity loaded,
//! noisy efforts, quantized encoders) with a known Stribeck curve per joint; the fit recovers
//! Coulomb and viscous within 5 %, breakaway within 10 %. A log without constant-velocity
//! segments is refused naming the joints.

use std::path::{Path, PathBuf};
use sysid::friction::{FrictionOptions, Stribeck, SweepOptions, identify_friction, synth_sweep};

fn arm_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/arm6.urdf")
}

/// Per joint: harmonic-drive-like big joints to Dynamixel-like small ones.
fn truths() -> Vec<Stribeck> {
    let s = |fc: f64, fs: f64, vs: f64, d: f64, fv: f64| Stribeck {
        coulomb: fc,
        breakaway: fs,
        stribeck_velocity: vs,
        exponent: d,
        viscous: fv,
    };
    vec![
        s(4.0, 6.0, 0.05, 1.0, 1.3),
        s(3.0, 4.8, 0.08, 2.0, 1.0),
        s(2.0, 3.0, 0.04, 1.0, 0.6),
        s(1.0, 1.6, 0.1, 1.5, 0.3),
        s(0.6, 1.0, 0.06, 1.0, 0.2),
        s(0.4, 0.7, 0.05, 2.0, 0.1),
    ]
}

#[test]
fn stribeck_parameters_recovered_from_a_gravity_loaded_sweep() {
    let truth = truths();
    let log = synth_sweep(&arm_urdf(), &truth, &SweepOptions { rate_hz: 250.0, ..Default::default() }).unwrap();
    let report = identify_friction(&log, &FrictionOptions::default()).unwrap();
    assert_eq!(report.joints.len(), 6);
    let mut failures = Vec::new();
    for (j, t) in report.joints.iter().zip(&truth) {
        let f = &j.fit;
        eprintln!("{}: {:?} (truth {:?}) ci {:?} points {}", j.joint, f, t, j.ci95, j.points.len());
        for p in &j.points {
            eprintln!("  v {:.4} f {:.4} truth {:.4} n {}", p.speed, p.friction, t.torque(p.speed), p.samples);
        }
        for (what, got, want, tol) in [
            ("Fc", f.coulomb, t.coulomb, 0.05),
            ("Fv", f.viscous, t.viscous, 0.05),
            ("Fs", f.breakaway, t.breakaway, 0.10),
        ] {
            if (got / want - 1.0).abs() > tol {
                failures.push(format!("{} {what}: got {got:.4}, want {want:.4}", j.joint));
            }
        }
        // The 95 % interval covers the truth for the Coulomb part.
        assert!((f.coulomb - t.coulomb).abs() <= j.ci95[0] * 3.0 + 0.02 * t.coulomb, "{}: {f:?} {:?}", j.joint, j.ci95);
        // 14 speeds swept; the fastest may cruise too briefly on the half stroke.
        assert!(j.points.len() >= 13, "{}: {}", j.joint, j.points.len());
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // Coulomb/viscous into the URDF's <dynamics>.
    let ups = report.joint_updates();
    assert_eq!(ups[0].friction, report.joints[0].fit.coulomb);
    assert_eq!(ups[0].damping, report.joints[0].fit.viscous);
    let svg = report.svg();
    assert!(roxmltree::Document::parse(&svg).is_ok());
}

#[test]
fn a_log_without_constant_velocity_segments_is_refused() {
    // The sysid excitation log: sums of sines, never at constant velocity for 0.5 s.
    let log =
        sysid::synth::simulate(&arm_urdf(), &sysid::synth::SynthOptions { duration_secs: 8.0, ..Default::default() })
            .unwrap();
    let err = identify_friction(&log, &FrictionOptions::default()).unwrap_err().to_string();
    assert!(err.contains("no joint has a usable velocity sweep"), "{err}");
    assert!(err.contains("no constant-velocity segment"), "{err}");
    assert!(err.contains("joint \""), "{err}");
}
