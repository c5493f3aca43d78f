//! The walking controller's cost per control tick against `mj_step` on the shipped humanoid.
//!
//!     cargo bench -p twin-core --bench walk -- [--steps N] [--reps R]
//!
//! Each repetition resets the humanoid (armature as `scenarios/walk.toml`) and walks at
//! 0.3 m/s for N steps, timing `Walker::compute` and the physics (`mj_step1` + `mj_step2`)
//! separately; a plain C loop of `mj_step` on the same model gives the reference step time.
//! Medians over the repetitions are printed as Markdown table rows: the controller's cost per
//! physics step, then where a walking tick's time goes against the C loop's step (per-core
//! throughput of walking over the C loop's): the same `mj_step1` + `mj_step2` calls from Rust
//! on the C loop's own trajectory (unactuated, from `home`) price the calls themselves, the
//! physics while walking prices the walking state (contacts, actuated joints).

use std::sync::Arc;
use std::time::Instant;
use twin_core::control::{Actuation, Controller, Observation, reset_to_home};
use twin_core::mj::{Data, Model, bench_c_step_loop};
use twin_core::walk::{WALK_ARMATURE, WalkOptions, Walker};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let (mut steps, mut reps) = (5_000u64, 7usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--steps" => steps = args.next().and_then(|v| v.parse().ok()).expect("--steps N"),
            "--reps" => reps = args.next().and_then(|v| v.parse().ok()).expect("--reps R"),
            _ => {}
        }
    }
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf");
    let loaded = Model::from_file(path).unwrap_or_else(|e| panic!("{e}"));
    let model = Arc::new(twin_core::scenario::prepare_model(&loaded, WALK_ARMATURE, None).unwrap());
    let actuation = Actuation::of(&model);
    let mut command = vec![0.0; actuation.len(&model)];
    let mut data = Data::new(model.clone()).unwrap();
    let mut walker = Walker::new(&model, WalkOptions { vx: 0.3, ..WalkOptions::default() }).unwrap();
    let (mut ctrl, mut phys, mut plain, mut passive) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..reps {
        reset_to_home(&mut data).unwrap();
        let t = Instant::now();
        bench_c_step_loop(&mut data, steps);
        plain.push(t.elapsed().as_secs_f64() / steps as f64);

        reset_to_home(&mut data).unwrap();
        let t = Instant::now();
        for _ in 0..steps {
            data.step1().unwrap();
            data.step2().unwrap();
        }
        passive.push(t.elapsed().as_secs_f64() / steps as f64);

        reset_to_home(&mut data).unwrap();
        walker.reset(&model, &Observation::of(&data)).unwrap();
        let (mut c, mut p) = (0.0, 0.0);
        for _ in 0..steps {
            let t0 = Instant::now();
            data.step1().unwrap();
            let t1 = Instant::now();
            walker.compute(&model, &Observation::of(&data), &mut command);
            let t2 = Instant::now();
            actuation.apply(&mut data, &command);
            data.step2().unwrap();
            let t3 = Instant::now();
            c += (t2 - t1).as_secs_f64();
            p += (t1 - t0).as_secs_f64() + (t3 - t2).as_secs_f64();
        }
        assert!(data.qpos()[2] > 0.5, "the humanoid fell during the benchmark");
        ctrl.push(c / steps as f64);
        phys.push(p / steps as f64);
    }
    let (c, p, m, r) = (median(ctrl), median(phys), median(plain), median(passive));
    println!(
        "| steps × reps | walker compute (µs/tick) | mj_step1+2 while walking (µs) | plain C mj_step loop (µs) | controller / mj_step |"
    );
    println!("|---|---|---|---|---|");
    println!("| {steps} × {reps} | {:.2} | {:.2} | {:.2} | {:.1} % |", c * 1e6, p * 1e6, m * 1e6, 100.0 * c / p);
    println!();
    println!(
        "| steps × reps | plain C mj_step loop (µs) | mj_step1+2 from Rust, same trajectory (µs) | mj_step1+2 while walking (µs) | walking tick (µs) | walking throughput / C loop |"
    );
    println!("|---|---|---|---|---|---|");
    println!(
        "| {steps} × {reps} | {:.2} | {:.2} | {:.2} | {:.2} | {:.3} |",
        m * 1e6,
        r * 1e6,
        p * 1e6,
        (c + p) * 1e6,
        m / (c + p)
    );
}
