//! Walker cost per physics step on several robots, side by side with a plain C `mj_step` loop.
//!
//!     cargo bench -p twin-scenario --bench walk_robots -- [--steps N] [--reps R] [--vx V] URDF...
//!
//! For each robot (loaded as `twin sim` loads it, armature as `scenarios/walk.toml`, walking
//! options derived from the robot by [`WalkOptions::for_robot`], no robot-specific option;
//! `--vx` the forward speed, m/s, default 0 = the walker stepping in place), each repetition
//! runs back to back from `home`. Leg joints on position servos are driven through them (the
//! walker sends the setpoint whose force is its torque); a robot whose servos the walker
//! refuses (no force limit) is converted again with torque motors (`twin convert --actuators
//! motor`), as the refusal says, and marked so in its row.
//!
//! 1. **pd-hold**: twin's loop (`mj_step1`, [`PdHold::compute`], `mj_step2`) for N steps.
//! 2. **walking**: the same loop with the walker at its derived speed, `Walker::compute` timed
//!    apart from the physics. A robot that falls keeps being stepped (the figure is cost, not
//!    success); the step of the fall (base below half its start height) is reported.
//! 3. **C replay**: a plain C loop that copies each walking step's recorded `ctrl` and calls
//!    `mj_step` from `home` (`twin_core::mj::bench_c_replay_loop`): the same physics as the walk
//!    with no controller, checked bit for bit against the walk's final state.
//! 4. **C loop, zero control**: `mj_step` from `home` with zero control (the robot collapses).
//!
//! One Markdown row per robot, medians over the repetitions.

#[path = "../../twin-core/benches/flags/mod.rs"]
mod flags;
mod walk_common;

use std::sync::Arc;
use std::time::Instant;
use twin_controllers::walk::{WALK_ARMATURE, WalkOptions, Walker};
use twin_core::control::{Actuation, Controller, Observation, PdHold, PdHoldOptions, reset_to_home};
use twin_core::convert::ActuatorMode;
use twin_core::mj::Data;
use walk_common::{median, state, step, time_c_replay, time_c_zero, timed_step};

fn main() {
    let flags = flags::Flags::from_env();
    let (steps, reps, vx) = (flags.get("--steps", 5_000u64), flags.get("--reps", 5usize), flags.get("--vx", 0.0f64));
    let urdfs = flags.rest();
    println!(
        "| robot | nv | nu | steps × reps | vx (m/s) | walk fell at step | C loop, zero ctrl (µs) | \
         C replay of the walk, mj_step (µs) | pd-hold loop (µs/step) | walking loop (µs/step) | \
         walker compute (µs/step) | walker / C replay step | walking throughput / C replay |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for path in &urdfs {
        let name = std::path::Path::new(path).file_stem().unwrap().to_string_lossy().to_string();
        let mut motors = false;
        let (model, options, mut walker) = loop {
            let convert = twin_core::convert::ConvertOptions {
                actuators: if motors { ActuatorMode::Motor } else { ActuatorMode::Auto },
                ..Default::default()
            };
            let robot = twin_core::robot::Robot::load_with(path, &convert).unwrap_or_else(|e| panic!("{e}"));
            let model = Arc::new(twin_scenario::prepare_model(&robot.model, WALK_ARMATURE, None).unwrap());
            let walker = WalkOptions::default().for_robot(&model, &|_| false).and_then(|o| {
                let o = WalkOptions { vx, ..o };
                Walker::new(&model, o.clone()).map(|w| (o, w))
            });
            match walker {
                Ok((o, w)) => break (model, o, w),
                Err(e) if !motors && e.to_string().contains("--actuators motor") => motors = true,
                Err(e) => panic!("{name}: {e}"),
            }
        };
        let name = if motors { format!("{name} (--actuators motor)") } else { name };
        let mut hold = PdHold::new(&model, PdHoldOptions::default());
        let actuation = Actuation::of(&model);
        let into_qfrc = actuation == Actuation::Qfrc;
        let mut command = vec![0.0; actuation.len(&model)];
        let mut commands = Vec::with_capacity(command.len() * steps as usize);
        let mut data = Data::new(model.clone()).unwrap();
        let mut rows: [Vec<f64>; 5] = Default::default();
        let [zero, replay, held, walking, ctrl] = &mut rows;
        let mut fell_at = None;
        for _ in 0..reps {
            // 1.
            reset_to_home(&mut data).unwrap();
            hold.reset(&model, &Observation::of(&data)).unwrap();
            let t = Instant::now();
            for _ in 0..steps {
                step(&model, &mut data, &mut hold, actuation, &mut command);
            }
            held.push(t.elapsed().as_secs_f64() / steps as f64);

            // 2.
            reset_to_home(&mut data).unwrap();
            let z0 = data.qpos()[2];
            walker.reset(&model, &Observation::of(&data)).unwrap();
            commands.clear();
            let (mut c, mut total) = (0.0, 0.0);
            fell_at = None;
            for i in 0..steps {
                let (compute, whole) = timed_step(&model, &mut data, &mut walker, actuation, &mut command);
                total += whole;
                c += compute;
                commands.extend_from_slice(&command);
                if fell_at.is_none() && data.qpos()[2] < 0.5 * z0 {
                    fell_at = Some(i);
                }
            }
            walking.push(total / steps as f64);
            ctrl.push(c / steps as f64);
            let walked = state(&data);

            // 3.
            replay.push(time_c_replay(&mut data, into_qfrc, &commands, steps, &walked));

            // 4.
            zero.push(time_c_zero(&mut data, steps));
        }
        let [zero, replay, held, walking, c] = rows.map(|v| median(v) * 1e6);
        let fell = fell_at.map_or("no".to_string(), |i| format!("{i} ({:.2} s)", i as f64 * model.timestep_secs()));
        println!(
            "| {name} | {} | {} | {steps} × {reps} | {:.2} | {fell} | {zero:.2} | {replay:.2} | {held:.2} | \
             {walking:.2} | {c:.2} | {:.1} % | {:.3} |",
            model.nv(),
            model.nu(),
            options.vx,
            100.0 * c / replay,
            replay / walking
        );
    }
}
