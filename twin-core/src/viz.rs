//! Recordings for the rerun viewer: the robot's geometry posed per body over time, and scalar
//! time series (joints, IMU, contacts), in a `.rrd` file or streamed to a running viewer.
//!
//! Entity layout (Z up, metres, radians):
//! - `world/<body>`: the body's frame, a `Transform3D` in the world frame per logged frame;
//! - `world/<body>/<geom>`: the geom's shape, posed statically in its body frame;
//! - `series/...`: scalars logged with [`Recorder::scalar`];
//! - `world/sensors/<camera>` (pose + pinhole) with `…/depth` (a depth image), and
//!   `world/sensors/<sensor>_points` (a point cloud in the world) for ray-cast sensors.
//!
//! Time is the simulation (or log) time on the `sim_time` timeline, wall-clock log time is off
//! and files are cut into chunks by size only (no wall-clock flush tick), so recordings of the
//! same run hold the same data in the same order (`rerun rrd compare` finds them equal); their
//! bytes differ, since rerun stamps every row and chunk with a unique id made from the wall clock
//! and a random number (its SDK has no way to set them).

use crate::error::{Error, Result};
use crate::mj::{Data, GeomType, JointType, Model, ObjType};
use std::path::{Path, PathBuf};

/// The rerun names twin uses, as the `rerun` umbrella crate re-exports them (twin depends on the
/// SDK crates alone, see the workspace manifest).
mod rerun {
    pub use re_sdk::{AsComponents, RecordingStream, RecordingStreamBuilder};
    pub use re_sdk_types::archetypes::*;
    pub use re_sdk_types::components::{Color, FillMode};
    pub use re_sdk_types::datatypes::{ChannelDatatype, Quaternion};
}

/// How long [`Recorder::finish`] waits for a viewer to take the recording.
const VIEWER_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// Name of the timeline everything is logged on.
pub const TIMELINE: &str = "sim_time";

/// Logs a model's geometry once and its body poses per frame.
pub struct Recorder {
    rec: rerun::RecordingStream,
    /// Entity path of each body (index = body id; the world body has none).
    body_paths: Vec<Option<String>>,
    path: Option<PathBuf>,
    /// The viewer's address when streaming.
    url: Option<String>,
}

fn rerun_err(path: Option<&Path>, e: impl std::fmt::Display) -> Error {
    Error::Rerun { path: path.map(Path::to_path_buf), message: e.to_string() }
}

