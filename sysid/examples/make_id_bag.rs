//! Regenerates `data/arm6_identification.mcap`, the identification bag the README's `twin sysid`
//! example runs on (run from the repository root):
//! `cargo run --release -p sysid --example make_id_bag -- data/arm6_identification.mcap`.
//!
//! The "real robot" is the shipped `models/arm6.urdf` with every mass, inertia, centre of mass,
//! damping and friction changed by 20–40 % ([`sysid::synth::perturbed_urdf`], seed
//! [`REAL_ROBOT_SEED`]); the bag is its `/joint_states` (position, velocity, effort with encoder
//! quantisation and noise) over 8 s at 1 kHz. So `twin sysid --log
//! data/arm6_identification.mcap --update models/arm6.urdf` moves the shipped arm's numbers to
//! the real robot's, which a test checks.

/// Seed of the perturbation that makes the "real robot" from `models/arm6.urdf`.
pub const REAL_ROBOT_SEED: u64 = 11;

fn main() {
    let out = std::env::args().nth(1).unwrap_or_else(|| "data/arm6_identification.mcap".into());
    let dir = tempfile::tempdir().expect("temp dir");
    let real = dir.path().join("arm6_real.urdf");
    sysid::synth::perturbed_urdf(std::path::Path::new("models/arm6.urdf"), &real, REAL_ROBOT_SEED)
        .unwrap_or_else(|e| fail(&e));
    let opts = sysid::synth::SynthOptions { duration_secs: 8.0, rate_hz: 1000.0, seed: 3, ..Default::default() };
    let log = sysid::synth::simulate(&real, &opts).unwrap_or_else(|e| fail(&e));
    log.write_mcap(&out, "/joint_states").unwrap_or_else(|e| fail(&e));
    eprintln!("wrote {out}");
}

fn fail(e: &dyn std::fmt::Display) -> ! {
    eprintln!("error: {e}");
    std::process::exit(1)
}
