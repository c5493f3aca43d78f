//! Perception of the grasping controller: one call, [`Eye::look`], that turns the simulation as
//! the robot's depth camera sees it into a cup estimate.

use crate::error::{Error, Result};
use crate::mj::{Data, Model, ObjType};
use nalgebra::Vector3;

/// Where the cup is, as perceived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CupSighting {
    /// Centre of the cup's axis at mid-height, world, m.
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

/// The robot's eye: its depth camera and the cup detector.
#[derive(Debug, Clone)]
pub struct Eye {
    camera: usize,
    cup_body: Option<usize>,
}

impl Eye {
    /// The eye of `model` looking through camera `camera`.
    ///
    /// # Errors
    /// [`Error::Grasp`] when the model has no such camera.
    pub fn new(model: &Model, camera: &str) -> Result<Eye> {
        let cam = model.id(ObjType::Camera, camera).ok_or_else(|| Error::Grasp {
            message: format!(
                "the model has no camera \"{camera}\": give the robot a Gazebo depth sensor (as \
                 models/humanoid_gripper.urdf's head_depth) or name its camera in [grasp] camera"
            ),
        })?;
        // STAND-IN until twin_core::sense lands (REMOVE): reads the cup body's pose.
        let cup_body = model.id(ObjType::Body, "cup");
        Ok(Eye { camera: cam, cup_body })
    }

    /// One look at the scene in `data` (positions current): the cup, or why not.
    ///
    /// # Errors
    /// [`Error::Grasp`] when no cup is seen.
    pub fn look(&mut self, model: &Model, data: &Data) -> Result<CupSighting> {
        let _ = self.camera;
        // STAND-IN until twin_core::sense lands (REMOVE).
        let body = self.cup_body.ok_or_else(|| Error::Grasp { message: "no cup in view".into() })?;
        let g = (0..model.ngeom())
            .find(|&g| model.geom_bodyid()[g] as usize == body)
            .ok_or_else(|| Error::Grasp { message: "no cup in view".into() })?;
        let size = model.geom_size()[g];
        let c = Vector3::from(data.geom_xpos()[g]);
        Ok(CupSighting {
            centre_world: c,
            radius_m: size[0],
            height_m: 2.0 * size[1],
            table_height_m: c.z - size[1],
            n_points: 0,
        })
    }
}
