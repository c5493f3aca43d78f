//! Perception of the grasping controller: one call, [`Eye::look`], that turns the simulation as
//! the robot's depth camera sees it into a cup estimate.

use nalgebra::Vector3;
use twin_core::error::{Error, Result};
use twin_core::mj::{Data, Model, ObjType, RayFilter};
use twin_core::sense::{CupDetectOptions, DepthCamera, DepthCameraOptions, RayOptions, detect_cup};

/// Where the cup is, as perceived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CupSighting {
    /// Centre of the cup's axis at mid-height above the table, world, m.
    pub centre_world: Vector3<f64>,
    /// Radius, m.
    pub radius_m: f64,
    /// Height, m.
    pub height_m: f64,
    /// Height of the table top it stands on, world z, m.
    pub table_height_m: f64,
    /// Depth points on the cup.
    pub n_points: usize,
}

impl CupSighting {
    /// The mean of several sightings (`None` for none).
    pub fn mean(sightings: &[CupSighting]) -> Option<CupSighting> {
        let n = sightings.len();
        if n == 0 {
            return None;
        }
        let k = n as f64;
        Some(CupSighting {
            centre_world: sightings.iter().map(|s| s.centre_world).sum::<Vector3<f64>>() / k,
            radius_m: sightings.iter().map(|s| s.radius_m).sum::<f64>() / k,
            height_m: sightings.iter().map(|s| s.height_m).sum::<f64>() / k,
            table_height_m: sightings.iter().map(|s| s.table_height_m).sum::<f64>() / k,
            n_points: sightings.iter().map(|s| s.n_points).sum::<usize>() / n,
        })
    }
}

/// The robot's eye: its depth camera ([`twin_core::sense::DepthCamera`], ray cast) and the cup
/// detector ([`twin_core::sense::detect_cup`]): the cup is found in the depth image's point cloud
/// alone, never read from the model.
pub struct Eye {
    camera: DepthCamera,
    detect: CupDetectOptions,
}

impl std::fmt::Debug for Eye {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Eye").field("camera", &self.camera).finish()
    }
}

impl Eye {
    /// The eye of `model` looking through camera `camera` with depth noise `noise_std_m`
    /// (seeded by `seed`).
    ///
    /// # Errors
    /// [`Error::Grasp`] when the model has no such camera; as [`DepthCamera::new`].
    pub fn new(model: &Model, camera: &str, noise_std_m: f64, seed: u64) -> Result<Eye> {
        let Some(cam) = model.id(ObjType::Camera, camera) else {
            return Err(Error::Grasp {
                message: format!(
                    "the model has no camera \"{camera}\": give the robot a Gazebo depth sensor (as \
                     models/humanoid_gripper.urdf's head_depth) or name its camera in [grasp] camera"
                ),
            });
        };
        // The camera's own housing and the head it sits on are not in view.
        let body = model.cam_bodyid()[cam] as usize;
        let filter =
            RayFilter { exclude_bodies: vec![body, model.body_parentid()[body] as usize], ..Default::default() };
        // One thread: randomized batches already run one episode per core.
        let defaults = DepthCameraOptions::default();
        let ray = RayOptions { noise_std_m, seed, threads: 1, max_range_m: 3.0, filter, ..defaults.ray };
        let options = DepthCameraOptions { ray, ..defaults };
        Ok(Eye { camera: DepthCamera::new(model, camera, options)?, detect: CupDetectOptions::default() })
    }

    /// One depth frame of the scene in `data` (positions current) and the cup in it.
    ///
    /// # Errors
    /// As [`DepthCamera::render`] and [`detect_cup`] (no table or cup in view).
    pub fn look(&mut self, model: &Model, data: &Data) -> Result<CupSighting> {
        let frame = self.camera.render(model, data)?;
        let cup = detect_cup(&frame.points_world(), &self.detect)?;
        Ok(CupSighting {
            centre_world: cup.centre_world.coords,
            radius_m: cup.radius_m,
            height_m: cup.height_m,
            table_height_m: cup.table_height_m,
            n_points: cup.n_points,
        })
    }
}
