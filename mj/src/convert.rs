//! The URDF → MJCF converter ([`twin_convert`]) with MuJoCo as its compiler, and the one place
//! in twin that turns a robot file into a compiled [`Model`].
//!
//! Data flows one way: a file's text → [`twin_convert`] (URDF only: parse, check, emit MJCF;
//! its two compiles, placing the robot on the floor and finding its home pose, run here by
//! [`MuJoCo`]) → [`Model::from_xml_str`]. An MJCF goes straight to MuJoCo's own parser. The
//! converter knows nothing of MuJoCo's API and the rest of this crate nothing of URDF.
//!
//! ```no_run
//! use twin_mj::convert::{convert_urdf, ConvertOptions};
//! let out = convert_urdf("models/humanoid.urdf".as_ref(), &ConvertOptions::default())?;
//! println!("{} IMUs, topic {:?}", out.meta.imus.len(), out.meta.imus[0].topic);
//! let model = twin_mj::Model::from_xml_str(&out.mjcf)?;
//! # Ok::<(), twin_mj::Error>(())
//! ```

pub use twin_convert::{
    ActuatorMode, Compile, Compiler, ConvertOptions, ConvertedModel, DifferentialMeta, ImuBias, ImuMeta, Interface,
    JointMeta, MAX_XML_DEPTH, Probe, RobotMeta, ScanMeta, SensorMeta, actuator, mesh, urdf,
};

use crate::error::{Error, Result};
use crate::{Data, GeomType, JointType, Model, ObjType, Transmission};
use nalgebra::{Matrix3, Vector3};
use std::path::Path;
use std::sync::Arc;

/// MuJoCo as the converter's [`Compiler`]: compiles each generated MJCF from its text.
#[derive(Debug, Default)]
pub struct MuJoCo;

impl Compiler for MuJoCo {
    type Error = Error;

    fn probe(
        &mut self,
        mjcf: &str,
        bodies: &[&str],
        pose: &[(String, f64)],
    ) -> std::result::Result<Probe, Compile<Error>> {
        let model = compile(mjcf)?;
        let geoms = collision_geoms(&model, pose).map_err(Compile::Other)?;
        let ids: Vec<Option<usize>> = bodies.iter().map(|b| model.id(ObjType::Body, b)).collect();
        Ok(Probe {
            lowest_collision_z_m: geoms.iter().map(|g| g.1[4]).reduce(f64::min),
            body_lowest_z_m: ids
                .iter()
                .map(|id| id.and_then(|b| geoms.iter().filter(|g| g.0 == b).map(|g| g.1[4]).reduce(f64::min)))
                .collect(),
            collision_geoms_m: geoms.into_iter().map(|g| g.1).collect(),
            body_invweight: ids.iter().map(|id| id.map(|b| model.body_invweight0()[b][0])).collect(),
        })
    }

    fn home_qpos(&mut self, mjcf: &str, pose: &[(String, f64)]) -> std::result::Result<Vec<f64>, Compile<Error>> {
        let model = compile(mjcf)?;
        home_pose(&model, pose).map_err(Compile::Other)
    }
}

/// MuJoCo's refusal of a document as [`Compile::Rejected`], anything else passed on.
fn compile(mjcf: &str) -> std::result::Result<Model, Compile<Error>> {
    Model::from_xml_str(mjcf).map_err(|e| match e {
        Error::Load { message, .. } => Compile::Rejected(message),
        other => Compile::Other(other),
    })
}

/// Converts the URDF file at `path` with MuJoCo as compiler ([`twin_convert::convert_urdf`]).
///
/// # Errors
/// [`Error::File`] if it can't be read; [`Error::Convert`] for malformed XML; [`Error::Convert`] naming
/// the file, line and element for invalid content (missing link, cycle, negative mass, bad
/// inertia, missing mesh …); [`Error::Load`] if MuJoCo rejects the result.
pub fn convert_urdf(path: &Path, opts: &ConvertOptions) -> Result<ConvertedModel> {
    crate::init()?;
    twin_convert::convert_urdf(path, opts, &mut MuJoCo)
}

/// Converts URDF `text`; `path` names it in errors and anchors relative mesh paths.
///
/// # Errors
/// As [`convert_urdf`].
pub fn convert_urdf_str(path: &Path, text: &str, opts: &ConvertOptions) -> Result<ConvertedModel> {
    crate::init()?;
    twin_convert::convert_urdf_str(path, text, opts, &mut MuJoCo)
}

