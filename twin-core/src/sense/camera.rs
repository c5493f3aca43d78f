//! A colour camera rendered by MuJoCo's own renderer ([`crate::mj::Renderer`], offscreen OpenGL:
//! EGL or OSMesa), with the real camera's imperfections from its Gazebo tags: pinhole
//! intrinsics from the field of view, Brown–Conrady (`plumb_bob`) lens distortion applied to
//! the image and written in `CameraInfo`, Gaussian pixel noise; and, on request, per-pixel
//! segmentation labels (instances: geoms; classes: bodies, i.e. URDF links) with their label
//! table.
//!
//! Pixel convention as [`Intrinsics`] (ROS): pixel `(u, v)` has its centre at integer
//! coordinates, so a centred camera has `cx = (width − 1) / 2`; OpenGL's pixel centres at
//! `u + ½` from the image edge are the same points.

use super::depth::Intrinsics;
use super::fan::noise_rng;
use crate::error::{Error, Result};
use crate::log::{CameraInfo, Header, Image, RegionOfInterest};
use crate::mj::{Data, Model, ObjType, Renderer, View};
use rand::Rng;
use rand_distr::StandardNormal;
use std::sync::Arc;

/// Brown–Conrady lens distortion of normalised image coordinates (Gazebo's `<distortion>`,
/// OpenCV's and ROS's `plumb_bob`): radial `k1 k2 k3`, tangential `p1 p2`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Distortion {
    /// Radial coefficient of r².
    pub k1: f64,
    /// Radial coefficient of r⁴.
    pub k2: f64,
    /// Radial coefficient of r⁶.
    pub k3: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
}

impl Distortion {
    /// Whether every coefficient is zero.
    pub fn is_none(&self) -> bool {
        [self.k1, self.k2, self.k3, self.p1, self.p2].iter().all(|&c| c == 0.0)
    }

    /// The coefficients in `CameraInfo`'s `plumb_bob` order: k1 k2 p1 p2 k3.
    pub fn plumb_bob(&self) -> Vec<f64> {
        vec![self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    /// Where the lens puts the ideal (pinhole) normalised point `(x, y)`.
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        (
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// The ideal point that the lens puts at `(xd, yd)`: the fixed-point iteration of
    /// OpenCV's `undistortPoints`, refined until it reproduces `(xd, yd)` within 1e-12 (or 50
    /// rounds); `None` where it does not converge (far outside the lens's valid field).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..50 {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
            let dx = 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
            let dy = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
            (x, y) = ((xd - dx) / radial, (yd - dy) / radial);
            let (ex, ey) = self.distort(x, y);
            if ((ex - xd).powi(2) + (ey - yd).powi(2)) < 1e-24 {
                return Some((x, y));
            }
        }
        let (ex, ey) = self.distort(x, y);
        (((ex - xd).powi(2) + (ey - yd).powi(2)) < 1e-12 && x.is_finite() && y.is_finite()).then_some((x, y))
    }
}

/// How a [`ColourCamera`] images.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct ColourCameraOptions {
    /// Image width, pixels. (default: 640)
    #[default(640)]
    pub width: u32,
    /// Image height, pixels. (default: 480)
    #[default(480)]
    pub height: u32,
    /// Lens distortion applied to the rendered pinhole image (and written in `CameraInfo`).
    /// (default: none)
    pub distortion: Distortion,
    /// Standard deviation of the Gaussian noise added to each colour channel, as a fraction of
    /// full scale (Gazebo's camera `<noise><stddev>`). (default: 0.0)
    pub noise_std: f64,
    /// Seed of the noise; frame `k` draws from stream `k` of it. (default: 0)
    pub seed: u64,
    /// Frames per second when published on a schedule, Hz. (default: 30.0)
    #[default(30.0)]
    pub rate_hz: f64,
    /// MuJoCo's shadows and reflections (its renderer's defaults; off here: on a CPU renderer
    /// they cost 2.5 times the frame). (default: false)
    pub shadows: bool,
    /// Also render per-pixel segmentation labels with each frame. (default: false)
    pub segmentation: bool,
    /// Multisamples per pixel (antialiasing); `None`: the model's `<visual><quality
    /// offsamples>` (MuJoCo's default 4). 0 is about three times faster on a CPU renderer, with
    /// stair-stepped edges. (default: `None`)
    pub multisamples: Option<u32>,
}

