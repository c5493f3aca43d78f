//! A depth camera by ray casting ([`crate::mj::RayScene`], no OpenGL; the ray setup it shares
//! with [`super::lidar`] is `sense::fan`): one ray through each
//! pixel centre of a pinhole camera, depth in metres along the optical axis (REP 118), NaN
//! where nothing is hit within range, in the ROS optical frame (REP 103/105: z forward, x
//! right, y down).
//!
//! ```no_run
//! use std::sync::Arc;
//! use twin_core::mj::{Data, Model};
//! use twin_core::sense::depth::{DepthCamera, DepthCameraOptions};
//!
//! let model = Arc::new(Model::from_file("scene.xml")?);
//! let mut data = Data::new(model.clone())?;
//! data.forward()?;
//! let mut camera = DepthCamera::new(&model, "head_depth", DepthCameraOptions::default())?;
//! let frame = camera.render(&model, &data)?;
//! println!("{} points", frame.points_world().len());
//! # Ok::<(), twin_core::Error>(())
//! ```

use super::fan::{RayFan, RayOptions, noise_rng};
use crate::error::{Error, Result};
use crate::log::{CameraInfo, Header, Image, PointCloud2, RegionOfInterest};
use crate::mj::{Data, Model, ObjType, RayStats};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

/// Pinhole intrinsics in pixels, ROS convention: pixel `(u, v)` (column, row) has its centre
/// at integer coordinates, so a centred camera has `cx = (width − 1) / 2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point, x, pixels.
    pub cx: f64,
    /// Principal point, y, pixels.
    pub cy: f64,
}

impl Intrinsics {
    /// A centred camera with square pixels and vertical field of view `fovy_rad`:
    /// `f = (height / 2) / tan(fovy / 2)`.
    pub fn from_fovy(width: u32, height: u32, fovy_rad: f64) -> Intrinsics {
        let f = f64::from(height) / 2.0 / (fovy_rad / 2.0).tan();
        Intrinsics::centred(width, height, f)
    }

    /// A centred camera with square pixels and horizontal field of view `hfov_rad`
    /// (Gazebo's `<horizontal_fov>`): `f = (width / 2) / tan(hfov / 2)`.
    pub fn from_hfov(width: u32, height: u32, hfov_rad: f64) -> Intrinsics {
        let f = f64::from(width) / 2.0 / (hfov_rad / 2.0).tan();
        Intrinsics::centred(width, height, f)
    }

    fn centred(width: u32, height: u32, f: f64) -> Intrinsics {
        Intrinsics {
            width,
            height,
            fx: f,
            fy: f,
            cx: (f64::from(width) - 1.0) / 2.0,
            cy: (f64::from(height) - 1.0) / 2.0,
        }
    }

