//! The home pose of a robot from its package's SRDF (MoveIt's semantic robot description): a
//! `<group_state>` gives joint values by name ("standing", "half_sitting", …) that MoveIt users
//! and example-robot-data's loaders rely on as the robot's reference pose. Without one, the home
//! pose is the zero pose clamped into every joint's range (decided by the [`crate::Compiler`]).
//!
//! Where an SRDF is looked for when none is named ([`find`]): `*.srdf` beside the URDF, in a
//! `srdf/` folder beside it, and in `srdf/` of the folder above (ROS packages keep `urdf/` or
//! `robots/` and `srdf/` side by side). Among those whose group states name joints of this robot,
//! the one with the URDF's file stem wins (`b1-z1.urdf` → `b1-z1.srdf`), then the one with the
//! URDF's robot name (`talos_full_v2.urdf`, robot `talos` → `talos.srdf`), then the one that sets
//! the most of the robot's joints.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// Group-state names taken as the home pose when none is asked for, best first: the first
/// state whose name equals one of these, else the first whose name contains "stand", else
/// "home"/"homing". Not taken by default: "tuck_left_arm", "hanging", and the humanoids'
/// "half_sitting" (`--pose half_sitting`): from it example-robot-data's iCub falls under `twin
/// check`'s hold where its zero pose stands, and the walker, derived and tuned from the zero
/// pose of Talos, falls at 3.9 s walking Talos on its servos at 0.25 m/s from it.
const DEFAULT_STATES: [&str; 4] = ["standing", "home", "default", "neutral"];

/// A named pose read from an SRDF.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPose {
    /// The SRDF file.
    pub file: PathBuf,
    /// The group state's name.
    pub name: String,
    /// Joint values by joint name (rad or m), for joints of the robot only.
    pub joints: Vec<(String, f64)>,
    /// Joints the state names that the robot does not have (skipped).
    pub unknown_joints: Vec<String>,
}

/// One `<group_state>`: name and `(joint, values)` pairs as written.
struct State {
    name: String,
    joints: Vec<(String, Vec<f64>)>,
}

/// The group states of the SRDF `text` (`path` names it in errors).
fn states(path: &Path, text: &str) -> Result<Vec<State>> {
    let doc = crate::urdf::parse(path, text)?;
    let line = |n: roxmltree::Node| doc.text_pos_at(n.range().start).row;
    let mut out: Vec<State> = Vec::new();
    for gs in doc.descendants().filter(|n| n.has_tag_name("group_state")) {
        let name = gs.attribute("name").unwrap_or_default().to_string();
        let mut joints = Vec::new();
        for j in gs.children().filter(|n| n.has_tag_name("joint")) {
            let (Some(jn), Some(v)) = (j.attribute("name"), j.attribute("value")) else {
                return Err(Error::Urdf {
                    path: path.to_path_buf(),
                    line: line(j),
                    element: "joint".into(),
                    name: Some(name.clone()),
                    message: "a group state's joint needs a name and a value".into(),
                });
            };
            let values: std::result::Result<Vec<f64>, _> = v.split_whitespace().map(str::parse::<f64>).collect();
            let values = values.ok().filter(|v| !v.is_empty() && v.iter().all(|x| x.is_finite()));
            let Some(values) = values else {
                return Err(Error::Urdf {
                    path: path.to_path_buf(),
                    line: line(j),
                    element: "joint".into(),
                    name: Some(name.clone()),
                    message: format!("joint \"{jn}\": value \"{v}\" is not a list of finite numbers"),
                });
            };
            joints.push((jn.to_string(), values));
        }
        // A state may be split over several groups (one per leg): merge by name.
        match out.iter_mut().find(|s| s.name == name) {
            Some(s) => s.joints.extend(joints),
            None => out.push(State { name, joints }),
        }
    }
    Ok(out)
}

/// The state taken by default: see [`DEFAULT_STATES`].
fn default_state(states: &[State]) -> Option<&State> {
    DEFAULT_STATES
        .iter()
        .find_map(|d| states.iter().find(|s| s.name == *d))
        .or_else(|| states.iter().find(|s| s.name.contains("stand")))
        .or_else(|| states.iter().find(|s| s.name.contains("home") || s.name.contains("homing")))
}

/// Reads pose `name` (default: [`DEFAULT_STATES`]) of the SRDF at `path` for a robot whose
/// 1-DOF joints are `robot_joints`; `Ok(None)` when no name was asked for and the file has no
/// default state.
///
/// # Errors
/// [`Error::File`], [`Error::Xml`]; [`Error::Urdf`] for a malformed state, a state asked for that
/// the file does not have (naming those it has), or a state that sets none of the robot's joints.
pub fn read(path: &Path, name: Option<&str>, robot_joints: &[&str]) -> Result<Option<NamedPose>> {
    let text = twin_fsio::read_to_string(path)?;
    let states = states(path, &text)?;
    let state = match name {
        Some(n) => match states.iter().find(|s| s.name == n) {
            Some(s) => s,
            None => {
                return Err(Error::Urdf {
                    path: path.to_path_buf(),
                    line: 1,
                    element: "group_state".into(),
                    name: Some(n.to_string()),
                    message: format!(
                        "no such pose: the file's group states are {} (choose one with --pose)",
                        if states.is_empty() {
                            "none".to_string()
                        } else {
                            states.iter().map(|s| format!("\"{}\"", s.name)).collect::<Vec<_>>().join(", ")
                        }
                    ),
                });
            }
        },
        None => match default_state(&states) {
            Some(s) => s,
            None => return Ok(None),
        },
    };
    let mut joints = Vec::new();
    let mut unknown_joints = Vec::new();
    for (j, v) in &state.joints {
        if robot_joints.contains(&j.as_str()) && v.len() == 1 {
            joints.push((j.clone(), v[0]));
        } else if v.len() == 1 {
            unknown_joints.push(j.clone());
        }
        // Multi-value joints are MoveIt's virtual (floating) joints: twin places the base itself.
    }
    if joints.is_empty() {
        return Err(Error::Urdf {
            path: path.to_path_buf(),
            line: 1,
            element: "group_state".into(),
            name: Some(state.name.clone()),
            message: "the pose sets none of the robot's joints: this SRDF is for another robot (name the right one with --srdf)"
                .into(),
        });
    }
    Ok(Some(NamedPose { file: path.to_path_buf(), name: state.name.clone(), joints, unknown_joints }))
}

