//! The arms a [`super::Grasper`] drives: joints found from the gripper's grasp frame up to the
//! trunk, fingers below the hand, and damped-least-squares IK on MuJoCo's Jacobians.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use twin_core::control::{Actuation, PdHoldOptions, pd_gains};
use twin_core::error::{Error, Result};
use twin_core::mj::{Data, JointType, Model, ObjType};

/// Left or right.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmSide {
    /// +y.
    Left,
    /// −y.
    Right,
}

impl ArmSide {
    /// `left` or `right`.
    pub fn label(self) -> &'static str {
        match self {
            ArmSide::Left => "left",
            ArmSide::Right => "right",
        }
    }
}

/// One PD-driven 1-DOF joint and where its command goes.
#[derive(Debug, Clone)]
pub(crate) struct Loop {
    pub joint: usize,
    pub qpos_adr: usize,
    pub dof: usize,
    /// Index in the command vector (`ctrl` or `qfrc_applied`).
    pub command: usize,
    /// Joint torque per unit of command.
    pub gear: f64,
    /// Command limits.
    pub limits: [f64; 2],
    /// Joint range, when limited.
    pub range: Option<[f64; 2]>,
    /// Weight in the IK (smaller: moves less).
    pub ik_weight: f64,
    pub kp: f64,
    pub kd: f64,
}

/// An arm with its gripper.
#[derive(Debug, Clone)]
pub(crate) struct Arm {
    pub side: ArmSide,
    /// Arm joints, trunk to hand.
    pub joints: Vec<Loop>,
    /// The two fingers (slide joints; positive opens).
    pub fingers: Vec<Loop>,
    /// Body whose origin is the grasp point (between the pads), its y axis the jaw axis and its
    /// −z axis the approach direction.
    pub grasp_body: usize,
    /// First body of the chain (the shoulder), for reach estimates.
    pub shoulder_body: usize,
}

/// Bodies on the path from `b` up to the world, `b` first.
fn ancestors(model: &Model, mut b: usize) -> Vec<usize> {
    let mut out = vec![b];
    while b != 0 {
        b = model.body_parentid()[b] as usize;
        out.push(b);
    }
    out
}

/// The command loop of 1-DOF joint `joint`, with the PD gain rule's gains at
/// `saturation_error`.
fn joint_loop(model: &Model, joint: usize, saturation_error: f64) -> Result<Loop> {
    let actuation = Actuation::of(model);
    let limits = actuation.limits(model);
    let dof = model.jnt_dofadr()[joint] as usize;
    // The joint's drive (the one actuator finder) and the torque it can give its joint (the one
    // reading of an actuator's strength, as pd-hold's); driven by qfrc, its actuator-force range.
    let (command, gear, effort) = match actuation {
        Actuation::Ctrl => twin_core::robot::actuators_of(model, &[])
            .into_iter()
            .find(|a| a.joint == Some(joint) && a.gear != 0.0)
            .map(|a| (a.id, a.gear, a.joint_effort(model)))
            .ok_or_else(|| Error::Grasp {
                message: format!(
                    "joint \"{}\" has no actuator: give it a transmission (or convert with --actuators motor)",
                    model.name(ObjType::Joint, joint)
                ),
            })?,
        Actuation::Qfrc => {
            let [lo, hi] = limits[dof];
            (dof, 1.0, lo.abs().min(hi.abs()))
        }
    };
    let effort = Some(effort).filter(|e| e.is_finite());
    let inertia = model.dof_m0()[dof] + model.dof_armature()[dof];
    let options = PdHoldOptions { saturation_error, ..PdHoldOptions::default() };
    let (kp, kd) = pd_gains(effort, inertia.max(1e-6), &options);
    Ok(Loop {
        joint,
        qpos_adr: model.jnt_qposadr()[joint] as usize,
        dof,
        command,
        gear,
        limits: limits[command],
        range: model.jnt_limited()[joint].then(|| model.jnt_range()[joint]),
        ik_weight: 1.0,
        kp,
        kd,
    })
}

