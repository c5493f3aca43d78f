//! Typed fast paths for the message types twin reads and writes most, with their `ros2msg`
//! definitions (dependencies appended the way ROS 2 does) for writing schemas.
//!
//! Decoding is a straight walk over the CDR bytes; it is used only when the file's own schema
//! has the canonical layout (checked once per channel), otherwise the generic decoder runs.

use super::cdr::{CdrError, CdrReader, CdrWriter, Value};
use super::msgdef::MsgDefs;

type CdrResult<T> = std::result::Result<T, CdrError>;

/// `std_msgs/msg/Header` with the stamp in nanoseconds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Header {
    /// `stamp.sec * 1e9 + stamp.nanosec`.
    pub stamp_nanos: i64,
    /// Frame the data is expressed in.
    pub frame_id: String,
}

/// `sensor_msgs/msg/JointState`. Positions in rad (or m), velocities in rad/s, efforts in N·m
/// (or whatever the driver reports). `velocity`/`effort` may be empty.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointState {
    /// Header.
    pub header: Header,
    /// Joint names, in this message's order.
    pub name: Vec<String>,
    /// Positions.
    pub position: Vec<f64>,
    /// Velocities (may be empty).
    pub velocity: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
}

/// `sensor_msgs/msg/Imu`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Imu {
    /// Header (frame: the IMU link).
    pub header: Header,
    /// Orientation quaternion, x y z w.
    pub orientation_xyzw: [f64; 4],
    /// Row-major 3×3 covariance (-1 in the first element: no orientation).
    pub orientation_covariance: [f64; 9],
    /// Angular velocity, rad/s, in the IMU frame.
    pub angular_velocity: [f64; 3],
    /// Row-major 3×3 covariance.
    pub angular_velocity_covariance: [f64; 9],
    /// Linear acceleration (specific force), m/s², in the IMU frame.
    pub linear_acceleration: [f64; 3],
    /// Row-major 3×3 covariance.
    pub linear_acceleration_covariance: [f64; 9],
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct Odometry {
    /// Header (frame: usually `odom`).
    pub header: Header,
    /// Body frame of the twist.
    pub child_frame_id: String,
    /// Position in the header frame, m.
    #[default([0.0; 3])]
    pub position: [f64; 3],
    /// Orientation x y z w.
    #[default([0.0, 0.0, 0.0, 1.0])]
    pub orientation_xyzw: [f64; 4],
    /// Row-major 6×6 pose covariance.
    #[default([0.0; 36])]
    pub pose_covariance: [f64; 36],
    /// Linear velocity in the child frame, m/s.
    #[default([0.0; 3])]
    pub linear_velocity: [f64; 3],
    /// Angular velocity in the child frame, rad/s.
    #[default([0.0; 3])]
    pub angular_velocity: [f64; 3],
    /// Row-major 6×6 twist covariance.
    #[default([0.0; 36])]
    pub twist_covariance: [f64; 36],
}

/// `geometry_msgs/msg/WrenchStamped`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WrenchStamped {
    /// Header.
    pub header: Header,
    /// Force, N.
    pub force: [f64; 3],
    /// Torque, N·m.
    pub torque: [f64; 3],
}

/// `geometry_msgs/msg/PointStamped`: a point, e.g. a controller's reference or measured CoM,
/// ZMP or DCM.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointStamped {
    /// Header (frame the point is expressed in).
    pub header: Header,
    /// The point, m.
    pub point: [f64; 3],
}

/// `geometry_msgs/msg/Pose` inside a [`PoseArray`].
#[derive(Debug, Clone, Copy, PartialEq, smart_default::SmartDefault)]
pub struct Pose {
    /// Position, m.
    #[default([0.0; 3])]
    pub position: [f64; 3],
    /// Orientation x y z w.
    #[default([0.0, 0.0, 0.0, 1.0])]
    pub orientation_xyzw: [f64; 4],
}

/// `geometry_msgs/msg/PoseArray`: e.g. a walking controller's planned footsteps.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PoseArray {
    /// Header (frame of the poses).
    pub header: Header,
    /// The poses.
    pub poses: Vec<Pose>,
}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MultiArrayDimension {
    /// Label.
    pub label: String,
    /// Size.
    pub size: u32,
    /// Stride.
    pub stride: u32,
}