/// The metadata a model converted by twin carries ([`RobotMeta`]), or `None` for other models.
pub fn robot_meta(model: &Model) -> Option<RobotMeta> {
    RobotMeta::from_custom_texts(&model.custom_texts())
}

/// `qpos0` with the hinges and slides named in `pose` (an SRDF's named pose) set to their
/// values, then every limited hinge and slide clamped into its range (some URDFs put 0 outside
/// the range, e.g. knees of quadrupeds): the nominal pose of keyframe `home`, decided here for
/// every command.
///
/// # Errors
/// [`Error::Options`] when `pose` names a joint the model does not have (a converter bug).
fn home_pose(model: &Model, pose: &[(String, f64)]) -> Result<Vec<f64>> {
    let mut q = model.qpos0().to_vec();
    for (name, value) in pose {
        let j = model
            .id(ObjType::Joint, name)
            .ok_or_else(|| Error::Options(format!("home pose: no joint \"{name}\" in the model")))?;
        if matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
            q[model.jnt_qposadr()[j] as usize] = *value;
        }
    }
    for j in 0..model.njnt() {
        if model.jnt_limited()[j] && matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
            let [lo, hi] = model.jnt_range()[j];
            let a = model.jnt_qposadr()[j] as usize;
            q[a] = q[a].clamp(lo, hi);
        }
    }
    Ok(q)
}

/// Each collision geom of the robot at the model's home pose (planes ignored): the world x-y box
/// around it (centre x, y, half sizes x, y, from MuJoCo's local bounding box) and its lowest
/// world z ([`Probe::collision_geoms_m`]), with the geom's body.
fn collision_geoms(model: &Model, pose: &[(String, f64)]) -> Result<Vec<(usize, [f64; 5])>> {
    let model = Arc::new(model.try_clone()?);
    let mut data = Data::new(model.clone())?;
    let home = home_pose(&model, pose)?;
    data.qpos_mut().copy_from_slice(&home);
    data.forward()?;
    let mut geoms = Vec::new();
    let m = &model;
    for g in 0..m.ngeom() {
        if m.geom_contype()[g] == 0 && m.geom_conaffinity()[g] == 0 {
            continue;
        }
        let p = Vector3::from(data.geom_xpos()[g]);
        let r = Matrix3::from_row_slice(&data.geom_xmat()[g]);
        let s = m.geom_size()[g];
        // Row 2 of R: how each geom axis maps onto world z.
        let rz = Vector3::new(r[(2, 0)], r[(2, 1)], r[(2, 2)]);
        let z = match m.geom_kind(g) {
            GeomType::Plane => continue,
            GeomType::Sphere => p.z - s[0],
            GeomType::Capsule => p.z - rz.z.abs() * s[1] - s[0],
            GeomType::Cylinder => p.z - rz.z.abs() * s[1] - s[0] * (1.0 - rz.z * rz.z).max(0.0).sqrt(),
            GeomType::Ellipsoid => p.z - ((s[0] * rz.x).powi(2) + (s[1] * rz.y).powi(2) + (s[2] * rz.z).powi(2)).sqrt(),
            GeomType::Box => p.z - (s[0] * rz.x.abs() + s[1] * rz.y.abs() + s[2] * rz.z.abs()),
            GeomType::Mesh => {
                let id = m.geom_dataid()[g];
                if id < 0 {
                    continue;
                }
                let adr = m.mesh_vertadr()[id as usize] as usize;
                let n = m.mesh_vertnum()[id as usize] as usize;
                m.mesh_vert()[adr..adr + n]
                    .iter()
                    .map(|v| p.z + rz.dot(&Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64)))
                    .fold(f64::INFINITY, f64::min)
            }
            _ => continue,
        };
        let [cx, cy, cz, hx, hy, hz] = m.geom_aabb()[g];
        let centre = p + r * Vector3::new(cx, cy, cz);
        let half = |row: usize| r[(row, 0)].abs() * hx + r[(row, 1)].abs() * hy + r[(row, 2)].abs() * hz;
        geoms.push((m.geom_bodyid()[g] as usize, [centre.x, centre.y, half(0), half(1), z]));
    }
    Ok(geoms)
}

/// Metadata of a compiled model for callers that only have a [`Model`]: the joints with an
/// actuator, with the actuator id (first actuator acting on each joint).
pub fn actuated_joints(model: &Model) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for a in 0..model.nu() {
        if model.actuator_transmission(a) != Transmission::Joint {
            continue;
        }
        let j = model.actuator_trnid()[a][0];
        if j >= 0 && !out.iter().any(|&(jj, _)| jj == j as usize) {
            let j = j as usize;
            if matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
                out.push((j, a));
            }
        }
    }
    out
}