impl Arm {
    /// The arm ending in body `grasp_name`; `other_grasp` is the other arm's grasp body (their
    /// common ancestor is the trunk, where the arm chain starts).
    pub fn find(
        model: &Model,
        side: ArmSide,
        grasp_name: &str,
        other_grasp: Option<usize>,
        saturation_error: f64,
        trunk_joints: &[(String, f64)],
    ) -> Result<Arm> {
        let grasp_body = model.id(ObjType::Body, grasp_name).ok_or_else(|| Error::Grasp {
            message: format!(
                "the model has no body \"{grasp_name}\" (the {} gripper's grasp frame): use a model with grippers \
                 such as models/humanoid_gripper.urdf, or name the grasp bodies in [grasp]",
                side.label()
            ),
        })?;
        let hand = model.body_parentid()[grasp_body] as usize;
        let up = ancestors(model, grasp_body);
        // The trunk: the first ancestor shared with the other arm, else the floating base.
        let trunk = match other_grasp {
            Some(o) => {
                let theirs = ancestors(model, o);
                *up.iter().find(|b| theirs.contains(b)).unwrap_or(&0)
            }
            None => model.free_joint().map_or(0, |f| f.body),
        };
        let chain_bodies: Vec<usize> = up.iter().copied().take_while(|&b| b != trunk).collect();
        let mut joints = Vec::new();
        for (name, weight) in trunk_joints {
            let j = model.id(ObjType::Joint, name).ok_or_else(|| Error::Grasp {
                message: format!("the model has no joint \"{name}\" (a trunk joint the arms' IK may use)"),
            })?;
            let mut l = joint_loop(model, j, saturation_error)?;
            l.ik_weight = *weight;
            joints.push(l);
        }
        for &b in chain_bodies.iter().rev() {
            for j in 0..model.njnt() {
                if model.jnt_bodyid()[j] as usize == b && model.joint_type(j) == JointType::Hinge {
                    joints.push(joint_loop(model, j, saturation_error)?);
                }
            }
        }
        if joints.len() < 3 {
            return Err(Error::Grasp {
                message: format!(
                    "the {} arm (up from \"{grasp_name}\") has {} hinge joints; reaching needs at least 3",
                    side.label(),
                    joints.len()
                ),
            });
        }
        let gripper_bodies = model.subtree(hand);
        let mut fingers = Vec::new();
        for j in 0..model.njnt() {
            let b = model.jnt_bodyid()[j] as usize;
            if model.joint_type(j) == JointType::Slide && gripper_bodies.contains(&b) {
                fingers.push(joint_loop(model, j, 0.01)?);
            }
        }
        if fingers.len() != 2 {
            return Err(Error::Grasp {
                message: format!(
                    "the {} gripper (below \"{}\") has {} slide joints; a parallel-jaw gripper needs 2 fingers",
                    side.label(),
                    model.name(ObjType::Body, hand),
                    fingers.len()
                ),
            });
        }
        Ok(Arm { side, joints, fingers, grasp_body, shoulder_body: *chain_bodies.last().unwrap_or(&hand) })
    }

    /// The arm joints' positions in `qpos`.
    pub fn q(&self, qpos: &[f64]) -> Vec<f64> {
        self.joints.iter().map(|l| qpos[l.qpos_adr]).collect()
    }
}