/// Per-pixel labels of a frame, top row first: 0 is background.
#[derive(Debug, Clone, PartialEq)]
pub struct Labels {
    /// Geom id + 1 of what each pixel shows (instances).
    pub instance: Vec<u16>,
    /// Body id + 1 (the URDF link) of what each pixel shows (classes).
    pub class: Vec<u16>,
    /// The label table of the model (JSON, [`label_table`]).
    pub table: Arc<str>,
}

/// One colour frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ColourFrame {
    /// Simulation time of the state it shows, ns.
    pub stamp_nanos: u64,
    /// The camera's pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// The lens distortion applied to the image.
    pub distortion: Distortion,
    /// RGB, 3 bytes a pixel, row-major, top row first.
    pub rgb: Vec<u8>,
    /// Segmentation labels (undistorted: the pinhole image's), when asked for.
    pub labels: Option<Labels>,
    /// The optical frame's name.
    pub frame_id: String,
}

impl ColourFrame {
    fn header(&self) -> Header {
        Header { stamp_nanos: self.stamp_nanos as i64, frame_id: self.frame_id.clone() }
    }

    /// The image as `sensor_msgs/Image`, encoding `rgb8`.
    pub fn image(&self) -> Image {
        let k = &self.intrinsics;
        Image {
            header: self.header(),
            height: k.height,
            width: k.width,
            encoding: "rgb8".into(),
            is_bigendian: false,
            step: 3 * k.width,
            data: self.rgb.clone(),
        }
    }

    /// The calibration as `sensor_msgs/CameraInfo`: K and P from the intrinsics, the lens's
    /// `plumb_bob` coefficients, R the identity.
    pub fn camera_info(&self) -> CameraInfo {
        let k = &self.intrinsics;
        CameraInfo {
            header: self.header(),
            height: k.height,
            width: k.width,
            distortion_model: "plumb_bob".into(),
            d: self.distortion.plumb_bob(),
            k: k.k(),
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: k.p(),
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        }
    }

    /// A label image (`16UC1`, little endian) of the instances or the classes; `None` without
    /// labels.
    pub fn label_image(&self, classes: bool) -> Option<Image> {
        let labels = self.labels.as_ref()?;
        let k = &self.intrinsics;
        let ids = if classes { &labels.class } else { &labels.instance };
        Some(Image {
            header: self.header(),
            height: k.height,
            width: k.width,
            encoding: "16UC1".into(),
            is_bigendian: false,
            step: 2 * k.width,
            data: ids.iter().flat_map(|v| v.to_le_bytes()).collect(),
        })
    }
}

/// The label table of a model's segmentation images as JSON (for a `std_msgs/String`): for each
/// instance label (geom id + 1) its geom's and body's names, for each class label (body id +
/// 1) its body's name (the URDF link). Unnamed objects read `geom<N>` / `body<N>`.
pub fn label_table(model: &Model) -> String {
    let name = |obj, id: usize, prefix: &str| {
        let n = model.name(obj, id);
        if n.is_empty() { format!("{prefix}{id}") } else { n.to_string() }
    };
    let bodies = model.geom_bodyid();
    let instances: Vec<serde_json::Value> = (0..model.ngeom())
        .map(|g| {
            let b = bodies[g] as usize;
            serde_json::json!({"label": g + 1, "geom": name(ObjType::Geom, g, "geom"), "body": name(ObjType::Body, b, "body"), "class": b + 1})
        })
        .collect();
    let classes: Vec<serde_json::Value> = (0..model.nbody())
        .map(|b| serde_json::json!({"label": b + 1, "body": name(ObjType::Body, b, "body")}))
        .collect();
    serde_json::json!({"background": 0, "instances": instances, "classes": classes}).to_string()
}

