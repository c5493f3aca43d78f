//! A scanning range finder (Gazebo `ray`/`gpu_ray`/`lidar`) by ray casting
//! ([`crate::mj::RayScene`], the ray setup shared with [`super::depth`]): every beam of its scan pattern at full resolution, cast in
//! parallel on scan ticks only, with its range limits and Gaussian range noise.
//!
//! Beams follow Gazebo's convention in the sensor frame (x forward, z up): horizontal angle
//! `h` about z from x, vertical angle `v` up from the x–y plane, direction
//! `(cos v cos h, cos v sin h, sin v)`. Ranges are along the beam. As in Gazebo, a beam starts
//! at the minimum range (`<range><min>`, the near clip): geometry nearer than that is not seen
//! and the beam measures what lies behind it, so a scanner inside its own housing sees out of
//! it. REP 117: `+Inf` for no return within range; `−Inf` (a return nearer than the minimum)
//! then never occurs.

use super::fan::{RayFan, RayOptions, noise_rng};
use crate::error::{Error, Result};
use crate::log::{Header, LaserScan, PointCloud2};
use crate::mj::{Data, Model, ObjType, RayStats};
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

/// Beam angles of a scan: `samples` evenly from `min_rad` to `max_rad` (both included).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanAxis {
    /// Beams along this axis (≥ 1).
    pub samples: usize,
    /// First angle, radians.
    pub min_rad: f64,
    /// Last angle, radians.
    pub max_rad: f64,
}

impl ScanAxis {
    /// Angle of beam `i`.
    pub fn angle(&self, i: usize) -> f64 {
        if self.samples <= 1 {
            self.min_rad
        } else {
            self.min_rad + (self.max_rad - self.min_rad) * i as f64 / (self.samples - 1) as f64
        }
    }

    /// Angle between neighbouring beams (0 for one beam).
    pub fn increment(&self) -> f64 {
        if self.samples <= 1 { 0.0 } else { (self.max_rad - self.min_rad) / (self.samples - 1) as f64 }
    }
}

/// How a [`Lidar`] scans.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct LidarOptions {
    /// Horizontal beams. (default: 360 from −π to π·359/180, one per degree)
    #[default(ScanAxis { samples: 360, min_rad: -std::f64::consts::PI, max_rad: std::f64::consts::PI * 179.0 / 180.0, })]
    pub horizontal: ScanAxis,
    /// Vertical beams (rings); one ring is a planar scan. (default: one ring at 0)
    #[default(ScanAxis { samples: 1, min_rad: 0.0, max_rad: 0.0 })]
    pub vertical: ScanAxis,
    /// Range limits, noise, rate, threads and the geoms the beams see. (default:
    /// [`RayOptions::default`])
    pub ray: RayOptions,
}

/// One scan.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarScan {
    /// Simulation time of the state it shows, ns.
    pub stamp_nanos: u64,
    /// Horizontal beams.
    pub horizontal: ScanAxis,
    /// Vertical beams (rings).
    pub vertical: ScanAxis,
    /// Range of each beam, ring-major (`ring · horizontal.samples + i`), metres along the
    /// beam; `+Inf` no return (REP 117; nothing nearer than the minimum range is seen).
    pub ranges_m: Vec<f32>,
    /// Nearest range measured, metres.
    pub min_range_m: f64,
    /// Farthest range measured, metres.
    pub max_range_m: f64,
    /// Pose of the sensor frame in the world.
    pub world_from_sensor: Isometry3<f64>,
    /// The sensor frame's name.
    pub frame_id: String,
}

/// Unit direction of the beam at horizontal angle `h` and vertical angle `v`, sensor frame.
pub fn beam_direction(h: f64, v: f64) -> Vector3<f64> {
    Vector3::new(v.cos() * h.cos(), v.cos() * h.sin(), v.sin())
}

impl LidarScan {
    /// The returns as points in the sensor frame, ring-major; `None` where there is none.
    pub fn points_sensor(&self) -> Vec<Option<Point3<f64>>> {
        let n = self.horizontal.samples;
        self.ranges_m
            .iter()
            .enumerate()
            .map(|(k, &r)| {
                r.is_finite().then(|| {
                    let d = beam_direction(self.horizontal.angle(k % n), self.vertical.angle(k / n));
                    Point3::from(d * f64::from(r))
                })
            })
            .collect()
    }

    /// Ring `ring` as a `sensor_msgs/LaserScan` stamped with the scan's time; `scan_time` is
    /// the period of the sensor's rate.
    pub fn laser_scan(&self, ring: usize, scan_time_secs: f64) -> LaserScan {
        let n = self.horizontal.samples;
        LaserScan {
            header: Header { stamp_nanos: self.stamp_nanos as i64, frame_id: self.frame_id.clone() },
            angle_min: self.horizontal.min_rad as f32,
            angle_max: self.horizontal.max_rad as f32,
            angle_increment: self.horizontal.increment() as f32,
            time_increment: 0.0,
            scan_time: scan_time_secs as f32,
            range_min: self.min_range_m as f32,
            range_max: self.max_range_m as f32,
            ranges: self.ranges_m[ring * n..(ring + 1) * n].to_vec(),
            intensities: Vec::new(),
        }
    }

