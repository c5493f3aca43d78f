//! Leg inverse kinematics ([`LegIk`]): joint angles that place a foot frame at a pose in the
//! pelvis frame, in closed form where the leg's axes allow it (Paden–Kahan subproblems), else by
//! damped least squares on the leg's geometric Jacobian.

use super::*;

/// Leg inverse kinematics: joint angles placing the foot frame at a pose in the pelvis frame.
#[derive(Debug, Clone)]
pub struct LegIk {
    /// Joint `qpos` addresses.
    pub(super) qpos_adr: Vec<usize>,
    /// Joint ranges (radians).
    pub(super) range: Vec<[f64; 2]>,
    /// Per body of the chain: its joints' indices into the chain.
    pub(super) chain: Vec<(usize, Vec<usize>)>,
    pub(super) qpos0: Vec<f64>,
    pub(super) axis: Vec<Vector3<f64>>,
    pub(super) pos: Vec<Vector3<f64>>,
    pub(super) body_pos: Vec<Vector3<f64>>,
    pub(super) body_rot: Vec<UnitQuaternion<f64>>,
    /// The knee: the chain joint farthest from both ends of the leg, and the sign of its
    /// larger range side (the way it bends).
    pub(super) knee: (usize, f64),
    /// Closed-form solution, for legs of the usual shape (see [`ClosedForm`]); the others use
    /// damped least squares only.
    pub(super) closed_form: Option<ClosedForm>,
}

/// Result of [`LegIk::solve`].
#[derive(Debug, Clone, Copy)]
pub struct IkResult {
    /// Position error left, metres.
    pub position_error_m: f64,
    /// Orientation error left, radians.
    pub rotation_error_rad: f64,
}

impl LegIk {
    /// IK of `leg` of `model`.
    pub fn new(model: &Model, leg: &Leg) -> LegIk {
        let chain = leg
            .bodies
            .iter()
            .map(|&b| {
                let js: Vec<usize> = leg
                    .joints
                    .iter()
                    .enumerate()
                    .filter(|&(_, &j)| model.jnt_bodyid()[j] as usize == b)
                    .map(|(k, _)| k)
                    .collect();
                (b, js)
            })
            .collect();
        let mut ik = LegIk {
            knee: (0, 1.0),
            qpos_adr: leg.joints.iter().map(|&j| model.jnt_qposadr()[j] as usize).collect(),
            range: leg
                .joints
                .iter()
                .map(|&j| if model.jnt_limited()[j] { model.jnt_range()[j] } else { [-1e9, 1e9] })
                .collect(),
            chain,
            qpos0: leg.joints.iter().map(|&j| model.qpos0()[model.jnt_qposadr()[j] as usize]).collect(),
            axis: leg.joints.iter().map(|&j| Vector3::from(model.jnt_axis()[j]).normalize()).collect(),
            pos: leg.joints.iter().map(|&j| Vector3::from(model.jnt_pos()[j])).collect(),
            body_pos: model.body_pos().iter().map(|&p| Vector3::from(p)).collect(),
            body_rot: model.body_quat().iter().map(|&q| quat(q)).collect(),
            closed_form: None,
        };
        let n = ik.len();
        let (mut anchors, mut axes) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        let q0 = ik.qpos0.clone();
        ik.fk(&q0, &mut anchors, &mut axes);
        if n > 0 {
            let (first, last) = (anchors[0], anchors[n - 1]);
            let knee = (0..n)
                .max_by(|&a, &b| {
                    let d = |k: usize| (anchors[k] - first).norm().min((anchors[k] - last).norm());
                    d(a).total_cmp(&d(b))
                })
                .unwrap_or(0);
            let [lo, hi] = ik.range[knee];
            ik.knee = (knee, if hi.abs() >= lo.abs() { 1.0 } else { -1.0 });
        }
        ik.closed_form = ClosedForm::new(&ik);
        ik
    }

    /// Whether this leg is solved in closed form (three hip axes meeting in a point, a knee,
    /// two ankle axes meeting in a point); otherwise by damped least squares only.
    pub fn is_closed_form(&self) -> bool {
        self.closed_form.is_some()
    }

    /// Bends a (nearly) straight knee in the guess `q`: straight legs are singular for IK.
    #[inline]
    pub fn bend_knee(&self, q: &mut [f64], angle: f64) {
        let (k, sign) = self.knee;
        if k < q.len() && (q[k] * sign) < angle {
            q[k] = (sign * angle).clamp(self.range[k][0], self.range[k][1]);
        }
    }

