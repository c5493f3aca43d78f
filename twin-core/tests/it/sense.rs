//! Sensing by ray casting on rendered scenes: cup detection from a depth camera's points
//! against the scene's known cup, and LiDAR ranges against analytic ones.

use nalgebra::{Point3, Vector3};
use std::sync::Arc;
use twin_core::mj::{Data, Model, ObjType, RayFilter};
use twin_core::sense::{CupDetectOptions, DepthCamera, DepthCameraOptions, RayOptions, detect_cup};

/// A floor, a 1.2 × 0.8 m table with its top at 0.75 m, a 4 cm-radius, 10 cm-high cup at
/// `cup_xy`, an arm over the table that the camera is told not to see, and a camera on that
/// arm's body at `eye` looking at `target`.
fn table_cup_scene(cup_xy: [f64; 2], eye: [f64; 3], target: [f64; 3]) -> String {
    let d = (Vector3::from(target) - Vector3::from(eye)).normalize();
    let right = d.cross(&Vector3::z()).normalize();
    let up = right.cross(&d);
    format!(
        r#"<mujoco><worldbody>
        <geom name="floor" type="plane" size="4 4 0.1"/>
        <body name="table" pos="0.6 0 0.375"><geom type="box" size="0.4 0.6 0.375"/></body>
        <body name="cup" pos="{} {} 0.8"><freejoint/><geom name="cup" type="cylinder" size="0.04 0.05" mass="0.2"/></body>
        <body name="robot" pos="0.1 0 1.0"><geom type="capsule" fromto="0 0 0 0.3 0.2 -0.1" size="0.03"/>
          <camera name="head" pos="{} {} {}" xyaxes="{} {} {} {} {} {}" fovy="58"/></body>
        </worldbody></mujoco>"#,
        cup_xy[0],
        cup_xy[1],
        eye[0] - 0.1,
        eye[1],
        eye[2] - 1.0,
        right.x,
        right.y,
        right.z,
        up.x,
        up.y,
        up.z
    )
}

#[test]
fn cup_is_found_within_a_centimetre_from_the_depth_points() {
    let positions = [[0.55, 0.0], [0.45, 0.25], [0.7, -0.3], [0.35, -0.1]];
    for (k, &xy) in positions.iter().enumerate() {
        let model = Arc::new(Model::from_xml_str(&table_cup_scene(xy, [0.0, 0.0, 1.35], [0.55, 0.0, 0.75])).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        data.forward().unwrap();
        let robot = model.id(ObjType::Body, "robot").unwrap();
        let filter = RayFilter { exclude_bodies: model.subtree(robot), ..RayFilter::default() };
        // Sensor noise of a good depth camera at ~1 m (1 mm); the estimate must still hold.
        let opts = DepthCameraOptions {
            ray: RayOptions { filter, noise_std_m: 0.001, seed: k as u64, ..DepthCameraOptions::default().ray },
            ..DepthCameraOptions::default()
        };
        let mut camera = DepthCamera::new(&model, "head", opts).unwrap();
        let frame = camera.render(&model, &data).unwrap();
        let points = frame.points_world();
        // The excluded arm is not in the image: no point near its capsule.
        assert!(points.iter().all(|p| p.z < 0.9), "cup {k}: a point above the cup's rim");
        let est = detect_cup(&points, &CupDetectOptions::default()).unwrap();
        let truth = Point3::new(xy[0], xy[1], 0.8);
        let err = (est.centre_world - truth).norm();
        eprintln!(
            "cup {k} at {xy:?}: centre off by {err:.5} m, radius {:.5} m, height {:.5} m",
            est.radius_m, est.height_m
        );
        assert!(err < 0.01, "cup {k} at {xy:?}: estimated {} ({err:.4} m off)", est.centre_world);
        assert!((est.radius_m - 0.04).abs() < 0.005, "cup {k}: radius {}", est.radius_m);
        assert!((est.height_m - 0.1).abs() < 0.005, "cup {k}: height {}", est.height_m);
        assert!((est.table_height_m - 0.75).abs() < 0.003, "cup {k}: table at {}", est.table_height_m);
        assert!(est.n_points > 100, "cup {k}: {} points", est.n_points);
    }
}

#[test]
fn no_cup_on_the_table_is_an_error_not_a_guess() {
    let scene = table_cup_scene([3.0, 3.0], [0.0, 0.0, 1.35], [0.55, 0.0, 0.75]);
    let model = Arc::new(Model::from_xml_str(&scene).unwrap());
    let mut data = Data::new(model.clone()).unwrap();
    data.forward().unwrap();
    let robot = model.id(ObjType::Body, "robot").unwrap();
    let filter = RayFilter { exclude_bodies: model.subtree(robot), ..RayFilter::default() };
    let opts = DepthCameraOptions {
        width: 160,
        height: 120,
        ray: RayOptions { filter, ..DepthCameraOptions::default().ray },
        ..DepthCameraOptions::default()
    };
    let frame = DepthCamera::new(&model, "head", opts).unwrap().render(&model, &data).unwrap();
    let err = detect_cup(&frame.points_world(), &CupDetectOptions::default()).unwrap_err().to_string();
    assert!(err.contains("nothing stands on the table"), "{err}");
}
