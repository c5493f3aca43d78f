//! Terrain composed with the shipped humanoid: MuJoCo's own ray casts see the ground where the
//! generator says it is, the robot starts seated on it (not inside it), a new terrain
//! written into a compiled model is the one MuJoCo then collides with, and a Gazebo world's
//! `<heightmap>` is ground the robot stands on at the PNG's elevation.

use std::path::PathBuf;
use std::sync::Arc;
use twin_core::mj::{Data, ObjType};
use twin_core::terrain::TerrainOptions;
use twin_scenario::Scenario;

fn humanoid() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/humanoid.urdf")
}

fn scenario(terrain: &str) -> Scenario {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    Scenario::parse(
        &dir.join("inline.toml"),
        &format!("model = {:?}\nduration = 1.0\narmature = 0.01\n[terrain]\n{terrain}", humanoid()),
    )
    .unwrap()
}

/// Height of the ground at (x, y) as MuJoCo's `mj_multiRay` sees it (a ray down from 2 m,
/// the robot's geoms excluded by casting before it is anywhere near: static geoms only).
fn ray_height(data: &mut Data, x: f64, y: f64) -> (f64, String) {
    let hit = data.multi_ray([x, y, 2.0], &[[0.0, 0.0, -1.0]], None, true, Some(1), 10.0).unwrap()[0].unwrap();
    (2.0 - hit.dist_m, data.model().name(ObjType::Geom, hit.geom).to_string())
}