/// Entity-path-safe version of a MuJoCo name (rerun splits paths on `/`).
fn entity_name(name: &str, fallback: &str, id: usize) -> String {
    let clean: String =
        name.chars().map(|c| if c.is_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
    if clean.is_empty() { format!("{fallback}_{id}") } else { clean }
}

fn quat(wxyz: [f64; 4]) -> rerun::Quaternion {
    rerun::Quaternion::from_wxyz(wxyz.map(|v| v as f32))
}

fn vec3(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

impl Recorder {
    /// Records to a `.rrd` file at `path` under application id `app_id`; an existing file there is
    /// kept as the first free of `<name>.bak`, `<name>.bak.1`, …
    ///
    /// # Errors
    /// [`Error::Rerun`] if the file can't be created.
    pub fn to_file(model: &Model, app_id: &'static str, path: impl AsRef<Path>) -> Result<Recorder> {
        let path = path.as_ref();
        // Not a folder or device; what was there is kept as the first free numbered backup
        // (never over an older one), like the MCAP writer does.
        let target = crate::fsio::check_output(path, &[])?;
        if target.existing.is_some() {
            crate::fsio::backup_numbered(&target.resolved)?;
        }
        let rec = rerun::RecordingStreamBuilder::new(app_id)
            // A fixed id keeps re-recordings of the same run comparable.
            .recording_id(format!("{app_id}-recording"))
            // Chunks cut by size only, never by a wall-clock tick: the same run gives the same
            // chunks however busy the machine is.
            .batcher_config(re_sdk::log::ChunkBatcherConfig {
                flush_tick: std::time::Duration::MAX,
                ..re_sdk::log::ChunkBatcherConfig::DEFAULT
            })
            .save(path)
            .map_err(|e| rerun_err(Some(path), e))?;
        Self::start(rec, model, Some(path.to_path_buf()))
    }

    /// Streams to a running rerun viewer at `url` (e.g. `rerun+http://127.0.0.1:9876/proxy`).
    ///
    /// # Errors
    /// [`Error::Rerun`] if the connection can't be set up.
    pub fn to_viewer(model: &Model, app_id: &'static str, url: &str) -> Result<Recorder> {
        let rec = rerun::RecordingStreamBuilder::new(app_id)
            .connect_grpc_opts(url.to_string())
            .map_err(|e| rerun_err(None, e))?;
        let mut recorder = Self::start(rec, model, None)?;
        recorder.url = Some(url.to_string());
        Ok(recorder)
    }

    fn start(rec: rerun::RecordingStream, model: &Model, path: Option<PathBuf>) -> Result<Recorder> {
        // Wall-clock log time would make files differ run to run; simulation time is what matters.
        rec.set_log_time_enabled(false);
        let mut recorder = Recorder { rec, body_paths: Vec::new(), path, url: None };
        recorder.log_geometry(model)?;
        Ok(recorder)
    }

    fn err(&self, e: impl std::fmt::Display) -> Error {
        rerun_err(self.path.as_deref(), e)
    }

    fn log_geometry(&mut self, model: &Model) -> Result<()> {
        let rec = &self.rec;
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP()).map_err(|e| self.err(e))?;
        self.body_paths = (0..model.nbody())
            .map(|b| (b > 0).then(|| format!("world/{}", entity_name(model.name(ObjType::Body, b), "body", b))))
            .collect();
        for g in 0..model.ngeom() {
            let body = model.geom_bodyid()[g] as usize;
            let parent = self.body_paths[body].clone().unwrap_or_else(|| "world".to_string());
            let entity = format!("{parent}/{}", entity_name(model.name(ObjType::Geom, g), "geom", g));
            let rgba = match model.geom_matid()[g] {
                m if m >= 0 => model.mat_rgba()[m as usize],
                _ => model.geom_rgba()[g],
            };
            let color = rerun::Color::from_unmultiplied_rgba(
                (rgba[0] * 255.0) as u8,
                (rgba[1] * 255.0) as u8,
                (rgba[2] * 255.0) as u8,
                (rgba[3] * 255.0) as u8,
            );
            let pose =
                rerun::Transform3D::from_translation_rotation(vec3(model.geom_pos()[g]), quat(model.geom_quat()[g]));
            let s = model.geom_size()[g];
            let solid = rerun::FillMode::Solid;
            let shape: Box<dyn rerun::AsComponents> = match model.geom_kind(g) {
                GeomType::Plane => {
                    // An infinite plane (size 0) is drawn as a 10 m square.
                    let hx = if s[0] > 0.0 { s[0] } else { 5.0 };
                    let hy = if s[1] > 0.0 { s[1] } else { 5.0 };
                    Box::new(
                        rerun::Boxes3D::from_half_sizes([[hx as f32, hy as f32, 0.0]])
                            .with_colors([color])
                            .with_fill_mode(solid),
                    )
                }
                GeomType::Sphere => {
                    Box::new(rerun::Ellipsoids3D::from_radii([s[0] as f32]).with_colors([color]).with_fill_mode(solid))
                }
                GeomType::Ellipsoid => {
                    Box::new(rerun::Ellipsoids3D::from_half_sizes([vec3(s)]).with_colors([color]).with_fill_mode(solid))
                }
                GeomType::Box => {
                    Box::new(rerun::Boxes3D::from_half_sizes([vec3(s)]).with_colors([color]).with_fill_mode(solid))
                }
                GeomType::Cylinder => Box::new(
                    rerun::Cylinders3D::from_lengths_and_radii([2.0 * s[1] as f32], [s[0] as f32])
                        .with_colors([color])
                        .with_fill_mode(solid),
                ),
                // rerun's capsule runs from the origin along +Z; MuJoCo's is centred.
                GeomType::Capsule => Box::new(
                    rerun::Capsules3D::from_lengths_and_radii([2.0 * s[1] as f32], [s[0] as f32])
                        .with_translations([[0.0, 0.0, -s[1] as f32]])
                        .with_colors([color]),
                ),
                GeomType::Mesh if model.geom_dataid()[g] >= 0 => {
                    let mesh = model.geom_dataid()[g] as usize;
                    let (v0, nv) = (model.mesh_vertadr()[mesh] as usize, model.mesh_vertnum()[mesh] as usize);
                    let (f0, nf) = (model.mesh_faceadr()[mesh] as usize, model.mesh_facenum()[mesh] as usize);
                    let vertices = model.mesh_vert()[v0..v0 + nv].to_vec();
                    let faces: Vec<[u32; 3]> =
                        model.mesh_face()[f0..f0 + nf].iter().map(|f| f.map(|i| i as u32)).collect();
                    Box::new(rerun::Mesh3D::new(vertices).with_triangle_indices(faces).with_albedo_factor(color.0))
                }
                // Height fields and SDFs have no rerun primitive; they are left out.
                _ => continue,
            };
            rec.log_static(entity.as_str(), &[&pose as &dyn rerun::AsComponents, shape.as_ref()])
                .map_err(|e| self.err(e))?;
        }
        Ok(())
    }

    /// Sets the time of what is logged next, in seconds of simulation (or log) time.
    pub fn set_time_secs(&self, t_secs: f64) {
        self.rec.set_duration_secs(TIMELINE, t_secs);
    }

    /// Logs every body's world pose from `data` (after `forward`/`step`) at `data`'s time.
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn log_poses(&self, data: &Data) -> Result<()> {
        self.log_poses_at(data.time_secs(), data)
    }

    /// Logs every body's world pose from `data` stamped `t_secs` (for a `data` whose poses
    /// belong to another time than `data.time`, e.g. between `mj_step1` and the end of a step).
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn log_poses_at(&self, t_secs: f64, data: &Data) -> Result<()> {
        self.log_world_poses(t_secs, data.xpos(), data.xquat())
    }

    /// Logs every body's world pose, `xpos[b]` and `xquat[b]` (w x y z) per body id (the world
    /// body's is not logged), stamped `t_secs`.
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn log_world_poses(&self, t_secs: f64, xpos: &[[f64; 3]], xquat: &[[f64; 4]]) -> Result<()> {
        self.set_time_secs(t_secs);
        for (b, path) in self.body_paths.iter().enumerate() {
            if let Some(path) = path {
                let world_from_body = rerun::Transform3D::from_translation_rotation(vec3(xpos[b]), quat(xquat[b]));
                self.rec.log(path.as_str(), &world_from_body).map_err(|e| self.err(e))?;
            }
        }
        Ok(())
    }

    /// Logs one scalar at `series/<name>` at the current time.
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn scalar(&self, name: &str, value: f64) -> Result<()> {
        self.rec.log(format!("series/{name}"), &rerun::Scalars::single(value)).map_err(|e| self.err(e))
    }

    /// Logs a depth camera's frame at the current time under `world/sensors/<name>`: the
    /// optical frame's pose, a pinhole with the intrinsics (RDF, as ROS's optical frame), the
    /// depth image (metres) at `…/depth`, and its returns as a 3-D point cloud in the world at
    /// `world/sensors/<name>_points`.
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn depth_frame(&self, name: &str, frame: &crate::sense::DepthFrame) -> Result<()> {
        let base = format!("world/sensors/{}", entity_name(name, "camera", 0));
        let t = frame.world_from_optical;
        let q = t.rotation;
        let pose = rerun::Transform3D::from_translation_rotation(
            vec3([t.translation.x, t.translation.y, t.translation.z]),
            quat([q.w, q.i, q.j, q.k]),
        );
        self.rec.log(base.as_str(), &pose).map_err(|e| self.err(e))?;
        let k = &frame.intrinsics;
        // rerun puts pixel centres at +0.5; ROS at integers.
        let pinhole = rerun::Pinhole::from_focal_length_and_resolution(
            [k.fx as f32, k.fy as f32],
            [k.width as f32, k.height as f32],
        )
        .with_principal_point([(k.cx + 0.5) as f32, (k.cy + 0.5) as f32]);
        self.rec.log(base.as_str(), &pinhole).map_err(|e| self.err(e))?;
        let bytes: Vec<u8> = frame.depth_m.iter().flat_map(|z| z.to_le_bytes()).collect();
        let depth =
            rerun::DepthImage::from_data_type_and_bytes(bytes, [k.width, k.height], rerun::ChannelDatatype::F32)
                .with_meter(1.0);
        self.rec.log(format!("{base}/depth"), &depth).map_err(|e| self.err(e))?;
        self.sensor_points(&format!("{}_points", entity_name(name, "camera", 0)), &frame.points_world())
    }

    /// Logs a rendered colour frame at `world/sensors/<name>/rgb` at the current time.
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn colour_frame(&self, name: &str, frame: &crate::sense::ColourFrame) -> Result<()> {
        let base = format!("world/sensors/{}", entity_name(name, "camera", 0));
        let k = &frame.intrinsics;
        let image = rerun::Image::from_rgb24(frame.rgb.clone(), [k.width, k.height]);
        self.rec.log(format!("{base}/rgb"), &image).map_err(|e| self.err(e))
    }

    /// Logs points (world frame, metres) at `world/sensors/<name>` at the current time.
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn sensor_points(&self, name: &str, points_world: &[nalgebra::Point3<f64>]) -> Result<()> {
        let pts = points_world.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]);
        self.rec
            .log(format!("world/sensors/{name}"), &rerun::Points3D::new(pts).with_radii([0.003]))
            .map_err(|e| self.err(e))
    }

    /// Logs points (world frame, m) at `<name>` at the current time (a controller's reference
    /// CoM, its planned footsteps).
    ///
    /// # Errors
    /// [`Error::Rerun`] if writing fails.
    pub fn points(&self, name: &str, points: &[[f64; 3]]) -> Result<()> {
        let points = rerun::Points3D::new(points.iter().map(|&p| vec3(p))).with_radii([0.02f32]);
        self.rec.log(name, &points).map_err(|e| self.err(e))
    }

    /// The `.rrd` file, when recording to one.
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// Flushes everything to the file or viewer.
    ///
    /// # Errors
    /// [`Error::Rerun`] if the sink can't be flushed.
    pub fn finish(self) -> Result<()> {
        match &self.url {
            // A viewer that is not running would make a blocking flush wait forever.
            Some(url) => match self.rec.flush_with_timeout(VIEWER_TIMEOUT) {
                Ok(()) => Ok(()),
                Err(e) => {
                    let err = self.err(format!(
                        "{e}: could not hand the recording to the rerun viewer at {url} within {} s; \
                         is a viewer running there (start one with `rerun`)?",
                        VIEWER_TIMEOUT.as_secs()
                    ));
                    // Dropping the stream would join its sender thread, which waits for the
                    // viewer forever: leave it to the end of the process instead.
                    std::mem::forget(self.rec);
                    Err(err)
                }
            },
            None => self.rec.flush_blocking().map_err(|e| self.err(e)),
        }
    }
}