/// Where each output pixel of a distorted image samples the pinhole image: bilinear, from
/// the top-left source pixel `index` with weights; `None` outside the rendered field.
type Remap = Vec<Option<(u32, [f32; 4])>>;

/// A colour camera on a named MuJoCo camera (an MJCF `<camera>`, or one the converter made
/// from a Gazebo `camera` sensor: its `fovy` from the sensor's horizontal FOV and aspect).
pub struct ColourCamera {
    camera: usize,
    name: String,
    renderer: Renderer,
    intrinsics: Intrinsics,
    options: ColourCameraOptions,
    frame_id: String,
    remap: Option<Remap>,
    /// The label table, made once when segmentation is asked for.
    table: Option<Arc<str>>,
    frames: u64,
}

impl std::fmt::Debug for ColourCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ColourCamera").field("name", &self.name).field("options", &self.options).finish()
    }
}

impl ColourCamera {
    /// A colour camera at MuJoCo camera `camera_name` of `model`.
    ///
    /// # Errors
    /// [`Error::NotFound`] without such a camera; [`Error::OutOfRange`] for an empty image or
    /// a negative noise; [`twin_mj::Error::Render`] without OpenGL (naming what to install).
    pub fn new(model: &Arc<Model>, camera_name: &str, options: ColourCameraOptions) -> Result<ColourCamera> {
        let camera = model.require_id(ObjType::Camera, camera_name)?;
        let what = || format!("camera \"{camera_name}\"");
        if options.width == 0 || options.height == 0 {
            return Err(Error::OutOfRange {
                what: what(),
                message: format!("image of {}×{} pixels: give a width and height ≥ 1", options.width, options.height),
            });
        }
        if !(options.noise_std >= 0.0 && options.noise_std.is_finite()) {
            return Err(Error::OutOfRange {
                what: what(),
                message: format!(
                    "pixel noise {}: give a standard deviation ≥ 0 (fraction of full scale)",
                    options.noise_std
                ),
            });
        }
        let intrinsics = Intrinsics::from_fovy(options.width, options.height, model.cam_fovy_rad()[camera]);
        let mut renderer = Renderer::with_samples(model.clone(), options.width, options.height, options.multisamples)
            .map_err(|e| {
            Error::Mj(twin_mj::Error::Render {
                message: format!("{}: {}", what(), e.to_string().trim_start_matches("rendering: ")),
            })
        })?;
        renderer.set_shadows_and_reflections(options.shadows, options.shadows);
        let remap = (!options.distortion.is_none()).then(|| remap_of(&intrinsics, &options.distortion));
        Ok(ColourCamera {
            camera,
            name: camera_name.to_string(),
            renderer,
            intrinsics,
            frame_id: format!("{camera_name}_optical_frame"),
            remap,
            table: options.segmentation.then(|| Arc::from(label_table(model))),
            options,
            frames: 0,
        })
    }

    /// Sets the `frame_id` of the frames (default: `<camera>_optical_frame`).
    pub fn with_frame_id(mut self, frame_id: impl Into<String>) -> ColourCamera {
        self.frame_id = frame_id.into();
        self
    }

    /// The pinhole intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The options it was made with.
    pub fn options(&self) -> &ColourCameraOptions {
        &self.options
    }

    /// The OpenGL backend rendering it, e.g. `EGL (device platform)`.
    pub fn backend(&self) -> String {
        self.renderer.backend()
    }