#[test]
fn mujoco_sees_the_generated_ground() {
    for (terrain, tol) in [
        ("kind = \"rough\"\namplitude_m = 0.02\nseed = 3\n", 1e-5),
        ("kind = \"slope\"\nslope_deg = 8.0\ndirection_deg = 30.0\n", 1e-5),
        ("kind = \"stairs\"\nrise_m = 0.05\n", 1e-9),
        ("kind = \"obstacles\"\ndensity_per_m = 2.0\n", 1e-9),
        ("kind = \"gaps\"\n", 1e-9),
    ] {
        let s = scenario(terrain);
        let geometry = s.terrain.as_ref().unwrap().build();
        let robot = s.robot(&humanoid()).unwrap();
        let mut data = Data::new(robot.model.clone()).unwrap();
        data.forward().unwrap();
        let mut checked = 0;
        // A grid over the terrain, clear of the robot at the origin.
        for i in 0..40 {
            for j in 0..9 {
                let (x, y) = (0.8 + 0.2 * f64::from(i), -1.2 + 0.3 * f64::from(j));
                let want = geometry.height_at(x, y);
                let (got, geom) = ray_height(&mut data, x, y);
                assert!(
                    (got - want).abs() < tol,
                    "{terrain}: at ({x}, {y}) MuJoCo's ground is {got} ({geom}), the generator's {want}"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 360);
    }
}

#[test]
fn the_robot_starts_seated_on_the_ground() {
    // Rough ground (its start pad on the floor), and a step right under the feet
    // (start_m = 0): the lowest foot point rests on the ground, nothing penetrates.
    for (terrain, ground) in
        [("kind = \"rough\"\namplitude_m = 0.01\n", 0.0), ("kind = \"steps\"\nheight_m = 0.04\nstart_m = 0.0\n", 0.04)]
    {
        let s = scenario(terrain);
        let robot = s.robot(&humanoid()).unwrap();
        let mut data = Data::new(robot.model.clone()).unwrap();
        twin_core::control::reset_to_home(&mut data).unwrap();
        let lowest = twin_core::robot::lowest_robot_point_z(&robot.model, &data);
        assert!((lowest - ground).abs() < 1e-9, "{terrain}: lowest robot point {lowest}, ground {ground}");
        let deepest = data.contacts().iter().map(|c| c.0).fold(0.0, f64::min);
        assert!(deepest > -1e-6, "{terrain}: penetrates by {deepest} m at reset");
    }
}

#[test]
fn a_new_terrain_written_into_the_model_is_the_one_mujoco_sees() {
    let s = scenario("kind = \"rough\"\namplitude_m = 0.03\nseed = 1\n");
    let robot = s.robot(&humanoid()).unwrap();
    let options = TerrainOptions { seed: 2, ..s.terrain.clone().unwrap() };
    let other = options.build();
    assert_ne!(other, s.terrain.as_ref().unwrap().build());
    let model = Arc::new(other.write_into(&robot.model).unwrap());
    let mut data = Data::new(model).unwrap();
    data.forward().unwrap();
    for i in 0..30 {
        let (x, y) = (1.0 + 0.23 * f64::from(i), 0.4 - 0.03 * f64::from(i));
        let (got, _) = ray_height(&mut data, x, y);
        assert!((got - other.height_at(x, y)).abs() < 1e-5, "at ({x}, {y}): {got} vs {}", other.height_at(x, y));
    }
    // Obstacles: the boxes move with the seed.
    let s = scenario("kind = \"obstacles\"\ndensity_per_m = 2.0\n");
    let robot = s.robot(&humanoid()).unwrap();
    let other = TerrainOptions { seed: 9, ..s.terrain.clone().unwrap() }.build();
    let mut data = Data::new(Arc::new(other.write_into(&robot.model).unwrap())).unwrap();
    data.forward().unwrap();
    let b = other.boxes[0];
    let (got, geom) = ray_height(&mut data, b.center_m[0], b.center_m[1]);
    assert!((got - (b.center_m[2] + b.half_m[2])).abs() < 1e-9 && geom == "twin_terrain_box0", "{got} {geom}");
}

#[test]
fn bad_terrain_keys_name_the_line() {
    let e =
        Scenario::parse(std::path::Path::new("s.toml"), "duration = 1\n[terrain]\nkind = \"rough\"\nslope_deg = 5\n")
            .unwrap_err()
            .to_string();
    assert!(e.starts_with("s.toml:4: `terrain.slope_deg`") && e.contains("does not apply"), "{e}");
    let e = Scenario::parse(std::path::Path::new("s.toml"), "duration = 1\n[terrain]\nkind = \"lava\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("s.toml:3: `terrain.kind`") && e.contains("rough"), "{e}");
}

/// A Gazebo world with a `<heightmap>`: a 33×33 grayscale PNG whose pixel (row r, column c) is
/// 60 + c + 2·(32 − r) (a plane rising 1 level per column towards +x and 2 per row towards +y,
/// the image's top row at +y), 4 × 3 m, 0.5 m from black to white, centred at (0.3, −0.2, −0.1).
/// The humanoid converted into it holds its pose for 2 s under twin's PD hold; every contact of
/// its feet with the heightmap is at the elevation the PNG gives under it, computed here from
/// the pixels alone (bilinear between the four pixels around the point: on a plane, exactly
/// MuJoCo's triangles), within 5 mm.
#[test]
fn the_robot_stands_on_a_gazebo_heightmap_at_its_elevation() {
    use twin_core::control::{Actuation, Controller, Observation, PdHold, PdHoldOptions};
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (33usize, 33usize);
    let pixel = |r: usize, c: usize| (60 + c + 2 * (h - 1 - r)) as u8;
    let mut image = Vec::with_capacity(w * h);
    for r in 0..h {
        for c in 0..w {
            image.push(pixel(r, c));
        }
    }
    {
        let file = std::fs::File::create(dir.path().join("ramp.png")).unwrap();
        let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header().unwrap().write_image_data(&image).unwrap();
    }
    let (size, pos) = ([4.0, 3.0, 0.5], [0.3, -0.2, -0.1]);
    let world = dir.path().join("terrain.world");
    std::fs::write(
        &world,
        format!(
            r#"<?xml version="1.0"?>
<sdf version="1.6">
  <world name="hills">
    <include><uri>model://sun</uri></include>
    <model name="terrain">
      <static>true</static>
      <link name="link">
        <collision name="collision">
          <geometry>
            <heightmap>
              <uri>ramp.png</uri>
              <size>{} {} {}</size>
              <pos>{} {} {}</pos>
            </heightmap>
          </geometry>
        </collision>
        <visual name="visual">
          <geometry>
            <heightmap>
              <uri>ramp.png</uri>
              <size>{} {} {}</size>
              <pos>{} {} {}</pos>
              <texture><diffuse>dirt.png</diffuse><size>1</size></texture>
            </heightmap>
          </geometry>
        </visual>
      </link>
    </model>
  </world>
</sdf>
"#,
            size[0], size[1], size[2], pos[0], pos[1], pos[2], size[0], size[1], size[2], pos[0], pos[1], pos[2]
        ),
    )
    .unwrap();
    // Elevation from the pixels: x, y → fractional column and row (row 0 at +y).
    let elevation = |x: f64, y: f64| -> f64 {
        let fc = (x - (pos[0] - size[0] / 2.0)) / size[0] * (w - 1) as f64;
        let fr = ((pos[1] + size[1] / 2.0) - y) / size[1] * (h - 1) as f64;
        let (c0, r0) = (fc.floor() as usize, fr.floor() as usize);
        let (tc, tr) = (fc - c0 as f64, fr - r0 as f64);
        let v = |r: usize, c: usize| f64::from(pixel(r, c));
        let top = v(r0, c0) * (1.0 - tc) + v(r0, c0 + 1) * tc;
        let bottom = v(r0 + 1, c0) * (1.0 - tc) + v(r0 + 1, c0 + 1) * tc;
        pos[2] + (top * (1.0 - tr) + bottom * tr) / 255.0 * size[2]
    };

    // A heightmap whose PNG is missing, or not a PNG: the world file's line and what to do.
    let text = std::fs::read_to_string(&world).unwrap();
    for (uri, want) in [("gone.png", "not found"), ("terrain.world", "not a readable PNG")] {
        let bad = dir.path().join("bad.world");
        std::fs::write(&bad, text.replacen("<uri>ramp.png</uri>", &format!("<uri>{uri}</uri>"), 1)).unwrap();
        let opts = twin_core::convert::ConvertOptions { world: Some(bad), ..Default::default() };
        let e = twin_core::convert::convert_urdf(&humanoid(), &opts).unwrap_err().to_string();
        assert!(e.contains("bad.world:11: <uri") && e.contains(want), "{e}");
    }
    let options = twin_core::convert::ConvertOptions { world: Some(world.clone()), ..Default::default() };
    let converted = twin_core::convert::convert_urdf(&humanoid(), &options).unwrap();
    // The texture is how Gazebo draws it: a note with its line; the visual copy is not a geom.
    assert!(
        converted.notes.iter().any(|n| n.contains("terrain.world:23: <heightmap><texture> not converted")),
        "{:?}",
        converted.notes
    );
    let robot = twin_core::robot::Robot::load_with(humanoid(), &options).unwrap();
    let model = robot.model.clone();
    let terrain = model.require_id(ObjType::Geom, "terrain_collision").unwrap();
    assert_eq!(model.geom_kind(terrain), twin_core::mj::GeomType::Hfield, "an hfield geom");
    let mut data = Data::new(model.clone()).unwrap();
    twin_core::control::reset_to_home(&mut data).unwrap();
    let start_z = data.qpos()[2];
    // Seated: nothing inside the ground at reset, the feet within 1.5 cm above the ground at the
    // origin (one foot rests on the ground; the other, over lower ground, hangs by the slope).
    let deepest = data.contacts().iter().map(|c| c.0).fold(0.0, f64::min);
    assert!(deepest > -1e-6, "penetrates by {deepest} m at reset");
    let gap = twin_core::robot::lowest_robot_point_z(&model, &data) - elevation(0.0, 0.0);
    assert!((0.0..0.015).contains(&gap), "lowest robot point {gap} m above the ground at the origin");
    let mut hold = PdHold::new(&model, PdHoldOptions::default());
    hold.reset(&model, &Observation::of(&data)).unwrap();
    let actuation = Actuation::of(&model);
    let mut command = vec![0.0; actuation.len(&model)];
    for _ in 0..(2.0 / model.timestep_secs()).round() as usize {
        hold.compute(&model, &Observation::of(&data), &mut command);
        actuation.apply(&mut data, &command);
        data.step().unwrap();
    }
    // Standing: the base has not dropped (seated on the ground, not inside nor far above it).
    let drop = start_z - data.qpos()[2];
    assert!(drop.abs() < 0.03, "the base moved {drop} m in 2 s of PD hold");
    let mut feet_contacts = 0;
    let mut worst: f64 = 0.0;
    for (geoms, p) in data.contact_points() {
        let other = if geoms[0] as usize == terrain {
            geoms[1]
        } else if geoms[1] as usize == terrain {
            geoms[0]
        } else {
            continue;
        };
        let body = model.geom_bodyid()[other as usize] as usize;
        assert!(robot.feet.contains(&body), "{} touches the heightmap", model.name(ObjType::Body, body));
        let want = elevation(p[0], p[1]);
        worst = worst.max((p[2] - want).abs());
        assert!((p[2] - want).abs() < 0.005, "contact at ({}, {}) z {}, the PNG's elevation {want}", p[0], p[1], p[2]);
        feet_contacts += 1;
    }
    assert!(feet_contacts >= 2, "{feet_contacts} foot contacts with the heightmap");
    // The ground under the feet is well above z 0 (the PNG's elevation at the origin, 0.115 m):
    // the robot was seated on it, not at the floor's height.
    assert!(elevation(0.0, 0.0) > 0.1, "{}", elevation(0.0, 0.0));

    // Over the whole map, not only under the feet: MuJoCo's ray casts hit the heightmap at the
    // PNG's elevation (the robot's geoms are away from these points).
    let mut data = Data::new(model.clone()).unwrap();
    data.forward().unwrap();
    for k in 0..12 {
        let (x, y) = (-1.5 + 0.31 * f64::from(k), 1.25 - 0.23 * f64::from(k));
        if x.abs() < 0.4 && y.abs() < 0.4 {
            continue;
        }
        let (z, geom) = ray_height(&mut data, x, y);
        assert!(
            geom == "terrain_collision" && (z - elevation(x, y)).abs() < 1e-6,
            "({x}, {y}): {z} on {geom}, the PNG {}",
            elevation(x, y)
        );
    }
    eprintln!("{feet_contacts} foot contacts, worst |z − elevation| {worst:.2e} m, base moved {drop:.4} m");
}
