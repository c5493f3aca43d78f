//! A 640×480 depth frame against Talos's meshes (PyPI `example-robot-data` 6.0.0,
//! `talos_full_v2.urdf`, converted with its Gazebo tags), twin's ray caster against the same
//! frame through MuJoCo's own `mj_multiRay` (which tests every geom, meshes through their BVH).
//!
//!     cargo bench -p twin-core --bench depth -- [TALOS_URDF] [--frames N] [--mj-frames M]
//!
//! TALOS_URDF defaults to the copy the tests fetch (`target/tmp/urdf-cache/…`, or under
//! `TWIN_URDF_CACHE`). Talos stands at its home pose (forward kinematics only). Two frames:
//!
//! 1. **external**: a 640×480 camera (vertical field of view 45°) 2.2 m in front of the robot
//!    at chest height looking at it: the meshes fill most of the image;
//! 2. **head**: Talos's own `rgbd` depth camera (640×480, near clip 0.6 m, far 8 m) at its
//!    pose in the head: what `twin sim --record` publishes.
//!
//! For each: the median wall time of N renders of `DepthCamera` on one thread and on all
//! threads, the thread's CPU time per frame, and M frames of `mj_multiRay` with the same rays
//! (unit directions, the same geom groups, one thread), whose depths are compared ray by ray
//! on frame (1) (`mj_multiRay` has no near clip: in (2) it sees the inside of the head).

mod common;
mod flags;

use common::{median, time_camera, with_camera};
use nalgebra::{Matrix3, Rotation3, Vector3};
use std::time::Instant;
use twin_core::convert::{ConvertOptions, convert_urdf};
use twin_core::mj::{Data, GeomType, ObjType};
use twin_core::sense::{DepthCamera, DepthCameraOptions, RayOptions};

fn default_talos() -> String {
    let cache = std::env::var("TWIN_URDF_CACHE")
        .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../target/tmp/urdf-cache").to_string());
    format!("{cache}/cmeel.prefix/share/example-robot-data/robots/talos_data/robots/talos_full_v2.urdf")
}

fn main() {
    let flags = flags::Flags::from_env();
    let (frames, mj_frames) = (flags.get("--frames", 20usize), flags.get("--mj-frames", 1usize));
    let urdf = flags.rest().pop().unwrap_or_else(default_talos);
    if !std::path::Path::new(&urdf).is_file() {
        panic!(
            "{urdf} not found: run `cargo test --release -p twin-core --test it example_robot_data` once (it fetches \
             example-robot-data) or give the path of talos_full_v2.urdf"
        );
    }
    let converted = convert_urdf(std::path::Path::new(&urdf), &ConvertOptions::default()).unwrap();
    let head_sensor =
        converted.meta.sensors.iter().find(|s| s.kind == "depth").expect("Talos's rgbd depth sensor").clone();
    let head_cam = head_sensor.mujoco[0].clone();
    let [near, far] = head_sensor.range_m.unwrap_or([0.05, 10.0]);
    // The external camera: 2.2 m in front (+x) at 1.0 m height, looking back at the robot.
    let (eye, target) = (Vector3::new(2.2, 0.0, 1.0), Vector3::new(0.0, 0.0, 0.9));
    let model = with_camera(&converted.mjcf, "bench_front", eye, target, "fovy=\"45\" resolution=\"640 480\"");
    let mut data = Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    data.forward().unwrap();
    let meshes = (0..model.ngeom()).filter(|&g| model.geom_kind(g) == GeomType::Mesh).count();
    println!(
        "Talos ({urdf}): {} geoms ({meshes} meshes), {} bodies; {} threads",
        model.ngeom(),
        model.nbody(),
        rayon::current_num_threads()
    );
    println!(
        "| frame | twin, 1 thread: median wall / mean CPU ms | twin, all threads: median wall ms | valid pixels | mj_multiRay: wall ms (frames) | rays that differ | bounding-sphere / exact tests per ray |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (label, cam, opts) in [
        ("external, 640×480", "bench_front", DepthCameraOptions { width: 640, height: 480, ..Default::default() }),
        (
            "Talos head `rgbd`, 640×480, clip 0.6–8 m",
            head_cam.as_str(),
            DepthCameraOptions {
                width: 640,
                height: 480,
                hfov_rad: Some(std::f64::consts::FRAC_PI_3),
                ray: RayOptions { min_range_m: near, max_range_m: far, ..DepthCameraOptions::default().ray },
            },
        ),
    ] {
        let on_threads = |threads| {
            let ray = RayOptions { threads, ..opts.ray.clone() };
            DepthCamera::new(&model, cam, DepthCameraOptions { ray, ..opts.clone() }).unwrap()
        };
        let mut one = on_threads(1);
        let (wall1, cpu1, valid) = time_camera(&model, &data, &mut one, frames);
        let (wall_all, _, _) = time_camera(&model, &data, &mut on_threads(0), frames);

        // The same rays through mj_multiRay: unit directions in the world from the frame's
        // optical pose; depth = distance × the ray's optical z.
        let frame = one.render(&model, &data).unwrap();
        let k = *one.intrinsics();
        let rot: Matrix3<f64> = *frame.world_from_optical.rotation.to_rotation_matrix().matrix();
        let origin = frame.world_from_optical.translation.vector;
        let mut dirs = Vec::with_capacity(k.len());
        let mut scale = Vec::with_capacity(k.len());
        for v in 0..k.height {
            for u in 0..k.width {
                let r = k.ray_optical(u, v);
                let n = r.norm();
                let w = Rotation3::from_matrix_unchecked(rot) * (r / n);
                dirs.push([w.x, w.y, w.z]);
                scale.push(1.0 / n);
            }
        }
        let cam_id = model.require_id(ObjType::Camera, cam).unwrap();
        let body = model.cam_bodyid()[cam_id] as usize;
        let exclude = (body != 0).then_some(body);
        let mut mj_times = Vec::new();
        let mut hits = Vec::new();
        for _ in 0..mj_frames {
            let t = Instant::now();
            hits = data
                .multi_ray(
                    [origin.x, origin.y, origin.z],
                    &dirs,
                    Some(opts.ray.filter.groups),
                    true,
                    exclude,
                    far.max(opts.ray.max_range_m) * 2.0,
                )
                .unwrap();
            mj_times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        // Compare where neither is clipped by the near plane (mj_multiRay has none).
        let mut differ = 0;
        for (i, h) in hits.iter().enumerate() {
            let mj =
                h.map(|h| h.dist_m * scale[i]).filter(|z| *z >= opts.ray.min_range_m && *z <= opts.ray.max_range_m);
            let ours = frame.depth_m[i];
            let same = match mj {
                Some(z) => (f64::from(ours) - z).abs() < 1e-4,
                None => !ours.is_finite(),
            };
            differ += usize::from(!same);
        }
        // mj_multiRay has no near clip: from inside the head it sees the head.
        let differ = if opts.ray.min_range_m > 0.1 {
            "n/a (no near clip in mj_multiRay)".to_string()
        } else {
            differ.to_string()
        };
        let st = one.last_ray_stats();
        println!(
            "| {label} | {wall1:.2} / {cpu1:.2} | {wall_all:.2} | {valid} of {} | {:.1} ({mj_frames}) | {differ} | {:.2} / {:.2} |",
            k.len(),
            median(mj_times),
            st.sphere_tests as f64 / st.rays as f64,
            st.exact_tests as f64 / st.rays as f64
        );
    }
}