/// SRDF files that may belong to the URDF at `urdf` (see the module docs), sorted.
fn candidates(urdf: &Path) -> Vec<PathBuf> {
    let Some(dir) = urdf.parent() else {
        return Vec::new();
    };
    let dir = if dir.as_os_str().is_empty() { Path::new(".") } else { dir };
    let mut dirs = vec![dir.to_path_buf(), dir.join("srdf")];
    if let Some(up) = dir.parent() {
        dirs.push(up.join("srdf"));
    }
    let mut out: Vec<PathBuf> = dirs
        .iter()
        .filter_map(|d| std::fs::read_dir(d).ok())
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("srdf")) && p.is_file())
        .collect();
    out.sort();
    out.dedup();
    out
}

/// The robot name an SRDF declares (`<robot name>`), if it parses.
fn robot_name(text: &str) -> Option<String> {
    let doc = roxmltree::Document::parse(text).ok()?;
    doc.root_element().attribute("name").map(str::to_string)
}

/// The home pose from the SRDF of the URDF at `urdf` (robot `robot_name_urdf`, 1-DOF joints
/// `robot_joints`): the file found beside it (module docs), its state `name` (default: a
/// standing or home state). `None` when no SRDF there names this robot's joints in such a state.
/// Files that do not parse, or lack the state, are passed over (another tool's file).
pub fn find(urdf: &Path, robot_name_urdf: &str, name: Option<&str>, robot_joints: &[&str]) -> Option<NamedPose> {
    let stem = urdf.file_stem().map(|s| s.to_string_lossy().to_lowercase());
    let mut best: Option<((bool, bool, usize), NamedPose)> = None;
    for file in candidates(urdf) {
        let Ok(text) = twin_fsio::read_to_string(&file) else { continue };
        let Ok(Some(pose)) = read(&file, name, robot_joints) else { continue };
        // A state that names joints this robot lacks is another variant's (solo12 vs solo8).
        if pose.unknown_joints.len() > pose.joints.len() {
            continue;
        }
        let same_stem = file.file_stem().map(|s| s.to_string_lossy().to_lowercase()) == stem;
        let same_name = robot_name(&text).is_some_and(|n| n.eq_ignore_ascii_case(robot_name_urdf));
        let key = (same_stem, same_name, pose.joints.len());
        if best.as_ref().is_none_or(|(k, _)| key > *k) {
            best = Some((key, pose));
        }
    }
    best.map(|(_, p)| p)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SRDF: &str = r#"<?xml version="1.0"?>
<robot name="dog">
  <group name="legs"><joint name="hip"/><joint name="knee"/></group>
  <group_state name="tuck" group="legs"><joint name="knee" value="-2.5"/></group_state>
  <group_state name="standing" group="legs">
    <joint name="root_joint" value="0 0 0.3 0 0 0 1"/>
    <joint name="hip" value="0.8"/>
    <joint name="knee" value="-1.6"/>
  </group_state>
</robot>"#;

    fn write(dir: &Path, rel: &str, text: &str) -> PathBuf {
        let p = dir.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn default_state_is_standing_and_the_virtual_joint_is_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let srdf = write(dir.path(), "dog/srdf/dog.srdf", SRDF);
        let urdf = write(dir.path(), "dog/urdf/dog.urdf", "<robot name=\"dog\"/>");
        let pose = find(&urdf, "dog", None, &["hip", "knee"]).unwrap();
        assert_eq!(pose.file, srdf);
        assert_eq!(pose.name, "standing");
        assert_eq!(pose.joints, vec![("hip".to_string(), 0.8), ("knee".to_string(), -1.6)]);
        let tuck = read(&srdf, Some("tuck"), &["hip", "knee"]).unwrap().unwrap();
        assert_eq!(tuck.joints, vec![("knee".to_string(), -2.5)]);
    }

    #[test]
    fn a_missing_pose_names_the_poses_there_are() {
        let dir = tempfile::tempdir().unwrap();
        let srdf = write(dir.path(), "dog.srdf", SRDF);
        let e = read(&srdf, Some("sitting"), &["hip", "knee"]).unwrap_err().to_string();
        assert!(e.contains("\"tuck\", \"standing\"") && e.contains("--pose"), "{e}");
        let e = read(&srdf, None, &["arm"]).unwrap_err().to_string();
        assert!(e.contains("none of the robot's joints"), "{e}");
    }

    #[test]
    fn an_srdf_of_another_robot_beside_the_urdf_is_not_taken() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "srdf/dog.srdf", SRDF);
        let urdf = write(dir.path(), "robots/arm.urdf", "<robot name=\"arm\"/>");
        assert_eq!(find(&urdf, "arm", None, &["shoulder", "elbow"]), None);
    }
}
