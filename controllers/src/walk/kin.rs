//! Kinematics of the walker, computed from the model's constants (no `mjData`): the whole-tree
//! forward kinematics (body frames, centre of mass, per-body subtree CoM for gravity
//! compensation), the legs found in the tree, and leg inverse kinematics by damped least
//! squares on each leg's geometric Jacobian.
//!
//! Doing this in the controller, on its own small arrays, keeps it independent of the
//! simulation's `mjData` (the controller sees only an [`twin_core::control::Observation`]) and costs
//! a few microseconds per tick.
//!
//! Its sines, cosines and arctangents are the `libm` crate's (musl's port of fdlibm, pure Rust):
//! glibc's `sincos`/`atan2` set and restore the rounding mode on every call, which was a third of
//! the whole-tree pass and half of the closed-form IK (docs/src/benchmarks-notebook.md, "Walking controller cost
//! per tick"). The headings' `sin_cos` stays std's, bit for bit, behind a small memo
//! ([`kept_sin_cos`]; why, with figures, in the same section).

use nalgebra::{Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};
use std::cell::Cell;
use twin_core::error::{Error, Result};
use twin_core::mj::{GeomType, JointType, Model, ObjType};

mod ik;
pub use ik::*;

/// A chain's Jacobian at its end point `p` (world or base frame, like the joints' `anchors`
/// and unit `axes`): its columns `[a × (p − anchor); a]` and `J·Jᵀ + damping²·I`, what a
/// damped least-squares step inverts.
fn damped_jacobian(
    p: Vector3<f64>,
    anchors: &[Vector3<f64>],
    axes: &[Vector3<f64>],
    damping: f64,
) -> ([Vector6<f64>; 12], Matrix6<f64>) {
    let mut jjt = Matrix6::<f64>::identity() * (damping * damping);
    let mut cols = [Vector6::zeros(); 12];
    for (k, (anchor, a)) in anchors.iter().zip(axes).enumerate().take(12) {
        let lin = a.cross(&(p - anchor));
        cols[k] = Vector6::new(lin.x, lin.y, lin.z, a.x, a.y, a.z);
        jjt += cols[k] * cols[k].transpose();
    }
    (cols, jjt)
}

/// Unit quaternion from MuJoCo's `w x y z`.
pub fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// `UnitQuaternion::from_euler_angles(roll, pitch, yaw)` bit for bit, without the library's
/// `sin` and `cos` of the angles that are zero (the walker's headings have two, its tilt
/// correction one: seven of its twelve angles a tick): sin ±0 = ±0 and cos 0 = 1 exactly, the
/// products and sums are nalgebra's.
pub fn euler_quat(roll: f64, pitch: f64, yaw: f64) -> UnitQuaternion<f64> {
    let half = |a: f64| if a == 0.0 { (a, 1.0) } else { (a * 0.5).sin_cos() };
    let ((sr, cr), (sp, cp), (sy, cy)) = (half(roll), half(pitch), half(yaw));
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ))
}

/// Entries of [`kept_sin_cos`]'s memo (a power of two).
const SIN_COS_MEMO: usize = 16;

thread_local! {
    /// [`kept_sin_cos`]'s memo: per slot, an angle's bits and its `sin_cos` (NaN's bits: empty;
    /// non-finite angles are never kept).
    static SIN_COS: [Cell<(u64, f64, f64)>; SIN_COS_MEMO] =
        const { [const { Cell::new((0x7ff8_0000_0000_0000, 0.0, 0.0)) }; SIN_COS_MEMO] };
}

/// `angle.sin_cos()` bit for bit, the last few angles' kept: the walker takes the sine and
/// cosine of the same few headings (the footholds', the pelvis's) many times a tick. A kept
/// angle costs 1.4 ns where std's `sin_cos` costs 16 ns and `libm::sincos` 8 ns (docs/src/benchmarks-notebook.md,
/// "libm for the walker's trigonometry"); `libm::sincos` would also change the walk's last bits
/// (it differs from glibc's in 6 % of angles).
pub fn kept_sin_cos(angle: f64) -> (f64, f64) {
    if !angle.is_finite() {
        return angle.sin_cos();
    }
    let bits = angle.to_bits();
    // Fibonacci hashing: the product's top bits mix all of the angle's.
    let slot = (bits.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> (64 - SIN_COS_MEMO.trailing_zeros())) as usize;
    SIN_COS.with(|memo| {
        let (key, s, c) = memo[slot].get();
        if key == bits {
            return (s, c);
        }
        let (s, c) = angle.sin_cos();
        memo[slot].set((bits, s, c));
        (s, c)
    })
}

/// `q.euler_angles().2` (the yaw) bit for bit, without the roll's `atan2` and the rotation
/// matrix's other entries: nalgebra's products for the three entries it needs, its branches.
pub fn yaw_of(q: &UnitQuaternion<f64>) -> f64 {
    let (i, j, k, w) = (q.i, q.j, q.k, q.w);
    let m20 = i * k * 2.0 - w * j * 2.0;
    if m20.abs() < 1.0 {
        let m10 = w * k * 2.0 + i * j * 2.0;
        let m00 = w * w + i * i - j * j - k * k;
        let cos_pitch = (-m20.asin()).cos();
        (m10 / cos_pitch).atan2(m00 / cos_pitch)
    } else {
        0.0
    }
}

/// Rotation by `angle` (radians) about the unit vector `axis`: one `sin_cos`, where
/// `UnitQuaternion::from_scaled_axis` also takes a norm and normalizes (MuJoCo's joint axes are
/// unit vectors already).
fn hinge_rotation(axis: &Vector3<f64>, angle: f64) -> UnitQuaternion<f64> {
    let (s, c) = libm::sincos(0.5 * angle);
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(c, axis.x * s, axis.y * s, axis.z * s))
}

/// One joint as forward kinematics needs it.
#[derive(Debug, Clone)]
struct Joint {
    kind: JointType,
    qpos_adr: usize,
    /// Reference position (`qpos0`): MuJoCo rotates hinges by `q − qpos0`.
    qpos0: f64,
    axis: Vector3<f64>,
    pos: Vector3<f64>,
    /// `pos` is zero: the anchor is the body's origin (URDF joints).
    at_origin: bool,
    /// `axis` is ± a frame axis (index, sign), as URDF axes mostly are: then its rotation is
    /// a product with two nonzero terms per component, its world axis a matrix column.
    frame_axis: Option<(usize, f64)>,
}

