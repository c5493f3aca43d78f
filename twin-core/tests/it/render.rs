//! MuJoCo's renderer through twin (`twin_core::mj::Renderer`, `twin_core::sense::ColourCamera`)
//! against independent references, on the shipped grasp scene (`twin convert
//! models/humanoid_gripper.urdf --world worlds/table_cup.world`):
//! - the colour, depth and segmentation frames of MuJoCo's own Python `Renderer`
//!   (`MUJOCO_GL=egl`, `mujoco==4.0.1` from the tests' venv) of the same MJCF, state and camera;
//! - the ray-cast depth camera of the same camera, pixel by pixel;
//! - the cup's silhouette projected analytically (a ray against the world file's cylinder);
//! - OpenCV's `undistort` of a distorted frame with the `CameraInfo` coefficients against the
//!   pinhole frame.
//!
//! Needs EGL (Mesa's llvmpipe here) or OSMesa: without them these tests FAIL with the renderer's
//! error, which names what to install.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use twin_core::convert::{ConvertOptions, convert_urdf};
use twin_core::mj::{Data, Model, ObjType, Renderer, View};
use twin_core::sense::{ColourCamera, ColourCameraOptions, DepthCamera, DepthCameraOptions, Distortion, RayOptions};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python").join(name)
}

/// The grasp scene as `twin convert` writes it, in `dir`, loaded at its first forward pass.
fn grasp_scene(dir: &Path) -> (PathBuf, Arc<Model>, Data) {
    let root = repo_root();
    let opts = ConvertOptions { world: Some(root.join("worlds/table_cup.world")), ..ConvertOptions::default() };
    let converted = convert_urdf(&root.join("models/humanoid_gripper.urdf"), &opts).unwrap();
    let path = dir.join("grasp_scene.xml");
    std::fs::write(&path, &converted.mjcf).unwrap();
    let model = Arc::new(Model::from_mujoco_file(&path).unwrap());
    let mut data = Data::new(model.clone()).unwrap();
    data.forward().unwrap();
    (path, model, data)
}

/// The head camera of the gripper humanoid (its Gazebo depth sensor's MuJoCo camera).
fn head_camera(model: &Model) -> (usize, String) {
    let id = (0..model.ncam()).next().expect("the grasp scene has a camera");
    (id, model.name(ObjType::Camera, id).to_string())
}

