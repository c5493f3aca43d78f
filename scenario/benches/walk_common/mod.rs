//! What the walker benches (`walk`, `walk_robots`) share: a median, one step of
//! twin's loop (plain and timed), and the two plain C loops the walk is set against (a replay
//! of its recorded `ctrl`, checked bit for bit, and zero control).

use std::time::Instant;
use twin_core::control::{Actuation, Controller, Observation, reset_to_home};
use twin_core::mj::{Data, Model, bench_c_replay_loop, bench_c_step_loop};

/// The median (upper middle for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One step of twin's loop: `mj_step1`, the controller's command applied, `mj_step2`.
pub fn step(
    model: &Model,
    data: &mut Data,
    controller: &mut dyn Controller,
    actuation: Actuation,
    command: &mut [f64],
) {
    data.step1().unwrap();
    controller.compute(model, &Observation::of(data), command);
    actuation.apply(data, command);
    data.step2().unwrap();
}

/// [`step`], timed: (seconds in `Controller::compute`, seconds of the whole step).
pub fn timed_step(
    model: &Model,
    data: &mut Data,
    controller: &mut dyn Controller,
    actuation: Actuation,
    command: &mut [f64],
) -> (f64, f64) {
    let t0 = Instant::now();
    data.step1().unwrap();
    let t1 = Instant::now();
    controller.compute(model, &Observation::of(data), command);
    let t2 = Instant::now();
    actuation.apply(data, command);
    data.step2().unwrap();
    ((t2 - t1).as_secs_f64(), t0.elapsed().as_secs_f64())
}

/// The state a run ended in: (qpos, qvel).
pub fn state(data: &Data) -> [Vec<f64>; 2] {
    [data.qpos().to_vec(), data.qvel().to_vec()]
}

/// Seconds per step of a plain C loop replaying `commands` (`steps` rows of `ctrl`, or of
/// `qfrc_applied` with `into_qfrc`) from `home`; asserts it ends in `walked` bit for bit.
pub fn time_c_replay(data: &mut Data, into_qfrc: bool, commands: &[f64], steps: u64, walked: &[Vec<f64>; 2]) -> f64 {
    reset_to_home(data).unwrap();
    let t = Instant::now();
    bench_c_replay_loop(data, into_qfrc, commands).unwrap();
    let secs = t.elapsed().as_secs_f64() / steps as f64;
    assert_eq!(&state(data), walked, "the C replay left the walk");
    secs
}

/// Seconds per step of a plain C loop of `mj_step` from `home` with zero control.
pub fn time_c_zero(data: &mut Data, steps: u64) -> f64 {
    reset_to_home(data).unwrap();
    let t = Instant::now();
    bench_c_step_loop(data, steps);
    t.elapsed().as_secs_f64() / steps as f64
}