    /// The scan as an organized `sensor_msgs/PointCloud2` in the sensor frame: one row per
    /// ring, NaN points where there is no return.
    pub fn point_cloud(&self) -> PointCloud2 {
        let xyz: Vec<[f32; 3]> = self
            .points_sensor()
            .iter()
            .map(|p| p.map_or([f32::NAN; 3], |p| [p.x as f32, p.y as f32, p.z as f32]))
            .collect();
        super::xyz_cloud(
            Header { stamp_nanos: self.stamp_nanos as i64, frame_id: self.frame_id.clone() },
            self.vertical.samples as u32,
            self.horizontal.samples as u32,
            &xyz,
        )
    }
}

/// Rays per bundle culled together: a stretch of one ring.
const BUNDLE: usize = 32;

/// A scanning range finder at a MuJoCo site (its frame is the sensor frame).
#[derive(Debug)]
pub struct Lidar {
    site: usize,
    options: LidarOptions,
    frame_id: String,
    /// The beams (unit, sensor frame), ring-major.
    fan: RayFan,
    scans: u64,
}

impl Lidar {
    /// A scanner at site `site_name` of `model` (the converter makes one per Gazebo
    /// `ray`/`gpu_ray`/`lidar` sensor, named after it).
    ///
    /// # Errors
    /// [`Error::NotFound`] without such a site; [`Error::OutOfRange`] for no beams or a range
    /// that is not 0 ≤ min < max; [`Error::Options`] when the thread pool can't be built.
    pub fn new(model: &Model, site_name: &str, options: LidarOptions) -> Result<Lidar> {
        let site = model.require_id(ObjType::Site, site_name)?;
        let what = || format!("LiDAR \"{site_name}\"");
        if options.horizontal.samples == 0 || options.vertical.samples == 0 {
            return Err(Error::OutOfRange {
                what: what(),
                message: format!(
                    "{} × {} beams: give at least one sample per axis",
                    options.horizontal.samples, options.vertical.samples
                ),
            });
        }
        options.ray.check(&what())?;
        let mut dirs_sensor = Vec::with_capacity(options.horizontal.samples * options.vertical.samples);
        for v in 0..options.vertical.samples {
            for h in 0..options.horizontal.samples {
                dirs_sensor.push(beam_direction(options.horizontal.angle(h), options.vertical.angle(v)));
            }
        }
        let fan = RayFan::new(dirs_sensor, BUNDLE, options.ray.threads, &what())?;
        Ok(Lidar { site, frame_id: site_name.to_string(), options, fan, scans: 0 })
    }

    /// Sets the `frame_id` of the scans (default: the site's name).
    pub fn with_frame_id(mut self, frame_id: impl Into<String>) -> Lidar {
        self.frame_id = frame_id.into();
        self
    }

    /// The options it was made with.
    pub fn options(&self) -> &LidarOptions {
        &self.options
    }

    /// What the last [`Lidar::scan`] cost in ray–geom tests.
    pub fn last_ray_stats(&self) -> RayStats {
        self.fan.last_stats()
    }