    /// How far the knee is bent in the chain's angles `q`, rad: its angle from zero (the
    /// straight leg of a URDF) toward its larger range side, the way [`LegIk::bend_knee`] bends it.
    pub fn knee_bend_rad(&self, q: &[f64]) -> f64 {
        let (k, sign) = self.knee;
        q.get(k).map_or(0.0, |v| v * sign)
    }

    /// Number of joints.
    #[inline]
    pub fn len(&self) -> usize {
        self.qpos_adr.len()
    }

    /// Whether the chain is empty.
    pub fn is_empty(&self) -> bool {
        self.qpos_adr.is_empty()
    }

    /// `qpos` address of chain joint `k`.
    #[inline]
    pub fn qpos_adr(&self, k: usize) -> usize {
        self.qpos_adr[k]
    }

    /// Foot pose in the pelvis frame for chain angles `q`, and each joint's anchor and axis.
    pub(super) fn fk(
        &self,
        q: &[f64],
        anchors: &mut [Vector3<f64>],
        axes: &mut [Vector3<f64>],
    ) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let mut pos = Vector3::zeros();
        let mut rot = UnitQuaternion::identity();
        for (b, js) in &self.chain {
            pos += rot * self.body_pos[*b];
            rot *= self.body_rot[*b];
            for &k in js {
                let anchor = pos + rot * self.pos[k];
                axes[k] = rot * self.axis[k];
                anchors[k] = anchor;
                rot *= hinge_rotation(&self.axis[k], q[k] - self.qpos0[k]);
                pos = anchor - rot * self.pos[k];
            }
        }
        (pos, rot)
    }

    /// Foot pose in the pelvis frame for chain angles `q`.
    pub fn foot_pose(&self, q: &[f64]) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let n = self.len();
        let (mut a, mut x) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        self.fk(q, &mut a, &mut x)
    }

    /// Updates `q` (the chain's angles, warm start) toward the foot pose `target` in the pelvis
    /// frame, within the joint ranges. A leg of the usual shape ([`LegIk::is_closed_form`]) is
    /// solved in closed form, on the branches (knee bend, ankle and hip) nearest `q`: exactly,
    /// or out of reach with the leg stretched toward the target and the foot turned as asked.
    /// When that needs a joint beyond its range, and for other legs, `iterations` steps of
    /// damped least squares (`damping`) follow from there (the clamped solution).
    pub fn solve(
        &self,
        target: (Vector3<f64>, UnitQuaternion<f64>),
        q: &mut [f64],
        iterations: usize,
        damping: f64,
    ) -> IkResult {
        if let Some(exact) = self.solve_closed_form(&target, q) {
            return exact;
        }
        // Damped least squares: `iterations` steps of `q` toward `target`; the error returned
        // is the one before the last step.
        let n = self.len();
        let mut anchors = [Vector3::zeros(); 12];
        let mut axes = [Vector3::zeros(); 12];
        let n = n.min(12);
        let mut result = IkResult { position_error_m: f64::INFINITY, rotation_error_rad: f64::INFINITY };
        for _ in 0..iterations.max(1) {
            let (p, r) = self.fk(q, &mut anchors[..n], &mut axes[..n]);
            let dp = target.0 - p;
            let dr = (target.1 * r.inverse()).scaled_axis();
            result = IkResult { position_error_m: dp.norm(), rotation_error_rad: dr.norm() };
            if result.position_error_m < 1e-7 && result.rotation_error_rad < 1e-6 {
                break;
            }
            let e = Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z);
            let (cols, jjt) = damped_jacobian(p, &anchors[..n], &axes[..n], damping);
            let Some(y) = jjt.cholesky().map(|c| c.solve(&e)) else { break };
            for k in 0..n {
                let step = cols[k].dot(&y).clamp(-0.5, 0.5);
                q[k] = (q[k] + step).clamp(self.range[k][0], self.range[k][1]);
            }
        }
        result
    }

    /// The closed-form step of [`LegIk::solve`]: `q` set to the closed-form solution nearest
    /// it, clamped to the joint ranges; its error when no joint needed the clamp, `None` when
    /// one did or the leg has no closed form (then damped least squares goes on from `q`).
    pub(super) fn solve_closed_form(
        &self,
        target: &(Vector3<f64>, UnitQuaternion<f64>),
        q: &mut [f64],
    ) -> Option<IkResult> {
        let cf = self.closed_form.as_ref()?;
        let warm: [f64; 6] = std::array::from_fn(|k| q[k] - self.qpos0[k]);
        let (theta, sc, _) = cf.solve(target, &warm);
        let mut within = true;
        for k in 0..6 {
            let v = self.qpos0[k] + theta[k];
            q[k] = v.clamp(self.range[k][0], self.range[k][1]);
            within &= q[k] == v;
        }
        within.then(|| cf.error(target, &sc))
    }

    /// How the chain's angles follow a small motion of the pelvis (the IK's base) with the
    /// foot held where it is in the world, at angles `q`: `out[k]` is joint `k`'s change, rad,
    /// per unit pelvis translation (x, y, z, m) and rotation (x, y, z, rad), both in the
    /// pelvis's own frame; through the damped least-squares inverse (`damping`) of the leg's
    /// Jacobian, the linear part of [`LegIk::solve`] about `q`.
    pub fn base_motion_map(&self, q: &[f64], damping: f64, out: &mut [[f64; 6]]) {
        let n = self.len().min(12).min(out.len());
        let mut anchors = [Vector3::zeros(); 12];
        let mut axes = [Vector3::zeros(); 12];
        let (p, _) = self.fk(q, &mut anchors[..n], &mut axes[..n]);
        let (cols, jjt) = damped_jacobian(p, &anchors[..n], &axes[..n], damping);
        // The foot's target in the pelvis frame, per unit pelvis motion: a translation `d`
        // moves it by −d, a rotation `w` by −w × p (position) and −w (orientation).
        let mut moves = Matrix6::<f64>::zeros();
        for j in 0..3 {
            let e = Vector3::ith(j, 1.0);
            let turn = p.cross(&e);
            moves.fixed_view_mut::<3, 1>(0, j).copy_from(&-e);
            moves.fixed_view_mut::<3, 1>(0, 3 + j).copy_from(&turn);
            moves.fixed_view_mut::<3, 1>(3, 3 + j).copy_from(&-e);
        }
        let Some(y) = jjt.cholesky().map(|c| c.solve(&moves)) else {
            out.iter_mut().for_each(|row| *row = [0.0; 6]);
            return;
        };
        for (k, row) in out.iter_mut().enumerate().take(n) {
            for (j, v) in row.iter_mut().enumerate() {
                *v = cols[k].dot(&y.column(j));
            }
        }
    }
}

