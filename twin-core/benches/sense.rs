//! Cost of the ray-cast depth camera on a grasp-like scene: the shipped humanoid in
//! `models/table_cup.world` (table, cup, floor) seen by a head-height camera looking at the
//! table.
//!
//!     cargo bench -p twin-core --bench sense -- [--frames N] [--secs S] [--reps R]
//!
//! (`TWIN_ROOT=DIR` runs the built binary against the repository at DIR.)
//!
//! 1. One 320×240 frame (76,800 rays), one thread and all threads: median of N renders.
//! 2. The simulation's wall and thread CPU time (PD hold, S simulated seconds) without the
//!    camera, with it rendering at 15 Hz on the simulation's thread, and pipelined
//!    ([`twin_core::sense::Pipelined`], as `twin sim --record` does), alternated R times.

use nalgebra::Vector3;
use rand::SeedableRng;
use std::sync::Arc;
use std::time::Instant;
use twin_core::control::{PdHold, PdHoldOptions};
use twin_core::convert::{ConvertOptions, convert_urdf};
use twin_core::engine::{Engine, Episode, Flow, Observer, StepView};
use twin_core::mj::{Data, Model};
use twin_core::robot::Robot;
use twin_core::sense::{DepthCamera, DepthCameraOptions, Device, Pipelined, Reading};