    /// Scans the state of `data` (its last forward pass), stamped with its time.
    ///
    /// # Errors
    /// [`Error::Size`] when `data`'s model has fewer sites than the one the scanner was made
    /// for.
    pub fn scan(&mut self, data: &Data) -> Result<LidarScan> {
        if self.site >= data.model().nsite() {
            return Err(Error::Size {
                what: "sites of the data's model",
                expected: self.site + 1,
                got: data.model().nsite(),
            });
        }
        let p = data.site_xpos()[self.site];
        let m = data.site_xmat()[self.site];
        let rot = Rotation3::from_matrix_unchecked(Matrix3::from_row_slice(&m));
        let world_from_sensor =
            Isometry3::from_parts(Translation3::new(p[0], p[1], p[2]), UnitQuaternion::from_rotation_matrix(&rot));
        let (lo, hi) = (self.options.ray.min_range_m, self.options.ray.max_range_m);
        // Beams start at the minimum range (Gazebo's near clip): what is nearer is not seen.
        let hits = self.fan.cast(data, &self.options.ray.filter, p, &rot, hi, &[lo])?;
        let mut rng = noise_rng(self.options.ray.seed, self.scans);
        let noise = self.options.ray.noise_std_m;
        let ranges_m = hits
            .iter()
            .map(|h| match h {
                None => f32::INFINITY,
                Some(h) if h.dist_m > hi => f32::INFINITY,
                Some(h) if noise > 0.0 => (h.dist_m + noise * rng.sample::<f64, _>(StandardNormal)) as f32,
                Some(h) => h.dist_m as f32,
            })
            .collect();
        self.scans += 1;
        Ok(LidarScan {
            stamp_nanos: (data.time_secs() * 1e9).round().max(0.0) as u64,
            horizontal: self.options.horizontal,
            vertical: self.options.vertical,
            ranges_m,
            min_range_m: lo,
            max_range_m: hi,
            world_from_sensor,
            frame_id: self.frame_id.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mj::RayFilter;
    use std::sync::Arc;

    /// A wall (a box face) 2 m in front of a scanner whose site is yawed 30° and lifted.
    const WALL: &str = r#"<mujoco><worldbody>
        <geom type="box" pos="2.05 0 1" size="0.05 5 3"/>
        <body name="robot" pos="0 0 1"><geom type="sphere" size="0.1"/>
          <site name="laser" euler="0 0 0"/></body></worldbody></mujoco>"#;

    #[test]
    fn wall_ranges_are_analytic() {
        let model = Arc::new(Model::from_xml_str(WALL).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        data.forward().unwrap();
        let robot = model.id(ObjType::Body, "robot").unwrap();
        let opts = LidarOptions {
            horizontal: ScanAxis { samples: 721, min_rad: -1.1, max_rad: 1.1 },
            vertical: ScanAxis { samples: 16, min_rad: -0.26, max_rad: 0.26 },
            ray: RayOptions {
                max_range_m: 30.0,
                filter: RayFilter { exclude_bodies: vec![robot], ..RayFilter::default() },
                ..RayOptions::default()
            },
        };
        let mut lidar = Lidar::new(&model, "laser", opts.clone()).unwrap();
        let scan = lidar.scan(&data).unwrap();
        assert_eq!(scan.ranges_m.len(), 721 * 16);
        let mut worst = 0.0f64;
        for v in 0..16 {
            for h in 0..721 {
                let (ha, va) = (opts.horizontal.angle(h), opts.vertical.angle(v));
                // The wall's face is the plane x = 2: range = 2 / (cos h cos v).
                let expected = 2.0 / (ha.cos() * va.cos());
                let got = f64::from(scan.ranges_m[v * 721 + h]);
                worst = worst.max((got - expected).abs());
            }
        }
        assert!(worst < 1e-3, "worst range error {worst} m");
        // One ring as a LaserScan, the whole scan as an organized cloud on the wall.
        let ring = scan.laser_scan(8, 0.1);
        assert_eq!(ring.ranges.len(), 721);
        assert!((f64::from(ring.angle_increment) - 2.2 / 720.0).abs() < 1e-7);
        let cloud = scan.point_cloud();
        assert_eq!((cloud.height, cloud.width, cloud.row_step), (16, 721, 721 * 12));
        let x0 = f32::from_le_bytes(cloud.data[0..4].try_into().unwrap());
        assert!((x0 - 2.0).abs() < 1e-4, "{x0}");
        // Beyond the maximum range: +Inf; the noise is seeded and about the asked size.
        let short = Lidar::new(
            &model,
            "laser",
            LidarOptions { ray: RayOptions { max_range_m: 2.1, ..opts.ray.clone() }, ..opts.clone() },
        )
        .unwrap()
        .scan(&data)
        .unwrap();
        assert!(short.ranges_m[0].is_infinite() && short.ranges_m[0] > 0.0);
        assert!((f64::from(short.ranges_m[8 * 721 + 360]) - 2.0 / opts.vertical.angle(8).cos()).abs() < 1e-6);
        let noisy = Lidar::new(
            &model,
            "laser",
            LidarOptions {
                ray: RayOptions { noise_std_m: 0.01, seed: 3, threads: 1, ..opts.ray.clone() },
                ..opts.clone()
            },
        )
        .unwrap()
        .scan(&data)
        .unwrap();
        let d: Vec<f64> = noisy.ranges_m.iter().zip(&scan.ranges_m).map(|(a, b)| f64::from(a - b)).collect();
        let std = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        assert!((std - 0.01).abs() < 0.0005, "noise std {std}");
    }

    /// Gazebo's beams start at the minimum range: a scanner inside its own housing (the robot's
    /// 0.1 m sphere, not excluded here) sees the wall behind it when the minimum range is
    /// beyond the housing, and sees the housing's inside (never `−Inf`) when it is not.
    #[test]
    fn beams_start_at_the_minimum_range() {
        let model = Arc::new(Model::from_xml_str(WALL).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        data.forward().unwrap();
        let opts = |min_range_m| LidarOptions {
            horizontal: ScanAxis { samples: 181, min_rad: -0.9, max_rad: 0.9 },
            ray: RayOptions { min_range_m, max_range_m: 30.0, ..RayOptions::default() },
            ..LidarOptions::default()
        };
        let scan = Lidar::new(&model, "laser", opts(0.15)).unwrap().scan(&data).unwrap();
        for (i, &r) in scan.ranges_m.iter().enumerate() {
            let expected = 2.0 / scan.horizontal.angle(i).cos();
            assert!((f64::from(r) - expected).abs() < 1e-4, "beam {i}: {r} m, expected {expected} m");
        }
        let inside = Lidar::new(&model, "laser", opts(0.05)).unwrap().scan(&data).unwrap();
        assert!(inside.ranges_m.iter().all(|&r| (r - 0.1).abs() < 1e-4), "{:?}", &inside.ranges_m[..4]);
    }
}