    /// Images the state of `data` (its last forward pass), stamped with its time.
    ///
    /// # Errors
    /// [`Error::Size`] for a `data` of another model layout; [`Error::Render`] when OpenGL or
    /// MuJoCo fails.
    pub fn render(&mut self, data: &mut Data) -> Result<ColourFrame> {
        let view = View::Camera(self.camera);
        let pinhole = self.renderer.rgb(data, view)?;
        let mut rgb = match &self.remap {
            None => pinhole,
            Some(remap) => apply_remap(&pinhole, remap, self.intrinsics.width as usize),
        };
        if self.options.noise_std > 0.0 {
            let sigma = self.options.noise_std * 255.0;
            let mut rng = noise_rng(self.options.seed, self.frames);
            for c in &mut rgb {
                let v = f64::from(*c) + sigma * rng.sample::<f64, _>(StandardNormal);
                *c = v.round().clamp(0.0, 255.0) as u8;
            }
        }
        let labels = if self.options.segmentation {
            let model = data.model().clone();
            let bodies = model.geom_bodyid();
            let segments = self.renderer.segmentation(data, view)?;
            let instance: Vec<u16> =
                segments.iter().map(|s| s.and_then(|s| s.geom()).map_or(0, |g| (g + 1).min(65_535) as u16)).collect();
            let class = instance
                .iter()
                .map(|&i| if i == 0 { 0 } else { (bodies[usize::from(i) - 1] as usize + 1).min(65_535) as u16 })
                .collect();
            let table = self.table.clone().unwrap_or_else(|| Arc::from(label_table(&model)));
            Some(Labels { instance, class, table })
        } else {
            None
        };
        self.frames += 1;
        Ok(ColourFrame {
            stamp_nanos: (data.time_secs() * 1e9).round().max(0.0) as u64,
            intrinsics: self.intrinsics,
            distortion: self.options.distortion,
            rgb,
            labels,
            frame_id: self.frame_id.clone(),
        })
    }
}

/// For each pixel of the distorted image, where it samples the pinhole image.
fn remap_of(k: &Intrinsics, lens: &Distortion) -> Remap {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut out = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            let (xd, yd) = ((u as f64 - k.cx) / k.fx, (v as f64 - k.cy) / k.fy);
            let src = lens.undistort(xd, yd).and_then(|(x, y)| {
                let (su, sv) = (k.fx * x + k.cx, k.fy * y + k.cy);
                let inside = su >= 0.0 && sv >= 0.0 && su <= (w - 1) as f64 && sv <= (h - 1) as f64;
                inside.then(|| {
                    let (u0, v0) = (
                        (su.floor() as usize).min(w.saturating_sub(2)),
                        (sv.floor() as usize).min(h.saturating_sub(2)),
                    );
                    let (fu, fv) = ((su - u0 as f64) as f32, (sv - v0 as f64) as f32);
                    let weights = [(1.0 - fu) * (1.0 - fv), fu * (1.0 - fv), (1.0 - fu) * fv, fu * fv];
                    ((v0 * w + u0) as u32, weights)
                })
            });
            out.push(src);
        }
    }
    out
}

/// The distorted RGB image: each pixel bilinear from the pinhole image, black outside it.
fn apply_remap(pinhole: &[u8], remap: &Remap, width: usize) -> Vec<u8> {
    let mut out = vec![0u8; remap.len() * 3];
    let height = pinhole.len() / (3 * width.max(1));
    for (o, src) in out.chunks_exact_mut(3).zip(remap) {
        let Some((i, wts)) = src else { continue };
        let i = *i as usize;
        let (right, down) = (usize::from(width > 1), if height > 1 { width } else { 0 });
        let taps = [i, i + right, i + down, i + down + right];
        for (c, value) in o.iter_mut().enumerate() {
            let s: f32 = taps.iter().zip(wts).map(|(&t, &wt)| wt * f32::from(pinhole[3 * t + c])).sum();
            *value = s.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undistort_inverts_distort() {
        let lens = Distortion { k1: -0.25, k2: 0.12, k3: -0.02, p1: 0.001, p2: -0.0005 };
        for &(x, y) in &[(0.0, 0.0), (0.3, -0.2), (-0.5, 0.4), (0.6, 0.45)] {
            let (xd, yd) = lens.distort(x, y);
            let (ux, uy) = lens.undistort(xd, yd).unwrap();
            assert!((ux - x).abs() < 1e-9 && (uy - y).abs() < 1e-9, "({x}, {y}) → ({ux}, {uy})");
        }
        assert_eq!(lens.plumb_bob(), vec![-0.25, 0.12, 0.001, -0.0005, -0.02]);
    }
}
