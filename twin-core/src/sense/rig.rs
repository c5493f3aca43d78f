//! A robot's cameras and ray sensors as its file describes them, with their topics: each Gazebo
//! depth camera (`depth`, `depth_camera`, `rgbd_camera`) is a ray-cast depth camera publishing
//! `<prefix>/depth/image_raw` (`32FC1`), `<prefix>/depth/camera_info` and `<prefix>/points`;
//! each colour camera (`camera`, `wideanglecamera`, `multicamera`) is rendered by MuJoCo's
//! renderer ([`super::camera`]) and publishes `<prefix>/image_raw` (`rgb8`) and
//! `<prefix>/camera_info` (an `rgbd_camera` both: its depth ray-cast, its colour rendered); a
//! `segmentation` camera publishes those and its labels,
//! `<prefix>/segmentation/instances` and `.../classes` (`16UC1`) with the label table
//! `<prefix>/segmentation/labels` (`std_msgs/String`, JSON). Without OpenGL the colour cameras
//! are left out and named in [`unrendered_cameras`] with what to install. Each
//! `ray`/`gpu_ray`/`lidar` sensor publishes one ring as `sensor_msgs/LaserScan` (`scan`)
//! or several as an organized `PointCloud2` (`points`). MJCF cameras that no metadata covers
//! count as depth cameras when they give a `resolution` (beyond MuJoCo's default 1×1).
//!
//! `<prefix>` is the plugin's topic without a trailing `/image_raw` (or `/depth/image_raw`),
//! else `/<robot>/<sensor>`.

use super::camera::{ColourCamera, ColourCameraOptions, ColourFrame};
use super::depth::{DepthCamera, DepthCameraOptions, DepthFrame};
use super::fan::RayOptions;
use super::lidar::{Lidar, LidarOptions, LidarScan, ScanAxis};
use crate::error::Result;
use crate::log::cdr::CdrWriter;
use crate::log::{CameraInfo, Image, LaserScan, PointCloud2, RosMessage, RosString};
use crate::mj::{Data, ObjType};
use crate::robot::Robot;

/// What a topic of a ray-cast sensor carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorStream {
    /// `sensor_msgs/Image`, `32FC1` depth.
    DepthImage,
    /// `sensor_msgs/CameraInfo`.
    CameraInfo,
    /// Organized `sensor_msgs/PointCloud2` (camera: optical frame; LiDAR: sensor frame).
    Points,
    /// `sensor_msgs/LaserScan` (one ring).
    Scan,
    /// `sensor_msgs/Image`, `rgb8` colour.
    ColourImage,
    /// `sensor_msgs/Image`, `16UC1` instance labels (geom id + 1; 0 background).
    Instances,
    /// `sensor_msgs/Image`, `16UC1` class labels (body id + 1, the URDF link; 0 background).
    Classes,
    /// `std_msgs/String`: the label table (JSON, [`super::camera::label_table`]).
    LabelTable,
}

impl SensorStream {
    /// ROS 2 type of the stream.
    pub fn type_name(self) -> &'static str {
        match self {
            SensorStream::DepthImage | SensorStream::ColourImage | SensorStream::Instances | SensorStream::Classes => {
                Image::TYPE_NAME
            }
            SensorStream::LabelTable => RosString::TYPE_NAME,
            SensorStream::CameraInfo => CameraInfo::TYPE_NAME,
            SensorStream::Points => PointCloud2::TYPE_NAME,
            SensorStream::Scan => LaserScan::TYPE_NAME,
        }
    }
}

/// How a ray-cast sensor is built.
#[derive(Debug, Clone, PartialEq)]
pub enum RaySensorKind {
    /// A depth camera on a MuJoCo camera.
    Depth {
        /// MuJoCo camera name.
        camera: String,
        /// Its options.
        options: DepthCameraOptions,
    },
    /// A colour camera on a MuJoCo camera, rendered.
    Colour {
        /// MuJoCo camera name.
        camera: String,
        /// Its options.
        options: ColourCameraOptions,
    },
    /// A scanning range finder on a MuJoCo site.
    Lidar {
        /// MuJoCo site name.
        site: String,
        /// Its options.
        options: LidarOptions,
    },
}