/// Closed-form IK of the usual humanoid leg: six hinges, the first three (hip) with axes
/// meeting in one point, the last two (ankle) with axes meeting in another, the fourth (knee)
/// between; any order of yaw/roll/pitch, any axis directions and offsets otherwise. Legs not
/// of this shape (within [`ClosedForm::MEET_M`]) are solved by damped least squares only.
///
/// With θ = q − qpos0 the foot pose is the product of exponentials
/// `T(θ) = e^{ξ₁θ₁} ⋯ e^{ξ₆θ₆} T(0)` of the joints' screws at qpos0 (Murray, Li & Sastry,
/// *A Mathematical Introduction to Robotic Manipulation*, §3.3), solved by Paden–Kahan
/// subproblems: the knee from the hip–ankle distance (hip and ankle rotations keep it), the
/// ankle from where the hip centre lies seen from the foot, the hip from what rotation is left.
/// The damped-least-squares step it replaces took a Jacobian, a 6×6 Cholesky and a
/// kinematics pass per iteration, and left the error of one Gauss–Newton step.
#[derive(Debug, Clone)]
pub(super) struct ClosedForm {
    /// Joint axes (unit), pelvis frame, at qpos0.
    pub(super) axis: [Vector3<f64>; 6],
    /// A point on each joint axis, pelvis frame, at qpos0.
    pub(super) point: [Vector3<f64>; 6],
    /// Where the hip axes meet, pelvis frame.
    pub(super) hip: Vector3<f64>,
    /// Where the ankle axes meet, pelvis frame at qpos0.
    pub(super) ankle: Vector3<f64>,
    /// A unit vector normal to the third hip axis: its angle is read from how this turns.
    pub(super) normal: Vector3<f64>,
    /// Foot pose at qpos0, pelvis frame.
    pub(super) foot0: (Vector3<f64>, UnitQuaternion<f64>),
}

