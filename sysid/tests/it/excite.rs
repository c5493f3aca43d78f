//! `twin excite`'s design: on the shipped 6-DOF arm and on the humanoid's left leg, the designed
//! (15-harmonic) trajectory's regressor is better conditioned than the best of 20 random
//! 5-harmonic trajectories within the same limits and better than the median one (the
//! trajectory a random draw typically gives; ≥ 10× on the leg, ≥ 5× on the arm), respects every limit, starts and ends at rest,
//! and identification along it predicts a held-out log better than along the median random one.
//! `TWIN_EXCITE_SEED` sets the design's seed (default 1) to see the spread over draws
//! (docs/src/benchmarks-notebook.md, "sysid's synthetic logs over many draws").

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use sysid::excite::{Excitation, ExciteOptions, ExciteReport, design};
use sysid::synth::{SynthOptions, perturbed_urdf, simulate, simulate_tracking};
use sysid::{RobotModel, SysidOptions, identify, validate};

fn models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

/// Every limit holds on a fine grid; rest at both ends.
fn check_limits(report: &ExciteReport) {
    let traj = &report.trajectory;
    let omega = 2.0 * PI * traj.base_frequency_hz;
    let period = traj.period_secs();
    for (f, lim) in traj.joints.iter().zip(&report.limits) {
        let (q0, qd0, qdd0) = f.sample(omega, 0.0);
        let (q1, qd1, qdd1) = f.sample(omega, period);
        assert!((q0 - q1).abs() < 1e-9 && (q0 - f.rest).abs() < 1e-12, "{}: ends at {q1}, starts at {q0}", f.name);
        for v in [qd0, qdd0, qd1, qdd1] {
            assert!(v.abs() < 1e-9, "{}: not at rest at the ends ({v})", f.name);
        }
        for k in 0..=2000 {
            let (q, qd, qdd) = f.sample(omega, k as f64 * period / 2000.0);
            assert!(
                q >= lim.lower - 1e-6 && q <= lim.upper + 1e-6,
                "{}: q = {q} outside [{}, {}]",
                f.name,
                lim.lower,
                lim.upper
            );
            assert!(qd.abs() <= lim.velocity * 1.001, "{}: q̇ = {qd} > {}", f.name, lim.velocity);
            assert!(qdd.abs() <= lim.acceleration * 1.001, "{}: q̈ = {qdd} > {}", f.name, lim.acceleration);
        }
    }
    for u in &report.usage {
        assert!(u.torque <= 1.01, "{}: torque at {:.0} % of its limit", u.name, 100.0 * u.torque);
    }
}

/// Mean held-out torque NRMSE after identifying the perturbed URDF from a log along `traj`.
fn held_out_nrmse(truth: &Path, start: &Path, traj: &Excitation, held_out: &sysid::JointLog, joints: &[String]) -> f64 {
    let reference = |j: usize, t: f64| traj.reference(j, t);
    // One period with 5 % effort noise: short and noisy enough that the excitation shows in
    // the estimate (with 20 s at 1 % both fits reach the noise floor).
    let opts =
        SynthOptions { duration_secs: traj.period_secs(), seed: 5, effort_noise_rel: 0.05, ..Default::default() };
    let log = simulate_tracking(truth, &opts, &reference).unwrap();
    let robot = RobotModel::from_urdf(start).unwrap();
    let sysid_opts = SysidOptions::default();
    let ident = identify(&robot, &log, &sysid_opts).unwrap();
    let nrmse = validate(&robot, held_out, &sysid_opts, &[&ident.after]).unwrap();
    let idx: Vec<usize> = joints.iter().map(|n| robot.joint_index(n).unwrap()).collect();
    idx.iter().map(|&j| nrmse[0][j]).sum::<f64>() / idx.len() as f64
}