    /// The camera matrix K, row-major.
    pub fn k(&self) -> [f64; 9] {
        [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
    }

    /// The projection matrix P (3×4, row-major) of a monocular camera: `[K | 0]`.
    pub fn p(&self) -> [f64; 12] {
        [self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    }

    /// Direction through the centre of pixel `(u, v)` in the optical frame, with z = 1 (so a
    /// point at depth z is `z` times it).
    pub fn ray_optical(&self, u: u32, v: u32) -> Vector3<f64> {
        Vector3::new((f64::from(u) - self.cx) / self.fx, (f64::from(v) - self.cy) / self.fy, 1.0)
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether the image has no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One depth image.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFrame {
    /// Simulation time of the state it shows, ns.
    pub stamp_nanos: u64,
    /// The camera's intrinsics.
    pub intrinsics: Intrinsics,
    /// Row-major depth, metres along the optical axis (REP 118); NaN: no return (nothing hit
    /// within range).
    pub depth_m: Vec<f32>,
    /// Pose of the optical frame (z forward, x right, y down) in the world.
    pub world_from_optical: Isometry3<f64>,
    /// The optical frame's name (`frame_id` of its messages).
    pub frame_id: String,
}

impl DepthFrame {
    /// Depth of pixel `(u, v)`, metres (NaN: no return).
    pub fn depth_at(&self, u: u32, v: u32) -> f32 {
        self.depth_m[v as usize * self.intrinsics.width as usize + u as usize]
    }

    /// The point seen at pixel `(u, v)` in the optical frame, `None` without a return.
    pub fn point_optical(&self, u: u32, v: u32) -> Option<Point3<f64>> {
        let z = f64::from(self.depth_at(u, v));
        z.is_finite().then(|| Point3::from(self.intrinsics.ray_optical(u, v) * z))
    }

    /// Every return as a point in the optical frame, metres, row-major order (pixels without a
    /// return are left out).
    pub fn points_optical(&self) -> Vec<Point3<f64>> {
        let w = self.intrinsics.width;
        self.depth_m
            .iter()
            .enumerate()
            .filter(|(_, z)| z.is_finite())
            .map(|(i, &z)| {
                let (u, v) = (i as u32 % w, i as u32 / w);
                Point3::from(self.intrinsics.ray_optical(u, v) * f64::from(z))
            })
            .collect()
    }

    /// Every return as a point in the world frame, metres, row-major order.
    pub fn points_world(&self) -> Vec<Point3<f64>> {
        self.points_optical().into_iter().map(|p| self.world_from_optical * p).collect()
    }

    fn header(&self) -> Header {
        Header { stamp_nanos: self.stamp_nanos as i64, frame_id: self.frame_id.clone() }
    }

    /// The depth image as `sensor_msgs/Image`, encoding `32FC1` (REP 118).
    pub fn image(&self) -> Image {
        let k = &self.intrinsics;
        Image {
            header: self.header(),
            height: k.height,
            width: k.width,
            encoding: "32FC1".into(),
            is_bigendian: false,
            step: 4 * k.width,
            data: self.depth_m.iter().flat_map(|z| z.to_le_bytes()).collect(),
        }
    }

    /// The calibration as `sensor_msgs/CameraInfo`: K and P from the intrinsics, no
    /// distortion (`plumb_bob`, zeros), R the identity.
    pub fn camera_info(&self) -> CameraInfo {
        let k = &self.intrinsics;
        CameraInfo {
            header: self.header(),
            height: k.height,
            width: k.width,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: k.k(),
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: k.p(),
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        }
    }

    /// The organized point cloud (one point per pixel, NaN without a return) in the optical
    /// frame, as `sensor_msgs/PointCloud2` with float32 x, y, z.
    pub fn point_cloud(&self) -> PointCloud2 {
        let k = &self.intrinsics;
        let xyz: Vec<[f32; 3]> = self
            .depth_m
            .iter()
            .enumerate()
            .map(|(i, &z)| {
                if !z.is_finite() {
                    return [f32::NAN; 3];
                }
                let r = k.ray_optical(i as u32 % k.width, i as u32 / k.width) * f64::from(z);
                [r.x as f32, r.y as f32, z]
            })
            .collect();
        super::xyz_cloud(self.header(), k.height, k.width, &xyz)
    }
}

/// How a [`DepthCamera`] images.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct DepthCameraOptions {
    /// Image width, pixels. (default: 320)
    #[default(320)]
    pub width: u32,
    /// Image height, pixels. (default: 240)
    #[default(240)]
    pub height: u32,
    /// Horizontal field of view, radians; `None`: the model camera's `fovy` (vertical) with
    /// square pixels. (default: `None`)
    pub hfov_rad: Option<f64>,
    /// Range limits (in depth along the optical axis), noise, rate, threads and the geoms the
    /// camera sees. (default: [`RayOptions::default`] with a near clip `min_range_m` of 0.05 and
    /// a `rate_hz` of 15.0)
    #[default(RayOptions { min_range_m: 0.05, rate_hz: 15.0, ..RayOptions::default() })]
    pub ray: RayOptions,
}

/// Pixels per tile side: the rays of a tile are culled against the geoms together.
const TILE: u32 = 8;

/// A depth camera on a named MuJoCo camera.
pub struct DepthCamera {
    camera: usize,
    name: String,
    intrinsics: Intrinsics,
    options: DepthCameraOptions,
    frame_id: String,
    /// `mujoco_camera_from_optical`: a half turn about x.
    cam_from_optical: Rotation3<f64>,
    /// The rays through the pixel centres (unit, optical frame), in tile order.
    fan: RayFan,
    /// z component of each unnormalised ray (depth = distance × this), in tile order.
    depth_per_dist: Vec<f64>,
    /// Distance along each ray of the near plane (`min_range_m / depth_per_dist`), in tile
    /// order: nearer geometry is clipped.
    clip_dist: Vec<f64>,
    /// Pixel index of each ray.
    pixel: Vec<u32>,
    /// What the rays see of the geoms that move with the camera (the bodies welded to its
    /// body: its housing, the head it sits in; with a camera welded to the world, the static
    /// scene): the same in every frame, so cast once per model and kept.
    rigid: Box<RigidHits>,
    frames: u64,
}

/// The hits of the geoms rigid with a camera, cast once per model: in the camera's frame they
/// never move, so each frame casts only against the others and takes the nearer hit. A camera
/// inside a mesh head (example-robot-data's TIAGo Pro: 17 000 triangles around the lens) would
/// otherwise test that mesh with every ray of every frame.
struct RigidHits {
    /// The bodies welded to the camera's body.
    bodies: Vec<usize>,
    /// The options' filter with those bodies left out: what each frame casts against.
    moving: crate::mj::RayFilter,
    /// The options' filter with every other body left out.
    only_rigid: crate::mj::RayFilter,
    /// The model the hits were cast on (a weak reference keeps its address from being reused
    /// by another model), and the nearest hit of each ray, in fan order.
    cached: Option<(std::sync::Weak<Model>, Vec<Option<crate::mj::RayHit>>)>,
}

impl std::fmt::Debug for DepthCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DepthCamera")
            .field("name", &self.name)
            .field("intrinsics", &self.intrinsics)
            .field("options", &self.options)
            .finish()
    }
}

impl DepthCamera {
    /// A depth camera at MuJoCo camera `camera_name` of `model` (an MJCF `<camera>`, or one the
    /// converter made from a Gazebo `camera`/`depth` sensor).
    ///
    /// # Errors
    /// [`Error::NotFound`] when the model has no such camera; [`Error::OutOfRange`] for an
    /// empty image, a field of view outside (0, π), or a range that is not
    /// 0 ≤ min < max; [`Error::Options`] when the thread pool can't be built.
    pub fn new(model: &Model, camera_name: &str, opts: DepthCameraOptions) -> Result<DepthCamera> {
        let camera = model.require_id(ObjType::Camera, camera_name)?;
        let what = || format!("depth camera \"{camera_name}\"");
        if opts.width == 0 || opts.height == 0 {
            return Err(Error::OutOfRange {
                what: what(),
                message: format!("image of {}×{} pixels: give a width and height ≥ 1", opts.width, opts.height),
            });
        }
        let intrinsics = match opts.hfov_rad {
            Some(h) => Intrinsics::from_hfov(opts.width, opts.height, h),
            None => Intrinsics::from_fovy(opts.width, opts.height, model.cam_fovy_rad()[camera]),
        };
        let fov_x = 2.0 * (f64::from(opts.width) / 2.0 / intrinsics.fx).atan();
        let fov_y = 2.0 * (f64::from(opts.height) / 2.0 / intrinsics.fy).atan();
        if !(fov_x.is_finite() && fov_y.is_finite() && fov_x > 0.0 && fov_y > 0.0 && intrinsics.fx > 0.0) {
            return Err(Error::OutOfRange {
                what: what(),
                message: format!(
                    "field of view {:.1}° × {:.1}°: give a horizontal field of view in (0, π) rad",
                    fov_x.to_degrees(),
                    fov_y.to_degrees()
                ),
            });
        }
        opts.ray.check(&what())?;
        // Rays in tile order: TILE×TILE blocks (the caster's bundles), 4×4 of them in a
        // super-tile (its groups), row-major within and between blocks.
        let (w, h) = (opts.width, opts.height);
        let mut rays_optical = Vec::with_capacity(intrinsics.len());
        let mut depth_per_dist = Vec::with_capacity(intrinsics.len());
        let mut pixel = Vec::with_capacity(intrinsics.len());
        let superb = 4 * TILE;
        for sv in (0..h).step_by(superb as usize) {
            for su in (0..w).step_by(superb as usize) {
                for tv in (sv..(sv + superb).min(h)).step_by(TILE as usize) {
                    for tu in (su..(su + superb).min(w)).step_by(TILE as usize) {
                        for v in tv..(tv + TILE).min(h) {
                            for u in tu..(tu + TILE).min(w) {
                                let r = intrinsics.ray_optical(u, v);
                                let n = r.norm();
                                rays_optical.push(r / n);
                                depth_per_dist.push(1.0 / n);
                                pixel.push(v * w + u);
                            }
                        }
                    }
                }
            }
        }
        let fan = RayFan::new(rays_optical, (TILE * TILE) as usize, opts.ray.threads, &what())?;
        let clip_dist = depth_per_dist.iter().map(|s| opts.ray.min_range_m / s).collect();
        let weld = model.body_weldid();
        let camera_weld = weld[model.cam_bodyid()[camera] as usize];
        let bodies: Vec<usize> = (0..model.nbody()).filter(|&b| weld[b] == camera_weld).collect();
        let mut moving = opts.ray.filter.clone();
        moving.exclude_bodies.extend(bodies.iter().copied());
        let mut only_rigid = opts.ray.filter.clone();
        only_rigid.exclude_bodies.extend((0..model.nbody()).filter(|b| !bodies.contains(b)));
        let rigid = Box::new(RigidHits { bodies, moving, only_rigid, cached: None });
        Ok(DepthCamera {
            camera,
            name: camera_name.to_string(),
            intrinsics,
            frame_id: format!("{camera_name}_optical_frame"),
            options: opts,
            cam_from_optical: Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
            fan,
            depth_per_dist,
            clip_dist,
            pixel,
            rigid,
            frames: 0,
        })
    }