impl ClosedForm {
    /// How close axes must pass to count as meeting, metres (rounding of the model's
    /// constants is far below; an offset hip or ankle is far above).
    const MEET_M: f64 = 1e-9;
    /// Least sine between the axes of one subproblem: nearly parallel axes would make it
    /// ill-conditioned.
    const MIN_SINE: f64 = 0.1;
    /// Least distance of the knee axis from the hip and ankle centres, metres: a knee through
    /// either would not change the leg's length.
    const MIN_KNEE_ARM_M: f64 = 1e-3;

    /// The closed form of `ik`'s leg, if it has the shape.
    pub(super) fn new(ik: &LegIk) -> Option<ClosedForm> {
        if ik.len() != 6 {
            return None;
        }
        let (mut point, mut axis) = ([Vector3::zeros(); 6], [Vector3::zeros(); 6]);
        let foot0 = ik.fk(&ik.qpos0, &mut point, &mut axis);
        let apart = |i: usize, j: usize| axis[i].cross(&axis[j]).norm() >= Self::MIN_SINE;
        if !(apart(0, 1) && apart(0, 2) && apart(1, 2) && apart(4, 5)) {
            return None;
        }
        let (hip, hip_gap) = closest_point(&point[0], &axis[0], &point[1], &axis[1]);
        let (ankle, ankle_gap) = closest_point(&point[4], &axis[4], &point[5], &axis[5]);
        if hip_gap > Self::MEET_M
            || line_distance(&hip, &point[2], &axis[2]) > Self::MEET_M
            || ankle_gap > Self::MEET_M
            || line_distance(&hip, &point[3], &axis[3]) < Self::MIN_KNEE_ARM_M
            || line_distance(&ankle, &point[3], &axis[3]) < Self::MIN_KNEE_ARM_M
        {
            return None;
        }
        let normal = axis[2].cross(&axis[0]).normalize();
        Some(ClosedForm { axis, point, hip, ankle, normal, foot0 })
    }

    /// Rotates point `x` about joint `k`'s axis by the angle of sine and cosine `sc`.
    pub(super) fn turn(&self, k: usize, sc: (f64, f64), x: &Vector3<f64>) -> Vector3<f64> {
        self.point[k] + rotate(&self.axis[k], sc, &(x - self.point[k]))
    }

    /// Joint angles θ (from qpos0) putting the foot at `target` (pelvis frame), on the branches
    /// nearest `warm` (θ too); their sines and cosines; whether the target is reached (else
    /// the nearest pose).
    pub(super) fn solve(
        &self,
        target: &(Vector3<f64>, UnitQuaternion<f64>),
        warm: &[f64; 6],
    ) -> ([f64; 6], [(f64, f64); 6], bool) {
        // G = T_target T(0)⁻¹: θ solves e^{ξ₁θ₁} ⋯ e^{ξ₆θ₆} = G.
        let g_rot = (target.1 * self.foot0.1.inverse()).to_rotation_matrix().into_inner();
        let g_pos = target.0 - g_rot * self.foot0.0;
        let mut theta = [0.0; 6];
        let mut sc = [(0.0, 1.0); 6];
        let inverse = |(s, c): (f64, f64)| (-s, c);
        // Knee: hip rotations fix the hip centre and ankle rotations the ankle centre, so
        // |e^{ξ₄θ₄} a − h| = |G a − h|.
        let distance = (g_rot * self.ankle + g_pos - self.hip).norm();
        let (knee, knee_exact) = subproblem3(&self.axis[3], &self.point[3], &self.ankle, &self.hip, distance, warm[3]);
        (theta[3], sc[3]) = knee;
        // Ankle: e^{ξ₅θ₅} e^{ξ₆θ₆} G⁻¹ h = e^{−ξ₄θ₄} h, as directions from the ankle centre (the
        // same when the knee reaches; out of reach, the foot points the leg at the target).
        let from = g_rot.transpose() * (self.hip - g_pos) - self.ankle;
        let to = self.turn(3, inverse(sc[3]), &self.hip) - self.ankle;
        let (ankle, ankle_exact) = subproblem2(&self.axis[4], &self.axis[5], &from, &to, warm[5]);
        for j in 0..2 {
            (theta[4 + j], sc[4 + j]) = (near(ankle[j].0, warm[4 + j]), ankle[j].1);
        }
        // Hip: the rotation left, R₁R₂R₃ = R_G R₆ᵀ R₅ᵀ R₄ᵀ (its axes meet, so rotations are all
        // of it): the third axis's direction gives θ₁ θ₂, a normal to it θ₃.
        let lower = [inverse(sc[3]), inverse(sc[4]), inverse(sc[5])];
        let left = |v: &Vector3<f64>| {
            let v = rotate(&self.axis[3], lower[0], v);
            let v = rotate(&self.axis[4], lower[1], &v);
            g_rot * rotate(&self.axis[5], lower[2], &v)
        };
        let (hip, hip_exact) = subproblem2(&self.axis[0], &self.axis[1], &self.axis[2], &left(&self.axis[2]), warm[1]);
        for j in 0..2 {
            (theta[j], sc[j]) = (near(hip[j].0, warm[j]), hip[j].1);
        }
        let to = rotate(&self.axis[1], inverse(sc[1]), &rotate(&self.axis[0], inverse(sc[0]), &left(&self.normal)));
        let (angle, angle_sc) = subproblem1(&self.axis[2], &self.normal, &to);
        (theta[2], sc[2]) = (near(angle, warm[2]), angle_sc);
        (theta, sc, knee_exact && ankle_exact && hip_exact)
    }