/// `std_msgs/msg/Float64MultiArray`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Float64MultiArray {
    /// Layout dimensions.
    pub dim: Vec<MultiArrayDimension>,
    /// Layout data offset.
    pub data_offset: u32,
    /// The data.
    pub data: Vec<f64>,
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct TransformStamped {
    /// Header (frame: the parent).
    pub header: Header,
    /// Child frame.
    pub child_frame_id: String,
    /// `parent_from_child` translation, m.
    pub translation: [f64; 3],
    /// `parent_from_child` rotation, x y z w.
    pub rotation_xyzw: [f64; 4],
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `geometry_msgs/msg/Twist`: a velocity in free space, linear (m/s) and angular (rad/s); on
/// `/cmd_vel`, in the robot's heading frame (x forward, y left, z up: REP 103).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: [f64; 3],
    /// Angular velocity, rad/s.
    pub angular: [f64; 3],
}

/// `rosgraph_msgs/msg/Clock`: simulation time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Clock {
    /// `clock.sec * 1e9 + clock.nanosec`.
    pub clock_nanos: i64,
}

/// `std_msgs/msg/String` (e.g. `/robot_description`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosString {
    /// The text.
    pub data: String,
}

/// `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointTrajectoryPoint {
    /// Positions, rad (m), one per joint name (or empty).
    pub positions: Vec<f64>,
    /// Velocities (or empty).
    pub velocities: Vec<f64>,
    /// Accelerations (or empty).
    pub accelerations: Vec<f64>,
    /// Efforts (or empty).
    pub effort: Vec<f64>,
    /// `time_from_start`, ns.
    pub time_from_start_nanos: i64,
}

/// `trajectory_msgs/msg/JointTrajectory`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct JointTrajectory {
    /// Header (stamp 0: start now).
    pub header: Header,
    /// Joints the points refer to.
    pub joint_names: Vec<String>,
    /// Waypoints, in time order.
    pub points: Vec<JointTrajectoryPoint>,
}

/// A message type with a typed CDR encoding.
pub trait RosMessage: Sized {
    /// Full type name, `pkg/msg/Type`.
    const TYPE_NAME: &'static str;
    /// Appends the fields (after the encapsulation header).
    fn encode(&self, w: &mut CdrWriter);
    /// Reads the fields.
    ///
    /// # Errors
    /// A [`CdrError`] when the payload is too short or malformed.
    fn decode(r: &mut CdrReader) -> CdrResult<Self>;
}

fn header(r: &mut CdrReader) -> CdrResult<Header> {
    let sec = r.i32()?;
    let nanosec = r.u32()?;
    Ok(Header { stamp_nanos: i64::from(sec) * 1_000_000_000 + i64::from(nanosec), frame_id: r.string()?.to_string() })
}

fn vec3(r: &mut CdrReader) -> CdrResult<[f64; 3]> {
    r.f64_fixed::<3>()
}

fn quat(r: &mut CdrReader) -> CdrResult<[f64; 4]> {
    r.f64_fixed::<4>()
}

impl JointState {
    /// Decodes into `self`, reusing its allocations (the hot path of long logs).
    ///
    /// # Errors
    /// A [`CdrError`] when the payload is too short or malformed.
    pub fn decode_into(&mut self, r: &mut CdrReader) -> CdrResult<()> {
        let sec = r.i32()?;
        let nanosec = r.u32()?;
        self.header.stamp_nanos = i64::from(sec) * 1_000_000_000 + i64::from(nanosec);
        self.header.frame_id.clear();
        self.header.frame_id.push_str(r.string()?);
        let n = r.seq_len(5)?;
        self.name.truncate(n);
        for i in 0..n {
            let s = r.string()?;
            if i < self.name.len() {
                if self.name[i] != s {
                    self.name[i].clear();
                    self.name[i].push_str(s);
                }
            } else {
                self.name.push(s.to_string());
            }
        }
        r.f64_seq(&mut self.position)?;
        r.f64_seq(&mut self.velocity)?;
        r.f64_seq(&mut self.effort)?;
        Ok(())
    }

    /// From a generically decoded message (files whose JointState definition differs from the
    /// canonical one but has the same field names).
    pub fn from_value(v: &Value) -> Option<Self> {
        let stamp = |p: &str| v.get(p).and_then(Value::as_i64);
        let list = |p: &str| match v.get(p) {
            None => Some(Vec::new()),
            Some(x) => x.as_f64_vec(),
        };
        let names = match v.get("name")? {
            Value::Array(items) => items.iter().map(|n| n.as_str().map(str::to_string)).collect::<Option<Vec<_>>>()?,
            _ => return None,
        };
        Some(Self {
            header: Header {
                stamp_nanos: stamp("header.stamp.sec").unwrap_or(0) * 1_000_000_000
                    + stamp("header.stamp.nanosec").or_else(|| stamp("header.stamp.nsec")).unwrap_or(0),
                frame_id: v.get("header.frame_id").and_then(Value::as_str).unwrap_or_default().to_string(),
            },
            name: names,
            position: list("position")?,
            velocity: list("velocity")?,
            effort: list("effort")?,
        })
    }