/// One ray-cast sensor of a robot, with its topics.
#[derive(Debug, Clone, PartialEq)]
pub struct RaySensor {
    /// Sensor name (the Gazebo sensor's, or the MJCF camera's).
    pub name: String,
    /// Device and options.
    pub kind: RaySensorKind,
    /// `frame_id` of its messages.
    pub frame_id: String,
    /// Publication rate, Hz.
    pub rate_hz: f64,
    /// Its topics, in publication order.
    pub topics: Vec<(String, SensorStream)>,
}

/// The ray-cast sensors of `robot`, in model order of its metadata, then plain MJCF cameras.
pub fn ray_sensors(robot: &Robot) -> Vec<RaySensor> {
    let model = &robot.model;
    let mut out = Vec::new();
    let mut covered = Vec::new();
    let prefix_of = |topic: &Option<String>, name: &str| -> String {
        match topic {
            Some(t) => {
                let t = t.trim_end_matches('/');
                let t = t.strip_suffix("/depth/image_raw").or_else(|| t.strip_suffix("/image_raw")).unwrap_or(t);
                if t.starts_with('/') { t.to_string() } else { format!("/{t}") }
            }
            None => format!("/{}/{}", robot.name, crate::topics::topic_safe(name)),
        }
    };
    for s in &robot.sensors {
        match s.kind.as_str() {
            "depth" | "depth_camera" | "rgbd_camera" => {
                for (k, cam) in s.mujoco.iter().enumerate() {
                    let Some(id) = model.id(ObjType::Camera, cam) else { continue };
                    covered.push(id);
                    let name = if s.mujoco.len() == 1 { s.name.clone() } else { format!("{}_{k}", s.name) };
                    let [w, h] = model.cam_resolution()[id];
                    let options = DepthCameraOptions {
                        width: w.max(1) as u32,
                        height: h.max(1) as u32,
                        ray: from_file(s, DepthCameraOptions::default().ray),
                        ..DepthCameraOptions::default()
                    };
                    let prefix = prefix_of(&if s.mujoco.len() == 1 { s.topic.clone() } else { None }, &name);
                    // An RGB-D camera's colour half, rendered, on `<prefix>/image_raw`.
                    let colour = (s.kind == "rgbd_camera" && crate::mj::gl_available().is_ok())
                        .then(|| colour_sensor(model, s, cam, id, format!("{name}_color"), &prefix, false));
                    out.push(RaySensor {
                        frame_id: s.frame_id.clone().unwrap_or_else(|| format!("{name}_optical_frame")),
                        rate_hz: options.ray.rate_hz,
                        kind: RaySensorKind::Depth { camera: cam.clone(), options },
                        topics: depth_topics(&prefix),
                        name,
                    });
                    out.extend(colour);
                }
            }
            kind if is_colour_camera(kind) => {
                if crate::mj::gl_available().is_err() {
                    continue; // named in unrendered_cameras, with what to install
                }
                for (k, cam) in s.mujoco.iter().enumerate() {
                    let Some(id) = model.id(ObjType::Camera, cam) else { continue };
                    covered.push(id);
                    let name = if s.mujoco.len() == 1 { s.name.clone() } else { format!("{}_{k}", s.name) };
                    let prefix = prefix_of(&if s.mujoco.len() == 1 { s.topic.clone() } else { None }, &name);
                    out.push(colour_sensor(model, s, cam, id, name, &prefix, kind == "segmentation"));
                }
            }
            "ray" | "gpu_ray" | "lidar" | "gpu_lidar" => {
                let (Some(scan), Some(site)) = (s.scan, s.mujoco.first()) else { continue };
                if model.id(ObjType::Site, site).is_none() {
                    continue;
                }
                let axis = |(samples, min_rad, max_rad): (usize, f64, f64)| ScanAxis { samples, min_rad, max_rad };
                let options = LidarOptions {
                    horizontal: axis(scan.horizontal),
                    vertical: axis(scan.vertical),
                    ray: from_file(s, LidarOptions::default().ray),
                };
                let stream = if scan.vertical.0 <= 1 { SensorStream::Scan } else { SensorStream::Points };
                let topic = s.topic.clone().unwrap_or_else(|| {
                    let leaf = if stream == SensorStream::Scan { "scan" } else { "points" };
                    format!("/{}/{}/{leaf}", robot.name, crate::topics::topic_safe(&s.name))
                });
                out.push(RaySensor {
                    name: s.name.clone(),
                    frame_id: s.frame_id.clone().unwrap_or_else(|| s.name.clone()),
                    rate_hz: options.ray.rate_hz,
                    kind: RaySensorKind::Lidar { site: site.clone(), options },
                    topics: vec![(topic, stream)],
                });
            }
            _ => {}
        }
    }
    // The MuJoCo cameras of colour sensors are covered too (rendered or not): they are not
    // depth cameras.
    for s in robot.sensors.iter().filter(|s| is_colour_camera(&s.kind)) {
        covered.extend(s.mujoco.iter().filter_map(|c| model.id(ObjType::Camera, c)));
    }
    for c in &robot.cameras {
        let [w, h] = model.cam_resolution()[c.id];
        if covered.contains(&c.id) || c.name.is_empty() || (w <= 1 && h <= 1) {
            continue;
        }
        let options = DepthCameraOptions { width: w as u32, height: h as u32, ..DepthCameraOptions::default() };
        out.push(RaySensor {
            name: c.name.clone(),
            frame_id: format!("{}_optical_frame", c.name),
            rate_hz: options.ray.rate_hz,
            kind: RaySensorKind::Depth { camera: c.name.clone(), options },
            topics: depth_topics(&prefix_of(&None, &c.name)),
        });
    }
    out
}