/// `axis` as ± a frame axis (index, sign), if it is one exactly.
fn frame_axis(axis: &Vector3<f64>) -> Option<(usize, f64)> {
    (0..3).find_map(|i| {
        let others_zero = (0..3).all(|k| k == i || axis[k] == 0.0);
        (others_zero && axis[i].abs() == 1.0).then_some((i, axis[i]))
    })
}

/// Column `i` of `q`'s rotation matrix: `q` applied to frame axis `i`.
fn rotated_frame_axis(q: &UnitQuaternion<f64>, i: usize) -> Vector3<f64> {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    match i {
        0 => Vector3::new(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
        1 => Vector3::new(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),
        _ => Vector3::new(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)),
    }
}

/// `q` times the rotation `(c, s·eᵢ)` about frame axis `i` (the hinge quaternion with its zero
/// terms left out: 8 products where the general one takes 16).
fn times_frame_rotation(q: &UnitQuaternion<f64>, i: usize, s: f64, c: f64) -> UnitQuaternion<f64> {
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    let (w, x, y, z) = match i {
        0 => (w * c - x * s, x * c + w * s, y * c + z * s, z * c - y * s),
        1 => (w * c - y * s, x * c - z * s, y * c + w * s, z * c + x * s),
        _ => (w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s),
    };
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, x, y, z))
}

/// The kinematic tree of a model.
#[derive(Debug, Clone)]
pub struct Tree {
    parent: Vec<usize>,
    body_pos: Vec<Vector3<f64>>,
    body_rot: Vec<UnitQuaternion<f64>>,
    /// `body_rot` is the identity (URDF links without `rpy`): no product.
    body_rot_identity: Vec<bool>,
    body_ipos: Vec<Vector3<f64>>,
    mass: Vec<f64>,
    /// Subtree masses, kg (constants of the model).
    subtree_mass: Vec<f64>,
    /// Per body, its joints `start..end` (MuJoCo numbers a body's joints consecutively).
    joints: Vec<(usize, usize)>,
    joint: Vec<Joint>,
    jnt_body: Vec<usize>,
    /// Per body, the last body of its subtree when the bodies are numbered depth first (each
    /// subtree one run of ids, as MuJoCo's compiler numbers them); empty otherwise.
    subtree_last: Vec<usize>,
    /// Total mass, kg.
    pub total_mass_kg: f64,
}

/// Body frames of one configuration, world frame.
#[derive(Debug, Clone)]
pub struct Frames {
    /// Body origins.
    pub xpos: Vec<Vector3<f64>>,
    /// Body orientations.
    pub xrot: Vec<UnitQuaternion<f64>>,
    /// Joint anchors.
    pub anchor: Vec<Vector3<f64>>,
    /// Joint axes.
    pub axis: Vec<Vector3<f64>>,
    /// Subtree centres of mass.
    pub subtree_com: Vec<Vector3<f64>>,
    /// Subtree masses, kg.
    pub subtree_mass: Vec<f64>,
}

impl Frames {
    /// Centre of mass of the whole model.
    #[inline]
    pub fn com(&self) -> Vector3<f64> {
        self.subtree_com[0]
    }
}

impl Tree {
    /// The tree of `model`.
    pub fn new(model: &Model) -> Tree {
        let nbody = model.nbody();
        let joint = (0..model.njnt())
            .map(|j| {
                let qpos_adr = model.jnt_qposadr()[j] as usize;
                let axis = Vector3::from(model.jnt_axis()[j]).normalize();
                let pos = Vector3::from(model.jnt_pos()[j]);
                Joint {
                    kind: model.joint_type(j),
                    qpos_adr,
                    qpos0: model.qpos0()[qpos_adr],
                    axis,
                    pos,
                    at_origin: pos == Vector3::zeros(),
                    frame_axis: frame_axis(&axis),
                }
            })
            .collect();
        let joints = (0..nbody)
            .map(|b| {
                let adr = model.body_jntadr()[b];
                let n = model.body_jntnum()[b];
                if adr < 0 { (0, 0) } else { (adr as usize, (adr + n) as usize) }
            })
            .collect();
        let parent: Vec<usize> = model.body_parentid().iter().map(|&p| p as usize).collect();
        let mut subtree_mass = model.body_mass().to_vec();
        for b in (1..nbody).rev() {
            subtree_mass[parent[b]] += subtree_mass[b];
        }
        Tree {
            body_rot_identity: model.body_quat().iter().map(|q| *q == [1.0, 0.0, 0.0, 0.0]).collect(),
            subtree_mass,
            subtree_last: depth_first_runs(&parent),
            parent,
            body_pos: model.body_pos().iter().map(|&p| Vector3::from(p)).collect(),
            body_rot: model.body_quat().iter().map(|&q| quat(q)).collect(),
            body_ipos: model.body_ipos().iter().map(|&p| Vector3::from(p)).collect(),
            mass: model.body_mass().to_vec(),
            joints,
            joint,
            jnt_body: model.jnt_bodyid().iter().map(|&b| b as usize).collect(),
            total_mass_kg: model.body_mass().iter().sum(),
        }
    }

    /// Empty frames for this tree.
    pub fn frames(&self) -> Frames {
        let n = self.parent.len();
        let nj = self.joint.len();
        Frames {
            xpos: vec![Vector3::zeros(); n],
            xrot: vec![UnitQuaternion::identity(); n],
            anchor: vec![Vector3::zeros(); nj],
            axis: vec![Vector3::z(); nj],
            subtree_com: vec![Vector3::zeros(); n],
            subtree_mass: vec![0.0; n],
        }
    }

    /// Forward kinematics of `qpos` into `out`, as `mj_kinematics` + `mj_comPos` compute them.
    pub fn forward(&self, qpos: &[f64], out: &mut Frames) {
        self.poses::<true>(qpos, out);
        self.subtree_sums(out);
        for b in 0..self.parent.len() {
            out.subtree_com[b] = self.subtree_com_of(out, b);
        }
    }