/// A curve for [`write_curves`]: its entity path and points `(x, y)`.
pub type Curve = (String, Vec<(f64, f64)>);

/// Writes curves (no robot) to a `.rrd` file: each as scalars `y` at entity path `curve.0` on
/// the sequence timeline `timeline`, whose index is `round(x · x_scale)` (a rerun timeline is
/// an integer sequence: e.g. `log10(τ)` in thousandths for an Allan deviation plot). An
/// existing file is replaced.
///
/// # Errors
/// [`Error::Rerun`] if the file can't be written.
pub fn write_curves(
    path: &Path,
    app_id: &'static str,
    timeline: &'static str,
    x_scale: f64,
    curves: &[Curve],
) -> Result<()> {
    let rec = rerun::RecordingStreamBuilder::new(app_id)
        .recording_id(format!("{app_id}-recording"))
        .save(path)
        .map_err(|e| rerun_err(Some(path), e))?;
    for (entity, points) in curves {
        for &(x, y) in points {
            if !(x.is_finite() && y.is_finite()) {
                continue;
            }
            rec.set_time_sequence(timeline, (x * x_scale).round() as i64);
            rec.log(entity.as_str(), &rerun::Scalars::single(y)).map_err(|e| rerun_err(Some(path), e))?;
        }
    }
    rec.flush_blocking().map_err(|e| rerun_err(Some(path), e))
}

