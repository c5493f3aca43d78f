//! Stepping through the safe wrapper vs a plain C loop of `mj_step`, same model, same steps.
//!
//!     cargo bench --bench step -- [MODEL ...] [--steps N] [--reps R]
//!
//! Each repetition resets the state, then runs N steps either as N calls of `Data::step`
//! (Rust → guarded shim → mj_step, the way every twin command steps) or as one call of a C
//! function that loops `mj_step` N times with no guard. Repetitions alternate between the two so
//! machine noise hits both alike; the medians are compared.

use std::sync::Arc;
use std::time::Instant;
use twin_core::mj::{Data, Model, bench_c_step_loop};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let mut models = Vec::new();
    let (mut steps, mut reps) = (20_000u64, 9usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--steps" => steps = args.next().and_then(|v| v.parse().ok()).expect("--steps N"),
            "--reps" => reps = args.next().and_then(|v| v.parse().ok()).expect("--reps R"),
            "--bench" => {}
            other => models.push(other.to_string()),
        }
    }
    if models.is_empty() {
        models.push(concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf").to_string());
        models.push(concat!(env!("CARGO_MANIFEST_DIR"), "/benches/boxes.xml").to_string());
    }
    println!("| model | nv | steps × reps | C mj_step loop (µs/step) | twin Data::step (µs/step) | overhead |");
    println!("|---|---|---|---|---|---|");
    for path in models {
        let model = Arc::new(Model::from_file(&path).unwrap_or_else(|e| panic!("{e}")));
        let mut data = Data::new(model.clone()).unwrap();
        // Warm up caches and the branch predictor on both paths.
        bench_c_step_loop(&mut data, steps / 4);
        data.reset().unwrap();
        for _ in 0..steps / 4 {
            data.step().unwrap();
        }
        let (mut c_times, mut rust_times) = (Vec::new(), Vec::new());
        for _ in 0..reps {
            data.reset().unwrap();
            let t = Instant::now();
            bench_c_step_loop(&mut data, steps);
            c_times.push(t.elapsed().as_secs_f64() / steps as f64);
            let c_end = data.qpos().to_vec();

            data.reset().unwrap();
            let t = Instant::now();
            for _ in 0..steps {
                data.step().unwrap();
            }
            rust_times.push(t.elapsed().as_secs_f64() / steps as f64);
            // Same work: the two paths must end in the same state, bit for bit.
            assert_eq!(c_end, data.qpos(), "the two loops diverged");
        }
        let (c, r) = (median(c_times), median(rust_times));
        let name = std::path::Path::new(&path).file_name().unwrap().to_string_lossy().into_owned();
        println!(
            "| {name} | {} | {steps} × {reps} | {:.3} | {:.3} | {:+.2} % |",
            model.nv(),
            c * 1e6,
            r * 1e6,
            (r / c - 1.0) * 100.0
        );
    }
}
