//! Throughput of `twin randomize` against a plain C `mj_step` loop and MuJoCo's Python
//! `mujoco.rollout`, on the same model and the same number of steps.
//!
//! `cargo bench --bench randomize [-- EPISODES SECONDS]` (default 24 episodes of 2.5 s).
//!
//! `cargo bench --bench randomize -- --scenario FILE [--episodes N] [--seed S] [--reps R]` measures
//! instead a scenario's randomized episodes (as `twin randomize --scenario FILE --threads 1`:
//! the scenario's spec or the default one) against a plain C loop that replays each episode
//! (see [`scenario_paired`]).
//!
//! - C loop: per episode, reset to the `home` keyframe and run `mj_step` S times in C with zero
//!   control (`twin_core::mj::bench_c_step_loop`). One thread.
//! - twin, same work: the randomize engine with an empty spec and the `passive` controller, so
//!   it simulates exactly the C loop's trajectories; it still copies and re-derives the model
//!   per episode (`mj_copyModel` + `mj_setConst`), reads observations, tracks contacts, tilt,
//!   energy; falls do not end episodes here, so both run every step. The ratio to the C loop is
//!   twin's own overhead.
//! - twin, real work: the default spec and the PD hold (what `twin randomize` runs); falls end
//!   episodes, steps/s counts the steps simulated.
//! - Python: `mujoco.rollout.rollout` on the same initial state, zero control, same steps,
//!   1 and 2 threads, when `TWIN_PYTHON` (default `python3`) has `mujoco`; skipped otherwise.

use randomize::{Batch, EpisodeOptions, Layout, RunOptions, Spec, run_batch};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;
use twin_core::control::reset_to_home;
use twin_core::engine::replay::InputLog;
use twin_core::mj::{Data, Model};
use twin_scenario::Scenario;

const MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/randomize/tests/fixtures/humanoid.xml");

fn engine(spec: &Spec, controller: &str, episodes: u64, secs: f64, threads: usize) -> f64 {
    let model = Arc::new(Model::from_file(MODEL).expect("fixture"));
    let layout = Layout::new(spec, &model).expect("spec");
    // Same work as the C loop: no early end on a fall, every episode runs all its steps.
    let same_work = controller == "passive";
    let options = EpisodeOptions {
        duration_secs: secs,
        controller: controller.into(),
        fall_height_fraction: if same_work { 0.0 } else { 0.6 },
        fall_tilt_rad: if same_work { 4.0 } else { 1.0 },
    };
    let batch = Batch::new(model, layout, options, 1).expect("batch");
    let info = randomize::run_info(&batch, MODEL, spec, episodes, None);
    let run = RunOptions { episodes, threads, ..RunOptions::default() };
    let t = Instant::now();
    let report = run_batch(&batch, info, &run, &AtomicBool::new(false), &|| {}).expect("run");
    let elapsed = t.elapsed().as_secs_f64();
    assert_eq!(report.summary.outcomes.episodes, episodes);
    if same_work {
        assert_eq!(report.simulated_steps, episodes * batch.steps_per_episode());
    }
    report.simulated_steps as f64 / elapsed
}

/// Per-core comparison robust to background load: episode by episode, alternately the C loop
/// and the engine's `Worker::run` (what each rayon worker does), on the same episode.
fn paired(episodes: u64, secs: f64) -> (f64, f64) {
    let model = Arc::new(Model::from_file(MODEL).expect("fixture"));
    let layout = Layout::new(&Spec::default(), &model).expect("spec");
    let options = EpisodeOptions {
        duration_secs: secs,
        controller: "passive".into(),
        fall_height_fraction: 0.0,
        fall_tilt_rad: 4.0,
    };
    let batch = Batch::new(model.clone(), layout, options, 1).expect("batch");
    let steps = batch.steps_per_episode();
    let mut worker = randomize::Worker::new(&batch).expect("worker");
    let mut data = Data::new(model).expect("data");
    let (mut c_secs, mut twin_secs) = (0.0, 0.0);
    for i in 0..episodes {
        let t = Instant::now();
        reset_to_home(&mut data).expect("reset");
        twin_core::mj::bench_c_step_loop(&mut data, steps);
        c_secs += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let r = worker.run(&batch, i, None).expect("episode");
        twin_secs += t.elapsed().as_secs_f64();
        assert_eq!((r.sim_secs / batch.nominal.timestep_secs()).round() as u64, steps);
    }
    let total = (episodes * steps) as f64;
    (total / c_secs, total / twin_secs)
}

