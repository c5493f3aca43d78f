//! Public robots' sensors as their files describe them: example-robot-data 6.0.0's TIAGo Pro
//! (PyPI; fetched into the target's tmp dir, `example_robot_data.rs`) converted with a Gazebo
//! world holding a wall 1.9 m in front of it. Its two base LiDARs (`gpu_ray`, 818 beams,
//! 0.05–25 m, each inside its own housing) read the wall's distance on the beams that face it,
//! as Gazebo's rays that start at `<range><min>` do; its head depth camera (1280 × 720) costs a
//! frame within the budget on one core.

use nalgebra::{Matrix3, Vector3};
use std::path::Path;
use std::time::Instant;
use twin_core::convert::ConvertOptions;
use twin_core::mj::{Data, ObjType};
use twin_core::robot::Robot;
use twin_core::sense::{Device, RaySensorKind, Reading, lidar::beam_direction, ray_sensors};

/// The wall's face, world x, metres.
const WALL_X: f64 = 1.9;

/// A Gazebo world: a ground plane and a static 0.2 m-thick wall, 8 m wide and 2 m high, its face
/// at x = 1.9 m.
fn wall_world(dir: &Path) -> std::path::PathBuf {
    let plane = "<plane><normal>0 0 1</normal><size>100 100</size></plane>";
    let wall = "<box><size>0.2 8 2</size></box>";
    let text = format!(
        r#"<?xml version="1.0"?><sdf version="1.6"><world name="wall">
  <model name="ground_plane"><static>true</static><link name="link">
    <collision name="collision"><geometry>{plane}</geometry></collision>
    <visual name="visual"><geometry>{plane}</geometry></visual></link></model>
  <model name="wall"><static>true</static><pose>{} 0 1 0 0 0</pose><link name="link">
    <collision name="collision"><geometry>{wall}</geometry></collision>
    <visual name="visual"><geometry>{wall}</geometry></visual></link></model>
</world></sdf>"#,
        WALL_X + 0.1
    );
    let path = dir.join("wall.world");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn tiago_pro_lidars_read_the_wall_and_its_head_depth_camera_keeps_its_budget() {
    let robots = crate::example_robot_data::example_robot_data();
    let dir = tempfile::tempdir().unwrap();
    let options = ConvertOptions { world: Some(wall_world(dir.path())), ..ConvertOptions::default() };
    let robot = Robot::load_with(robots.join("tiago_pro_description/robots/tiago_pro.urdf"), &options).unwrap();
    let mut data = Data::new(robot.model.clone()).unwrap();
    data.forward().unwrap();
    let sensors = ray_sensors(&robot);
    let names: Vec<&str> = sensors.iter().map(|s| s.name.as_str()).collect();
    eprintln!("TIAGo Pro sensors: {names:?}");

    let mut lidars = 0;
    for s in &sensors {
        let RaySensorKind::Lidar { site, options } = &s.kind else { continue };
        lidars += 1;
        assert_eq!((options.horizontal.samples, options.ray.min_range_m, options.ray.max_range_m), (818, 0.05, 25.0));
        assert!((options.ray.noise_std_m - 0.01).abs() < 1e-12, "the file's 1 cm range noise");
        // Noise off: the geometry alone, to the file's 1 mm resolution.
        let mut exact = s.clone();
        if let RaySensorKind::Lidar { options, .. } = &mut exact.kind {
            options.ray.noise_std_m = 0.0;
        }
        let Reading::Lidar(scan) = exact.build(&robot).unwrap().read(&mut data).unwrap() else { unreachable!() };
        let Reading::Lidar(noisy) = s.build(&robot).unwrap().read(&mut data).unwrap() else { unreachable!() };
        let sid = robot.model.id(ObjType::Site, site).unwrap();
        let origin = Vector3::from(data.site_xpos()[sid]);
        let rot = Matrix3::from_row_slice(&data.site_xmat()[sid]);
        let (mut facing, mut on_wall, mut own_body, mut worst) = (0, 0, 0, 0.0f64);
        let mut noise = Vec::new();
        for (i, (&r, &rn)) in scan.ranges_m.iter().zip(&noisy.ranges_m).enumerate() {
            let d = rot * beam_direction(scan.horizontal.angle(i), 0.0);
            // Beams that meet the wall's face (inside its 8 × 2 m).
            if d.x <= 1e-9 {
                continue;
            }
            let t = (WALL_X - origin.x) / d.x;
            let p = origin + t * d;
            if p.y.abs() >= 3.9 || !(0.05..1.95).contains(&p.z) {
                continue;
            }
            facing += 1;
            if (f64::from(r) - t).abs() <= 0.02 {
                on_wall += 1;
                noise.push(f64::from(rn) - f64::from(r));
            } else if r.is_finite() && f64::from(r) < 0.8 {
                // The robot's own body (a wheel, the base), as in Gazebo.
                own_body += 1;
            } else {
                worst = worst.max((f64::from(r) - t).abs());
            }
        }
        let std = (noise.iter().map(|e| e * e).sum::<f64>() / noise.len().max(1) as f64).sqrt();
        eprintln!(
            "{}: {facing} beams face the wall; {on_wall} read its distance ±2 cm (noise off), {own_body} see the \
             robot's own body nearer than 0.8 m; worst other {worst:.3} m; with the file's noise: std {std:.4} m; \
             -inf beams: {}",
            s.name,
            noisy.ranges_m.iter().filter(|r| r.is_infinite() && **r < 0.0).count()
        );
        assert!(facing >= 150, "{}: only {facing} beams face the wall", s.name);
        assert!(on_wall * 10 >= facing * 9, "{}: only {on_wall} of {facing} wall-facing beams read the wall", s.name);
        assert_eq!(
            on_wall + own_body,
            facing,
            "{}: beams read neither the wall nor the robot (worst {worst} m)",
            s.name
        );
        assert!((std - 0.01).abs() < 0.002, "{}: range noise std {std} m, the file says 0.01 m", s.name);
        assert!(noisy.ranges_m.iter().all(|r| !(r.is_infinite() && *r < 0.0)), "{}: a beam reads -inf", s.name);
    }
    assert_eq!(lidars, 2, "TIAGo Pro has two base LiDARs: {names:?}");

    // The head depth camera, 1280 × 720, ray-cast on one core: the head's meshes around the
    // lens (rigid with the camera) are cast on the first frame only.
    let depth = sensors
        .iter()
        .find(|s| s.name == "head_front_cameradepth")
        .unwrap_or_else(|| panic!("no head depth camera in {names:?}"));
    let mut one_core = depth.clone();
    let RaySensorKind::Depth { options, .. } = &mut one_core.kind else {
        panic!("{} is not a depth camera", depth.name)
    };
    assert_eq!((options.width, options.height), (1280, 720));
    options.ray.threads = 1;
    options.ray.noise_std_m = 0.0;
    let Device::Depth(mut camera) = one_core.build(&robot).unwrap() else { unreachable!() };
    let cpu = thread_cpu_secs();
    let first = camera.render(&robot.model, &data).unwrap();
    let first_ms = (thread_cpu_secs() - cpu) * 1e3;
    let frames = 5;
    let (cpu, wall) = (thread_cpu_secs(), Instant::now());
    for _ in 0..frames {
        let frame = camera.render(&robot.model, &data).unwrap();
        assert!(frame.depth_m.iter().zip(&first.depth_m).all(|(a, b)| a.to_bits() == b.to_bits()), "frames differ");
    }
    let ms = (thread_cpu_secs() - cpu) * 1e3 / f64::from(frames);
    let wall_ms = wall.elapsed().as_secs_f64() * 1e3 / f64::from(frames);
    // Every pixel against the world: the wall's face or the floor, whichever its ray meets
    // first (depth along the optical axis).
    let (k, t) = (first.intrinsics, first.world_from_optical);
    let (mut checked, mut agree) = (0usize, 0usize);
    for v in (0..k.height).step_by(4) {
        for u in (0..k.width).step_by(4) {
            let d = t.rotation * k.ray_optical(u, v);
            let o = t.translation.vector;
            let wall = (d.x > 0.0).then(|| (WALL_X - o.x) / d.x).filter(|&s| {
                let p = o + s * d;
                p.y.abs() < 4.0 && (0.0..2.0).contains(&p.z)
            });
            let floor = (d.z < 0.0).then(|| -o.z / d.z);
            let want = match (wall, floor) {
                (Some(a), Some(b)) => a.min(b),
                (a, b) => a.or(b).unwrap_or(f64::NAN),
            };
            let got = f64::from(first.depth_at(u, v));
            checked += 1;
            if (want.is_nan() && got.is_nan()) || (got - want).abs() <= 0.005 {
                agree += 1;
            }
        }
    }
    eprintln!(
        "TIAGo Pro head depth camera 1280×720 on one core: first frame {first_ms:.0} ms CPU (the head's meshes \
         cast once, bodies {:?}), then {ms:.1} ms CPU a frame ({wall_ms:.1} ms wall); {agree} of {checked} sampled \
         pixels at the wall's or floor's depth ±5 mm",
        camera.rigid_bodies()
    );
    assert!(agree * 100 >= checked * 99, "only {agree} of {checked} pixels see the wall or floor where they are");
    assert!(ms <= 50.0, "{ms:.1} ms CPU a frame");
}

/// CPU time of the calling thread, seconds (Linux): a frame's cost on one core, not inflated by
/// waiting for a core on a busy machine.
fn thread_cpu_secs() -> f64 {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap_or_default();
    text.split_whitespace().next().and_then(|n| n.parse::<u64>().ok()).map_or(f64::NAN, |n| n as f64 * 1e-9)
}