fn read_raw(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// MuJoCo's Python Renderer on `scene`: its frames in `dir` and its timings.
fn python_reference(scene: &Path, width: u32, height: u32, camera: &str, dir: &Path) -> serde_json::Value {
    let python = crate::test_python::python();
    let out = Command::new(&python)
        .env("MUJOCO_GL", "egl")
        .arg(script("render_reference.py"))
        .arg(scene)
        .args([width.to_string(), height.to_string(), camera.to_string()])
        .arg(dir)
        .arg("2")
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", python.display()));
    assert!(out.status.success(), "render_reference.py failed:\n{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("render_reference.py prints JSON")
}

#[test]
fn frames_equal_mujocos_python_renderer() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, model, mut data) = grasp_scene(dir.path());
    let (w, h) = (640u32, 480u32);
    let reference = python_reference(&scene, w, h, "-1", dir.path());
    assert_eq!(reference["mujoco"], "4.0.1", "the tests' venv pins mujoco==4.0.1, the library's version");
    let mut renderer = Renderer::new(model.clone(), w, h).unwrap();
    let n = (w * h) as usize;

    // Colour, MuJoCo's default flags and without shadows and reflections: the same library on
    // the same OpenGL, so the same bytes but for rasterizer rounding.
    let mut aliased = Renderer::with_samples(model.clone(), w, h, Some(0)).unwrap();
    aliased.set_shadows_and_reflections(false, false);
    for (file, shadows) in [("rgb_shadows.raw", true), ("rgb_plain.raw", false), ("rgb_plain_aliased.raw", false)] {
        renderer.set_shadows_and_reflections(shadows, shadows);
        let ours = if file == "rgb_plain_aliased.raw" { &mut aliased } else { &mut renderer }
            .rgb(&mut data, View::Free)
            .unwrap();
        let theirs = read_raw(&dir.path().join(file));
        assert_eq!(ours.len(), theirs.len());
        let diffs: Vec<u8> = ours.iter().zip(&theirs).map(|(a, b)| a.abs_diff(*b)).collect();
        let worst = diffs.iter().copied().max().unwrap();
        let off = diffs.iter().filter(|&&d| d > 2).count();
        let mean = diffs.iter().map(|&d| f64::from(d)).sum::<f64>() / diffs.len() as f64;
        eprintln!(
            "{file}: worst channel difference {worst}, {off} of {} channels off by > 2, mean {mean:.4}",
            diffs.len()
        );
        assert!(off * 1000 <= diffs.len(), "{file}: {off} of {} channel values differ by more than 2", diffs.len());
        assert!(mean < 0.1, "{file}: mean difference {mean}");
        // Not a blank frame: the table, the robot and the floor differ in colour.
        let distinct: std::collections::BTreeSet<&[u8]> = ours.chunks_exact(3).collect();
        assert!(distinct.len() > 200, "{file}: only {} colours", distinct.len());
    }

    // Depth, metres, with MuJoCo's linearisation.
    let ours = renderer.depth(&mut data, View::Free).unwrap();
    let theirs: Vec<f32> = read_raw(&dir.path().join("depth.raw"))
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(ours.len(), n);
    let worst = ours.iter().zip(&theirs).map(|(a, b)| ((a - b) / b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "depth differs by up to {worst} (relative)");

    // Segmentation: (object id, object type) per pixel.
    let ours = renderer.segmentation(&mut data, View::Free).unwrap();
    let theirs: Vec<i32> = read_raw(&dir.path().join("segmentation.raw"))
        .chunks_exact(4)
        .map(|b| i32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let mismatched = ours
        .iter()
        .zip(theirs.chunks_exact(2))
        .filter(|(a, b)| a.map_or([-1, -1], |s| [s.objid, s.objtype]) != [b[0], b[1]])
        .count();
    assert!(mismatched * 10_000 <= n, "{mismatched} of {n} segmentation pixels differ");
    eprintln!("python Renderer ms/frame: {}", reference["ms"]);
}

/// Where the ray from `o` along `d` (a point is `o + t·d`) first meets the cylinder of radius
/// `r` about the vertical axis through `c` from z `z0` to `z1`: its `t`.
fn cylinder_hit(o: [f64; 3], d: [f64; 3], c: [f64; 3], r: f64, z0: f64, z1: f64) -> Option<f64> {
    let (px, py) = (o[0] - c[0], o[1] - c[1]);
    let a = d[0] * d[0] + d[1] * d[1];
    let b = px * d[0] + py * d[1];
    let cc = px * px + py * py - r * r;
    let mut best: Option<f64> = None;
    let disc = b * b - a * cc;
    if a > 0.0 && disc >= 0.0 {
        let t = (-b - disc.sqrt()) / a;
        let z = o[2] + t * d[2];
        if t > 0.0 && (z0..=z1).contains(&z) {
            best = Some(t);
        }
    }
    for zc in [z0, z1] {
        if d[2] != 0.0 {
            let t = (zc - o[2]) / d[2];
            let (x, y) = (px + t * d[0], py + t * d[1]);
            if t > 0.0 && x * x + y * y <= r * r && best.is_none_or(|b| t < b) {
                best = Some(t);
            }
        }
    }
    best
}

#[test]
fn segmentation_shows_the_cup_where_it_projects_and_depth_agrees_with_the_ray_caster() {
    let dir = tempfile::tempdir().unwrap();
    let (_, model, mut data) = grasp_scene(dir.path());
    let (cam, cam_name) = head_camera(&model);
    let [w, h] = model.cam_resolution()[cam];
    let (w, h) = (w as u32, h as u32);
    let mut renderer = Renderer::new(model.clone(), w, h).unwrap();
    let segments = renderer.segmentation(&mut data, View::Camera(cam)).unwrap();

    // The cup: the world file's cylinder (r 0.04 m, 0.1 m high) where MuJoCo placed it; its
    // pixels are those of any geom of its body (the visual geom is the one drawn).
    let cup_geom = (0..model.ngeom())
        .find(|&g| {
            let body = model.geom_bodyid()[g] as usize;
            model.name(ObjType::Body, body) == "cup"
        })
        .expect("a cup geom");
    let c = data.geom_xpos()[cup_geom];
    let half = model.geom_size()[cup_geom][1];
    let radius = model.geom_size()[cup_geom][0];
    // The camera's pixel rays (MuJoCo camera: −z forward, y up; square pixels, centres at
    // integer coordinates from (w − 1) / 2).
    let f = f64::from(h) / 2.0 / (model.cam_fovy_rad()[cam] / 2.0).tan();
    let o = data.cam_xpos()[cam];
    let m = data.cam_xmat()[cam];
    let ray = |u: u32, v: u32| {
        let x = (f64::from(u) - (f64::from(w) - 1.0) / 2.0) / f;
        let y = -(f64::from(v) - (f64::from(h) - 1.0) / 2.0) / f;
        let local = [x, y, -1.0];
        std::array::from_fn::<f64, 3, _>(|i| m[3 * i] * local[0] + m[3 * i + 1] * local[1] + m[3 * i + 2] * local[2])
    };
    let (mut both, mut either) = (0usize, 0usize);
    for v in 0..h {
        for u in 0..w {
            let analytic = cylinder_hit(o, ray(u, v), c, radius, c[2] - half, c[2] + half).is_some();
            let rendered = segments[(v * w + u) as usize]
                .and_then(|s| s.geom())
                .is_some_and(|g| model.geom_bodyid()[g] == model.geom_bodyid()[cup_geom]);
            both += usize::from(analytic && rendered);
            either += usize::from(analytic || rendered);
        }
    }
    let iou = both as f64 / either.max(1) as f64;
    eprintln!("cup silhouette from camera \"{cam_name}\": {both} pixels in both, {either} in either, IoU {iou:.4}");
    assert!(either >= 100, "the cup covers only {either} pixels of the head camera");
    assert!(iou >= 0.95, "cup IoU {iou:.4} against its projected silhouette");

    // Depth: the renderer's against the ray-caster's, pixel by pixel. The ray-caster's near
    // clip (5 cm) takes it out of the camera's housing (a box around it, 1 cm away), which the
    // renderer does not draw from inside (back faces are culled).
    let depth = renderer.depth(&mut data, View::Camera(cam)).unwrap();
    let (_, far) = renderer.clip_planes();
    let opts = DepthCameraOptions {
        width: w,
        height: h,
        ray: RayOptions { min_range_m: 0.05, max_range_m: f64::from(far) * 0.999, threads: 1, ..RayOptions::default() },
        ..DepthCameraOptions::default()
    };
    let cast = DepthCamera::new(&model, &cam_name, opts).unwrap().render(&model, &data).unwrap();
    let (mut agree, mut compared, mut worst_inside) = (0usize, 0usize, 0.0f64);
    for v in 1..h - 1 {
        for u in 1..w - 1 {
            let i = (v * w + u) as usize;
            let (r, c) = (f64::from(depth[i]), f64::from(cast.depth_m[i]));
            compared += 1;
            let same = if c.is_nan() { r >= f64::from(far) * 0.99 } else { (r - c).abs() <= 1e-3 + 1e-3 * c };
            if same {
                agree += 1;
            } else {
                // A disagreement is allowed only on an edge: where the 3×3 neighbourhood of
                // ray-cast depths spans more than 2 cm (the rasterizer samples an edge pixel
                // at another point of it).
                let around: Vec<f64> =
                    [(0i32, 0i32), (-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, 1), (-1, 1), (1, -1)]
                        .iter()
                        .map(|(du, dv)| {
                            f64::from(cast.depth_m[((v as i32 + dv) as u32 * w + (u as i32 + du) as u32) as usize])
                        })
                        .collect();
                let (lo, hi) = around.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    if x.is_nan() { (a, f64::INFINITY) } else { (a.min(x), b.max(x)) }
                });
                if hi - lo <= 0.02 {
                    worst_inside = worst_inside.max((r - c).abs());
                }
            }
        }
    }
    eprintln!("depth: {agree} of {compared} pixels agree within 1 mm + 0.1 %; worst off an edge {worst_inside:.4} m");
    assert!(agree * 100 >= compared * 99, "only {agree} of {compared} depth pixels agree");
    assert!(worst_inside == 0.0, "a pixel off any edge differs by {worst_inside} m");
}