/// A rendered colour camera of sensor `s` on MuJoCo camera `cam` (id `id`), publishing
/// `<prefix>/image_raw` and `<prefix>/camera_info`, and its labels with `segmentation`.
fn colour_sensor(
    model: &crate::mj::Model,
    s: &crate::convert::SensorMeta,
    cam: &str,
    id: usize,
    name: String,
    prefix: &str,
    segmentation: bool,
) -> RaySensor {
    let [w, h] = model.cam_resolution()[id];
    let options = ColourCameraOptions {
        width: w.max(1) as u32,
        height: h.max(1) as u32,
        // A depth sensor's noise is in metres, not a colour's.
        noise_std: if s.kind == "rgbd_camera" { 0.0 } else { s.noise_std },
        distortion: s.distortion.map_or_else(Default::default, |[k1, k2, k3, p1, p2]| super::camera::Distortion {
            k1,
            k2,
            k3,
            p1,
            p2,
        }),
        rate_hz: s.update_rate_hz.unwrap_or(ColourCameraOptions::default().rate_hz),
        segmentation,
        ..ColourCameraOptions::default()
    };
    let mut topics = vec![
        (format!("{prefix}/image_raw"), SensorStream::ColourImage),
        (format!("{prefix}/camera_info"), SensorStream::CameraInfo),
    ];
    if segmentation {
        topics.push((format!("{prefix}/segmentation/instances"), SensorStream::Instances));
        topics.push((format!("{prefix}/segmentation/classes"), SensorStream::Classes));
        topics.push((format!("{prefix}/segmentation/labels"), SensorStream::LabelTable));
    }
    RaySensor {
        frame_id: s.frame_id.clone().unwrap_or_else(|| format!("{name}_optical_frame")),
        rate_hz: options.rate_hz,
        kind: RaySensorKind::Colour { camera: cam.to_string(), options },
        topics,
        name,
    }
}

/// What the robot file says of sensor `s` over a camera's or LiDAR's `defaults`: its noise
/// (standard deviation, metres), its range limits (`[min, max]`, metres) and its rate (Hz),
/// the last two where the file gives them.
fn from_file(s: &crate::convert::SensorMeta, defaults: RayOptions) -> RayOptions {
    let [min_range_m, max_range_m] = s.range_m.unwrap_or([defaults.min_range_m, defaults.max_range_m]);
    RayOptions {
        min_range_m,
        max_range_m,
        noise_std_m: s.noise_std,
        rate_hz: s.update_rate_hz.unwrap_or(defaults.rate_hz),
        ..defaults
    }
}

/// Whether a Gazebo sensor type is a camera twin renders in colour.
fn is_colour_camera(kind: &str) -> bool {
    matches!(kind, "camera" | "wideanglecamera" | "multicamera" | "segmentation")
}