/// CPU time of the calling thread, seconds (Linux): not inflated by waiting for a core on a
/// busy machine, unlike wall time.
fn thread_cpu_secs() -> f64 {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap_or_default();
    text.split_whitespace().next().and_then(|n| n.parse::<u64>().ok()).map_or(f64::NAN, |n| n as f64 * 1e-9)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The humanoid at the table with a fixed camera at head height looking at the cup.
fn grasp_scene() -> Arc<Model> {
    // TWIN_ROOT: the repository when the binary runs elsewhere (another machine).
    let root = std::env::var("TWIN_ROOT").unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/..").to_string());
    let opts = ConvertOptions { world: Some(format!("{root}/models/table_cup.world").into()), ..Default::default() };
    let converted = convert_urdf(std::path::Path::new(&format!("{root}/models/humanoid.urdf")), &opts)
        .unwrap_or_else(|e| panic!("{e}"));
    let (eye, target) = (Vector3::new(0.1, 0.0, 1.45), Vector3::new(0.5, 0.0, 0.75));
    let d = (target - eye).normalize();
    let right = d.cross(&Vector3::z()).normalize();
    let up = right.cross(&d);
    let camera = format!(
        "<camera name=\"bench_head\" pos=\"{} {} {}\" xyaxes=\"{} {} {} {} {} {}\" fovy=\"58\"/>",
        eye.x, eye.y, eye.z, right.x, right.y, right.z, up.x, up.y, up.z
    );
    let mjcf = converted.mjcf.replacen("<worldbody>", &format!("<worldbody>\n{camera}"), 1);
    Arc::new(Model::from_xml_str(&mjcf).unwrap_or_else(|e| panic!("{e}")))
}

/// Renders the camera at its rate during a rollout: on the simulation's thread, or pipelined
/// (cast on rayon's pool while the simulation goes on, handed back at the next tick).
struct CameraTicks {
    camera: DepthCamera,
    pipe: Option<Pipelined>,
    period_nanos: u64,
    next_nanos: u64,
    frames: usize,
    valid: usize,
}

impl Observer for CameraTicks {
    fn observe(&mut self, step: &StepView<'_>) -> twin_core::Result<Flow> {
        let t = (step.time_secs * 1e9).round() as u64;
        if t >= self.next_nanos {
            self.next_nanos += self.period_nanos;
            self.frames += 1;
            match self.pipe.as_mut() {
                None => {
                    let frame = self.camera.render(step.data.model(), step.data)?;
                    self.valid += frame.depth_m.iter().filter(|z| z.is_finite()).count();
                }
                Some(pipe) => {
                    if let Some(Reading::Depth(frame)) = pipe.submit(step.data, t)? {
                        self.valid += frame.depth_m.iter().filter(|z| z.is_finite()).count();
                    }
                }
            }
        }
        Ok(Flow::Continue)
    }
}

fn main() {
    let (mut frames, mut secs, mut reps) = (20usize, 2.0f64, 5usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--frames" => frames = args.next().and_then(|v| v.parse().ok()).expect("--frames N"),
            "--secs" => secs = args.next().and_then(|v| v.parse().ok()).expect("--secs S"),
            "--reps" => reps = args.next().and_then(|v| v.parse().ok()).expect("--reps R"),
            _ => {}
        }
    }
    let model = grasp_scene();
    let mut data = Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    println!("scene: humanoid + table_cup.world, {} geoms, {} bodies", model.ngeom(), model.nbody());

    println!("| frame | threads | median wall ms/frame | median CPU ms/frame (1 thread) | valid pixels |");
    println!("|---|---|---|---|---|");
    for threads in [1usize, 0] {
        let opts = DepthCameraOptions { threads, ..DepthCameraOptions::default() };
        let mut camera = DepthCamera::new(&model, "bench_head", opts).unwrap();
        let first = camera.render(&model, &data).unwrap();
        let valid = first.depth_m.iter().filter(|z| z.is_finite()).count();
        let (times, cpu): (Vec<f64>, Vec<f64>) = (0..frames)
            .map(|_| {
                let (t, c) = (Instant::now(), thread_cpu_secs());
                std::hint::black_box(camera.render(&model, &data).unwrap());
                (t.elapsed().as_secs_f64() * 1e3, (thread_cpu_secs() - c) * 1e3)
            })
            .unzip();
        let (label, cpu) = if threads == 1 {
            ("1".to_string(), format!("{:.2}", median(cpu)))
        } else {
            (format!("all ({})", rayon::current_num_threads()), "–".to_string())
        };
        println!("| 320×240 | {label} | {:.2} | {cpu} | {valid} |", median(times));
    }

    let robot = Robot::from_model(model.clone(), "humanoid", std::path::Path::new("humanoid.urdf")).unwrap();
    let steps = (secs / model.timestep_secs()).round() as u64;
    let episode = Episode { steps, ..Episode::default() };
    let mut engine = Engine::new();
    // 0: no camera, 1: on the simulation's thread, 2: pipelined.
    let mut run = |mode: u8| -> (f64, f64, usize) {
        let mut controller = PdHold::new(&robot.model, PdHoldOptions::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        let opts = DepthCameraOptions { threads: 1, ..DepthCameraOptions::default() };
        let pipe = (mode == 2).then(|| {
            let cam = DepthCamera::new(&model, "bench_head", DepthCameraOptions::default()).unwrap();
            Pipelined::new(Device::Depth(cam), model.clone()).unwrap()
        });
        let mut ticks = CameraTicks {
            camera: DepthCamera::new(&model, "bench_head", opts).unwrap(),
            pipe,
            period_nanos: (1e9 / 15.0f64).round() as u64,
            next_nanos: 0,
            frames: 0,
            valid: 0,
        };
        let (t, c) = (Instant::now(), thread_cpu_secs());
        if mode > 0 {
            engine.run(&robot.model, &episode, &mut controller, &mut [], &mut [&mut ticks], &mut rng).unwrap();
            if let Some(pipe) = ticks.pipe.as_mut() {
                pipe.finish().unwrap();
            }
        } else {
            engine.run(&robot.model, &episode, &mut controller, &mut [], &mut [], &mut rng).unwrap();
        }
        (t.elapsed().as_secs_f64(), thread_cpu_secs() - c, ticks.frames)
    };
    let (mut without, mut with, mut without_cpu, mut with_cpu) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut piped, mut piped_cpu) = (Vec::new(), Vec::new());
    let mut frames_per_run = 0;
    for _ in 0..reps {
        let (w, c, _) = run(0);
        without.push(w);
        without_cpu.push(c);
        let (w, c, n) = run(1);
        with.push(w);
        with_cpu.push(c);
        frames_per_run = n;
        let (w, c, _) = run(2);
        piped.push(w);
        piped_cpu.push(c);
    }
    let (a, b, p) = (median(without), median(with), median(piped));
    let (ac, bc, pc) = (median(without_cpu), median(with_cpu), median(piped_cpu));
    println!();
    println!(
        "| simulation ({secs} s, {steps} steps, PD hold) | median wall s | median CPU s | real-time factor (wall) |"
    );
    println!("|---|---|---|---|");
    println!("| without camera | {a:.3} | {ac:.3} | {:.1} |", secs / a);
    println!("| with camera at 15 Hz, 1 thread ({frames_per_run} frames) | {b:.3} | {bc:.3} | {:.1} |", secs / b);
    println!(
        "| with camera at 15 Hz, pipelined on {} pool threads | {p:.3} | {pc:.3} (simulation thread) | {:.1} |",
        rayon::current_num_threads(),
        secs / p
    );
    println!(
        "pipelined: adds {:.1} % to the wall time, {:.1} % to the simulation thread's CPU",
        (p / a - 1.0) * 100.0,
        (pc / ac - 1.0) * 100.0
    );
    println!(
        "on the simulation's thread: camera adds {:.1} % to the wall time ({:.1} % CPU); its cost per simulated second: {:.1} ms CPU",
        (b / a - 1.0) * 100.0,
        (bc / ac - 1.0) * 100.0,
        (bc - ac) / secs * 1e3
    );
}