    /// Body poses of `qpos` into `out.xpos`/`out.xrot`; with `JOINTS`, the joints' anchors and
    /// axes into `out.anchor`/`out.axis` too.
    #[inline(always)]
    fn poses<const JOINTS: bool>(&self, qpos: &[f64], out: &mut Frames) {
        for b in 1..self.parent.len() {
            let p = self.parent[b];
            let mut rot = if self.body_rot_identity[b] { out.xrot[p] } else { out.xrot[p] * self.body_rot[b] };
            let mut pos = out.xpos[p] + out.xrot[p] * self.body_pos[b];
            let (first, end) = self.joints[b];
            for j in first..end {
                let jt = &self.joint[j];
                let a = jt.qpos_adr;
                match jt.kind {
                    JointType::Free => {
                        pos = Vector3::new(qpos[a], qpos[a + 1], qpos[a + 2]);
                        rot = quat([qpos[a + 3], qpos[a + 4], qpos[a + 5], qpos[a + 6]]);
                        if JOINTS {
                            out.anchor[j] = pos;
                            out.axis[j] = Vector3::z();
                        }
                    }
                    JointType::Ball => {
                        let anchor = pos + rot * jt.pos;
                        rot *= quat([qpos[a], qpos[a + 1], qpos[a + 2], qpos[a + 3]]);
                        pos = anchor - rot * jt.pos;
                        if JOINTS {
                            out.anchor[j] = anchor;
                            out.axis[j] = Vector3::z();
                        }
                    }
                    JointType::Hinge => {
                        let anchor = if jt.at_origin { pos } else { pos + rot * jt.pos };
                        if let Some((i, sign)) = jt.frame_axis {
                            if JOINTS {
                                out.axis[j] = rotated_frame_axis(&rot, i) * sign;
                            }
                            let (s, c) = libm::sincos(0.5 * (qpos[a] - jt.qpos0));
                            rot = times_frame_rotation(&rot, i, sign * s, c);
                        } else {
                            if JOINTS {
                                out.axis[j] = rot * jt.axis;
                            }
                            rot *= hinge_rotation(&jt.axis, qpos[a] - jt.qpos0);
                        }
                        pos = if jt.at_origin { anchor } else { anchor - rot * jt.pos };
                        if JOINTS {
                            out.anchor[j] = anchor;
                        }
                    }
                    JointType::Slide => {
                        let axis = rot * jt.axis;
                        pos += axis * (qpos[a] - jt.qpos0);
                        if JOINTS {
                            out.anchor[j] = pos + rot * jt.pos;
                            out.axis[j] = axis;
                        }
                    }
                }
            }
            out.xpos[b] = pos;
            out.xrot[b] = rot;
        }
    }

    /// Each subtree's mass and mass-weighted sum of its bodies' centres into
    /// `out.subtree_mass`/`out.subtree_com`, from the body poses.
    #[inline(always)]
    fn subtree_sums(&self, out: &mut Frames) {
        out.subtree_mass.copy_from_slice(&self.subtree_mass);
        for b in 0..self.parent.len() {
            out.subtree_com[b] = (out.xpos[b] + out.xrot[b] * self.body_ipos[b]) * self.mass[b];
        }
        for b in (1..self.parent.len()).rev() {
            let c = out.subtree_com[b];
            out.subtree_com[self.parent[b]] += c;
        }
    }

    /// Subtree `b`'s centre of mass from [`Tree::subtree_sums`].
    #[inline(always)]
    fn subtree_com_of(&self, out: &Frames, b: usize) -> Vector3<f64> {
        let m = out.subtree_mass[b];
        // A massless subtree's centre is its body's inertial frame, as in `mj_comPos`.
        if m >= 1e-15 { out.subtree_com[b] / m } else { out.xpos[b] + out.xrot[b] * self.body_ipos[b] }
    }

    /// Centre of mass of the whole model at `qpos`, as [`Tree::forward`]'s `com()` bit for bit
    /// (same poses, same sums), using `scratch` for the body poses and sums; its joint anchors,
    /// axes and the other subtrees' centres are left stale. Half the work of a whole pass.
    pub fn com(&self, qpos: &[f64], scratch: &mut Frames) -> Vector3<f64> {
        self.poses::<false>(qpos, scratch);
        self.subtree_sums(scratch);
        self.subtree_com_of(scratch, 0)
    }

    /// Parent of body `b`.
    pub fn parent(&self, b: usize) -> usize {
        self.parent[b]
    }

    /// Whether body `b` is `ancestor` or below it.
    #[inline]
    pub fn is_below(&self, mut b: usize, ancestor: usize) -> bool {
        if let Some(&last) = self.subtree_last.get(ancestor) {
            return (ancestor..=last).contains(&b);
        }
        loop {
            if b == ancestor {
                return true;
            }
            if b == 0 {
                return false;
            }
            b = self.parent[b];
        }
    }

    /// Static joint torque of hinge/slide `joint` holding its subtree against gravity `g` and
    /// the point `forces` (position, force; world frame) acting on bodies below it:
    /// `τ = −axis · Σ (r − anchor) × f`.
    #[inline]
    pub fn static_torque(
        &self,
        frames: &Frames,
        joint: usize,
        gravity: Vector3<f64>,
        forces: &[(usize, Vector3<f64>, Vector3<f64>)],
    ) -> f64 {
        let body = self.joint_body(joint);
        let anchor = frames.anchor[joint];
        let axis = frames.axis[joint];
        let mut moment = (frames.subtree_com[body] - anchor).cross(&(gravity * frames.subtree_mass[body]));
        for &(b, r, f) in forces {
            if self.is_below(b, body) {
                moment += (r - anchor).cross(&f);
            }
        }
        -axis.dot(&moment)
    }

    /// Body of `joint`.
    #[inline]
    pub fn joint_body(&self, joint: usize) -> usize {
        self.jnt_body[joint]
    }