/// One note per colour camera of `robot`'s file (Gazebo `camera`, `wideanglecamera`,
/// `multicamera`, `segmentation`) when this machine has no OpenGL to render it: such a camera
/// publishes nothing, and the note says what to install. Empty when there is none or OpenGL
/// is there.
pub fn unrendered_cameras(robot: &Robot) -> Vec<String> {
    let Err(why) = crate::mj::gl_available() else { return Vec::new() };
    robot
        .sensors
        .iter()
        .filter(|s| is_colour_camera(&s.kind) || s.kind == "rgbd_camera")
        .map(|s| {
            let size = s
                .mujoco
                .first()
                .and_then(|c| robot.model.id(ObjType::Camera, c))
                .map(|id| {
                    let [w, h] = robot.model.cam_resolution()[id];
                    format!("{w}×{h} ")
                })
                .unwrap_or_default();
            format!(
                "camera sensor \"{}\" (Gazebo type=\"{}\", {size}colour): its colour image is not rendered: \
                 {why}",
                s.name, s.kind
            )
        })
        .collect()
}

fn depth_topics(prefix: &str) -> Vec<(String, SensorStream)> {
    vec![
        (format!("{prefix}/depth/image_raw"), SensorStream::DepthImage),
        (format!("{prefix}/depth/camera_info"), SensorStream::CameraInfo),
        (format!("{prefix}/points"), SensorStream::Points),
    ]
}

/// One reading of a ray-cast sensor.
#[derive(Debug, Clone, PartialEq)]
pub enum Reading {
    /// A depth image.
    Depth(DepthFrame),
    /// A colour frame (with its labels when asked for).
    Colour(ColourFrame),
    /// A LiDAR scan.
    Lidar(LidarScan),
}

impl Reading {
    /// Simulation time of the state it shows, ns.
    pub fn stamp_nanos(&self) -> u64 {
        match self {
            Reading::Depth(f) => f.stamp_nanos,
            Reading::Colour(f) => f.stamp_nanos,
            Reading::Lidar(l) => l.stamp_nanos,
        }
    }

    fn set_stamp_nanos(&mut self, stamp_nanos: u64) {
        match self {
            Reading::Depth(f) => f.stamp_nanos = stamp_nanos,
            Reading::Colour(f) => f.stamp_nanos = stamp_nanos,
            Reading::Lidar(l) => l.stamp_nanos = stamp_nanos,
        }
    }
}

/// One message of a ray-cast sensor's topic.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorMessage {
    /// `sensor_msgs/Image`.
    Image(Image),
    /// `sensor_msgs/CameraInfo` (boxed: it is several times the others' size).
    CameraInfo(Box<CameraInfo>),
    /// `sensor_msgs/PointCloud2`.
    PointCloud2(PointCloud2),
    /// `sensor_msgs/LaserScan`.
    LaserScan(LaserScan),
    /// `std_msgs/String` (a label table).
    Text(RosString),
}

impl SensorMessage {
    /// The ROS 2 type name.
    pub fn type_name(&self) -> &'static str {
        match self {
            SensorMessage::Image(_) => Image::TYPE_NAME,
            SensorMessage::CameraInfo(_) => CameraInfo::TYPE_NAME,
            SensorMessage::PointCloud2(_) => PointCloud2::TYPE_NAME,
            SensorMessage::LaserScan(_) => LaserScan::TYPE_NAME,
            SensorMessage::Text(_) => RosString::TYPE_NAME,
        }
    }

    /// Encodes the message's fields (CDR, after the encapsulation header).
    pub fn encode(&self, w: &mut CdrWriter) {
        match self {
            SensorMessage::Image(m) => m.encode(w),
            SensorMessage::CameraInfo(m) => m.encode(w),
            SensorMessage::PointCloud2(m) => m.encode(w),
            SensorMessage::LaserScan(m) => m.encode(w),
            SensorMessage::Text(m) => m.encode(w),
        }
    }
}

/// A built ray-cast sensor: reads on demand.
#[derive(Debug)]
pub enum Device {
    /// A depth camera.
    Depth(DepthCamera),
    /// A colour camera (rendered).
    Colour(Box<ColourCamera>),
    /// A LiDAR.
    Lidar(Lidar),
}

impl RaySensor {
    /// Builds the device on `robot`'s model.
    ///
    /// # Errors
    /// As [`DepthCamera::new`], [`ColourCamera::new`] and [`Lidar::new`] (bad options from the
    /// file, a missing camera or site, no OpenGL for a colour camera).
    pub fn build(&self, robot: &Robot) -> Result<Device> {
        Ok(match &self.kind {
            RaySensorKind::Depth { camera, options } => {
                Device::Depth(DepthCamera::new(&robot.model, camera, options.clone())?.with_frame_id(&self.frame_id))
            }
            RaySensorKind::Colour { camera, options } => Device::Colour(Box::new(
                ColourCamera::new(&robot.model, camera, options.clone())?.with_frame_id(&self.frame_id),
            )),
            RaySensorKind::Lidar { site, options } => {
                Device::Lidar(Lidar::new(&robot.model, site, options.clone())?.with_frame_id(&self.frame_id))
            }
        })
    }

