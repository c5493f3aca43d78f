//! Writes a copy of a URDF with inertias and friction off by 20–40 %:
//! `cargo run -p sysid --example perturb -- SRC.urdf DST.urdf [SEED]`.
fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        eprintln!("usage: perturb SRC.urdf DST.urdf [SEED]");
        std::process::exit(2);
    }
    let seed = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(3);
    if let Err(e) = sysid::synth::perturbed_urdf(a[1].as_ref(), a[2].as_ref(), seed) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