/// One damped-least-squares step on task rows `j`, errors `e`: the first `min(rows, 4)` rows
/// (position, jaw) with priority, the fifth (approach) in their null space; `weights` per joint.
fn prioritized(j: &DMatrix<f64>, e: &DVector<f64>, weights: &[f64], rows: usize, damping: f64) -> DVector<f64> {
    let n = j.ncols();
    let w = DMatrix::<f64>::from_diagonal(&DVector::from_column_slice(weights));
    let pinv = |a: &DMatrix<f64>| -> Option<DMatrix<f64>> {
        let m = a * &w * a.transpose() + DMatrix::<f64>::identity(a.nrows(), a.nrows()) * (damping * damping);
        m.try_inverse().map(|inv| &w * a.transpose() * inv)
    };
    let primary = rows.min(4);
    let j1 = j.rows(0, primary).into_owned();
    let Some(j1p) = pinv(&j1) else { return DVector::zeros(n) };
    let mut dq = &j1p * e.rows(0, primary);
    if rows == 5 {
        let null = DMatrix::<f64>::identity(n, n) - &j1p * &j1;
        let j2 = j.rows(4, 1).into_owned();
        if let Some(j2p) = pinv(&(&j2 * &null)) {
            let r = DVector::from_element(1, e[4]) - &j2 * &dq;
            dq += &null * (j2p * r);
        }
    }
    dq
}

/// A grasp-frame target: position, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Grasp point, world, m.
    pub position: Vector3<f64>,
    /// Pitch the approach axis (the grasp frame's −z) down by this much, rad, with the jaw axis
    /// level, as soft tasks (`None`: the position alone, any orientation).
    pub approach: Option<f64>,
}

/// What an IK solve reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkResult {
    /// Remaining position error, m.
    pub position_error_m: f64,
    /// Remaining tilt of the jaw axis out of the horizontal, rad.
    pub jaw_tilt_rad: f64,
}

/// Weight of the jaw-horizontal task relative to position (m per rad).
const W_JAW: f64 = 0.3;
/// Weight of the approach-direction task.
const W_APPROACH: f64 = 0.3;

