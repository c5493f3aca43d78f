//! Writes a synthetic CSV log of a URDF robot: `cargo run -p sysid --example synth_log -- ROBOT.urdf OUT.csv [SECONDS] [SEED]`.
fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 3 {
        eprintln!("usage: synth_log ROBOT.urdf OUT.csv [SECONDS] [SEED]");
        std::process::exit(2);
    }
    let opts = sysid::synth::SynthOptions {
        duration_secs: a.get(3).and_then(|s| s.parse().ok()).unwrap_or(20.0),
        seed: a.get(4).and_then(|s| s.parse().ok()).unwrap_or(1),
        ..Default::default()
    };
    let log = sysid::synth::simulate(std::path::Path::new(&a[1]), &opts).unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(1)
    });
    log.write_csv(&a[2]).unwrap();
}
