//! Cost of the ray-cast depth camera on a grasp-like scene: the shipped humanoid in
//! `models/table_cup.world` (table, cup, floor) seen by a head-height camera looking at the
//! table.
//!
//!     cargo bench -p twin-scenario --bench sense -- [--frames N] [--secs S] [--reps R]
//!
//! (`TWIN_ROOT=DIR` runs the built binary against the repository at DIR.)
//!
//! 1. One 320×240 frame (76,800 rays), one thread and all threads: median wall time of N
//!    renders, the thread's mean CPU time over them, and the ray–geom tests per ray; then the
//!    same on the grasp scenario's own head camera.
//! 2. `scenarios/grasp.toml` as `twin sim --scenario` runs it (grasp controller with its own
//!    camera frames, checks; S simulated seconds, default the scenario's 10 s): wall and
//!    simulation-thread CPU time without an added camera, with the head camera rendering at
//!    15 Hz on the simulation's thread, and pipelined ([`twin_core::sense::Pipelined`], as
//!    `twin sim --record` does), alternated R times.

#[path = "../../twin-core/benches/common/mod.rs"]
mod common;
#[path = "../../twin-core/benches/flags/mod.rs"]
mod flags;

use common::{median, time_camera, with_camera};
use nalgebra::Vector3;
use std::sync::Arc;
use twin_controllers::grasp::Grasper;
use twin_core::convert::{ConvertOptions, convert_urdf};
use twin_core::engine::{Flow, Observer, StepView};
use twin_core::mj::{Data, Model, RayFilter};
use twin_core::sense::{DepthCamera, DepthCameraOptions, Device, Pipelined, RayOptions, Reading};
use twin_core::sim::{self, SimOptions};
use twin_scenario::Scenario;

/// The repository: `TWIN_ROOT` when the binary runs elsewhere (another machine).
fn repo_root() -> String {
    std::env::var("TWIN_ROOT").unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/..").to_string())
}

/// The humanoid at the table with a fixed camera at head height looking at the cup.
fn grasp_scene() -> Arc<Model> {
    let root = repo_root();
    let opts = ConvertOptions { world: Some(format!("{root}/models/table_cup.world").into()), ..Default::default() };
    let converted = convert_urdf(std::path::Path::new(&format!("{root}/models/humanoid.urdf")), &opts)
        .unwrap_or_else(|e| panic!("{e}"));
    let (eye, target) = (Vector3::new(0.1, 0.0, 1.45), Vector3::new(0.5, 0.0, 0.75));
    with_camera(&converted.mjcf, "bench_head", eye, target, "fovy=\"58\"")
}