/// A robot file compiled: the model and, for a URDF, the conversion (its metadata and notes).
#[derive(Debug)]
pub struct Loaded {
    /// The compiled model.
    pub model: Model,
    /// What the converter produced, when the file is a URDF (`None` for an MJCF or scene).
    pub converted: Option<ConvertedModel>,
}

/// The one way from a robot file to a compiled model, used by [`Model::from_file`],
/// [`Model::from_urdf`] and [`crate::robot::Robot::load_with_extra`] (so by every command): a
/// URDF (root `<robot>`) goes through the converter with `options`, with `extra_mjcf` (MJCF
/// elements such as `<option>`) added inside its `<mujoco>` element; anything else goes to
/// MuJoCo's own parser as it is (`options` and `extra_mjcf` unused).
///
/// # Errors
/// [`Error::File`] if the file can't be read, [`Error::Convert`] for an invalid
/// URDF, [`Error::Load`] naming the file with MuJoCo's message if MuJoCo refuses it.
pub fn load(path: &Path, options: &ConvertOptions, extra_mjcf: &str) -> Result<Loaded> {
    let text = twin_fsio::read_to_string(path)?;
    load_str(path, &text, options, extra_mjcf)
}

/// [`load`] of a file whose text the caller has already read (`text`, the contents of `path`;
/// an MJCF is still compiled from `path`, for its includes and assets), so that a caller that
/// reads the URDF itself (sysid's inertials) reads it once.
///
/// # Errors
/// As [`load`].
pub fn load_str(path: &Path, text: &str, options: &ConvertOptions, extra_mjcf: &str) -> Result<Loaded> {
    crate::init()?;
    if !urdf::is_urdf(text) {
        return Ok(Loaded { model: Model::from_mujoco_file(path)?, converted: None });
    }
    let converted = convert_urdf_str(path, text, options)?;
    let model = match converted.mjcf.rfind("</mujoco>") {
        Some(end) if !extra_mjcf.is_empty() => {
            Model::from_xml_str(&format!("{}{extra_mjcf}\n{}", &converted.mjcf[..end], &converted.mjcf[end..]))
        }
        _ => Model::from_xml_str(&converted.mjcf),
    }
    .map_err(|e| match e {
        Error::Load { message, .. } => Error::Load { path: Some(path.to_path_buf()), message },
        other => other,
    })?;
    check_delay_buffers(path, &model)?;
    Ok(Loaded { model, converted: Some(converted) })
}

/// Every delayed actuator's history buffer spans its delay at the model's timestep: MuJoCo
/// reads a buffer too short for its delay at its oldest sample, a shorter delay without a word.
fn check_delay_buffers(path: &Path, model: &Model) -> Result<()> {
    let dt = model.timestep_secs();
    for a in 0..model.nu() {
        let delay = model.actuator_delay()[a];
        let nsample = model.actuator_history()[a][0];
        if delay > 0.0 && f64::from(nsample - 1) * dt < delay - 1e-12 {
            return Err(Error::Load {
                path: Some(path.to_path_buf()),
                message: format!(
                    "actuator \"{}\": its {delay} s delay needs at least {} history samples at the {dt} s timestep, \
                     it has {nsample}: convert the robot with this timestep (ConvertOptions::timestep_secs) instead \
                     of overriding it afterwards",
                    model.name(ObjType::Actuator, a),
                    (delay / dt).ceil() as i64 + 1
                ),
            });
        }
    }
    Ok(())
}

impl Model {
    /// Loads an MJCF or URDF file ([`load`]). A URDF goes through twin's converter with
    /// default options: free-floating base placed on a floor, one actuator per transmission,
    /// IMU and joint sensors, keyframe `home`.
    ///
    /// # Errors
    /// As [`load`].
    pub fn from_file(path: impl AsRef<Path>) -> Result<Model> {
        Ok(load(path.as_ref(), &ConvertOptions::default(), "")?.model)
    }

    /// Loads a robot file with converter `opts` ([`load`]; `opts` apply to a URDF only).
    ///
    /// # Errors
    /// As [`load`].
    pub fn from_urdf(path: impl AsRef<Path>, opts: &ConvertOptions) -> Result<Model> {
        Ok(load(path.as_ref(), opts, "")?.model)
    }
}
