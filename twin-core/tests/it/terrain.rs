//! Terrain composed with the shipped humanoid: MuJoCo's own ray casts see the ground where the
//! generator says it is, the robot starts seated on it (not inside it), and a new terrain
//! written into a compiled model is the one MuJoCo then collides with.

use std::path::PathBuf;
use std::sync::Arc;
use twin_core::mj::{Data, ObjType};
use twin_core::scenario::Scenario;
use twin_core::terrain::TerrainOptions;

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