/// Renders the camera at its rate during a rollout: on the simulation's thread, or pipelined
/// (cast on its own pool, one thread fewer than the cores, while the simulation goes on, handed back at the next tick).
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
    let flags = flags::Flags::from_env();
    let (frames, secs, reps) =
        (flags.get("--frames", 200usize), flags.opt::<f64>("--secs"), flags.get("--reps", 3usize));
    let unknown = flags.rest();
    assert!(unknown.is_empty(), "unknown arguments {unknown:?} (options: --frames N --secs S --reps R)");
    let model = grasp_scene();
    let mut data = Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    println!("scene: humanoid + table_cup.world, {} geoms, {} bodies", model.ngeom(), model.nbody());

    println!(
        "| frame | threads | median wall ms/frame | mean CPU ms/frame (1 thread) | valid pixels | bounding-sphere tests per ray | exact tests per ray |"
    );
    println!("|---|---|---|---|---|---|---|");
    for threads in [1usize, 0] {
        let opts = DepthCameraOptions {
            ray: RayOptions { threads, ..DepthCameraOptions::default().ray },
            ..DepthCameraOptions::default()
        };
        let mut camera = DepthCamera::new(&model, "bench_head", opts).unwrap();
        let (wall_ms, cpu_ms, valid) = time_camera(&model, &data, &mut camera, frames);
        let (label, cpu) = if threads == 1 {
            ("1".to_string(), format!("{cpu_ms:.2}"))
        } else {
            (format!("all ({})", rayon::current_num_threads()), "–".to_string())
        };
        let st = camera.last_ray_stats();
        let per_ray = |n: u64| n as f64 / st.rays as f64;
        println!(
            "| 320×240 | {label} | {wall_ms:.2} | {cpu} | {valid} | {:.2} | {:.2} |",
            per_ray(st.sphere_tests),
            per_ray(st.exact_tests)
        );
    }

    // The grasp scenario's own head camera, on its robot at the start.
    let root = repo_root();
    let scenario = Scenario::load(format!("{root}/scenarios/grasp.toml")).unwrap_or_else(|e| panic!("{e}"));
    let robot = scenario.robot(std::path::Path::new(&format!("{root}/models/humanoid_gripper.urdf"))).unwrap();
    let gmodel = robot.model.clone();
    let cam_name = scenario.grasp.camera.clone();
    // As the grasp controller's eye: the camera's housing and the head it sits on not in view.
    let head_options = |threads: usize| {
        let cam = gmodel.id(twin_core::mj::ObjType::Camera, &cam_name).expect("the scenario's camera");
        let body = gmodel.cam_bodyid()[cam] as usize;
        let exclude_bodies = vec![body, gmodel.body_parentid()[body] as usize];
        DepthCameraOptions {
            ray: RayOptions {
                threads,
                filter: RayFilter { exclude_bodies, ..RayFilter::default() },
                ..DepthCameraOptions::default().ray
            },
            ..Default::default()
        }
    };
    {
        let mut gdata = Data::new(gmodel.clone()).unwrap();
        twin_core::control::reset_to_home(&mut gdata).unwrap();
        let mut camera = DepthCamera::new(&gmodel, &cam_name, head_options(1)).unwrap();
        let (wall_ms, cpu_ms, valid) = time_camera(&gmodel, &gdata, &mut camera, frames);
        let st = camera.last_ray_stats();
        println!(
            "| 320×240, grasp scenario's `{cam_name}` ({} geoms) | 1 | {wall_ms:.2} | {cpu_ms:.2} | {valid} | {:.2} | {:.2} |",
            gmodel.ngeom(),
            st.sphere_tests as f64 / st.rays as f64,
            st.exact_tests as f64 / st.rays as f64
        );
    }

    // The grasp scenario as `twin sim --scenario` runs it (controller and checks), with
    // the head camera added at 15 Hz: 0 none, 1 on the simulation's thread, 2 pipelined.
    let duration = secs.unwrap_or(scenario.duration_secs);
    let run = |mode: u8| -> (f64, f64, usize) {
        let mut grasper = Grasper::new(&gmodel, scenario.grasp.clone(), scenario.walk.clone()).unwrap();
        let mut check = scenario.check(&gmodel).unwrap();
        let pipe = (mode == 2).then(|| {
            let cam = DepthCamera::new(&gmodel, &cam_name, head_options(0)).unwrap();
            Pipelined::new(Device::Depth(cam), gmodel.clone()).unwrap()
        });
        let mut ticks = CameraTicks {
            camera: DepthCamera::new(&gmodel, &cam_name, head_options(1)).unwrap(),
            pipe,
            period_nanos: (1e9 / 15.0f64).round() as u64,
            next_nanos: 0,
            frames: 0,
            valid: 0,
        };
        let options = SimOptions { duration_secs: duration, ..SimOptions::default() };
        let report = if mode > 0 {
            let r = sim::simulate_with(
                &robot,
                &mut grasper,
                &options,
                None,
                &mut |_| {},
                &mut [],
                &mut [&mut check, &mut ticks],
            )
            .unwrap();
            if let Some(pipe) = ticks.pipe.as_mut() {
                pipe.finish().unwrap();
            }
            r
        } else {
            sim::simulate_with(&robot, &mut grasper, &options, None, &mut |_| {}, &mut [], &mut [&mut check]).unwrap()
        };
        // The whole scenario must succeed, or the figures are not those of a grasp.
        if secs.is_none() {
            assert!(check.verdicts().iter().all(|v| v.passed), "the grasp failed: {:?}", check.verdicts());
        }
        (report.wall_secs, report.loop_cpu_secs.unwrap_or(f64::NAN), ticks.frames)
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
    let steps = (duration / gmodel.timestep_secs()).round();
    let (a, b, p) = (median(without), median(with), median(piped));
    let (ac, bc, pc) = (median(without_cpu), median(with_cpu), median(piped_cpu));
    println!();
    println!(
        "| grasp scenario ({duration} s, {steps} steps, controller and checks; median of {reps}) | wall s | simulation thread CPU s | µs per step (wall) |"
    );
    println!("|---|---|---|---|");
    println!("| without the added camera | {a:.3} | {ac:.3} | {:.0} |", a / steps * 1e6);
    println!(
        "| with the camera at 15 Hz on the simulation's thread ({frames_per_run} frames) | {b:.3} | {bc:.3} | {:.0} |",
        b / steps * 1e6
    );
    println!(
        "| with the camera at 15 Hz pipelined (`Pipelined`'s pool: {} threads) | {p:.3} | {pc:.3} | {:.0} |",
        std::thread::available_parallelism().map_or(1, |n| n.get().saturating_sub(1).max(1)),
        p / steps * 1e6
    );
    println!(
        "camera at 15 Hz on the simulation's thread: +{:.1} % wall, +{:.1} % CPU ({:.2} ms CPU a frame); pipelined: +{:.1} % wall, +{:.1} % simulation-thread CPU",
        (b / a - 1.0) * 100.0,
        (bc / ac - 1.0) * 100.0,
        (bc - ac) / frames_per_run as f64 * 1e3,
        (p / a - 1.0) * 100.0,
        (pc / ac - 1.0) * 100.0
    );
}
