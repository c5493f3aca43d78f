//! Joints the log never names: held at their home position for the fit.
//!
//! A real robot's log often lacks some of its URDF's joints: the gripper's fingers when its
//! driver publishes them on a topic that was not recorded, a head or a tool that did not move.
//! Those joints are made `fixed` at their home position (0, or the nearer limit when 0 is
//! outside the joint's range) in the text twin compiles, so their links are lumped into the
//! parent body (their inertia stays at the URDF's values, as any fixed-joint link's does) and
//! the fit runs on the joints that were logged. The URDF file itself is not changed: the
//! write-back edits only the numbers of the links and joints that were identified.

use crate::error::{Error, Result};
use crate::model::{RobotModel, UrdfSource};
use nalgebra::{Rotation3, Unit, Vector3};
use std::path::Path;
use std::sync::Arc;

/// A robot loaded with some of its joints held.
#[derive(Debug, Clone)]
pub struct HeldRobot {
    /// The model the fit uses (held joints fixed).
    pub robot: RobotModel,
    /// The held joints and their home positions (rad or m), in URDF order.
    pub held: Vec<(String, f64)>,
}

impl HeldRobot {
    /// The warning that names the held joints, or `None` when none is held.
    pub fn warning(&self) -> Option<String> {
        if self.held.is_empty() {
            return None;
        }
        let names: Vec<String> = self.held.iter().map(|(n, q)| format!("\"{n}\" (at {q})")).collect();
        Some(format!(
            "joint(s) {} of {} are not in the log: held at their home position for the fit, their links \
             lumped into the parent link with their URDF inertia (left unchanged); --strict refuses instead",
            names.join(", "),
            self.robot.urdf_path.display()
        ))
    }
}

/// Loads `urdf` (fixed base) for identification from a log that names `logged` joints: every
/// movable joint of the URDF that `logged` lacks is held at its home position. With `strict`,
/// an unlogged joint is an error instead.
///
/// # Errors
/// [`Error::BadLog`]-like [`Error::Urdf`] naming the unlogged joints (`strict`), or when no
/// movable joint of the URDF is in the log; as [`RobotModel::from_urdf`].
pub fn from_urdf_holding(urdf: &Path, logged: &[String], strict: bool) -> Result<HeldRobot> {
    let source = UrdfSource::read(urdf)?;
    let (text, held) = hold_joints(&source, logged)?;
    if held.is_empty() {
        return Ok(HeldRobot { robot: RobotModel::from_urdf(urdf)?, held });
    }
    if strict {
        let names: Vec<String> = held.iter().map(|(n, _)| format!("\"{n}\"")).collect();
        return Err(Error::Urdf {
            path: urdf.to_path_buf(),
            message: format!(
                "joint names do not match the log: the robot's joint(s) {} are not in the log (which has {}); \
                 without --strict they are held at their home position",
                names.join(", "),
                crate::condition::quote_list(logged)
            ),
        });
    }
    let edited = UrdfSource { path: source.path.clone(), text };
    let model = edited.model("", false)?;
    let robot = RobotModel::of_urdf(&edited, Arc::new(model), false)?;
    Ok(HeldRobot { robot, held })
}