    /// Sets the `frame_id` of the frames (default: `<camera>_optical_frame`).
    pub fn with_frame_id(mut self, frame_id: impl Into<String>) -> DepthCamera {
        self.frame_id = frame_id.into();
        self
    }

    /// The intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The options it was made with.
    pub fn options(&self) -> &DepthCameraOptions {
        &self.options
    }

    /// The MuJoCo camera's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// What the last [`DepthCamera::render`] cost in ray–geom tests (against the geoms that
    /// move relative to the camera; those rigid with it are cast on its first frame only).
    pub fn last_ray_stats(&self) -> RayStats {
        self.fan.last_stats()
    }

    /// The bodies welded to the camera's body (its housing, the head it sits in; the world's
    /// static bodies for a camera fixed in the world): their geoms are cast once per model.
    pub fn rigid_bodies(&self) -> &[usize] {
        &self.rigid.bodies
    }

    /// Pose of the optical frame in the world at `data`'s last forward pass.
    pub fn world_from_optical(&self, data: &Data) -> Isometry3<f64> {
        let p = data.cam_xpos()[self.camera];
        let m = data.cam_xmat()[self.camera];
        let world_from_cam = Rotation3::from_matrix_unchecked(Matrix3::from_row_slice(&m));
        let rot = UnitQuaternion::from_rotation_matrix(&(world_from_cam * self.cam_from_optical));
        Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), rot)
    }

    /// Images the state of `data` (its last forward pass: `geom_xpos`, `cam_xpos`), stamped
    /// with its time.
    ///
    /// # Errors
    /// [`Error::Size`] when `data` belongs to a model with fewer cameras than `model`
    /// (`model` must be `data`'s model or an edited copy of it).
    pub fn render(&mut self, model: &Model, data: &Data) -> Result<DepthFrame> {
        if data.model().ncam() != model.ncam() || self.camera >= model.ncam() {
            return Err(Error::Size {
                what: "cameras of the data's model",
                expected: model.ncam(),
                got: data.model().ncam(),
            });
        }
        let world_from_optical = self.world_from_optical(data);
        let origin = world_from_optical.translation.vector;
        let (min_z, max_z) = (self.options.ray.min_range_m, self.options.ray.max_range_m);
        // The farthest distance along any ray that can still be within max depth.
        let max_dist = max_z / self.depth_per_dist.iter().copied().fold(1.0f64, f64::min);
        let rot = world_from_optical.rotation.to_rotation_matrix();
        let origin = [origin.x, origin.y, origin.z];
        // The geoms rigid with the camera: cast once per model (their hits never change).
        let key = std::sync::Arc::downgrade(data.model());
        if self.rigid.cached.as_ref().is_none_or(|(k, _)| !k.ptr_eq(&key)) {
            let hits = self.fan.cast(data, &self.rigid.only_rigid, origin, &rot, max_dist, &self.clip_dist)?;
            self.rigid.cached = Some((key, hits.to_vec()));
        }
        let rigid = &self.rigid.cached.as_ref().expect("cast just above").1;
        let hits = self.fan.cast(data, &self.rigid.moving, origin, &rot, max_dist, &self.clip_dist)?;
        // Depth along the optical axis, in pixel order; NaN outside the range.
        let mut depth_m = vec![f32::NAN; self.intrinsics.len()];
        for (((hit, fixed), &k), &s) in hits.iter().zip(rigid).zip(&self.pixel).zip(&self.depth_per_dist) {
            let nearest = match (hit, fixed) {
                (Some(a), Some(b)) => Some(if b.dist_m < a.dist_m { b } else { a }),
                (a, b) => a.as_ref().or(b.as_ref()),
            };
            if let Some(h) = nearest {
                let z = h.dist_m * s;
                if z >= min_z && z <= max_z {
                    depth_m[k as usize] = z as f32;
                }
            }
        }
        let noise = self.options.ray.noise_std_m;
        if noise > 0.0 {
            // Drawn in pixel order, so the noise of a pixel does not depend on the tiling.
            let mut rng = noise_rng(self.options.ray.seed, self.frames);
            for z in depth_m.iter_mut().filter(|z| z.is_finite()) {
                *z = (f64::from(*z) + noise * rng.sample::<f64, _>(StandardNormal)) as f32;
            }
        }
        self.frames += 1;
        Ok(DepthFrame {
            stamp_nanos: (data.time_secs() * 1e9).round().max(0.0) as u64,
            intrinsics: self.intrinsics,
            depth_m,
            world_from_optical,
            frame_id: self.frame_id.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A camera 1 m above the floor looking straight down at a 0.2 m cube resting on it.
    const BOX_SCENE: &str = r#"<mujoco><worldbody><geom type="plane" size="3 3 0.1"/>
        <geom name="cube" type="box" pos="0.1 -0.05 0.1" size="0.1 0.1 0.1"/>
        <camera name="down" pos="0 0 1" fovy="60"/></worldbody></mujoco>"#;

    fn setup(xml: &str) -> (Arc<Model>, Data) {
        let model = Arc::new(Model::from_xml_str(xml).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        data.forward().unwrap();
        (model, data)
    }

    #[test]
    fn depth_of_a_box_and_floor_is_analytic() {
        let (model, data) = setup(BOX_SCENE);
        let opts = DepthCameraOptions { width: 64, height: 48, ..DepthCameraOptions::default() };
        let mut cam = DepthCamera::new(&model, "down", opts).unwrap();
        let frame = cam.render(&model, &data).unwrap();
        // MuJoCo's camera looks along −z with y up; the optical frame looks along −z_world,
        // x along world x, y along −world y.
        let t = frame.world_from_optical;
        assert!((t * Point3::origin() - Point3::new(0.0, 0.0, 1.0)).norm() < 1e-12);
        assert!((t.rotation * Vector3::z() - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        assert!((t.rotation * Vector3::y() - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-12);
        let k = frame.intrinsics;
        let mut on_box = 0;
        let mut on_floor = 0;
        for v in 0..k.height {
            for u in 0..k.width {
                let r = k.ray_optical(u, v);
                // Where the ray meets the cube's top (z = 0.2, depth 0.8) in world x/y.
                let (x, y) = (0.8 * r.x, -0.8 * r.y);
                let inside = (x - 0.1).abs() < 0.1 - 1e-6 && (y + 0.05).abs() < 0.1 - 1e-6;
                let edge = (x - 0.1).abs() < 0.1 + 0.02 && (y + 0.05).abs() < 0.1 + 0.02;
                let expected = if inside { 0.8 } else { 1.0 };
                if !inside && edge {
                    continue; // the cube's sides: seen at depths between the two
                }
                let got = f64::from(frame.depth_at(u, v));
                // Depth along the optical axis, not ray length: equal at the corners too.
                assert!((got - expected).abs() < 1e-3, "pixel ({u}, {v}): depth {got}, expected {expected}");
                if inside { on_box += 1 } else { on_floor += 1 }
            }
        }
        assert!(on_box > 100 && on_floor > 1000, "{on_box} box pixels, {on_floor} floor pixels");
        // The corner pixel's ray is long (1 m depth, √(1 + x² + y²) along the ray).
        let r = k.ray_optical(0, 0);
        assert!(r.norm() > 1.2);
        // Points land on the surfaces they came from.
        let p = frame.point_optical(0, 0).unwrap();
        assert!(((t * p).z).abs() < 1e-3);
        for p in frame.points_world() {
            assert!(
                p.z.abs() < 1e-3
                    || (p.z - 0.2).abs() < 1e-3
                    || (p.x - 0.2).abs() < 1e-3
                    || (p.y - 0.05).abs() < 1e-3
                    || (p.y + 0.15).abs() < 1e-3
                    || p.x.abs() < 1e-3,
                "{p}"
            );
        }
    }

    /// A camera inside its own housing (a box around it) and a head (a sphere it sits in):
    /// with the near clip beyond them it sees the floor, 1 m down, in every pixel; with a near
    /// clip inside the housing it sees the housing's inside.
    #[test]
    fn a_camera_inside_its_housing_sees_out_of_it() {
        let xml = r#"<mujoco><worldbody><geom type="plane" size="3 3 0.1"/>
            <body name="head" pos="0 0 1"><geom type="sphere" size="0.08" pos="-0.05 0 0"/>
              <geom type="box" size="0.01 0.025 0.01"/>
              <camera name="eye" fovy="60"/></body></worldbody></mujoco>"#;
        let (model, data) = setup(xml);
        let opts = DepthCameraOptions {
            width: 32,
            height: 24,
            ray: RayOptions { min_range_m: 0.1, ..DepthCameraOptions::default().ray },
            ..DepthCameraOptions::default()
        };
        let frame = DepthCamera::new(&model, "eye", opts.clone()).unwrap().render(&model, &data).unwrap();
        assert!(frame.depth_m.iter().all(|&z| (z - 1.0).abs() < 1e-6), "{:?}", &frame.depth_m[..8]);
        // A near clip of 5 mm: the housing (1 cm below the camera along its axis) is what it sees.
        let opts = DepthCameraOptions { ray: RayOptions { min_range_m: 0.005, ..opts.ray }, ..opts };
        let frame = DepthCamera::new(&model, "eye", opts).unwrap().render(&model, &data).unwrap();
        assert!((frame.depth_at(16, 12) - 0.01).abs() < 1e-6, "{}", frame.depth_at(16, 12));
    }

    #[test]
    fn messages_carry_the_image() {
        let (model, data) = setup(BOX_SCENE);
        let opts = DepthCameraOptions { width: 64, height: 48, ..DepthCameraOptions::default() };
        let frame = DepthCamera::new(&model, "down", opts).unwrap().render(&model, &data).unwrap();
        let image = frame.image();
        assert_eq!((image.encoding.as_str(), image.width, image.height, image.step), ("32FC1", 64, 48, 256));
        let px = |u: usize, v: usize| f32::from_le_bytes(image.data[(v * 64 + u) * 4..][..4].try_into().unwrap());
        assert_eq!(px(5, 7), frame.depth_at(5, 7));
        let info = frame.camera_info();
        // f = (H/2) / tan(fovy/2) for MuJoCo's fovy = 60°.
        assert!((info.k[0] - 24.0 / (30f64.to_radians()).tan()).abs() < 1e-9 && info.k[2] == 31.5 && info.k[5] == 23.5);
        assert_eq!(info.d, vec![0.0; 5]);
        let cloud = frame.point_cloud();
        assert_eq!((cloud.height, cloud.width, cloud.point_step, cloud.row_step), (48, 64, 12, 768));
        // Point (u, v) = depth · K⁻¹ (u, v, 1).
        let at = |u: usize, v: usize, c: usize| {
            f32::from_le_bytes(cloud.data[(v * 64 + u) * 12 + 4 * c..][..4].try_into().unwrap())
        };
        let p = frame.point_optical(3, 40).unwrap();
        assert!((f64::from(at(3, 40, 0)) - p.x).abs() < 1e-6 && (f64::from(at(3, 40, 1)) - p.y).abs() < 1e-6);
        assert_eq!(at(3, 40, 2), frame.depth_at(3, 40));
    }

    #[test]
    fn range_limits_noise_and_threads() {
        let (model, data) = setup(BOX_SCENE);
        let base = DepthCameraOptions { width: 32, height: 24, ..DepthCameraOptions::default() };
        // The base image with other ray options.
        let camera = |ray: RayOptions| DepthCamera::new(&model, "down", DepthCameraOptions { ray, ..base.clone() });
        // Beyond max range: NaN.
        let far = camera(RayOptions { max_range_m: 0.9, ..base.ray.clone() }).unwrap().render(&model, &data).unwrap();
        assert!(far.depth_at(0, 0).is_nan());
        assert!((far.depth_at(16, 12) - 0.8).abs() < 1e-6);
        // Nearer than the near clip: the cube's top (depth 0.8) is clipped, the floor behind it
        // seen.
        let near = camera(RayOptions { min_range_m: 0.9, ..base.ray.clone() }).unwrap().render(&model, &data).unwrap();
        assert!((near.depth_at(16, 12) - 1.0).abs() < 1e-6 && (near.depth_at(0, 0) - 1.0).abs() < 1e-6);
        // Noise: seeded, about the asked deviation, independent of the thread count.
        let noisy = |threads| {
            let o = DepthCameraOptions {
                width: 160,
                height: 120,
                ray: RayOptions { noise_std_m: 0.01, seed: 7, threads, ..base.ray.clone() },
                ..base.clone()
            };
            DepthCamera::new(&model, "down", o).unwrap().render(&model, &data).unwrap()
        };
        let (a, b, c) = (noisy(1), noisy(3), noisy(0));
        assert_eq!(
            a.depth_m.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            b.depth_m.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        assert_eq!(
            a.depth_m.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            c.depth_m.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        let clean = DepthCamera::new(&model, "down", DepthCameraOptions { width: 160, height: 120, ..base.clone() })
            .unwrap()
            .render(&model, &data)
            .unwrap();
        let diffs: Vec<f64> = a
            .depth_m
            .iter()
            .zip(&clean.depth_m)
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| f64::from(x - y))
            .collect();
        let std = (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len() as f64).sqrt();
        assert!((std - 0.01).abs() < 0.0005, "noise std {std}");
        // Bad options are refused with the camera's name.
        let err = camera(RayOptions { min_range_m: 20.0, ..base.ray.clone() }).unwrap_err();
        assert!(err.to_string().contains("\"down\""), "{err}");
        assert!(DepthCamera::new(&model, "nope", base).unwrap_err().to_string().contains("camera named \"nope\""));
    }
}