    /// Rays per reading: a camera's pixels, a LiDAR's beams.
    pub fn rays(&self) -> usize {
        match &self.kind {
            RaySensorKind::Depth { options, .. } => options.width as usize * options.height as usize,
            RaySensorKind::Colour { options, .. } => options.width as usize * options.height as usize,
            RaySensorKind::Lidar { options, .. } => options.horizontal.samples * options.vertical.samples,
        }
    }

    /// Where the sensor's frame sits on the robot: `(body, body_from_frame translation (m),
    /// rotation w x y z)`; a camera's frame is its optical frame (z forward, x right, y down),
    /// a LiDAR's its site. `None` when the model lacks the camera or site.
    pub fn body_from_frame(&self, model: &crate::mj::Model) -> Option<(usize, [f64; 3], [f64; 4])> {
        match &self.kind {
            RaySensorKind::Depth { camera, .. } | RaySensorKind::Colour { camera, .. } => {
                let c = model.id(ObjType::Camera, camera)?;
                let q = model.cam_quat()[c];
                // body_from_optical = body_from_camera · (half turn about x) = q ⊗ (0, 1, 0, 0).
                let optical = [-q[1], q[0], q[3], -q[2]];
                Some((model.cam_bodyid()[c] as usize, model.cam_pos()[c], optical))
            }
            RaySensorKind::Lidar { site, .. } => {
                let s = model.id(ObjType::Site, site)?;
                Some((model.site_bodyid()[s] as usize, model.site_pos()[s], model.site_quat()[s]))
            }
        }
    }

    /// The messages of `reading`, one per topic of [`RaySensor::topics`], in that order.
    pub fn messages(&self, reading: &Reading) -> Vec<SensorMessage> {
        self.topics
            .iter()
            .map(|(_, stream)| match (stream, reading) {
                (SensorStream::DepthImage, Reading::Depth(f)) => SensorMessage::Image(f.image()),
                (SensorStream::CameraInfo, Reading::Depth(f)) => SensorMessage::CameraInfo(Box::new(f.camera_info())),
                (SensorStream::Points, Reading::Depth(f)) => SensorMessage::PointCloud2(f.point_cloud()),
                (SensorStream::Points, Reading::Lidar(s)) => SensorMessage::PointCloud2(s.point_cloud()),
                (_, Reading::Lidar(s)) => SensorMessage::LaserScan(s.laser_scan(0, 1.0 / self.rate_hz)),
                (_, Reading::Depth(f)) => SensorMessage::Image(f.image()),
                (SensorStream::CameraInfo, Reading::Colour(f)) => SensorMessage::CameraInfo(Box::new(f.camera_info())),
                (SensorStream::Instances | SensorStream::Classes, Reading::Colour(f)) => {
                    SensorMessage::Image(f.label_image(*stream == SensorStream::Classes).unwrap_or_else(|| f.image()))
                }
                (SensorStream::LabelTable, Reading::Colour(f)) => SensorMessage::Text(RosString {
                    data: f.labels.as_ref().map_or_else(String::new, |l| l.table.to_string()),
                }),
                (_, Reading::Colour(f)) => SensorMessage::Image(f.image()),
            })
            .collect()
    }
}

impl Device {
    /// Reads the state of `data` (its last forward pass; a renderer updates its scene from it).
    ///
    /// # Errors
    /// As [`DepthCamera::render`], [`ColourCamera::render`] and [`Lidar::scan`].
    pub fn read(&mut self, data: &mut Data) -> Result<Reading> {
        Ok(match self {
            Device::Depth(c) => Reading::Depth(c.render(&data.model().clone(), data)?),
            Device::Colour(c) => Reading::Colour(c.render(data)?),
            Device::Lidar(l) => Reading::Lidar(l.scan(data)?),
        })
    }
}

/// What a pool thread hands back: the device, its scratch state, the reading and its wall
/// time, seconds.
type Finished = (Device, Data, Result<Reading>, f64);