    /// From a JSON-encoded JointState (Foxglove-style: `header.stamp.{sec,nsec|nanosec}`).
    pub fn from_json(v: &serde_json::Value) -> Option<Self> {
        let stamp = v.pointer("/header/stamp");
        let sec = stamp.and_then(|s| s.get("sec")).and_then(|x| x.as_i64());
        let nsec = stamp.and_then(|s| s.get("nanosec").or_else(|| s.get("nsec"))).and_then(|x| x.as_i64());
        let floats = |key: &str| -> Option<Vec<f64>> {
            match v.get(key) {
                None | Some(serde_json::Value::Null) => Some(Vec::new()),
                Some(serde_json::Value::Array(a)) => a
                    .iter()
                    // JSON has no NaN: writers emit null for it.
                    .map(|x| if x.is_null() { Some(f64::NAN) } else { x.as_f64() })
                    .collect(),
                Some(_) => None,
            }
        };
        Some(Self {
            header: Header {
                stamp_nanos: sec.unwrap_or(0) * 1_000_000_000 + nsec.unwrap_or(0),
                frame_id: v.pointer("/header/frame_id").and_then(|x| x.as_str()).unwrap_or_default().to_string(),
            },
            name: v
                .get("name")?
                .as_array()?
                .iter()
                .map(|n| n.as_str().map(str::to_string))
                .collect::<Option<Vec<_>>>()?,
            position: floats("position")?,
            velocity: floats("velocity")?,
            effort: floats("effort")?,
        })
    }
}

impl RosMessage for JointState {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/JointState";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.seq_len(self.name.len());
        for n in &self.name {
            w.string(n);
        }
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let mut js = JointState::default();
        js.decode_into(r)?;
        Ok(js)
    }
}

impl RosMessage for Imu {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Imu";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.f64_fixed(&self.orientation_xyzw);
        w.f64_fixed(&self.orientation_covariance);
        w.f64_fixed(&self.angular_velocity);
        w.f64_fixed(&self.angular_velocity_covariance);
        w.f64_fixed(&self.linear_acceleration);
        w.f64_fixed(&self.linear_acceleration_covariance);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self {
            header: header(r)?,
            orientation_xyzw: quat(r)?,
            orientation_covariance: r.f64_fixed()?,
            angular_velocity: vec3(r)?,
            angular_velocity_covariance: r.f64_fixed()?,
            linear_acceleration: vec3(r)?,
            linear_acceleration_covariance: r.f64_fixed()?,
        })
    }
}

impl RosMessage for Odometry {
    const TYPE_NAME: &'static str = "nav_msgs/msg/Odometry";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.string(&self.child_frame_id);
        w.f64_fixed(&self.position);
        w.f64_fixed(&self.orientation_xyzw);
        w.f64_fixed(&self.pose_covariance);
        w.f64_fixed(&self.linear_velocity);
        w.f64_fixed(&self.angular_velocity);
        w.f64_fixed(&self.twist_covariance);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self {
            header: header(r)?,
            child_frame_id: r.string()?.to_string(),
            position: vec3(r)?,
            orientation_xyzw: quat(r)?,
            pose_covariance: r.f64_fixed()?,
            linear_velocity: vec3(r)?,
            angular_velocity: vec3(r)?,
            twist_covariance: r.f64_fixed()?,
        })
    }
}

impl RosMessage for WrenchStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/WrenchStamped";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.f64_fixed(&self.force);
        w.f64_fixed(&self.torque);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self { header: header(r)?, force: vec3(r)?, torque: vec3(r)? })
    }
}

impl RosMessage for PointStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PointStamped";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.f64_fixed(&self.point);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self { header: header(r)?, point: vec3(r)? })
    }
}

impl RosMessage for PoseArray {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseArray";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.seq_len(self.poses.len());
        for p in &self.poses {
            w.f64_fixed(&p.position);
            w.f64_fixed(&p.orientation_xyzw);
        }
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let header = header(r)?;
        let n = r.seq_len(56)?;
        let mut poses = Vec::with_capacity(n);
        for _ in 0..n {
            poses.push(Pose { position: vec3(r)?, orientation_xyzw: quat(r)? });
        }
        Ok(Self { header, poses })
    }
}

