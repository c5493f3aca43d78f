//! The URDF's kinematic tree: one root, no cycles, every link reached.

use super::ir::{JointIr, RobotIr};
use crate::error::{Error, Result};
use std::collections::HashMap;

/// Kinematic tree of the URDF.
pub(crate) struct Tree {
    pub root: usize,
    /// Joint whose child each link is (`None` for the root).
    pub parent_joint: Vec<Option<usize>>,
    /// Joint indices by parent link index, in URDF order.
    pub children: Vec<Vec<usize>>,
    pub link_index: HashMap<String, usize>,
}

impl Tree {
    pub fn build(robot: &RobotIr) -> Result<Tree> {
        let link_index: HashMap<String, usize> =
            robot.links.iter().enumerate().map(|(i, l)| (l.name.clone(), i)).collect();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children = vec![Vec::new(); robot.links.len()];
        let err = |j: &JointIr, message: String| Error::Urdf {
            path: robot.path.clone(),
            line: j.line,
            element: "joint".into(),
            name: Some(j.name.clone()),
            message,
        };
        for (ji, j) in robot.joints.iter().enumerate() {
            let c = link_index[&j.child];
            if let Some(prev) = parent_joint[c] {
                let p = &robot.joints[prev];
                return Err(err(
                    j,
                    format!(
                        "link \"{}\" is already the child of joint \"{}\" (line {}): a URDF must be a tree; \
                         remove one of the joints or use <mimic>/a closed-loop constraint instead",
                        j.child, p.name, p.line
                    ),
                ));
            }
            if j.parent == j.child {
                return Err(err(j, format!("joint connects link \"{}\" to itself: fix parent or child", j.child)));
            }
            parent_joint[c] = Some(ji);
            children[link_index[&j.parent]].push(ji);
        }
        let roots: Vec<usize> = (0..robot.links.len()).filter(|&i| parent_joint[i].is_none()).collect();
        let root = match roots.as_slice() {
            [r] => *r,
            [] => {
                let j = &robot.joints[0];
                return Err(err(
                    j,
                    "the joints form a cycle: every link is some joint's child, so there is no root link; \
                     break the loop (a URDF must be a tree)"
                        .into(),
                ));
            }
            many => {
                let names: Vec<&str> = many.iter().map(|&i| robot.links[i].name.as_str()).collect();
                let l = &robot.links[many[1]];
                return Err(Error::Urdf {
                    path: robot.path.clone(),
                    line: l.line,
                    element: "link".into(),
                    name: Some(l.name.clone()),
                    message: format!(
                        "the robot has {} root links ({}): connect each to the tree with a joint",
                        many.len(),
                        names.join(", ")
                    ),
                });
            }
        };
        // Links not reachable from the root sit on a cycle.
        let mut reached = vec![false; robot.links.len()];
        let mut stack = vec![root];
        while let Some(l) = stack.pop() {
            reached[l] = true;
            for &j in &children[l] {
                let c = link_index[&robot.joints[j].child];
                if !reached[c] {
                    stack.push(c);
                }
            }
        }
        if let Some(l) = (0..robot.links.len()).find(|&l| !reached[l]) {
            let j = &robot.joints[parent_joint[l].expect("unreached links have a parent joint")];
            return Err(err(
                j,
                format!(
                    "link \"{}\" is on a cycle of joints (not reachable from the root \"{}\"): a URDF must be a tree; break the loop",
                    robot.links[l].name, robot.links[root].name
                ),
            ));
        }
        Ok(Tree { root, parent_joint, children, link_index })
    }
}
