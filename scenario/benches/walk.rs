//! The walking controller's cost per control tick against `mj_step` on the shipped humanoid.
//!
//!     cargo bench -p twin-scenario --bench walk -- [--steps N] [--reps R] [--plan-every K]
//!
//! Each repetition resets the humanoid (armature as `scenarios/walk.toml`) and, back to back:
//!
//! 1. **C loop, collapsing**: a plain C loop of `mj_step` from `home` with zero control (the
//!    humanoid falls: cheaper physics than walking's). The reference of earlier figures.
//! 2. **Rust, same trajectory**: the same `mj_step1` + `mj_step2` calls the walk makes, from
//!    Rust, on the collapsing trajectory: what the calls themselves cost.
//! 3. **walking**: the walker at 0.3 m/s for N steps, the whole loop timed (the controller's
//!    commands are recorded outside the timed calls, as a copy of `ctrl`).
//! 4. **C replay**: a plain C loop that copies each step's recorded `ctrl` and calls `mj_step`
//!    from `home` (`twin_core::mj::bench_c_replay_loop`): the same physics as the walk,
//!    checked bit for bit against the walk's final state. The fair reference for walking.
//! 5. **walking, split**: the walk again, timing `Walker::compute` apart from `mj_step1` +
//!    `mj_step2` (its final state checked against 3's: the timers change nothing).
//!
//! Medians over the repetitions are printed as one Markdown table row, with the controller's
//! cost against each step and walking's per-core throughput against each C loop. With
//! `--plan-every K` (`WalkOptions::plan_every_ticks`, default 1) the walker solves on one step
//! in K: its cost is given per physics step (every `compute` call) and per control tick (all
//! its time over the solves, the joint PD of the steps between them included).

#[path = "../../twin-core/benches/flags/mod.rs"]
mod flags;
mod walk_common;

use std::sync::Arc;
use std::time::Instant;
use twin_controllers::walk::{WALK_ARMATURE, WalkOptions, Walker};
use twin_core::control::{Actuation, Controller, Observation, reset_to_home};
use twin_core::mj::{Data, Model};
use walk_common::{median, state, step, time_c_replay, time_c_zero, timed_step};

fn main() {
    let flags = flags::Flags::from_env();
    let (steps, reps, plan_every) =
        (flags.get("--steps", 5_000u64), flags.get("--reps", 7usize), flags.get("--plan-every", 1u64));
    let unknown = flags.rest();
    assert!(unknown.is_empty(), "unknown arguments {unknown:?} (options: --steps N --reps R --plan-every K)");
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf");
    let loaded = Model::from_file(path).unwrap_or_else(|e| panic!("{e}"));
    let model = Arc::new(twin_scenario::prepare_model(&loaded, WALK_ARMATURE, None).unwrap());
    let actuation = Actuation::of(&model);
    let into_qfrc = actuation == Actuation::Qfrc;
    let mut command = vec![0.0; actuation.len(&model)];
    let mut commands = Vec::with_capacity(command.len() * steps as usize);
    let mut data = Data::new(model.clone()).unwrap();
    let options = WalkOptions { vx: 0.3, plan_every_ticks: plan_every, ..WalkOptions::default() };
    let mut walker = Walker::new(&model, options).unwrap_or_else(|e| panic!("{e}"));
    let mut rows: [Vec<f64>; 6] = Default::default();
    let [collapsing, passive, walking, replay, ctrl, phys] = &mut rows;
    for _ in 0..reps {
        // 1.
        collapsing.push(time_c_zero(&mut data, steps));

        // 2.
        reset_to_home(&mut data).unwrap();
        let t = Instant::now();
        for _ in 0..steps {
            data.step1().unwrap();
            data.step2().unwrap();
        }
        passive.push(t.elapsed().as_secs_f64() / steps as f64);

        // 3.
        reset_to_home(&mut data).unwrap();
        walker.reset(&model, &Observation::of(&data)).unwrap();
        commands.clear();
        let t = Instant::now();
        for _ in 0..steps {
            step(&model, &mut data, &mut walker, actuation, &mut command);
            // Capacity reserved up front: a copy of 25 numbers, no allocation.
            commands.extend_from_slice(&command);
        }
        walking.push(t.elapsed().as_secs_f64() / steps as f64);
        assert!(data.qpos()[2] > 0.5, "the humanoid fell during the benchmark");
        let walked = state(&data);

        // 4.
        replay.push(time_c_replay(&mut data, into_qfrc, &commands, steps, &walked));

        // 5.
        reset_to_home(&mut data).unwrap();
        walker.reset(&model, &Observation::of(&data)).unwrap();
        let (mut c, mut p) = (0.0, 0.0);
        for _ in 0..steps {
            let (compute, whole) = timed_step(&model, &mut data, &mut walker, actuation, &mut command);
            c += compute;
            p += whole - compute;
        }
        assert_eq!(state(&data), walked, "the timed walk left the walk");
        ctrl.push(c / steps as f64);
        phys.push(p / steps as f64);
    }
    let [collapsing, passive, walking, replay, c, p] = rows.map(|v| median(v) * 1e6);
    // The solves: the first step's and one in `plan_every` after it.
    let solves = steps.div_ceil(plan_every);
    let per_control_tick = c * steps as f64 / solves as f64;
    println!(
        "| steps × reps | plan every | walker compute (µs/physics step) | walker compute (µs/control tick) | \
         mj_step1+2 while walking (µs) | C replay of the walk, mj_step (µs) | \
         walking tick, whole loop (µs) | C loop, collapsing (µs) | Rust mj_step1+2, collapsing (µs) | \
         walker / step while walking | walker / C replay step | walker per control tick / step while walking | \
         walker / collapsing C step | walking throughput / C replay | walking throughput / collapsing C loop |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    println!(
        "| {steps} × {reps} | {plan_every} | {c:.2} | {per_control_tick:.2} | {p:.2} | {replay:.2} | {walking:.2} | \
         {collapsing:.2} | {passive:.2} | {:.1} % | {:.1} % | {:.1} % | {:.1} % | {:.3} | {:.3} |",
        100.0 * c / p,
        100.0 * c / replay,
        100.0 * per_control_tick / p,
        100.0 * c / collapsing,
        replay / walking,
        collapsing / walking
    );
}