impl RosMessage for Float64MultiArray {
    const TYPE_NAME: &'static str = "std_msgs/msg/Float64MultiArray";
    fn encode(&self, w: &mut CdrWriter) {
        w.seq_len(self.dim.len());
        for d in &self.dim {
            w.string(&d.label);
            w.u32(d.size);
            w.u32(d.stride);
        }
        w.u32(self.data_offset);
        w.f64_seq(&self.data);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let n = r.seq_len(12)?;
        let mut dim = Vec::with_capacity(n);
        for _ in 0..n {
            dim.push(MultiArrayDimension { label: r.string()?.to_string(), size: r.u32()?, stride: r.u32()? });
        }
        let data_offset = r.u32()?;
        let mut data = Vec::new();
        r.f64_seq(&mut data)?;
        Ok(Self { dim, data_offset, data })
    }
}

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    fn encode(&self, w: &mut CdrWriter) {
        w.seq_len(self.transforms.len());
        for t in &self.transforms {
            w.header(t.header.stamp_nanos, &t.header.frame_id);
            w.string(&t.child_frame_id);
            w.f64_fixed(&t.translation);
            w.f64_fixed(&t.rotation_xyzw);
        }
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let n = r.seq_len(80)?;
        let mut transforms = Vec::with_capacity(n);
        for _ in 0..n {
            transforms.push(TransformStamped {
                header: header(r)?,
                child_frame_id: r.string()?.to_string(),
                translation: vec3(r)?,
                rotation_xyzw: quat(r)?,
            });
        }
        Ok(Self { transforms })
    }
}

impl RosMessage for Twist {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Twist";
    fn encode(&self, w: &mut CdrWriter) {
        w.f64_fixed(&self.linear);
        w.f64_fixed(&self.angular);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self { linear: vec3(r)?, angular: vec3(r)? })
    }
}

impl RosMessage for Clock {
    const TYPE_NAME: &'static str = "rosgraph_msgs/msg/Clock";
    fn encode(&self, w: &mut CdrWriter) {
        w.time(self.clock_nanos);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let sec = r.i32()?;
        let nanosec = r.u32()?;
        Ok(Self { clock_nanos: i64::from(sec) * 1_000_000_000 + i64::from(nanosec) })
    }
}

impl RosMessage for RosString {
    const TYPE_NAME: &'static str = "std_msgs/msg/String";
    fn encode(&self, w: &mut CdrWriter) {
        w.string(&self.data);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self { data: r.string()?.to_string() })
    }
}

impl RosMessage for JointTrajectory {
    const TYPE_NAME: &'static str = "trajectory_msgs/msg/JointTrajectory";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.seq_len(self.joint_names.len());
        for n in &self.joint_names {
            w.string(n);
        }
        w.seq_len(self.points.len());
        for p in &self.points {
            w.f64_seq(&p.positions);
            w.f64_seq(&p.velocities);
            w.f64_seq(&p.accelerations);
            w.f64_seq(&p.effort);
            w.time(p.time_from_start_nanos);
        }
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let header = header(r)?;
        let n = r.seq_len(5)?;
        let mut joint_names = Vec::with_capacity(n);
        for _ in 0..n {
            joint_names.push(r.string()?.to_string());
        }
        let n = r.seq_len(24)?;
        let mut points = Vec::with_capacity(n);
        for _ in 0..n {
            let mut p = JointTrajectoryPoint::default();
            r.f64_seq(&mut p.positions)?;
            r.f64_seq(&mut p.velocities)?;
            r.f64_seq(&mut p.accelerations)?;
            r.f64_seq(&mut p.effort)?;
            let sec = r.i32()?;
            let nanosec = r.u32()?;
            p.time_from_start_nanos = i64::from(sec) * 1_000_000_000 + i64::from(nanosec);
            points.push(p);
        }
        Ok(Self { header, joint_names, points })
    }
}