/// A 4 × 4 grid of small red spheres on a grey wall 1 m in front of a camera with a wide field
/// of view (MuJoCo: 70° vertical), the outer ones near the image's corners.
const DOTS: &str = r#"<mujoco><visual><headlight ambient="0.6 0.6 0.6" diffuse="0.4 0.4 0.4"/></visual>
  <asset><material name="red" rgba="1 0 0 1" specular="0"/><material name="grey" rgba="0.5 0.5 0.5 1" specular="0"/></asset>
  <worldbody><geom type="box" pos="0 0 -1.02" size="3 3 0.01" material="grey"/>
  DOTS_HERE
  <camera name="eye" pos="0 0 0" fovy="70"/></worldbody></mujoco>"#;

/// Centroid (u, v) of the red pixels within `r` pixels of `(u0, v0)`.
fn red_centroid(rgb: &[u8], w: usize, (u0, v0): (f64, f64), r: f64) -> Option<(f64, f64)> {
    let (mut su, mut sv, mut n) = (0.0, 0.0, 0.0);
    let h = rgb.len() / 3 / w;
    for v in (v0 - r).max(0.0) as usize..((v0 + r) as usize).min(h) {
        for u in (u0 - r).max(0.0) as usize..((u0 + r) as usize).min(w) {
            let p = &rgb[3 * (v * w + u)..][..3];
            // Redness: how much red stands above green (grey has none).
            let weight = (f64::from(p[0]) - f64::from(p[1])).max(0.0);
            if weight > 40.0 {
                su += weight * u as f64;
                sv += weight * v as f64;
                n += weight;
            }
        }
    }
    (n > 0.0).then(|| (su / n, sv / n))
}

