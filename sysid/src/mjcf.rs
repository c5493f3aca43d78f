//! `--mjcf OUT.xml`: a MuJoCo model with the identified values, armature included (URDF has no
//! place for it). The updated URDF goes through twin's converter (the same model every twin
//! command simulates: free or fixed base as the converter decides, actuators, sensors) with the
//! identified armature of each joint, and the MJCF is written atomically.

use crate::error::Result;
use crate::identify::Identification;
use crate::model::RobotModel;
use crate::writeback::{JointUpdate, LinkUpdate, rewrite_urdf};
use std::path::Path;
use twin_core::convert::{ConvertOptions, convert_urdf_str};
use twin_core::mj::Model;

/// Writes `out` (MJCF, see [`mjcf_text`]) atomically.
///
/// # Errors
/// As [`mjcf_text`]; writing `out`.
pub fn write_mjcf(
    urdf: &Path,
    robot: &RobotModel,
    ident: &Identification,
    links: &[LinkUpdate],
    joints: &[JointUpdate],
    out: &Path,
) -> Result<()> {
    let text = mjcf_text(urdf, robot, ident, links, joints)?;
    twin_core::fsio::write_atomic(out, text.as_bytes(), twin_core::fsio::Backup::None)?;
    Ok(())
}

/// The MJCF: the URDF at `urdf` with `links`/`joints` applied, converted by twin's converter
/// with the identified armature of each joint, checked by MuJoCo.
///
/// # Errors
/// Reading the URDF, conversion errors, MuJoCo refusing the result.
pub fn mjcf_text(
    urdf: &Path,
    robot: &RobotModel,
    ident: &Identification,
    links: &[LinkUpdate],
    joints: &[JointUpdate],
) -> Result<String> {
    let text = twin_core::fsio::read_to_string(urdf)?;
    let updated = rewrite_urdf(urdf, &text, links, joints)?;
    let mut opts = ConvertOptions::default();
    for (j, joint) in robot.joints.iter().enumerate() {
        let (_, _, armature) = ident.joint_friction(j);
        opts.joint_armature.insert(joint.name.clone(), armature.max(0.0));
    }
    // Relative mesh paths resolve against the original URDF's folder, as for the original.
    let converted = convert_urdf_str(urdf, &updated, &opts)?;
    // MuJoCo must accept what we write.
    Model::from_xml_str(&converted.mjcf)?;
    Ok(converted.mjcf)
}