/// `sensor_msgs/msg/Image`. A depth image (REP 118) is `32FC1`: metres along the optical
/// axis as little-endian f32, `step = 4 · width`, NaN where there is no return.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Image {
    /// Header (frame: the camera's optical frame).
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding, e.g. `32FC1`, `rgb8`.
    pub encoding: String,
    /// Whether multi-byte pixels are big endian.
    pub is_bigendian: bool,
    /// Bytes per row.
    pub step: u32,
    /// Pixels, row-major.
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RegionOfInterest {
    /// Leftmost column.
    pub x_offset: u32,
    /// Topmost row.
    pub y_offset: u32,
    /// Rows (0: the full image).
    pub height: u32,
    /// Columns (0: the full image).
    pub width: u32,
    /// Whether the region is to be rectified.
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`: a pinhole camera's calibration.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraInfo {
    /// Header (frame: the camera's optical frame).
    pub header: Header,
    /// Rows of the image.
    pub height: u32,
    /// Columns of the image.
    pub width: u32,
    /// Distortion model, e.g. `plumb_bob`.
    pub distortion_model: String,
    /// Distortion coefficients (plumb_bob: k1 k2 t1 t2 k3).
    pub d: Vec<f64>,
    /// Intrinsic camera matrix K, row-major.
    pub k: [f64; 9],
    /// Rectification rotation R, row-major.
    pub r: [f64; 9],
    /// Projection matrix P (3×4), row-major.
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// Region of interest.
    pub roi: RegionOfInterest,
}

/// `sensor_msgs/msg/PointField`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointField {
    /// Field name, e.g. `x`.
    pub name: String,
    /// Byte offset in a point.
    pub offset: u32,
    /// Type: [`PointField::FLOAT32`], …
    pub datatype: u8,
    /// Elements in the field.
    pub count: u32,
}

impl PointField {
    /// `datatype` of a 32-bit float.
    pub const FLOAT32: u8 = 7;
}

/// `sensor_msgs/msg/PointCloud2`. Organized clouds have `height` rows; `is_dense = false` when
/// some points are NaN.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud2 {
    /// Header (frame the points are in).
    pub header: Header,
    /// Rows (1: unorganized).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Layout of a point.
    pub fields: Vec<PointField>,
    /// Whether the data is big endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// The points.
    pub data: Vec<u8>,
    /// Whether no point is invalid (NaN).
    pub is_dense: bool,
}

/// `sensor_msgs/msg/LaserScan`: one ring of a planar laser, ranges in metres along each beam
/// (outside `[range_min, range_max]`: invalid; +Inf: no return within range, REP 117).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LaserScan {
    /// Header (frame: the laser; angles about its z axis, 0 along x).
    pub header: Header,
    /// Angle of the first beam, radians.
    pub angle_min: f32,
    /// Angle of the last beam, radians.
    pub angle_max: f32,
    /// Angle between beams, radians.
    pub angle_increment: f32,
    /// Time between beams, seconds.
    pub time_increment: f32,
    /// Time between scans, seconds.
    pub scan_time: f32,
    /// Nearest valid range, metres.
    pub range_min: f32,
    /// Farthest valid range, metres.
    pub range_max: f32,
    /// Range of each beam, metres.
    pub ranges: Vec<f32>,
    /// Intensity of each beam (may be empty).
    pub intensities: Vec<f32>,
}

impl RosMessage for Image {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Image";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.encoding);
        w.u8(u8::from(self.is_bigendian));
        w.u32(self.step);
        w.u8_seq(&self.data);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(Self {
            header: header(r)?,
            height: r.u32()?,
            width: r.u32()?,
            encoding: r.string()?.to_string(),
            is_bigendian: r.u8()? != 0,
            step: r.u32()?,
            data: r.bytes()?.to_vec(),
        })
    }
}

impl RosMessage for CameraInfo {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/CameraInfo";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.distortion_model);
        w.f64_seq(&self.d);
        w.f64_fixed(&self.k);
        w.f64_fixed(&self.r);
        w.f64_fixed(&self.p);
        w.u32(self.binning_x);
        w.u32(self.binning_y);
        w.u32(self.roi.x_offset);
        w.u32(self.roi.y_offset);
        w.u32(self.roi.height);
        w.u32(self.roi.width);
        w.u8(u8::from(self.roi.do_rectify));
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let header = header(r)?;
        let (height, width) = (r.u32()?, r.u32()?);
        let distortion_model = r.string()?.to_string();
        let mut d = Vec::new();
        r.f64_seq(&mut d)?;
        Ok(Self {
            header,
            height,
            width,
            distortion_model,
            d,
            k: r.f64_fixed()?,
            r: r.f64_fixed()?,
            p: r.f64_fixed()?,
            binning_x: r.u32()?,
            binning_y: r.u32()?,
            roi: RegionOfInterest {
                x_offset: r.u32()?,
                y_offset: r.u32()?,
                height: r.u32()?,
                width: r.u32()?,
                do_rectify: r.u8()? != 0,
            },
        })
    }
}

impl RosMessage for PointCloud2 {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/PointCloud2";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        w.u32(self.height);
        w.u32(self.width);
        w.seq_len(self.fields.len());
        for f in &self.fields {
            w.string(&f.name);
            w.u32(f.offset);
            w.u8(f.datatype);
            w.u32(f.count);
        }
        w.u8(u8::from(self.is_bigendian));
        w.u32(self.point_step);
        w.u32(self.row_step);
        w.u8_seq(&self.data);
        w.u8(u8::from(self.is_dense));
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let header = header(r)?;
        let (height, width) = (r.u32()?, r.u32()?);
        let n = r.seq_len(13)?;
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            fields.push(PointField {
                name: r.string()?.to_string(),
                offset: r.u32()?,
                datatype: r.u8()?,
                count: r.u32()?,
            });
        }
        Ok(Self {
            header,
            height,
            width,
            fields,
            is_bigendian: r.u8()? != 0,
            point_step: r.u32()?,
            row_step: r.u32()?,
            data: r.bytes()?.to_vec(),
            is_dense: r.u8()? != 0,
        })
    }
}

impl RosMessage for LaserScan {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/LaserScan";
    fn encode(&self, w: &mut CdrWriter) {
        w.header(self.header.stamp_nanos, &self.header.frame_id);
        for x in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(x);
        }
        w.f32_seq(&self.ranges);
        w.f32_seq(&self.intensities);
    }
    fn decode(r: &mut CdrReader) -> CdrResult<Self> {
        let header = header(r)?;
        let mut v = [0f32; 7];
        for x in &mut v {
            *x = r.f32()?;
        }
        let (mut ranges, mut intensities) = (Vec::new(), Vec::new());
        r.f32_seq(&mut ranges)?;
        r.f32_seq(&mut intensities)?;
        Ok(Self {
            header,
            angle_min: v[0],
            angle_max: v[1],
            angle_increment: v[2],
            time_increment: v[3],
            scan_time: v[4],
            range_min: v[5],
            range_max: v[6],
            ranges,
            intensities,
        })
    }
}

/// `.msg` bodies of the types above and their dependencies (`pkg/Type`, body).
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    ("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"),
    (
        "sensor_msgs/JointState",
        "std_msgs/Header header\n\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
         float64[] effort\n",
    ),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\n\ngeometry_msgs/Quaternion orientation\n\
         float64[9] orientation_covariance\n\ngeometry_msgs/Vector3 angular_velocity\n\
         float64[9] angular_velocity_covariance\n\ngeometry_msgs/Vector3 linear_acceleration\n\
         float64[9] linear_acceleration_covariance\n",
    ),
    ("geometry_msgs/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Pose", "Point position\nQuaternion orientation\n"),
    ("geometry_msgs/PoseWithCovariance", "Pose pose\nfloat64[36] covariance\n"),
    ("geometry_msgs/Twist", "Vector3  linear\nVector3  angular\n"),
    ("geometry_msgs/TwistWithCovariance", "Twist twist\nfloat64[36] covariance\n"),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\n\
         geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    ),
    ("geometry_msgs/Wrench", "Vector3  force\nVector3  torque\n"),
    ("geometry_msgs/WrenchStamped", "std_msgs/Header header\nWrench wrench\n"),
    ("geometry_msgs/PointStamped", "std_msgs/Header header\nPoint point\n"),
    ("geometry_msgs/PoseArray", "std_msgs/Header header\nPose[] poses\n"),
    ("std_msgs/MultiArrayDimension", "string label\nuint32 size\nuint32 stride\n"),
    ("std_msgs/MultiArrayLayout", "MultiArrayDimension[] dim\nuint32 data_offset\n"),
    ("std_msgs/Float64MultiArray", "MultiArrayLayout  layout\nfloat64[]         data\n"),
    ("geometry_msgs/Transform", "Vector3 translation\nQuaternion rotation\n"),
    ("geometry_msgs/TransformStamped", "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"),
    ("tf2_msgs/TFMessage", "geometry_msgs/TransformStamped[] transforms\n"),
    ("rosgraph_msgs/Clock", "builtin_interfaces/Time clock\n"),
    ("std_msgs/String", "string data\n"),
    ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
    (
        "trajectory_msgs/JointTrajectoryPoint",
        "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\nfloat64[] effort\n\
         builtin_interfaces/Duration time_from_start\n",
    ),
    (
        "trajectory_msgs/JointTrajectory",
        "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points\n",
    ),
    (
        "sensor_msgs/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
         uint32 step\nuint8[] data\n",
    ),
    (
        "sensor_msgs/RegionOfInterest",
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n",
    ),
    (
        "sensor_msgs/CameraInfo",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n\
         float64[9]  k\nfloat64[9]  r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n\
         RegionOfInterest roi\n",
    ),
    (
        "sensor_msgs/PointField",
        "uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\nuint8 INT32   = 5\n\
         uint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\nstring name\nuint32 offset\n\
         uint8  datatype\nuint32 count\n",
    ),
    (
        "sensor_msgs/PointCloud2",
        "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\nbool    is_bigendian\n\
         uint32  point_step\nuint32  row_step\nuint8[] data\nbool is_dense\n",
    ),
    (
        "sensor_msgs/LaserScan",
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
         float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
         float32[] ranges\nfloat32[] intensities\n",
    ),
];

fn body_of(short: &str) -> Option<&'static str> {
    DEFINITIONS.iter().find(|(n, _)| *n == short).map(|(_, b)| *b)
}

fn dependencies(short: &str, out: &mut Vec<&'static str>) {
    let package = short.split('/').next().unwrap_or_default();
    let Some(body) = body_of(short) else { return };
    for line in body.lines() {
        let Some(ty) = line.split_whitespace().next() else {
            continue;
        };
        let base = ty.split('[').next().unwrap_or(ty);
        let full = if base.contains('/') { base.to_string() } else { format!("{package}/{base}") };
        if let Some(&(name, _)) = DEFINITIONS.iter().find(|(n, _)| *n == full)
            && !out.contains(&name)
        {
            out.push(name);
            dependencies(name, out);
        }
    }
}

/// The `ros2msg` schema text of one of the types above, as ROS 2 writes it: the type's body,
/// then each dependency (depth first, once) after a line of 80 `=` and a `MSG: pkg/Type` line.
pub fn schema_text(type_name: &str) -> Option<String> {
    let short = type_name.replace("/msg/", "/");
    let mut text = body_of(&short)?.to_string();
    let mut deps = Vec::new();
    dependencies(&short, &mut deps);
    for d in deps {
        text.push_str(&"=".repeat(80));
        text.push_str("\nMSG: ");
        text.push_str(d);
        text.push('\n');
        text.push_str(body_of(d).unwrap_or_default());
    }
    Some(text)
}

/// The canonical layout of a type (see [`MsgDefs::layout`]), to compare with a file's schema.
pub fn canonical_layout(type_name: &str) -> Option<String> {
    let text = schema_text(type_name)?;
    MsgDefs::parse(type_name, &text).ok().map(|d| d.layout())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip<T: RosMessage + PartialEq + std::fmt::Debug>(m: &T) {
        let mut w = CdrWriter::new();
        m.encode(&mut w);
        let mut r = CdrReader::new(w.bytes()).unwrap();
        assert_eq!(&T::decode(&mut r).unwrap(), m);
        assert_eq!(r.remaining(), 0);
        // The generic decoder reads the same bytes to the end with the schema text.
        let defs = MsgDefs::parse(T::TYPE_NAME, &schema_text(T::TYPE_NAME).unwrap()).unwrap();
        super::super::cdr::decode(&defs, w.bytes()).unwrap();
    }

    #[test]
    fn typed_messages_roundtrip_and_match_their_schemas() {
        let h = Header { stamp_nanos: 12_345_678_901, frame_id: "base".into() };
        roundtrip(&JointState {
            header: h.clone(),
            name: vec!["a".into(), "bb".into(), "ccc".into()],
            position: vec![0.1, -0.2, 0.3],
            velocity: vec![],
            effort: vec![1.0, 2.0, 3.0],
        });
        roundtrip(&Imu {
            header: h.clone(),
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            angular_velocity: [0.1, 0.2, 0.3],
            linear_acceleration: [0.0, 0.0, 9.81],
            ..Default::default()
        });
        roundtrip(&Odometry {
            header: h.clone(),
            child_frame_id: "pelvis".into(),
            position: [1.0, 2.0, 0.71],
            ..Default::default()
        });
        roundtrip(&WrenchStamped { header: h.clone(), force: [1.0, 2.0, 3.0], torque: [4.0, 5.0, 6.0] });
        roundtrip(&PointStamped { header: h.clone(), point: [0.1, -0.2, 0.8] });
        roundtrip(&PoseArray {
            header: h.clone(),
            poses: vec![Pose::default(), Pose { position: [0.3, -0.1, 0.0], orientation_xyzw: [0.0, 0.0, 0.6, 0.8] }],
        });
        roundtrip(&Float64MultiArray {
            dim: vec![MultiArrayDimension { label: "joints".into(), size: 2, stride: 2 }],
            data_offset: 0,
            data: vec![0.5, -0.5],
        });
        roundtrip(&Clock { clock_nanos: 3_000_000_001 });
        roundtrip(&RosString { data: "<robot name=\"r\"/>".into() });
        roundtrip(&JointTrajectory {
            header: h.clone(),
            joint_names: vec!["a".into(), "b".into()],
            points: vec![JointTrajectoryPoint {
                positions: vec![0.1, 0.2],
                time_from_start_nanos: 500_000_000,
                ..Default::default()
            }],
        });
        roundtrip(&TfMessage {
            transforms: vec![TransformStamped {
                header: h,
                child_frame_id: "pelvis".into(),
                translation: [0.0, 0.0, 0.71],
                rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
            }],
        });
    }

    #[test]
    fn sensor_messages_roundtrip_and_match_their_schemas() {
        let h = Header { stamp_nanos: 66_666_667, frame_id: "head_optical_frame".into() };
        let depth = [1.0f32, f32::NAN, 0.5, 2.25];
        roundtrip(&Image {
            header: h.clone(),
            height: 2,
            width: 2,
            encoding: "32FC1".into(),
            is_bigendian: false,
            step: 8,
            data: depth.iter().flat_map(|x| x.to_le_bytes()).collect(),
        });
        roundtrip(&CameraInfo {
            header: h.clone(),
            height: 240,
            width: 320,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [277.0, 0.0, 159.5, 0.0, 277.0, 119.5, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [277.0, 0.0, 159.5, 0.0, 0.0, 277.0, 119.5, 0.0, 0.0, 0.0, 1.0, 0.0],
            ..Default::default()
        });
        let field =
            |name: &str, offset| PointField { name: name.into(), offset, datatype: PointField::FLOAT32, count: 1 };
        roundtrip(&PointCloud2 {
            header: h.clone(),
            height: 1,
            width: 2,
            fields: vec![field("x", 0), field("y", 4), field("z", 8)],
            is_bigendian: false,
            point_step: 12,
            row_step: 24,
            data: [0.1f32, 0.2, 1.0, f32::NAN, f32::NAN, f32::NAN].iter().flat_map(|x| x.to_le_bytes()).collect(),
            is_dense: false,
        });
        roundtrip(&LaserScan {
            header: h,
            angle_min: -1.5,
            angle_max: 1.5,
            angle_increment: 0.01,
            scan_time: 0.1,
            range_min: 0.1,
            range_max: 30.0,
            ranges: vec![1.0, f32::INFINITY, 2.5],
            ..Default::default()
        });
    }

    #[test]
    fn joint_state_bytes_match_ros2() {
        // Known CDR of JointState{stamp 1.5 s, frame "", name ["j"], position [1.0]}.
        let js = JointState {
            header: Header { stamp_nanos: 1_500_000_000, frame_id: String::new() },
            name: vec!["j".into()],
            position: vec![1.0],
            velocity: vec![],
            effort: vec![],
        };
        let mut w = CdrWriter::new();
        js.encode(&mut w);
        let expected: Vec<u8> = [
            &[0u8, 1, 0, 0][..],
            &1i32.to_le_bytes(),
            &500_000_000u32.to_le_bytes(),
            &1u32.to_le_bytes(),
            &[0, 0, 0, 0], // "" = len 1 + NUL, padded
            &1u32.to_le_bytes(),
            &2u32.to_le_bytes(),
            b"j\0",
            &[0, 0],
            &1u32.to_le_bytes(), // payload offset 28..32: f64 at 32 needs no padding
            &1.0f64.to_le_bytes(),
            &0u32.to_le_bytes(),
            &0u32.to_le_bytes(),
        ]
        .concat();
        assert_eq!(w.bytes(), &expected[..]);
    }

    #[test]
    fn schema_text_lists_dependencies_once() {
        let t = schema_text("nav_msgs/msg/Odometry").unwrap();
        assert_eq!(t.matches("MSG: geometry_msgs/Vector3").count(), 1);
        assert!(t.contains("MSG: builtin_interfaces/Time"));
        MsgDefs::parse("nav_msgs/msg/Odometry", &t).unwrap();
    }
}