/// Options of [`record_log`].
#[derive(Debug, Clone, smart_default::SmartDefault)]
pub struct ViewOptions {
    /// JointState topic that animates the robot (default: `/joint_states`).
    #[default("/joint_states")]
    pub joint_states_topic: String,
    /// Odometry topic that moves the floating base, used when the log has it (default: `/odom`).
    #[default("/odom")]
    pub odom_topic: String,
    /// Rate of the posed frames, Hz; joint and IMU scalars keep every sample (default: 50).
    #[default(50.0)]
    pub pose_rate_hz: f64,
    /// Polled between frames and topics: once raised (e.g. Ctrl-C through
    /// [`crate::fsio::interrupt_flag`]), [`record_log`] stops and returns what it logged so far
    /// with [`ViewSummary::interrupted`] set (default: none).
    pub stop: Option<&'static std::sync::atomic::AtomicBool>,
}

/// What [`record_log`] did.
#[derive(Debug, Clone, Default)]
pub struct ViewSummary {
    /// Posed frames logged.
    pub frames: u64,
    /// Log joints that animate a model joint.
    pub joints_matched: Vec<String>,
    /// Log joints the model lacks (logged as scalars only).
    pub joints_unknown: Vec<String>,
    /// Odometry messages that moved the base (0: base kept at its home pose).
    pub odom_messages: u64,
    /// IMU topics logged as scalars.
    pub imu_topics: Vec<String>,
    /// Scalars logged.
    pub scalars: u64,
    /// Log time span shown, seconds.
    pub duration_secs: f64,
    /// Warnings about the log (damage, odd stamps).
    pub warnings: Vec<String>,
    /// Whether [`ViewOptions::stop`] ended the recording early (its frames cover the start of
    /// the log only).
    pub interrupted: bool,
}

