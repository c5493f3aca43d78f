//! `--mjcf OUT.xml`: a MuJoCo model with the identified values, armature included (URDF has no
//! place for it). MuJoCo compiles the updated URDF, the armature is set per joint, and MuJoCo
//! saves the result as MJCF (`mj_saveLastXML`).

use crate::error::{Error, Result};
use crate::identify::Identification;
use crate::model::RobotModel;
use crate::writeback::{JointUpdate, LinkUpdate, rewrite_urdf, write_atomic};
use std::path::Path;
use twin_core::mj::{Model, ObjType};

/// Writes `out` (MJCF): the URDF at `urdf` with `links`/`joints` applied, MuJoCo's default URDF
/// import (links joined by fixed joints fused, root welded to the world), the identified
/// armature of each joint.
///
/// # Errors
/// Reading the URDF, MuJoCo's load or save errors.
pub fn write_mjcf(
    urdf: &Path,
    robot: &RobotModel,
    ident: &Identification,
    links: &[LinkUpdate],
    joints: &[JointUpdate],
    out: &Path,
) -> Result<()> {
    let text = std::fs::read_to_string(urdf).map_err(|source| Error::Io {
        path: urdf.to_path_buf(),
        source,
    })?;
    let updated = rewrite_urdf(urdf, &text, links, joints)?;
    // Next to the URDF so that relative mesh paths resolve as for the original.
    let dir = urdf
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let tmp = tempfile::Builder::new()
        .suffix(".urdf")
        .tempfile_in(dir)
        .map_err(|source| Error::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    write_atomic(tmp.path(), updated.as_bytes())?;
    let model = Model::from_file(tmp.path())?;
    let mut edit = model.edit()?;
    for (j, joint) in robot.joints.iter().enumerate() {
        if let Some(id) = model.id(ObjType::Joint, &joint.name) {
            let dof = model.jnt_dofadr()[id] as usize;
            let (_, _, armature) = ident.joint_friction(j);
            edit.set_dof_armature(dof, armature.max(0.0))?;
        }
    }
    let edited = edit.finish()?;
    // MuJoCo writes the file itself: into a temporary file beside OUT, renamed when complete.
    let out_dir = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let io = |source| Error::Io {
        path: out.to_path_buf(),
        source,
    };
    let staged = tempfile::Builder::new()
        .suffix(".xml")
        .tempfile_in(out_dir)
        .map_err(io)?;
    twin_core::mj::save_last_xml(staged.path(), &edited)?;
    staged.persist(out).map_err(|e| io(e.error))?;
    Ok(())
}