    /// Foot pose error from `target` at the sines and cosines `sc` of the solution's angles:
    /// the product of exponentials, the position with those sines and cosines, the orientation
    /// with unit quaternions of the half angles (fewer products than matrices).
    pub(super) fn error(&self, target: &(Vector3<f64>, UnitQuaternion<f64>), sc: &[(f64, f64); 6]) -> IkResult {
        let mut pos = self.foot0.0;
        let mut rot = self.foot0.1.into_inner();
        for k in (0..6).rev() {
            pos = self.turn(k, sc[k], &pos);
            let (s, c) = half_angle(sc[k]);
            let a = &self.axis[k];
            rot = nalgebra::Quaternion::new(c, a.x * s, a.y * s, a.z * s) * rot;
        }
        // Angle of the rotation between: from its quaternion's vector and scalar parts (exact
        // near zero, where an arccosine of the scalar is not).
        let e = target.1.into_inner().conjugate() * rot;
        IkResult {
            position_error_m: (target.0 - pos).norm(),
            rotation_error_rad: 2.0 * libm::atan2(e.imag().norm(), e.w.abs()),
        }
    }
}

/// Sine and cosine of half the angle of sine and cosine `(s, c)`, up to a common sign (the
/// same rotation as a quaternion): a square root where `sin_cos` of the half angle costs a
/// polynomial. Each branch divides by the larger half (≥ √½), so both stay accurate near 0
/// and near a half turn.
pub(super) fn half_angle((s, c): (f64, f64)) -> (f64, f64) {
    if c >= 0.0 {
        let half_c = (0.5 + 0.5 * c).sqrt();
        (s / (2.0 * half_c), half_c)
    } else {
        let half_s = (0.5 - 0.5 * c).sqrt().copysign(s);
        (half_s, s / (2.0 * half_s))
    }
}

/// `v` rotated about the unit `axis` by the angle of sine and cosine `(s, c)` (Rodrigues).
pub(super) fn rotate(axis: &Vector3<f64>, (s, c): (f64, f64), v: &Vector3<f64>) -> Vector3<f64> {
    v * c + axis.cross(v) * s + axis * (axis.dot(v) * (1.0 - c))
}

/// `angle` plus the multiple of 2π that brings it nearest `reference` (a loop: the angles are
/// from `atan2`, the references joint angles, a turn or two apart at most).
pub(super) fn near(mut angle: f64, reference: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    while angle - reference > PI {
        angle -= TAU;
    }
    while angle - reference < -PI {
        angle += TAU;
    }
    angle
}

/// The point midway between the closest points of two lines (point, unit direction), and
/// their distance.
pub(super) fn closest_point(
    p1: &Vector3<f64>,
    d1: &Vector3<f64>,
    p2: &Vector3<f64>,
    d2: &Vector3<f64>,
) -> (Vector3<f64>, f64) {
    let w = p1 - p2;
    let (b, d, e) = (d1.dot(d2), d1.dot(&w), d2.dot(&w));
    let den = 1.0 - b * b;
    let (s, t) = ((b * e - d) / den, (e - b * d) / den);
    let (c1, c2) = (p1 + d1 * s, p2 + d2 * t);
    ((c1 + c2) / 2.0, (c1 - c2).norm())
}