/// A device read on another thread while the simulation goes on: the reading asked for at one
/// tick comes back at the next ([`Pipelined::submit`]) or at the end ([`Pipelined::finish`]),
/// whatever the threads' timing, so recordings stay the same run to run. The simulation thread
/// only copies the poses the rays need (a few kB); the rays are cast on a pool of its own with
/// one thread fewer than the machine has cores (at least one): a device casting on the global
/// pool (`threads = 0`) would take every core, the simulation's too, and the simulation waits
/// for nothing it did not ask for. A reading takes longer that way but stays off the
/// simulation's core: on 2 cores a 15 Hz camera at 2 ms a frame fills a sixth of the other one.
pub struct Pipelined {
    idle: Option<(Device, Data)>,
    pending: Option<std::sync::mpsc::Receiver<Finished>>,
    pool: rayon::ThreadPool,
    readings: u64,
    read_secs: f64,
}

impl std::fmt::Debug for Pipelined {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipelined")
            .field("device", &self.idle.as_ref().map(|(d, _)| d))
            .field("pending", &self.pending.is_some())
            .field("threads", &self.pool.current_num_threads())
            .finish()
    }
}

impl Pipelined {
    /// `device` with a scratch state of `model` (the model its readings come from).
    ///
    /// # Errors
    /// [`crate::Error::MuJoCo`] when MuJoCo can't allocate the scratch state;
    /// [`crate::Error::Options`] when the ray threads can't be started.
    pub fn new(device: Device, model: std::sync::Arc<crate::mj::Model>) -> Result<Pipelined> {
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get().saturating_sub(1).max(1));
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("twin-rays-{i}"))
            .build()
            .map_err(|e| crate::Error::Options(format!("can't start {threads} ray-casting threads: {e}")))?;
        Ok(Pipelined { idle: Some((device, Data::new(model)?)), pending: None, pool, readings: 0, read_secs: 0.0 })
    }

    /// Readings taken so far and the wall time they took on the pool, seconds (the device's
    /// cost, whether or not the simulation waited for it).
    pub fn cost(&self) -> (u64, f64) {
        (self.readings, self.read_secs)
    }

    /// Starts a reading of `data`'s poses (its last forward pass), stamped `stamp_nanos`, and
    /// hands back the previous reading, waiting for it if it is not ready.
    ///
    /// # Errors
    /// The previous reading's error; [`crate::Error::Size`] for a `data` of another model
    /// layout.
    pub fn submit(&mut self, data: &Data, stamp_nanos: u64) -> Result<Option<Reading>> {
        let previous = self.finish()?;
        let (mut device, mut scratch) = self.idle.take().expect("finish() leaves the device idle");
        if let Err(e) = scratch.copy_poses_from(data) {
            self.idle = Some((device, scratch));
            return Err(e.into());
        }
        let (tx, rx) = std::sync::mpsc::channel();
        // Inside the pool, a device's `threads = 0` (the current pool) means this pool.
        self.pool.spawn(move || {
            let started = std::time::Instant::now();
            let reading = device.read(&mut scratch).map(|mut r| {
                r.set_stamp_nanos(stamp_nanos);
                r
            });
            // The receiver is gone only when the owner was dropped: nothing to hand back.
            let _ = tx.send((device, scratch, reading, started.elapsed().as_secs_f64()));
        });
        self.pending = Some(rx);
        Ok(previous)
    }

    /// Waits for the reading in flight, if any, and hands it back.
    ///
    /// # Errors
    /// The reading's error; [`crate::Error::Options`] if its thread died (a panic).
    pub fn finish(&mut self) -> Result<Option<Reading>> {
        let Some(rx) = self.pending.take() else { return Ok(None) };
        let (device, scratch, reading, secs) = rx
            .recv()
            .map_err(|_| crate::Error::Options("a ray-cast sensor's thread ended without its reading".into()))?;
        self.idle = Some((device, scratch));
        self.readings += 1;
        self.read_secs += secs;
        reading.map(Some)
    }
}

impl Drop for Pipelined {
    /// Waits for the reading in flight, so the device (a colour camera's rendering thread and
    /// OpenGL context) is dropped here, before its owner goes on, and not on a pool thread that
    /// may still be running when the process exits (the pool's threads are not joined).
    fn drop(&mut self) {
        let _ = self.finish();
    }
}