/// Damped least squares on MuJoCo's Jacobians (`mj_jac` at the grasp point, rotational
/// Jacobian for the jaw and approach axes): moves `q` (the arm's joints) towards `target`
/// on `scratch` (whose other joints stay as they are), `iterations` times, each step at most
/// 0.2 rad. Joint ranges are enforced.
///
/// # Errors
/// As [`Data::kinematics_with_velocity`].
pub(crate) fn solve(
    scratch: &mut Data,
    arm: &Arm,
    target: &Target,
    q: &mut [f64],
    iterations: usize,
    damping: f64,
) -> Result<IkResult> {
    let jaw_task = target.approach.is_some();
    let nv = scratch.model().nv();
    let n = arm.joints.len();
    let mut jacp = vec![0.0; 3 * nv];
    let mut jacr = vec![0.0; 3 * nv];
    let mut result = IkResult { position_error_m: f64::INFINITY, jaw_tilt_rad: f64::INFINITY };
    for it in 0..=iterations {
        for (l, &v) in arm.joints.iter().zip(q.iter()) {
            scratch.qpos_mut()[l.qpos_adr] = v;
        }
        scratch.kinematics_with_velocity()?;
        let p = Vector3::from(scratch.xpos()[arm.grasp_body]);
        let r = Matrix3::from_row_slice(&scratch.xmat()[arm.grasp_body]);
        let jaw = r.column(1).into_owned();
        let approach = -r.column(2).into_owned();
        let e_p = target.position - p;
        result = IkResult { position_error_m: e_p.norm(), jaw_tilt_rad: jaw.z.clamp(-1.0, 1.0).asin().abs() };
        if it == iterations {
            break;
        }
        scratch.point_jacobian(arm.grasp_body, p.into(), &mut jacp, &mut jacr)?;
        // Rows: position (3), the jaw axis's vertical component → 0 and, when asked, the
        // approach axis's vertical component → 0 (softer: a 4-joint arm can't meet all).
        let rows = if !jaw_task {
            3
        } else if target.approach.is_some() {
            5
        } else {
            4
        };
        let mut j = DMatrix::<f64>::zeros(rows, n);
        let mut e = DVector::<f64>::zeros(rows);
        for (k, l) in arm.joints.iter().enumerate() {
            let w = Vector3::new(jacr[l.dof], jacr[nv + l.dof], jacr[2 * nv + l.dof]);
            for a in 0..3 {
                j[(a, k)] = jacp[a * nv + l.dof];
            }
            if rows >= 4 {
                j[(3, k)] = W_JAW * w.cross(&jaw).z;
            }
            if rows == 5 {
                j[(4, k)] = W_APPROACH * w.cross(&approach).z;
            }
        }
        e.fixed_rows_mut::<3>(0).copy_from(&e_p);
        if rows >= 4 {
            e[3] = -W_JAW * jaw.z;
        }
        if rows == 5 {
            e[4] = W_APPROACH * (-target.approach.unwrap_or(0.0).sin() - approach.z);
        }
        // Position and jaw first (weighted damped least squares: J# = W Jᵀ (J W Jᵀ + λ² I)⁻¹);
        // the approach pitch only in their null space, so it never costs position. A joint at
        // a limit that the step would push further is taken out (weight 0) and the step redone.
        let mut weights: Vec<f64> = arm.joints.iter().map(|l| l.ik_weight).collect();
        let mut dq = DVector::<f64>::zeros(n);
        for _pass in 0..3 {
            dq = prioritized(&j, &e, &weights, rows, damping);
            let mut blocked = false;
            for (k, l) in arm.joints.iter().enumerate() {
                if let Some([lo, hi]) = l.range
                    && weights[k] > 0.0
                    && ((q[k] <= lo + 1e-6 && dq[k] < 0.0) || (q[k] >= hi - 1e-6 && dq[k] > 0.0))
                {
                    weights[k] = 0.0;
                    blocked = true;
                }
            }
            if !blocked {
                break;
            }
        }
        let biggest = dq.amax();
        if biggest > 0.2 {
            dq *= 0.2 / biggest;
        }
        for (k, l) in arm.joints.iter().enumerate() {
            q[k] += dq[k];
            if let Some([lo, hi]) = l.range {
                q[k] = q[k].clamp(lo, hi);
            }
        }
    }
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// From a hanging arm, position first and then the jaw: the grasp point lands on targets
    /// over the table within 1 cm with the jaws level.
    #[test]
    fn ik_reaches_table_targets_with_level_jaws() {
        // The grasp scenario's robot (`scenarios/grasp.toml`); the table does not change the IK.
        let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
        let model = Model::from_file(root.join("models/humanoid_gripper.urdf")).unwrap();
        let left = model.id(ObjType::Body, "left_grasp_link");
        let arm = Arm::find(&model, ArmSide::Right, "right_grasp_link", left, 0.15, &[]).unwrap();
        assert_eq!(arm.joints.len(), 4);
        assert_eq!(arm.fingers.len(), 2);
        let mut d = Data::new(Arc::new(model.try_clone().unwrap())).unwrap();
        twin_core::control::reset_to_home(&mut d).unwrap();
        // Crouched as the walker stands (CoM 0.62 m instead of 0.68 m).
        d.qpos_mut()[2] -= 0.06;
        let qpos = d.qpos().to_vec();
        for p in [[0.33, -0.12, 0.67], [0.3, -0.05, 0.7], [0.35, -0.16, 0.67]] {
            d.qpos_mut().copy_from_slice(&qpos);
            let mut q = arm.q(&qpos);
            let p = Vector3::from(p);
            solve(&mut d, &arm, &Target { position: p, approach: None }, &mut q, 200, 0.05).unwrap();
            let r = solve(&mut d, &arm, &Target { position: p, approach: Some(0.1) }, &mut q, 300, 0.05).unwrap();
            assert!(r.position_error_m < 0.01 && r.jaw_tilt_rad < 0.05, "{p:?}: {r:?}");
            // The solution is where MuJoCo's forward kinematics puts the grasp frame.
            d.forward().unwrap();
            assert!((Vector3::from(d.xpos()[arm.grasp_body]) - p).norm() < 0.01);
        }
    }
}