    /// The bodies that turn rigidly with `root` about the unit `axis` (world, at `frames`):
    /// `root` and the bodies below it reached through joints that can't take the turn (hinges
    /// whose axis is within 45° of perpendicular to `axis`, slides), none below `excluded`
    /// (e.g. the legs, held by the ground); and their moment of inertia about the line through
    /// `point` along `axis`, kg·m² (own inertias as in [`Tree::subtree_axis_inertia`]). What a
    /// torque on `root` meets within one physics step: a joint that can take the turn puts
    /// what is beyond it behind its spring, which at the step's Nyquist frequency transmits
    /// next to nothing.
    pub fn rigid_axis_inertia(
        &self,
        model: &Model,
        frames: &Frames,
        root: usize,
        (point, axis): (Vector3<f64>, Vector3<f64>),
        excluded: &[usize],
    ) -> (Vec<bool>, f64) {
        let mut rigid = vec![false; self.parent.len()];
        let mut inertia = 0.0;
        // Parents come before children (MuJoCo's numbering).
        for b in root..self.parent.len() {
            let with_parent = b == root
                || (rigid[self.parent[b]]
                    && !excluded.contains(&b)
                    && (self.joints[b].0..self.joints[b].1).all(|j| match self.joint[j].kind {
                        JointType::Hinge => frames.axis[j].dot(&axis).abs() < std::f64::consts::FRAC_1_SQRT_2,
                        JointType::Slide => true,
                        _ => false,
                    }));
            if !with_parent {
                continue;
            }
            rigid[b] = true;
            let c = frames.xpos[b] + frames.xrot[b] * self.body_ipos[b];
            let r = c - point;
            let perp = r - axis * axis.dot(&r);
            let principal = model.body_inertia()[b];
            inertia += self.mass[b] * perp.norm_squared() + (principal[0] + principal[1] + principal[2]) / 3.0;
        }
        (rigid, inertia)
    }

    /// Moment of inertia of the subtree below hinge `joint` about its axis at `frames`, kg·m²
    /// (bodies' own inertias approximated as point masses plus their principal moments' mean).
    pub fn subtree_axis_inertia(&self, model: &Model, frames: &Frames, joint: usize) -> f64 {
        let body = self.joint_body(joint);
        let (anchor, axis) = (frames.anchor[joint], frames.axis[joint]);
        let mut inertia = 0.0;
        for b in 1..self.parent.len() {
            if !self.is_below(b, body) {
                continue;
            }
            let c = frames.xpos[b] + frames.xrot[b] * self.body_ipos[b];
            let r = c - anchor;
            let perp = r - axis * axis.dot(&r);
            let principal = model.body_inertia()[b];
            inertia += self.mass[b] * perp.norm_squared() + (principal[0] + principal[1] + principal[2]) / 3.0;
        }
        inertia
    }
}

/// Per body, the last body of its subtree, when each subtree is one run of ids (bodies
/// numbered depth first, parents before children); empty when not.
fn depth_first_runs(parent: &[usize]) -> Vec<usize> {
    let n = parent.len();
    let (mut last, mut size) = ((0..n).collect::<Vec<usize>>(), vec![1usize; n]);
    for b in (1..n).rev() {
        let p = parent[b];
        if p >= b {
            return Vec::new();
        }
        last[p] = last[p].max(last[b]);
        size[p] += size[b];
    }
    if (0..n).all(|b| last[b] - b + 1 == size[b]) { last } else { Vec::new() }
}

/// Which side a leg is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// +y of the pelvis.
    Left,
    /// −y of the pelvis.
    Right,
}

impl Side {
    /// The other side.
    pub fn other(self) -> Side {
        match self {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        }
    }
    /// +1 for left, −1 for right.
    pub fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }
    /// Index 0 (left) or 1 (right).
    pub fn index(self) -> usize {
        match self {
            Side::Left => 0,
            Side::Right => 1,
        }
    }
}

/// A leg: the hinge joints from the pelvis down to the foot, and the foot's sole.
#[derive(Debug, Clone)]
pub struct Leg {
    /// Side.
    pub side: Side,
    /// Foot body.
    pub foot: usize,
    /// Hinge joints from the pelvis to the foot, in order.
    pub joints: Vec<usize>,
    /// Bodies from the pelvis's child to the foot, in order.
    pub bodies: Vec<usize>,
    /// Sole centre (bottom face) in the foot frame, metres.
    pub sole_in_foot: Vector3<f64>,
    /// Half extents of the sole along the foot frame's x and y, metres.
    pub sole_half: [f64; 2],
    /// Foot orientation in the pelvis frame in the home pose (soles flat).
    pub foot_rot_home: UnitQuaternion<f64>,
}

/// The walker's view of a humanoid: pelvis, two legs, IMU.
#[derive(Debug, Clone)]
pub struct Body {
    /// Floating-base body.
    pub pelvis: usize,
    /// `qpos` address of the free joint.
    pub base_qpos: usize,
    /// `qvel` address of the free joint.
    pub base_dof: usize,
    /// Left, right.
    pub legs: [Leg; 2],
    /// IMU (a gyro, with the framequat of the same site when there is one).
    pub imu: Option<Imu>,
}

/// IMU sensors the walker reads.
#[derive(Debug, Clone)]
pub struct Imu {
    /// Name of the gyro sensor.
    pub name: String,
    /// Address of the orientation (framequat, w x y z, world frame) in `sensordata`.
    pub quat_adr: Option<usize>,
    /// Address of the angular velocity (site frame, rad/s) in `sensordata`.
    pub gyro_adr: usize,
    /// Orientation of the IMU site in the pelvis frame, home pose (the site's own orientation
    /// in the body it is on, turned by that body's orientation relative to the pelvis).
    pub site_rot: UnitQuaternion<f64>,
}

/// Overrides of what [`Body::find`] detects.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct BodyNames {
    /// Floating-base body (default: the body of the free joint).
    pub pelvis: Option<String>,
    /// Left foot body (default: the lowest collision body on the pelvis's +y side).
    pub left_foot: Option<String>,
    /// Right foot body (default: the lowest collision body on the −y side).
    pub right_foot: Option<String>,
    /// Gyro sensor (`<name>_gyro`) of the IMU the walker reads (default: the first IMU of
    /// [`twin_core::robot::imus_of`]; none: the base orientation is used).
    pub imu_gyro: Option<String>,
}

fn walk_err(message: String) -> Error {
    Error::Walk { message }
}