/// Per-core throughput of a scenario's randomized episodes against plain C `mj_step` loops.
/// Episode by episode, back to back: the episode as each `twin randomize` worker runs it
/// (`Worker::run`: the draw, the model copy, the controller under the sensor model, the
/// disturbances, fall detection, metrics and checks), timed; the same episode again, untimed,
/// recording its inputs (`InputLog`: the applied `ctrl` per step, the kicks); a plain C loop
/// replaying them on the episode's model from its initial state, timed, checked to end in the
/// episode's final state bit for bit: the same physics without twin. Then, for the figure of
/// earlier sessions, a C loop of as many steps from `home` with zero control on the nominal
/// model (the robot collapses: cheaper physics than walking). An unstable episode (MuJoCo reset
/// a diverged state) has nothing to replay: it is left out of the times.
///
/// With `reps` > 1 each episode's twin run and C replay are timed `reps` times, alternately, and
/// each keeps its fastest: on a shared machine a burst of load then slows one repetition of one
/// side, not the figure (both sides measured alike, the same work each time).
fn scenario_paired(path: &Path, episodes: u64, seed: u64, reps: u64) {
    let scenario = Scenario::load(path).unwrap_or_else(|e| panic!("{e}"));
    let default_model = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf"));
    let robot = scenario.robot(default_model).unwrap_or_else(|e| panic!("{e}"));
    // As `twin randomize --scenario` without `--config`: the scenario's own spec, else the default.
    let layout = match &scenario.randomize {
        Some(file) => Spec::from_file(file).and_then(|spec| Layout::new(&spec, &robot.model)),
        None => {
            let mut spec = Spec::default_spec();
            if robot.base.is_none() {
                spec.push = None;
            }
            Layout::new_skipping_missing(&spec, &robot.model).map(|(layout, _)| layout)
        }
    }
    .unwrap_or_else(|e| panic!("{e}"));
    let options = EpisodeOptions {
        duration_secs: scenario.duration_secs,
        controller: scenario.controller.clone(),
        ..EpisodeOptions::default()
    };
    let nominal = robot.model.clone();
    let batch = Batch::from_robot(robot, layout, options, seed)
        .and_then(|b| b.with_scenario(Arc::new(scenario)))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut worker = randomize::Worker::new(&batch).expect("worker");
    let mut log = InputLog::new();
    let mut collapsing = Data::new(nominal).expect("data");
    let (mut twin_secs, mut replay_secs, mut c_secs) = (0.0, 0.0, 0.0);
    let (mut steps, mut events, mut successes, mut unstable) = (0u64, 0usize, 0u64, 0u64);
    for i in 0..episodes {
        let t = Instant::now();
        let r = worker.run(&batch, i, None).expect("episode");
        let mut secs = t.elapsed().as_secs_f64();
        if r.unstable {
            // MuJoCo reset a diverged state (or raised an error): nothing to replay.
            unstable += 1;
            continue;
        }
        let again = worker.run_recorded(&batch, i, None, Some(&mut log)).expect("episode");
        assert_eq!(r, again, "episode {i} is not reproducible");
        let end = worker.data().expect("data");
        let (qpos, qvel) = (end.qpos().to_vec(), end.qvel().to_vec());
        let model = end.model().clone();
        let mut replay = f64::INFINITY;
        let mut n = 0;
        for rep in 0..reps {
            if rep > 0 {
                let t = Instant::now();
                let again = worker.run(&batch, i, None).expect("episode");
                secs = secs.min(t.elapsed().as_secs_f64());
                assert_eq!(r, again, "episode {i} is not reproducible");
            }
            let mut data = Data::new(model.clone()).expect("data");
            let t = Instant::now();
            n = log.replay_c(&mut data).expect("replay");
            replay = replay.min(t.elapsed().as_secs_f64());
            assert_eq!([data.qpos(), data.qvel()], [&qpos[..], &qvel[..]], "the C replay of episode {i} left it");
        }
        twin_secs += secs;
        replay_secs += replay;

        reset_to_home(&mut collapsing).expect("reset");
        let t = Instant::now();
        twin_core::mj::bench_c_step_loop(&mut collapsing, n);
        c_secs += t.elapsed().as_secs_f64();
        steps += n;
        events += log.events();
        successes += u64::from(r.success());
    }
    let rate = |secs: f64| steps as f64 / secs;
    println!(
        "| scenario | episodes (successes; unstable) | steps (disturbed) | twin `Worker::run` (µs/step) | C replay (µs/step) | \
         C loop, collapsing (µs/step) | twin / C replay, per core | twin / collapsing C loop, per core |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    println!(
        "| {} | {episodes} ({successes}; {unstable}) | {steps} ({events}) | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} |",
        path.file_name().unwrap_or_default().to_string_lossy(),
        1e6 / rate(twin_secs),
        1e6 / rate(replay_secs),
        1e6 / rate(c_secs),
        rate(twin_secs) / rate(replay_secs),
        rate(twin_secs) / rate(c_secs),
    );
}