/// Distance of `x` from the line through `p` along the unit `d`.
pub(super) fn line_distance(x: &Vector3<f64>, p: &Vector3<f64>, d: &Vector3<f64>) -> f64 {
    let r = x - p;
    (r - d * d.dot(&r)).norm()
}

/// An angle, radians, with its sine and cosine.
type Angle = (f64, (f64, f64));

/// Paden–Kahan subproblem 1: the angle turning `u` toward `v` about the unit `axis` (both
/// relative to a point on it), with its sine and cosine (from the same `atan2` arguments).
pub(super) fn subproblem1(axis: &Vector3<f64>, u: &Vector3<f64>, v: &Vector3<f64>) -> Angle {
    let (up, vp) = (u - axis * axis.dot(u), v - axis * axis.dot(v));
    let (y, x) = (axis.dot(&up.cross(&vp)), up.dot(&vp));
    let r = (y * y + x * x).sqrt();
    (libm::atan2(y, x), if r > 0.0 { (y / r, x / r) } else { (0.0, 1.0) })
}

/// Paden–Kahan subproblem 2 on directions: angles `θ₁`, `θ₂` (with sines and cosines) for
/// `R₁(θ₁) R₂(θ₂) û = v̂` about the unit axes `a1`, `a2` (`û`, `v̂`: `u`, `v` normalized), and
/// whether it is exact (else the nearest direction reachable). Of the two branches, the one on
/// the side of the `a1`–`a2` plane where `θ₂ = warm2` puts `û` (one `sin_cos`, where comparing
/// both branches' angles would take four `atan2`).
pub(super) fn subproblem2(
    a1: &Vector3<f64>,
    a2: &Vector3<f64>,
    u: &Vector3<f64>,
    v: &Vector3<f64>,
    warm2: f64,
) -> ([Angle; 2], bool) {
    let (u, v) = (u.normalize(), v.normalize());
    // z = R₂ û = R₁ᵀ v̂ keeps û's component along a2 and v̂'s along a1.
    let w = a1.dot(a2);
    let den = 1.0 - w * w;
    let alpha = (a1.dot(&v) - w * a2.dot(&u)) / den;
    let beta = (a2.dot(&u) - w * a1.dot(&v)) / den;
    let n = a1.cross(a2);
    let gamma2 = (1.0 - alpha * alpha - beta * beta - 2.0 * alpha * beta * w) / n.norm_squared();
    // Rounding leaves a touching solution slightly negative.
    let exact = gamma2 >= -1e-12;
    let side = if n.dot(&rotate(a2, libm::sincos(warm2), &u)) < 0.0 { -1.0 } else { 1.0 };
    let z = a1 * alpha + a2 * beta + n * (side * gamma2.max(0.0).sqrt());
    ([subproblem1(a1, &z, &v), subproblem1(a2, &u, &z)], exact)
}

/// Paden–Kahan subproblem 3: the angle θ (with its sine and cosine), nearest `warm`, turning
/// `p` about the unit `axis` through `point` to `distance` from `centre`, and whether it is
/// exact (else the nearest distance reachable).
pub(super) fn subproblem3(
    axis: &Vector3<f64>,
    point: &Vector3<f64>,
    p: &Vector3<f64>,
    centre: &Vector3<f64>,
    distance: f64,
    warm: f64,
) -> (Angle, bool) {
    let (u, v) = (p - point, centre - point);
    let (ua, va) = (axis.dot(&u), axis.dot(&v));
    let (up, vp) = (u - axis * ua, v - axis * va);
    let planar2 = distance * distance - (ua - va) * (ua - va);
    let (theta0, (s0, c0)) = subproblem1(axis, &up, &vp);
    let (nu, nv) = (up.norm(), vp.norm());
    let c = (nu * nu + nv * nv - planar2) / (2.0 * nu * nv);
    // Rounding can put a reachable straight or folded knee just past ±1.
    let exact = c.abs() <= 1.0 + 1e-12;
    let c = c.clamp(-1.0, 1.0);
    let s = (1.0 - c * c).sqrt();
    let phi = libm::atan2(s, c);
    let (plus, minus) = (near(theta0 + phi, warm), near(theta0 - phi, warm));
    let solution = if (minus - warm).abs() < (plus - warm).abs() {
        (minus, (s0 * c - c0 * s, c0 * c + s0 * s))
    } else {
        (plus, (s0 * c + c0 * s, c0 * c - s0 * s))
    };
    (solution, exact)
}