impl Body {
    /// Finds pelvis, feet (bodies whose collision geoms are lowest in the home pose `home`),
    /// legs (the hinge chains from the pelvis to each foot) and IMU, with `names` overriding.
    ///
    /// # Errors
    /// [`Error::Walk`] when the model has no floating base, no two feet or a leg with fewer than
    /// six hinges.
    pub fn find(model: &Model, tree: &Tree, home: &[f64], names: &BodyNames) -> Result<Body> {
        let find_body = |name: &Option<String>| -> Result<Option<usize>> {
            match name {
                None => Ok(None),
                Some(n) => model.id(ObjType::Body, n).map(Some).ok_or_else(|| {
                    walk_err(format!("the model has no body \"{n}\" (named in the walker's `bodies` options)"))
                }),
            }
        };
        let free = (0..model.njnt()).find(|&j| model.joint_type(j) == JointType::Free);
        let pelvis = match find_body(&names.pelvis)? {
            Some(b) => b,
            None => free
                .map(|j| model.jnt_bodyid()[j] as usize)
                .ok_or_else(|| walk_err("the model has no floating base (free joint): a walker needs one".into()))?,
        };
        let free = free.filter(|&j| model.jnt_bodyid()[j] as usize == pelvis).ok_or_else(|| {
            walk_err(format!("pelvis body \"{}\" has no free joint", model.name(ObjType::Body, pelvis)))
        })?;
        let mut frames = tree.frames();
        tree.forward(home, &mut frames);
        let pelvis_rot = frames.xrot[pelvis];
        let pelvis_pos = frames.xpos[pelvis];

        // Collision geoms of the robot: their lowest point and extent, per body.
        let collides = |g: usize| model.geom_contype()[g] != 0 || model.geom_conaffinity()[g] != 0;
        let mut lowest_by_body: Vec<Option<(f64, usize)>> = vec![None; model.nbody()];
        let mut lowest = f64::INFINITY;
        for g in 0..model.ngeom() {
            let b = model.geom_bodyid()[g] as usize;
            if b == 0 || !collides(g) || !tree.is_below(b, pelvis) {
                continue;
            }
            let (z, _) = geom_bottom(model, &frames, g);
            lowest = lowest.min(z);
            if lowest_by_body[b].is_none_or(|(lz, _)| z < lz) {
                lowest_by_body[b] = Some((z, g));
            }
        }
        let mut left = find_body(&names.left_foot)?;
        let mut right = find_body(&names.right_foot)?;
        if left.is_none() || right.is_none() {
            let mut feet: Vec<(usize, f64)> = (0..model.nbody())
                .filter_map(|b| lowest_by_body[b].filter(|(z, _)| *z < lowest + 0.01).map(|_| b))
                .map(|b| (b, (pelvis_rot.inverse() * (frames.xpos[b] - pelvis_pos)).y))
                .collect();
            feet.sort_by(|a, b| b.1.total_cmp(&a.1));
            if left.is_none() {
                left = feet.first().filter(|f| f.1 > 0.0).map(|f| f.0);
            }
            if right.is_none() {
                right = feet.last().filter(|f| f.1 < 0.0).map(|f| f.0);
            }
        }
        let (Some(left), Some(right)) = (left, right) else {
            return Err(walk_err(
                "found no two feet (the lowest collision bodies on the +y and −y sides of the pelvis in the \
                 home pose); name them with `bodies.left_foot` / `bodies.right_foot`"
                    .into(),
            ));
        };
        let leg = |side: Side, foot: usize| -> Result<Leg> {
            let mut bodies = Vec::new();
            let mut b = foot;
            while b != pelvis {
                if b == 0 {
                    return Err(walk_err(format!(
                        "foot \"{}\" is not below the pelvis \"{}\"",
                        model.name(ObjType::Body, foot),
                        model.name(ObjType::Body, pelvis)
                    )));
                }
                bodies.push(b);
                b = tree.parent(b);
            }
            bodies.reverse();
            let joints: Vec<usize> = bodies
                .iter()
                .flat_map(|&b| tree.joints[b].0..tree.joints[b].1)
                .filter(|&j| model.joint_type(j) == JointType::Hinge)
                .collect();
            if joints.len() < 6 {
                return Err(walk_err(format!(
                    "the leg to \"{}\" has {} hinge joints; the walker needs six (3 hip, knee, 2 ankle) to place a \
                     foot in position and orientation",
                    model.name(ObjType::Body, foot),
                    joints.len()
                )));
            }
            let g = lowest_by_body[foot].map(|(_, g)| g).ok_or_else(|| {
                walk_err(format!("foot \"{}\" has no collision geometry (its sole)", model.name(ObjType::Body, foot)))
            })?;
            // The sole: every collision geom of the foot whose bottom is within 1 cm of its
            // lowest (a box; or the four small spheres at the corners of the G1's soles, whose
            // contact points span it), as the rectangle around their footprints; one geom
            // alone, its own bottom.
            let (bottom_z, half) = geom_bottom(model, &frames, g);
            let foot_rot = frames.xrot[foot];
            let soles: Vec<usize> = (0..model.ngeom())
                .filter(|&k| model.geom_bodyid()[k] as usize == foot && collides(k))
                .filter(|&k| geom_bottom(model, &frames, k).0 <= bottom_z + 0.01)
                .collect();
            let (centre_world, half) = if soles.len() <= 1 {
                (Vector3::new(frames.geom_center(model, g).x, frames.geom_center(model, g).y, bottom_z), half)
            } else {
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for &k in &soles {
                    // A sphere touches at the point under its centre.
                    let sphere = model.geom_kind(k) == GeomType::Sphere;
                    let h = if sphere { [0.0; 2] } else { geom_bottom(model, &frames, k).1 };
                    let c = frames.geom_center(model, k);
                    for a in 0..2 {
                        lo[a] = lo[a].min(c[a] - h[a]);
                        hi[a] = hi[a].max(c[a] + h[a]);
                    }
                }
                let centre = Vector3::new((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0, bottom_z);
                (centre, [(hi[0] - lo[0]) / 2.0, (hi[1] - lo[1]) / 2.0])
            };
            let sole_in_foot = foot_rot.inverse() * (centre_world - frames.xpos[foot]);
            Ok(Leg {
                side,
                foot,
                joints,
                bodies,
                sole_in_foot,
                sole_half: half,
                foot_rot_home: pelvis_rot.inverse() * foot_rot,
            })
        };
        let legs = [leg(Side::Left, left)?, leg(Side::Right, right)?];

        // The one IMU finder (`<name>_gyro` + `<name>_accel` on a site, `<name>_quat` when
        // present), as the recorder and the ROS bridge see them.
        let imus = twin_core::robot::imus_of(model);
        let found = match &names.imu_gyro {
            Some(n) => Some(imus.iter().find(|i| format!("{}_gyro", i.meta.name) == *n).ok_or_else(|| {
                walk_err(format!(
                    "the model has no IMU with the gyro sensor \"{n}\" (an IMU is a `<name>_gyro` + \
                     `<name>_accel` sensor pair on one site)"
                ))
            })?),
            None => imus.first(),
        };
        let imu = found.map(|i| Imu {
            name: format!("{}_gyro", i.meta.name),
            quat_adr: i.quat_adr,
            gyro_adr: i.gyro_adr,
            // The site's orientation in the pelvis frame at home: an IMU on a child body
            // of the pelvis (Talos's `imu_link`, turned half a turn) reads that body's turn too.
            site_rot: pelvis_rot.inverse() * frames.xrot[i.body] * quat(i.body_from_imu.1),
        });
        Ok(Body {
            pelvis,
            base_qpos: model.jnt_qposadr()[free] as usize,
            base_dof: model.jnt_dofadr()[free] as usize,
            legs,
            imu,
        })
    }
}

impl Frames {
    fn geom_center(&self, model: &Model, g: usize) -> Vector3<f64> {
        let b = model.geom_bodyid()[g] as usize;
        self.xpos[b] + self.xrot[b] * Vector3::from(model.geom_pos()[g])
    }
}

/// Lowest world z of geom `g` and its half extents along world x and y (boxes exactly, other
/// shapes by their bounding radius).
fn geom_bottom(model: &Model, frames: &Frames, g: usize) -> (f64, [f64; 2]) {
    let b = model.geom_bodyid()[g] as usize;
    let rot = frames.xrot[b] * quat(model.geom_quat()[g]);
    let centre = frames.geom_center(model, g);
    let size = model.geom_size()[g];
    let m: Matrix3<f64> = rot.to_rotation_matrix().into_inner();
    let extent = |row: usize, s: [f64; 3]| (0..3).map(|k| (m[(row, k)] * s[k]).abs()).sum::<f64>();
    match model.geom_kind(g) {
        GeomType::Box => (centre.z - extent(2, size), [extent(0, size), extent(1, size)]),
        GeomType::Sphere => (centre.z - size[0], [size[0], size[0]]),
        _ => {
            let r = model.geom_rbound()[g];
            (centre.z - r, [r * 0.5, r * 0.5])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A leg of the usual shape but nothing lined up with the pelvis: tilted hip and ankle
    /// axes (each set meeting in a point, not at right angles), a knee off the hip–ankle line
    /// and skewed, body frames rotated. `hip_offset_m` moves the third hip axis off the others.
    fn skewed_leg(hip_offset_m: f64) -> (Model, Leg) {
        let xml = format!(
            r#"<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="pelvis" pos="0 0 1">
      <freejoint/>
      <geom type="sphere" size="0.1"/>
      <body name="hip_a" pos="0.01 0.08 -0.05" quat="0.98 0.1 0.05 0.1">
        <joint name="hip_a" axis="0.1 0.2 1" range="-2 2"/>
        <geom type="sphere" size="0.02"/>
        <body name="hip_b" quat="0.95 0 0.2 0.1">
          <joint name="hip_b" axis="1 0.3 0" range="-2 2"/>
          <geom type="sphere" size="0.02"/>
          <body name="thigh" pos="0 {hip_offset_m} 0">
            <joint name="hip_c" axis="0.2 1 -0.1" range="-2 2"/>
            <geom type="capsule" fromto="0 0 0 0.02 0.03 -0.3" size="0.03"/>
            <body name="shin" pos="0.02 0.03 -0.3" quat="0.99 0.05 0 0">
              <joint name="knee" axis="0.1 1 0.05" range="-0.1 2.5"/>
              <geom type="capsule" fromto="0 0 0 -0.01 -0.02 -0.3" size="0.03"/>
              <body name="ankle" pos="-0.01 -0.02 -0.3">
                <joint name="ankle_a" axis="0 1 0.2" range="-2 2"/>
                <geom type="sphere" size="0.02"/>
                <body name="foot" quat="0.97 0.1 -0.1 0.2">
                  <joint name="ankle_b" axis="1 0 0.3" range="-2 2"/>
                  <geom type="box" pos="0.03 0 -0.04" size="0.1 0.05 0.01"/>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>"#
        );
        let model = Model::from_xml_str(&xml).unwrap();
        let body = |n: &str| model.id(ObjType::Body, n).unwrap();
        let bodies: Vec<usize> = ["hip_a", "hip_b", "thigh", "shin", "ankle", "foot"].iter().map(|n| body(n)).collect();
        let joints = ["hip_a", "hip_b", "hip_c", "knee", "ankle_a", "ankle_b"]
            .iter()
            .map(|n| model.id(ObjType::Joint, n).unwrap())
            .collect();
        let leg = Leg {
            side: Side::Left,
            foot: body("foot"),
            joints,
            bodies,
            sole_in_foot: Vector3::zeros(),
            sole_half: [0.1, 0.05],
            foot_rot_home: UnitQuaternion::identity(),
        };
        (model, leg)
    }

    fn humanoid_legs() -> (Model, [Leg; 2]) {
        let model = Model::from_file(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/humanoid.urdf")).unwrap();
        let tree = Tree::new(&model);
        let body = Body::find(&model, &tree, model.qpos0(), &BodyNames::default()).unwrap();
        (model, body.legs)
    }

    /// Random reachable targets (the foot pose of random angles within the ranges, knee bent)
    /// solved from a warm start 0.1 rad away: the closed form lands on them and on those
    /// angles.
    fn closed_form_matches_kinematics(ik: &LegIk, seed: u64) {
        assert!(ik.is_closed_form());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let (knee, sign) = ik.knee;
        for _ in 0..200 {
            let want: Vec<f64> = (0..6)
                .map(|k| {
                    if k == knee {
                        sign * rng.random_range(0.2..1.8)
                    } else {
                        let [lo, hi] = ik.range[k];
                        rng.random_range((lo + 0.01).max(ik.qpos0[k] - 0.5)..(hi - 0.01).min(ik.qpos0[k] + 0.5))
                    }
                })
                .collect();
            let target = ik.foot_pose(&want);
            let mut q: Vec<f64> = want.iter().map(|&v| v + rng.random_range(-0.1..0.1)).collect();
            let r = ik.solve(target, &mut q, 1, 1e-3);
            let (p, rot) = ik.foot_pose(&q);
            assert!((p - target.0).norm() < 1e-9, "{p} {}", target.0);
            assert!((rot * target.1.inverse()).angle() < 1e-9);
            assert!(r.position_error_m < 1e-9 && r.rotation_error_rad < 1e-9, "{r:?}");
            for k in 0..6 {
                assert!((q[k] - want[k]).abs() < 1e-7, "joint {k}: {q:?} {want:?}");
            }
        }
    }

    /// The tree's kinematics equal MuJoCo's on every kind of joint and frame: hinges along
    /// frame axes (± signs, at the origin or offset) and tilted, rotated and plain bodies, a
    /// ball, a slide, a massless body, at random configurations.
    #[test]
    fn forward_kinematics_match_mujoco_on_all_joint_kinds() {
        let xml = r#"<mujoco>
  <compiler angle="radian"/>
  <worldbody>
    <body name="base" pos="0 0 1">
      <freejoint/>
      <geom type="sphere" size="0.1"/>
      <body name="a" pos="0.1 0 -0.1">
        <joint type="hinge" axis="0 -1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
        <body name="b" pos="0 0.05 -0.2" quat="0.9 0.3 0.1 -0.2">
          <joint type="hinge" axis="1 0 0" pos="0.01 -0.02 0.03"/>
          <joint type="hinge" axis="0 0 -1"/>
          <geom type="box" size="0.03 0.02 0.05" pos="0.02 0 -0.03"/>
          <body name="c" pos="0 0 -0.1">
            <joint type="hinge" axis="0.3 -0.4 0.8" pos="0 0.01 0"/>
            <geom type="sphere" size="0.02" pos="0.01 0.02 0"/>
            <body name="slider" pos="0.05 0 0">
              <joint type="slide" axis="0 1 0.2"/>
              <geom type="sphere" size="0.01"/>
              <body name="massless" pos="0.02 0 0"/>
            </body>
          </body>
        </body>
      </body>
      <body name="d" pos="-0.1 0 0.05" quat="0.7 0 0.7 0">
        <joint type="ball" pos="0 0 0.02"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.02"/>
        <body name="e" pos="0.1 0 0">
          <joint type="slide" axis="0 0 1" pos="0.01 0 0"/>
          <geom type="sphere" size="0.03"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>"#;
        let model = std::sync::Arc::new(Model::from_xml_str(xml).unwrap());
        let tree = Tree::new(&model);
        assert!(tree.joint.iter().any(|j| j.frame_axis == Some((1, -1.0)) && j.at_origin));
        assert!(tree.joint.iter().any(|j| j.frame_axis == Some((0, 1.0)) && !j.at_origin));
        assert!(tree.joint.iter().any(|j| j.kind == JointType::Hinge && j.frame_axis.is_none()));
        let mut data = twin_core::mj::Data::new(model.clone()).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut frames = tree.frames();
        for _ in 0..20 {
            let q: Vec<f64> = (0..model.nq()).map(|_| rng.random_range(-1.5..1.5)).collect();
            data.qpos_mut().copy_from_slice(&q);
            for j in 0..model.njnt() {
                let a = model.jnt_qposadr()[j] as usize;
                let n = match model.joint_type(j) {
                    JointType::Free => Some((a + 3, 4)),
                    JointType::Ball => Some((a, 4)),
                    _ => None,
                };
                if let Some((a, n)) = n {
                    let norm = data.qpos()[a..a + n].iter().map(|v| v * v).sum::<f64>().sqrt();
                    data.qpos_mut()[a..a + n].iter_mut().for_each(|v| *v /= norm);
                }
            }
            data.forward().unwrap();
            // The CoM-only pass first, on the frames the full pass then overwrites: the same
            // bits as the full pass's.
            let com = tree.com(data.qpos(), &mut frames);
            tree.forward(data.qpos(), &mut frames);
            assert_eq!(com, frames.com());
            for b in 0..model.nbody() {
                assert!((frames.xpos[b] - Vector3::from(data.xpos()[b])).norm() < 1e-12, "body {b}");
                assert!((frames.xrot[b].inverse() * quat(data.xquat()[b])).angle() < 1e-12, "body {b}");
                let com = Vector3::from(data.subtree_com()[b]);
                assert!((frames.subtree_com[b] - com).norm() < 1e-12, "body {b}");
            }
            // Anchors and axes from the joints' bodies (a hinge's axis is fixed in its body,
            // when it is the body's last joint).
            for (j, jt) in tree.joint.iter().enumerate() {
                let b = tree.jnt_body[j];
                if tree.joints[b].1 != j + 1 {
                    continue;
                }
                if matches!(jt.kind, JointType::Hinge) {
                    assert!((frames.axis[j] - frames.xrot[b] * jt.axis).norm() < 1e-12, "joint {j}");
                }
                if !matches!(jt.kind, JointType::Free | JointType::Slide) {
                    let anchor = frames.xpos[b] + frames.xrot[b] * jt.pos;
                    assert!((frames.anchor[j] - anchor).norm() < 1e-12, "joint {j}");
                }
            }
        }
    }

    #[test]
    fn euler_conversions_match_nalgebra_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut angle = |zero: bool| if zero { 0.0 } else { rng.random_range(-4.0..4.0) };
        for k in 0..4000 {
            // Every pattern of zero angles, as the walker passes them (and -0).
            let (r, p, y) = (angle(k & 1 != 0), angle(k & 2 != 0), angle(k & 4 != 0));
            let r = if k & 8 != 0 { -r } else { r };
            let q = euler_quat(r, p, y);
            assert_eq!(q.coords, UnitQuaternion::from_euler_angles(r, p, y).coords, "{r} {p} {y}");
            assert_eq!(yaw_of(&q).to_bits(), q.euler_angles().2.to_bits(), "{r} {p} {y}");
        }
        // Pitch ±90°: nalgebra's gimbal-lock branches give yaw 0.
        for p in [std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2] {
            let q = UnitQuaternion::from_euler_angles(0.3, p, 0.2);
            assert_eq!(yaw_of(&q).to_bits(), q.euler_angles().2.to_bits());
        }
    }

    #[test]
    fn half_angle_is_the_half_angles_sine_and_cosine_up_to_sign() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(10);
        let quarter = std::f64::consts::FRAC_PI_4;
        let edges = (-16..=16).flat_map(|k| [-1e-12, 0.0, 1e-12].map(|e| k as f64 * quarter + e));
        let random = (0..100_000).map(|_| rng.random_range(-10.0..10.0));
        for x in edges.chain(random).chain([1e-300, -3e-9]) {
            let (s, c) = half_angle(x.sin_cos());
            let (ws, wc) = (0.5 * x).sin_cos();
            let sign = if s * ws + c * wc >= 0.0 { 1.0 } else { -1.0 };
            assert!((s - sign * ws).abs() <= 1e-15 && (c - sign * wc).abs() <= 1e-15, "{x}: {s} {c} / {ws} {wc}");
        }
    }

    #[test]
    fn subtree_runs_agree_with_the_parent_chain() {
        let (model, _) = humanoid_legs();
        let tree = Tree::new(&model);
        assert_eq!(tree.subtree_last.len(), model.nbody(), "MuJoCo numbers bodies depth first");
        let walk_up = |mut b: usize, ancestor: usize| loop {
            if b == ancestor {
                return true;
            }
            if b == 0 {
                return false;
            }
            b = tree.parent[b];
        };
        for a in 0..model.nbody() {
            for b in 0..model.nbody() {
                assert_eq!(tree.is_below(b, a), walk_up(b, a), "body {b} below {a}");
            }
        }
        // Not depth first: no runs (the parent chain is walked instead).
        assert!(depth_first_runs(&[0, 0, 0, 1]).is_empty());
        assert_eq!(depth_first_runs(&[0, 0, 1, 0]), vec![3, 2, 2, 3]);
    }

    #[test]
    fn closed_form_ik_of_the_humanoid_matches_forward_kinematics() {
        let (model, legs) = humanoid_legs();
        for (seed, leg) in legs.iter().enumerate() {
            closed_form_matches_kinematics(&LegIk::new(&model, leg), seed as u64);
        }
    }

    #[test]
    fn closed_form_ik_of_a_skewed_leg_matches_forward_kinematics() {
        let (model, leg) = skewed_leg(0.0);
        closed_form_matches_kinematics(&LegIk::new(&model, &leg), 3);
    }

    #[test]
    fn leg_with_offset_hip_axes_is_solved_by_least_squares() {
        let (model, leg) = skewed_leg(0.02);
        let ik = LegIk::new(&model, &leg);
        assert!(!ik.is_closed_form(), "the third hip axis passes 2 cm from the others");
        let want = [0.1, -0.1, 0.2, 0.8, -0.3, 0.1];
        let target = ik.foot_pose(&want);
        let mut q = [0.0, 0.0, 0.0, 0.5, 0.0, 0.0];
        let r = ik.solve(target, &mut q, 100, 1e-4);
        assert!(r.position_error_m < 1e-6 && r.rotation_error_rad < 1e-5, "{r:?}");
    }

    /// Out of reach (1 m below the foot): the leg straight and pointed at the target, the
    /// foot turned as asked, the remaining distance reported.
    #[test]
    fn unreachable_target_stretches_the_leg_toward_it() {
        let (model, legs) = humanoid_legs();
        let ik = LegIk::new(&model, &legs[0]);
        let cf = ik.closed_form.clone().unwrap();
        // The humanoid's foot frame is at its ankle centre.
        assert!((cf.foot0.0 - cf.ankle).norm() < 1e-12);
        let mut q: Vec<f64> = ik.qpos0.clone();
        ik.bend_knee(&mut q, 0.5);
        let (home_pos, home_rot) = ik.foot_pose(&q);
        let target = (home_pos + Vector3::new(0.0, 0.0, -1.0), home_rot);
        let warm: [f64; 6] = std::array::from_fn(|k| q[k] - ik.qpos0[k]);
        assert!(!cf.solve(&target, &warm).2, "out of reach");
        let r = ik.solve(target, &mut q, 1, 1e-3);
        let (p, rot) = ik.foot_pose(&q);
        assert!((r.position_error_m - (target.0 - p).norm()).abs() < 1e-12, "{r:?}");
        assert!(r.rotation_error_rad < 1e-9 && (rot * target.1.inverse()).angle() < 1e-9, "{r:?}");
        let (leg, aim) = (p - cf.hip, target.0 - cf.hip);
        assert!(leg.cross(&aim).norm() / aim.norm() < 1e-9, "pointed at the target: {leg} {aim}");
        // Straight: the leg as long as its thigh and shin (0.28 m each).
        assert!((leg.norm() - 0.56).abs() < 1e-9, "{}", leg.norm());
        assert!((r.position_error_m - (aim.norm() - 0.56)).abs() < 1e-9, "{r:?}");
        for k in 0..6 {
            assert!((ik.range[k][0]..=ik.range[k][1]).contains(&q[k]), "joint {k}: {q:?}");
        }
    }

    /// The held steps' map (`LegIk::base_motion_map`) is the IK's own answer to a small pelvis
    /// motion with the foot held: each column against the solved angles' change for a 1-mm /
    /// 1-mrad move of the base, within a per cent of the largest entry.
    #[test]
    fn base_motion_map_matches_the_ik_of_a_moved_pelvis() {
        let (model, legs) = humanoid_legs();
        for leg in &legs {
            let ik = LegIk::new(&model, leg);
            let n = ik.len();
            // A crouched stance: knee bent, hip and ankle pitched against it.
            let mut q: Vec<f64> = (0..n).map(|k| model.qpos0()[ik.qpos_adr(k)]).collect();
            ik.bend_knee(&mut q, 0.6);
            let (p, r) = ik.foot_pose(&q);
            let mut map = vec![[0.0; 6]; n];
            ik.base_motion_map(&q, 1e-3, &mut map);
            let biggest = map.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs()));
            assert!(biggest > 0.5, "{map:?}");
            let h = 1e-3;
            for j in 0..6 {
                // The base moved by `h` along (or about) axis j: the foot's pose in its frame.
                let e = Vector3::ith(j % 3, h);
                let target = if j < 3 {
                    (p - e, r)
                } else {
                    let turn = UnitQuaternion::from_scaled_axis(e).inverse();
                    (turn * p, turn * r)
                };
                let mut moved = q.clone();
                let res = ik.solve(target, &mut moved, 50, 1e-6);
                assert!(res.position_error_m < 1e-7, "{res:?}");
                for (k, ((after, before), row)) in moved.iter().zip(&q).zip(&map).enumerate() {
                    let fd = (after - before) / h;
                    assert!((fd - row[j]).abs() < 0.01 * biggest, "joint {k}, axis {j}: {fd} vs {}", row[j]);
                }
            }
        }
    }
}