/// Turns a robot's ROS 2 log into a recording: the model posed from the log's joint states
/// (positions set by joint name, interpolated to [`ViewOptions::pose_rate_hz`] frames, then
/// `mj_forward`), the floating base from odometry when the log has it, and joint positions /
/// IMU readings as scalars (`series/joints/<joint>`, `series/imu/<topic>/{gyro,accel}_{x,y,z}`).
/// Time 0 is the first joint-state stamp.
///
/// # Errors
/// Log errors ([`Error::LogTopic`] when the joint-state topic is missing); [`Error::Rerun`].
pub fn record_log(
    robot: &crate::sim::Robot,
    log: &crate::log::Log,
    options: &ViewOptions,
    recorder: &Recorder,
) -> Result<ViewSummary> {
    use crate::control::JointTrajectory;
    use crate::log::{Imu, Odometry};
    let model = &robot.model;
    let mut summary = ViewSummary::default();
    let stopped = || options.stop.is_some_and(|f| f.load(std::sync::atomic::Ordering::Relaxed));
    let series = log.joint_states(&options.joint_states_topic)?;
    summary.warnings = series.report.warnings();
    let trajectory = JointTrajectory::from_log(log.path(), &options.joint_states_topic)?;
    let t0 = trajectory.start_nanos;
    let rel = |stamp_nanos: i64, log_nanos: u64| {
        let t = if stamp_nanos != 0 { stamp_nanos } else { log_nanos as i64 };
        (t - t0) as f64 * 1e-9
    };
    summary.duration_secs = trajectory.duration_secs();
    let mut animated = Vec::new();
    for j in &trajectory.joints {
        if stopped() {
            summary.interrupted = true;
            return Ok(summary);
        }
        match model.id(ObjType::Joint, &j.name) {
            Some(id) if model.joint_type(id) != JointType::Free => {
                summary.joints_matched.push(j.name.clone());
                animated.push((model.jnt_qposadr()[id] as usize, j));
            }
            _ => summary.joints_unknown.push(j.name.clone()),
        }
        for (t, q) in j.time_secs.iter().zip(&j.position) {
            recorder.set_time_secs(*t);
            recorder.scalar(&format!("joints/{}", entity_name(&j.name, "joint", 0)), *q)?;
            summary.scalars += 1;
        }
    }

    let topics = log.info()?.topics;
    let free_adr = robot.base.map(|b| b.qpos_adr);
    let mut odom: Vec<(f64, [f64; 3], [f64; 4])> = Vec::new();
    if free_adr.is_some() && topics.iter().any(|t| t.topic == options.odom_topic) {
        let (msgs, _) = log.read_typed::<Odometry>(&options.odom_topic)?;
        odom = msgs
            .iter()
            .map(|(log_nanos, m)| {
                let q = m.orientation_xyzw;
                (rel(m.header.stamp_nanos, *log_nanos), m.position, [q[3], q[0], q[1], q[2]])
            })
            .collect();
        odom.sort_by(|a, b| a.0.total_cmp(&b.0));
        summary.odom_messages = odom.len() as u64;
    }
    for t in topics.iter().filter(|t| t.type_name == "sensor_msgs/msg/Imu") {
        if stopped() {
            summary.interrupted = true;
            return Ok(summary);
        }
        let (msgs, _) = log.read_typed::<Imu>(&t.topic)?;
        let name = entity_name(t.topic.trim_start_matches('/'), "imu", 0);
        for (log_nanos, m) in &msgs {
            recorder.set_time_secs(rel(m.header.stamp_nanos, *log_nanos));
            let v = [m.angular_velocity, m.linear_acceleration].concat();
            for (i, axis) in ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"].iter().enumerate() {
                recorder.scalar(&format!("imu/{name}/{axis}"), v[i])?;
                summary.scalars += 1;
            }
        }
        summary.imu_topics.push(t.topic.clone());
    }

    let mut data = Data::new(model.clone())?;
    crate::control::reset_to_home(&mut data)?;
    let frames = ((summary.duration_secs * options.pose_rate_hz.max(1e-3)).floor() as u64) + 1;
    let mut next_odom = 0usize;
    for k in 0..frames {
        if stopped() {
            summary.interrupted = true;
            break;
        }
        let t = k as f64 / options.pose_rate_hz;
        for (adr, j) in &animated {
            data.qpos_mut()[*adr] = j.sample(t).0;
        }
        if let Some(adr) = free_adr {
            while next_odom + 1 < odom.len() && odom[next_odom + 1].0 <= t {
                next_odom += 1;
            }
            if let Some((_, p, q)) = odom.get(next_odom) {
                let qpos = data.qpos_mut();
                qpos[adr..adr + 3].copy_from_slice(p);
                qpos[adr + 3..adr + 7].copy_from_slice(q);
            }
        }
        data.forward()?;
        recorder.log_poses_at(t, &data)?;
        summary.frames += 1;
    }
    Ok(summary)
}