fn check_design(urdf: &str, joints: &[&str], held_out_opts: SynthOptions, min_ratio: f64) {
    let truth = models_dir().join(urdf);
    let joints: Vec<String> = joints.iter().map(|s| s.to_string()).collect();
    let seed = std::env::var("TWIN_EXCITE_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    let opts = ExciteOptions { joints: joints.clone(), seed, ..Default::default() };
    let report = design(&truth, &opts).unwrap();
    eprintln!("{}", report.table());
    assert_eq!(report.random_conditions.len(), 20, "{:?}", report.notes);
    let median = report.median_random_condition;
    eprintln!(
        "EXCITE {urdf} seed {seed}: designed {:.4e} best random {:.4e} median random {median:.4e} \
         ratio to best {:.2} to median {:.2}",
        report.condition,
        report.best_random_condition,
        report.best_random_condition / report.condition,
        median / report.condition
    );
    // The search starts from the best random draw and improves on it; against the random
    // trajectory a user would log without a design (the median draw), it is `min_ratio`×
    // better conditioned. The best of 20 draws is itself a lucky draw (its condition moves 5×
    // from one seed to the next, BENCHMARKS.md), not the figure to hold a design to.
    assert!(
        report.condition < report.best_random_condition && report.condition * min_ratio <= median,
        "designed condition {:.3e}: not below the best random {:.3e}, or not {min_ratio}× below the median random \
         {median:.3e}",
        report.condition,
        report.best_random_condition
    );
    check_limits(&report);

    let dir = tempfile::tempdir().unwrap();
    let start = dir.path().join(urdf);
    perturbed_urdf(&truth, &start, 3).unwrap();
    let held_out = simulate(&truth, &held_out_opts).unwrap();
    let names = if joints.is_empty() { report.trajectory.joint_names.clone() } else { joints };
    let designed = held_out_nrmse(&truth, &start, &report.trajectory, &held_out, &names);
    let best = held_out_nrmse(&truth, &start, &report.best_random, &held_out, &names);
    let random = held_out_nrmse(&truth, &start, &report.median_random, &held_out, &names);
    eprintln!(
        "EXCITE {urdf} seed {seed} held-out NRMSE: designed {designed:.6}, median random {random:.6}, best random \
         {best:.6}"
    );
    assert!(
        designed < random,
        "designed trajectory's held-out NRMSE {designed:.4} is not below the median random one's {random:.4}"
    );
}

// Each design costs 70 s (arm) and 15 s (leg) of CPU in the release profile: run by
// `cargo test --release` (what CI runs).
#[test]
#[cfg_attr(debug_assertions, ignore = "slow in the dev profile: cargo test --release")]
fn arm6_designed_trajectory_beats_random() {
    // Measured against the median random draw: 7.3×, 35× and 25× (seeds 1 to 3).
    check_design("arm6.urdf", &[], SynthOptions { duration_secs: 8.0, seed: 2, ..Default::default() }, 5.0);
}

#[test]
#[cfg_attr(debug_assertions, ignore = "slow in the dev profile: cargo test --release")]
fn humanoid_leg_designed_trajectory_beats_random() {
    let leg = [
        "left_hip_yaw_joint",
        "left_hip_roll_joint",
        "left_hip_pitch_joint",
        "left_knee_joint",
        "left_ankle_pitch_joint",
        "left_ankle_roll_joint",
    ];
    // Measured against the median random draw: 13×, 28×, 13× and 84× (seeds 1 to 4).
    check_design("humanoid.urdf", &leg, SynthOptions { duration_secs: 8.0, seed: 2, ..Default::default() }, 10.0);
}

#[test]
fn limits_that_leave_no_trajectory_name_what_is_missing() {
    let truth = models_dir().join("arm6.urdf");
    let opts = ExciteOptions { effort_fraction: 1e-4, random_candidates: 2, ..Default::default() };
    let e = design(&truth, &opts).unwrap_err().to_string();
    assert!(e.contains("no feasible excitation trajectory") && e.contains("torque"), "{e}");
    assert!(e.contains("joint \""), "{e}");
}