/// `source`'s text with every movable joint not in `logged` made `fixed` at its home position
/// (its `<mimic>` removed, as are mimics of it), and those joints with their home positions.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML or when no movable joint is logged.
pub fn hold_joints(source: &UrdfSource, logged: &[String]) -> Result<(String, Vec<(String, f64)>)> {
    let text = source.text.as_str();
    let err = |message: String| Error::Urdf { path: source.path.clone(), message };
    let doc = roxmltree::Document::parse(text).map_err(|e| err(e.to_string()))?;
    let movable = |t: &str| matches!(t, "revolute" | "continuous" | "prismatic");
    let joints: Vec<roxmltree::Node<'_, '_>> = doc
        .root_element()
        .children()
        .filter(|n| n.has_tag_name("joint") && n.attribute("type").is_some_and(movable))
        .collect();
    let held_nodes: Vec<roxmltree::Node<'_, '_>> =
        joints.iter().copied().filter(|j| !logged.iter().any(|l| Some(l.as_str()) == j.attribute("name"))).collect();
    if held_nodes.is_empty() {
        return Ok((text.to_string(), Vec::new()));
    }
    if held_nodes.len() == joints.len() {
        return Err(err(format!(
            "none of the robot's movable joints is in the log (which has {}); log joint names must be the \
             URDF's <joint name> values",
            crate::condition::quote_list(logged)
        )));
    }
    let held_names: Vec<&str> = held_nodes.iter().filter_map(|j| j.attribute("name")).collect();
    // (byte range, replacement), applied back to front.
    let mut edits: Vec<(std::ops::Range<usize>, String)> = Vec::new();
    let mut held = Vec::new();
    let num = |s: Option<&str>| s.and_then(|v| v.trim().parse::<f64>().ok());
    let triplet = |s: Option<&str>| -> Vector3<f64> {
        let v: Vec<f64> = s.unwrap_or("").split_whitespace().filter_map(|x| x.parse().ok()).collect();
        if v.len() == 3 { Vector3::new(v[0], v[1], v[2]) } else { Vector3::zeros() }
    };
    for j in &held_nodes {
        let name = j.attribute("name").unwrap_or_default();
        let kind = j.attribute("type").unwrap_or_default();
        let limit = j.children().find(|c| c.has_tag_name("limit"));
        let (lower, upper) = if kind == "continuous" {
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            (
                num(limit.and_then(|l| l.attribute("lower"))).unwrap_or(0.0),
                num(limit.and_then(|l| l.attribute("upper"))).unwrap_or(0.0),
            )
        };
        let home = if lower <= upper { 0.0f64.clamp(lower, upper) } else { 0.0 };
        held.push((name.to_string(), home));
        let type_attr = j.attributes().find(|a| a.name() == "type").expect("filtered on type");
        edits.push((type_attr.range_value(), "fixed".into()));
        for m in j.children().filter(|c| c.has_tag_name("mimic")) {
            edits.push((m.range(), String::new()));
        }
        if home != 0.0 {
            let origin = j.children().find(|c| c.has_tag_name("origin"));
            let xyz = triplet(origin.and_then(|o| o.attribute("xyz")));
            let rpy = triplet(origin.and_then(|o| o.attribute("rpy")));
            let axis_node = j.children().find(|c| c.has_tag_name("axis"));
            let axis = axis_node.map_or(Vector3::x(), |a| triplet(a.attribute("xyz")));
            let axis = Unit::try_new(axis, 1e-12).unwrap_or(Vector3::x_axis());
            let parent_from_joint = Rotation3::from_euler_angles(rpy.x, rpy.y, rpy.z);
            let (xyz, rpy) = if kind == "prismatic" {
                (xyz + parent_from_joint * (axis.into_inner() * home), rpy)
            } else {
                let r = parent_from_joint * Rotation3::from_axis_angle(&axis, home);
                let (r0, p0, y0) = r.euler_angles();
                (xyz, Vector3::new(r0, p0, y0))
            };
            let new_origin =
                format!("<origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>", xyz.x, xyz.y, xyz.z, rpy.x, rpy.y, rpy.z);
            match origin {
                Some(o) => edits.push((o.range(), new_origin)),
                None => {
                    let at = j.first_child().map_or(j.range().end, |c| c.range().start);
                    edits.push((at..at, new_origin));
                }
            }
        }
    }
    // Mimics of a held joint on joints that stay movable: they follow nothing now.
    for j in &joints {
        if held_nodes.iter().any(|h| h.id() == j.id()) {
            continue;
        }
        for m in j.children().filter(|c| c.has_tag_name("mimic")) {
            if m.attribute("joint").is_some_and(|leader| held_names.contains(&leader)) {
                edits.push((m.range(), String::new()));
            }
        }
    }
    edits.sort_by_key(|(r, _)| std::cmp::Reverse(r.start));
    let mut out = text.to_string();
    for (range, with) in edits {
        out.replace_range(range, &with);
    }
    Ok((out, held))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unlogged_joints_become_fixed_at_home_and_lose_their_mimics() {
        let urdf = r#"<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/><link name="d"/>
  <joint name="arm" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="f1" type="prismatic"><origin xyz="0 0 0.1" rpy="0 0 0"/><parent link="b"/><child link="c"/>
    <axis xyz="1 0 0"/><limit lower="0.01" upper="0.04" effort="1" velocity="1"/></joint>
  <joint name="f2" type="prismatic"><parent link="b"/><child link="d"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/><mimic joint="f1"/></joint>
</robot>"#;
        let src = UrdfSource { path: "r.urdf".into(), text: urdf.into() };
        let (text, held) = hold_joints(&src, &["arm".to_string()]).unwrap();
        assert_eq!(held, vec![("f1".to_string(), 0.01), ("f2".to_string(), 0.0)]);
        let doc = roxmltree::Document::parse(&text).unwrap();
        let joint =
            |n: &str| doc.descendants().find(|j| j.has_tag_name("joint") && j.attribute("name") == Some(n)).unwrap();
        assert_eq!(joint("arm").attribute("type"), Some("revolute"));
        assert_eq!(joint("f1").attribute("type"), Some("fixed"));
        assert_eq!(joint("f2").attribute("type"), Some("fixed"));
        assert!(!text.contains("<mimic"));
        // f1 home 0.01 along x: the origin moves by 0.01 m along the axis.
        let o = joint("f1").children().find(|c| c.has_tag_name("origin")).unwrap();
        assert_eq!(o.attribute("xyz"), Some("0.01 0 0.1"));
        let err = hold_joints(&src, &["other".to_string()]).unwrap_err().to_string();
        assert!(err.contains("none of the robot's movable joints"), "{err}");
    }
}
