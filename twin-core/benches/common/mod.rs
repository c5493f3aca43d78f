//! What the camera benches share: the thread's CPU clock, a median, a camera's timing loop,
//! and a model with an added camera looking from one point at another.

use nalgebra::Vector3;
use std::sync::Arc;
use std::time::Instant;
use twin_core::mj::{Data, Model};
use twin_core::sense::DepthCamera;

/// CPU time of the calling thread, seconds (Linux): not inflated by waiting for a core on a
/// busy machine, unlike wall time.
pub fn thread_cpu_secs() -> f64 {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").unwrap_or_default();
    text.split_whitespace().next().and_then(|n| n.parse::<u64>().ok()).map_or(f64::NAN, |n| n as f64 * 1e-9)
}

/// The median (upper middle for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Renders `camera` once (warm-up; its valid pixels are counted), then `frames` times: median
/// wall ms, mean CPU ms of the calling thread (measured over all the frames: the thread's CPU
/// time advances in scheduler ticks), valid pixels.
pub fn time_camera(model: &Model, data: &Data, camera: &mut DepthCamera, frames: usize) -> (f64, f64, usize) {
    let valid = camera.render(model, data).unwrap().depth_m.iter().filter(|z| z.is_finite()).count();
    let cpu = thread_cpu_secs();
    let times: Vec<f64> = (0..frames)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(camera.render(model, data).unwrap());
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    (median(times), (thread_cpu_secs() - cpu) * 1e3 / frames as f64, valid)
}

/// Compiles `mjcf` with a world camera `name` at `eye` (world, m) looking at `target`, its
/// image x axis horizontal; `attributes` adds to the element (`fovy`, `resolution`).
pub fn with_camera(mjcf: &str, name: &str, eye: Vector3<f64>, target: Vector3<f64>, attributes: &str) -> Arc<Model> {
    let d = (target - eye).normalize();
    let right = d.cross(&Vector3::z()).normalize();
    let up = right.cross(&d);
    let camera = format!(
        "<camera name=\"{name}\" pos=\"{} {} {}\" xyaxes=\"{} {} {} {} {} {}\" {attributes}/>",
        eye.x, eye.y, eye.z, right.x, right.y, right.z, up.x, up.y, up.z
    );
    let mjcf = mjcf.replacen("<worldbody>", &format!("<worldbody>\n{camera}"), 1);
    Arc::new(Model::from_xml_str(&mjcf).unwrap_or_else(|e| panic!("{e}")))
}
