//! Milliseconds per rendered frame of the shipped grasp scene (`twin convert
//! models/humanoid_gripper.urdf --world worlds/table_cup.world`, MuJoCo's default free camera),
//! twin's renderer (`twin_core::mj::Renderer`, `twin_core::sense::ColourCamera`) side by side
//! with MuJoCo's Python `Renderer` on the same MJCF, size and flags, on this machine's OpenGL
//! (Mesa's llvmpipe on a CPU machine, the GPU's EGL where there is one).
//!
//!     cargo bench -p twin-core --bench render -- [--width 640] [--height 480] [--frames 30] [--python PYTHON]
//!
//! PYTHON (default: the tests' venv, `target/test-venv/bin/python`, made by the tests from
//! `.ci/requirements.txt`) runs `twin-core/tests/python/render_reference.py`; without it only
//! twin's figures are printed. Median wall ms of N frames after one warm-up.

#[allow(dead_code)] // the camera benches' helpers; this one uses `median`
mod common;
#[allow(dead_code)] // `rest`: this bench takes no file argument
mod flags;

use common::median;
use std::sync::Arc;
use std::time::Instant;
use twin_core::convert::{ConvertOptions, convert_urdf};
use twin_core::mj::{Data, Model, Renderer, View};
use twin_core::sense::{ColourCamera, ColourCameraOptions, Distortion};

fn time(frames: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..frames)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

fn main() {
    let flags = flags::Flags::from_env();
    let (w, h, frames) = (flags.get("--width", 640u32), flags.get("--height", 480u32), flags.get("--frames", 30usize));
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    let python = flags.get("--python", root.join("target/test-venv/bin/python").display().to_string());
    let opts = ConvertOptions { world: Some(root.join("worlds/table_cup.world")), ..ConvertOptions::default() };
    let converted = convert_urdf(&root.join("models/humanoid_gripper.urdf"), &opts).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("grasp_scene.xml");
    std::fs::write(&scene, &converted.mjcf).unwrap();
    // The free camera's view as a named camera, for the colour camera's distortion figure.
    let model = Arc::new(Model::from_mujoco_file(&scene).unwrap());
    let mut data = Data::new(model.clone()).unwrap();
    data.forward().unwrap();
    let mut renderer = Renderer::new(model.clone(), w, h).unwrap();
    println!("grasp scene: {} geoms, {w}×{h}, {frames} frames, OpenGL: {}", model.ngeom(), renderer.backend());
    let mut rows: Vec<(&str, f64)> = Vec::new();
    renderer.set_shadows_and_reflections(true, true);
    rows.push(("RGB, shadows and reflections", time(frames, || drop(renderer.rgb(&mut data, View::Free).unwrap()))));
    renderer.set_shadows_and_reflections(false, false);
    rows.push(("RGB, no shadows or reflections", time(frames, || drop(renderer.rgb(&mut data, View::Free).unwrap()))));
    let mut aliased = Renderer::with_samples(model.clone(), w, h, Some(0)).unwrap();
    aliased.set_shadows_and_reflections(false, false);
    rows.push((
        "RGB, no shadows or reflections, no antialiasing",
        time(frames, || drop(aliased.rgb(&mut data, View::Free).unwrap())),
    ));
    rows.push(("depth", time(frames, || drop(renderer.depth(&mut data, View::Free).unwrap()))));
    rows.push(("segmentation", time(frames, || drop(renderer.segmentation(&mut data, View::Free).unwrap()))));
    // The head camera as a colour camera at this size: pinhole, then with a lens and noise.
    let head = model.name(twin_core::mj::ObjType::Camera, 0).to_string();
    let base = ColourCameraOptions { width: w, height: h, ..ColourCameraOptions::default() };
    let mut pinhole = ColourCamera::new(&model, &head, base.clone()).unwrap();
    rows.push(("head camera RGB (ColourCamera)", time(frames, || drop(pinhole.render(&mut data).unwrap()))));
    let mut plain =
        ColourCamera::new(&model, &head, ColourCameraOptions { multisamples: Some(0), ..base.clone() }).unwrap();
    rows.push(("head camera RGB, no antialiasing", time(frames, || drop(plain.render(&mut data).unwrap()))));
    let lens = Distortion { k1: -0.28, k2: 0.08, k3: -0.01, p1: 0.0015, p2: -0.001 };
    let mut distorted =
        ColourCamera::new(&model, &head, ColourCameraOptions { distortion: lens, noise_std: 0.007, ..base }).unwrap();
    rows.push(("head camera RGB + distortion + noise", time(frames, || drop(distorted.render(&mut data).unwrap()))));

    let reference = std::process::Command::new(&python)
        .env("MUJOCO_GL", "egl")
        .arg(root.join("twin-core/tests/python/render_reference.py"))
        .arg(&scene)
        .args([w.to_string(), h.to_string(), "-1".into()])
        .arg(dir.path())
        .arg(frames.to_string())
        .output();
    let ms: Option<serde_json::Value> = match reference {
        Ok(out) if out.status.success() => {
            serde_json::from_slice::<serde_json::Value>(&out.stdout).ok().map(|j| j["ms"].clone())
        }
        Ok(out) => {
            eprintln!("{python}: render_reference.py failed:\n{}", String::from_utf8_lossy(&out.stderr));
            None
        }
        Err(e) => {
            eprintln!("{python}: {e}: no Python reference");
            None
        }
    };
    let keys = ["rgb_shadows", "rgb_plain", "rgb_plain_aliased", "depth", "segmentation"];
    println!("| frame ({w}×{h}) | twin (ms) | MuJoCo Python Renderer (ms, mean) |");
    println!("|---|---|---|");
    for (k, (what, twin)) in rows.iter().enumerate() {
        let py = keys.get(k).and_then(|key| ms.as_ref().and_then(|m| m[key].as_f64()));
        println!("| {what} | {twin:.1} | {} |", py.map_or("–".into(), |p| format!("{p:.1}")));
    }
}
