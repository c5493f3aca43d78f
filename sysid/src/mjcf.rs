//! `--mjcf OUT.xml`: a MuJoCo model with the identified values, armature included (URDF has no
//! place for it). The updated URDF goes through twin's converter (the same model every twin
//! command simulates: free or fixed base as the converter decides, actuators, sensors) with the
//! identified armature of each joint, and the MJCF is written atomically.

use crate::error::{Error, Result};
use crate::identify::Identification;
use crate::model::RobotModel;
use crate::writeback::{JointUpdate, LinkUpdate, rewrite_urdf, write_atomic};
use std::path::Path;
use twin_core::convert::{ConvertOptions, convert_urdf_str};
use twin_core::mj::Model;

/// Writes `out` (MJCF): the URDF at `urdf` with `links`/`joints` applied, converted by twin's
/// converter with the identified armature of each joint.
///
/// # Errors
/// Reading the URDF, conversion errors, MuJoCo refusing the result, writing `out`.
pub fn write_mjcf(
    urdf: &Path,
    robot: &RobotModel,
    ident: &Identification,
    links: &[LinkUpdate],
    joints: &[JointUpdate],
    out: &Path,
) -> Result<()> {
    let text = std::fs::read_to_string(urdf).map_err(|source| Error::Io { path: urdf.to_path_buf(), source })?;
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
    write_atomic(out, converted.mjcf.as_bytes())
}