fn c_loop(episodes: u64, steps: u64) -> f64 {
    let model = Arc::new(Model::from_file(MODEL).expect("fixture"));
    let mut data = Data::new(model).expect("data");
    let t = Instant::now();
    for _ in 0..episodes {
        reset_to_home(&mut data).expect("reset");
        twin_core::mj::bench_c_step_loop(&mut data, steps);
    }
    (episodes * steps) as f64 / t.elapsed().as_secs_f64()
}

const PY: &str = r#"
import sys, time
try:
    import mujoco
    from mujoco import rollout
except ImportError as e:
    print("SKIP", e); sys.exit(0)
import numpy as np
path, nbatch, nstep = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
m = mujoco.MjModel.from_xml_path(path)
d = mujoco.MjData(m)
mujoco.mj_resetDataKeyframe(m, d, 0)
size = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_FULLPHYSICS)
x0 = np.zeros(size); mujoco.mj_getState(m, d, x0, mujoco.mjtState.mjSTATE_FULLPHYSICS)
x0 = np.tile(x0, (nbatch, 1))
ctrl = np.zeros((nbatch, nstep, m.nu))
for threads in (1, 2):
    datas = [mujoco.MjData(m) for _ in range(threads)]
    rollout.rollout(m, datas, x0[:1], ctrl[:1, :10])  # warm-up
    t = time.perf_counter()
    rollout.rollout(m, datas, x0, ctrl)
    dt = time.perf_counter() - t
    print(threads, nbatch * nstep / dt)
