//! Per-core throughput of the rollout engine against a plain C `mj_step` loop, episode by
//! episode on the same core (robust to background load), plus the default spec + PD hold.
//!
//! `cargo run --release -p randomize --example engine_vs_c_loop -- [EPISODES] [SECONDS] [MODEL]`
//! (default 24 episodes of 2.5 s on the humanoid fixture). The "same work" rows run the engine
//! with an empty spec and the passive controller, falls not ending episodes, so it simulates
//! exactly the C loop's trajectories (checked: identical final base positions bit for bit).
use randomize::{Batch, EpisodeOptions, Layout, Spec};
use std::sync::Arc;
use std::time::Instant;
use twin_core::mj::{Data, Model};

fn main() -> Result<(), randomize::Error> {
    let args: Vec<String> = std::env::args().collect();
    let episodes: u64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(24);
    let secs: f64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(2.5);
    let path = args.get(3).cloned().unwrap_or("randomize/tests/fixtures/humanoid.xml".into());
    let model = Arc::new(Model::from_file(&path)?);
    let options = EpisodeOptions {
        duration_secs: secs,
        controller: "passive".into(),
        fall_height_fraction: 0.0,
        fall_tilt_rad: 4.0,
    };
    let b = Batch::new(model.clone(), Layout::new(&Spec::default(), &model)?, options, 1)?;
    let steps = b.steps_per_episode();
    let mut w = randomize::Worker::new(&b)?;
    let mut d = Data::new(model.clone())?;
    // Same trajectory: the engine's final base position equals the C loop's bit for bit.
    w.run(&b, 0, None)?;
    twin_core::control::reset_to_home(&mut d)?;
    twin_core::mj::bench_c_step_loop(&mut d, steps);
    let base = model.free_joint().expect("floating base").qpos_adr;
    let engine_end = &w.data().expect("ran").qpos()[base..base + 3];
    println!("final base position: engine {engine_end:?}, C loop {:?}", &d.qpos()[base..base + 3]);
    assert_eq!(engine_end, &d.qpos()[base..base + 3]);
    let (mut c_secs, mut twin_secs) = (0.0, 0.0);
    for i in 0..episodes {
        let t = Instant::now();
        twin_core::control::reset_to_home(&mut d)?;
        twin_core::mj::bench_c_step_loop(&mut d, steps);
        c_secs += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let r = w.run(&b, i, None)?;
        twin_secs += t.elapsed().as_secs_f64();
        assert_eq!((r.sim_secs / model.timestep_secs()).round() as u64, steps);
    }
    let total = (episodes * steps) as f64;
    let (c, e) = (total / c_secs, total / twin_secs);
    println!(
        "paired, {episodes} episodes × {steps} steps: C loop {c:.0} steps/s, engine {e:.0} steps/s, ratio {:.3}",
        e / c
    );

    // What `twin randomize` runs: the default spec and the PD hold (falls end episodes).
    let spec = Spec::default_spec();
    let b = Batch::new(
        model.clone(),
        Layout::new(&spec, &model)?,
        EpisodeOptions { duration_secs: secs, ..EpisodeOptions::default() },
        1,
    )?;
    let mut w = randomize::Worker::new(&b)?;
    let (mut stepped, mut twin_secs, mut c_secs) = (0u64, 0.0, 0.0);
    for i in 0..episodes {
        let t = Instant::now();
        let r = w.run(&b, i, None)?;
        twin_secs += t.elapsed().as_secs_f64();
        let n = (r.sim_secs / model.timestep_secs()).round() as u64;
        stepped += n;
        let t = Instant::now();
        twin_core::control::reset_to_home(&mut d)?;
        twin_core::mj::bench_c_step_loop(&mut d, n);
        c_secs += t.elapsed().as_secs_f64();
    }
    let (e, c) = (stepped as f64 / twin_secs, stepped as f64 / c_secs);
    println!("default spec + PD hold, paired: engine {e:.0} steps/s, C loop {c:.0} steps/s, ratio {:.3}", e / c);
    Ok(())
}
