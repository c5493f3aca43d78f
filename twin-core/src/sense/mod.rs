//! Sensing: by ray casting, without OpenGL, depth cameras ([`depth`]) and scanning range finders
//! ([`lidar`]); by MuJoCo's renderer, colour and segmentation cameras ([`camera`]); all as a
//! robot's file describes them with their topics ([`rig`]); and finding a cup on a table in
//! their point clouds ([`cup`]).

pub mod camera;
pub mod cup;
pub mod depth;
mod fan;
pub mod lidar;
pub mod rig;

pub use camera::{ColourCamera, ColourCameraOptions, ColourFrame, Distortion, Labels};
pub use cup::{CupDetectOptions, CupEstimate, detect_cup};
pub use depth::{DepthCamera, DepthCameraOptions, DepthFrame, Intrinsics};
pub use fan::RayOptions;
pub use lidar::{Lidar, LidarOptions, LidarScan, ScanAxis};
pub use rig::{
    Device, Pipelined, RaySensor, RaySensorKind, Reading, SensorMessage, SensorStream, ray_sensors, unrendered_cameras,
};

use crate::log::{Header, PointCloud2, PointField};

/// An organized `sensor_msgs/PointCloud2` of `rows × cols` points with float32 fields x, y, z
/// (12 bytes a point, little endian); `is_dense` when no point is NaN.
pub(crate) fn xyz_cloud(header: Header, rows: u32, cols: u32, xyz: &[[f32; 3]]) -> PointCloud2 {
    let field = |name: &str, offset| PointField { name: name.into(), offset, datatype: PointField::FLOAT32, count: 1 };
    let mut data = Vec::with_capacity(xyz.len() * 12);
    for p in xyz {
        for c in p {
            data.extend_from_slice(&c.to_le_bytes());
        }
    }
    PointCloud2 {
        header,
        height: rows,
        width: cols,
        fields: vec![field("x", 0), field("y", 4), field("z", 8)],
        is_bigendian: false,
        point_step: 12,
        row_step: 12 * cols,
        data,
        is_dense: xyz.iter().all(|p| p.iter().all(|c| c.is_finite())),
    }
}