print("VERSION", mujoco.__version__)
"#;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--bench").collect();
    if let Some(k) = args.iter().position(|a| a == "--scenario") {
        let value = |flag: &str| args.iter().position(|a| a == flag).and_then(|k| args.get(k + 1));
        let path = args.get(k + 1).expect("--scenario FILE");
        let episodes = value("--episodes").map_or(20, |v| v.parse().expect("--episodes N"));
        let seed = value("--seed").map_or(0, |v| v.parse().expect("--seed S"));
        let reps = value("--reps").map_or(1, |v| v.parse().expect("--reps N"));
        assert!(reps >= 1, "--reps N needs N ≥ 1");
        scenario_paired(Path::new(path), episodes, seed, reps);
        return;
    }
    let episodes: u64 = args.first().and_then(|a| a.parse().ok()).unwrap_or(24);
    let secs: f64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(2.5);
    let model = Model::from_file(MODEL).expect("fixture");
    let steps = (secs / model.timestep_secs()).round() as u64;
    let total = episodes * steps;
    println!(
        "model {} (nv {}, nu {}), {episodes} episodes × {steps} steps = {total} steps per row\n",
        Path::new(MODEL).file_name().unwrap().to_string_lossy(),
        model.nv(),
        model.nu()
    );
    // Warm-up (page in the library, caches).
    c_loop(2, steps);
    let empty = Spec::default();
    let default = Spec::default_spec();
    let mut c = Vec::new();
    let mut same1 = Vec::new();
    let mut same2 = Vec::new();
    let mut real1 = Vec::new();
    let mut real2 = Vec::new();
    // Interleave repetitions so background load affects all rows alike; keep the best of 3.
    for _ in 0..3 {
        c.push(c_loop(episodes, steps));
        same1.push(engine(&empty, "passive", episodes, secs, 1));
        same2.push(engine(&empty, "passive", episodes, secs, 2));
        real1.push(engine(&default, "pd-hold", episodes, secs, 1));
        real2.push(engine(&default, "pd-hold", episodes, secs, 2));
    }
    let best = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
    let (c, same1, same2) = (best(&c), best(&same1), best(&same2));
    let (pc, pt) = paired(episodes, secs);
    let (real1, real2) = (best(&real1), best(&real2));
    println!("| run | threads | steps/s | vs C loop |");
    println!("| --- | --- | --- | --- |");
    println!("| paired, episode by episode: C loop {pc:.0} vs twin `Worker::run` | 1 | {pt:.0} | {:.3} |", pt / pc);
    println!("| plain C `mj_step` loop | 1 | {c:.0} | 1.00 |");
    println!("| twin randomize, same work (empty spec, passive) | 1 | {same1:.0} | {:.3} |", same1 / c);
    println!(
        "| twin randomize, same work (empty spec, passive) | 2 | {same2:.0} | {:.3} ({:.2}× 1 thread) |",
        same2 / c,
        same2 / same1
    );
    println!("| twin randomize, default spec + PD hold | 1 | {real1:.0} | {:.3} |", real1 / c);
    println!(
        "| twin randomize, default spec + PD hold | 2 | {real2:.0} | {:.3} ({:.2}× 1 thread) |",
        real2 / c,
        real2 / real1
    );
    let python = std::env::var("TWIN_PYTHON").unwrap_or_else(|_| "python3".into());
    match std::process::Command::new(&python)
        .args(["-c", PY, MODEL, &episodes.to_string(), &steps.to_string()])
        .output()
    {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            if let Some(skip) = text.lines().find(|l| l.starts_with("SKIP")) {
                println!("\nPython comparison skipped ({python}: {skip}); set TWIN_PYTHON");
            }
            let version = text.lines().find_map(|l| l.strip_prefix("VERSION ")).unwrap_or("?");
            for line in text.lines() {
                let mut it = line.split_whitespace();
                if let (Some(t), Some(rate)) = (it.next(), it.next())
                    && let (Ok(t), Ok(rate)) = (t.parse::<usize>(), rate.parse::<f64>())
                {
                    println!(
                        "| Python `mujoco.rollout` {version} (zero control) | {t} | {rate:.0} | {:.3} |",
                        rate / c
                    );
                }
            }
        }
        Ok(out) => println!("\nPython comparison failed: {}", String::from_utf8_lossy(&out.stderr)),
        Err(e) => println!("\nPython comparison skipped ({python}: {e}); set TWIN_PYTHON"),
    }
}