#[test]
fn distorted_frames_undistorted_by_opencv_match_the_pinhole_frame() {
    let mut dots = String::new();
    for i in 0..4 {
        for j in 0..4 {
            let (x, y) = (-0.75 + 0.5 * f64::from(i), -0.5 + f64::from(j) / 3.0);
            dots.push_str(&format!(r#"<geom type="sphere" size="0.025" pos="{x} {y} -1" material="red"/>"#));
        }
    }
    let model = Arc::new(Model::from_xml_str(&DOTS.replace("DOTS_HERE", &dots)).unwrap());
    let mut data = Data::new(model.clone()).unwrap();
    data.forward().unwrap();
    let (w, h) = (640usize, 480usize);
    let base = ColourCameraOptions { width: w as u32, height: h as u32, ..ColourCameraOptions::default() };
    let lens = Distortion { k1: -0.28, k2: 0.08, k3: -0.01, p1: 0.0015, p2: -0.001 };
    let pinhole = ColourCamera::new(&model, "eye", base.clone()).unwrap().render(&mut data).unwrap();
    let distorted = ColourCamera::new(&model, "eye", ColourCameraOptions { distortion: lens, ..base })
        .unwrap()
        .render(&mut data)
        .unwrap();
    let info = distorted.camera_info();
    assert_eq!(info.distortion_model, "plumb_bob");
    assert_eq!(info.d, vec![-0.28, 0.08, 0.0015, -0.001, -0.01]);

    // OpenCV undistorts the distorted frame with the CameraInfo's K and D.
    let dir = tempfile::tempdir().unwrap();
    let (input, output) = (dir.path().join("distorted.raw"), dir.path().join("undistorted.raw"));
    std::fs::write(&input, &distorted.rgb).unwrap();
    let args = serde_json::json!({"width": w, "height": h, "k": info.k, "d": info.d}).to_string();
    let python = crate::test_python::python();
    let out = Command::new(&python).arg(script("undistort.py")).arg(&input).arg(&output).arg(&args).output().unwrap();
    assert!(out.status.success(), "undistort.py failed:\n{}", String::from_utf8_lossy(&out.stderr));
    let undistorted = read_raw(&output);

    // Every dot: where the pinhole frame has it, the undistorted frame has it within 1 px; the
    // distorted frame has the outer ones well away (the lens does something).
    let k = pinhole.intrinsics;
    let (mut worst, mut moved) = (0.0f64, 0.0f64);
    for i in 0..4 {
        for j in 0..4 {
            let (x, y) = (-0.75 + 0.5 * f64::from(i), -0.5 + f64::from(j) / 3.0);
            // Projection of the dot's centre (optical frame: x right, y down, z = 1 m ahead).
            let guess = (k.fx * x + k.cx, k.fy * -y + k.cy);
            let p = red_centroid(&pinhole.rgb, w, guess, 20.0)
                .unwrap_or_else(|| panic!("dot {i} {j} not in the pinhole frame"));
            let u = red_centroid(&undistorted, w, p, 20.0)
                .unwrap_or_else(|| panic!("dot {i} {j} not in the undistorted frame"));
            let (xd, yd) = lens.distort((p.0 - k.cx) / k.fx, (p.1 - k.cy) / k.fy);
            let d = red_centroid(&distorted.rgb, w, (k.fx * xd + k.cx, k.fy * yd + k.cy), 20.0)
                .unwrap_or_else(|| panic!("dot {i} {j} not in the distorted frame"));
            worst = worst.max(((u.0 - p.0).powi(2) + (u.1 - p.1).powi(2)).sqrt());
            moved = moved.max(((d.0 - p.0).powi(2) + (d.1 - p.1).powi(2)).sqrt());
        }
    }
    eprintln!("distortion: dots moved up to {moved:.1} px by the lens, back within {worst:.3} px after OpenCV");
    assert!(moved > 10.0, "the lens moved no dot by more than {moved} px");
    assert!(worst <= 1.0, "a dot is {worst} px from its pinhole place after undistortion");
}
