//! Kinematics of the walker, computed from the model's constants (no `mjData`): the whole-tree
//! forward kinematics (body frames, centre of mass, per-body subtree CoM for gravity
//! compensation), the legs found in the tree, and leg inverse kinematics by damped least
//! squares on each leg's geometric Jacobian.
//!
//! Doing this in the controller, on its own small arrays, keeps it independent of the
//! simulation's `mjData` (the controller sees only an [`crate::control::Observation`]) and costs
//! a few microseconds per tick.

use crate::error::{Error, Result};
use crate::mj::{JointType, Model, ObjType};
use nalgebra::{Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

/// Unit quaternion from MuJoCo's `w x y z`.
pub fn quat(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// Rotation by `angle` (radians) about the unit vector `axis`: one `sin_cos`, where
/// `UnitQuaternion::from_scaled_axis` also takes a norm and normalizes (MuJoCo's joint axes are
/// unit vectors already).
fn hinge_rotation(axis: &Vector3<f64>, angle: f64) -> UnitQuaternion<f64> {
    let (s, c) = (0.5 * angle).sin_cos();
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
}

/// The kinematic tree of a model.
#[derive(Debug, Clone)]
pub struct Tree {
    parent: Vec<usize>,
    body_pos: Vec<Vector3<f64>>,
    body_rot: Vec<UnitQuaternion<f64>>,
    body_ipos: Vec<Vector3<f64>>,
    mass: Vec<f64>,
    joints: Vec<Vec<usize>>,
    joint: Vec<Joint>,
    jnt_body: Vec<usize>,
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
                Joint {
                    kind: model.joint_type(j),
                    qpos_adr,
                    qpos0: model.qpos0()[qpos_adr],
                    axis: Vector3::from(model.jnt_axis()[j]).normalize(),
                    pos: Vector3::from(model.jnt_pos()[j]),
                }
            })
            .collect();
        let joints = (0..nbody)
            .map(|b| {
                let adr = model.body_jntadr()[b];
                let n = model.body_jntnum()[b];
                if adr < 0 { Vec::new() } else { (adr as usize..(adr + n) as usize).collect() }
            })
            .collect();
        Tree {
            parent: model.body_parentid().iter().map(|&p| p as usize).collect(),
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
        for b in 1..self.parent.len() {
            let p = self.parent[b];
            let mut rot = out.xrot[p] * self.body_rot[b];
            let mut pos = out.xpos[p] + out.xrot[p] * self.body_pos[b];
            for &j in &self.joints[b] {
                let jt = &self.joint[j];
                let a = jt.qpos_adr;
                match jt.kind {
                    JointType::Free => {
                        pos = Vector3::new(qpos[a], qpos[a + 1], qpos[a + 2]);
                        rot = quat([qpos[a + 3], qpos[a + 4], qpos[a + 5], qpos[a + 6]]);
                        out.anchor[j] = pos;
                        out.axis[j] = Vector3::z();
                    }
                    JointType::Ball => {
                        let anchor = pos + rot * jt.pos;
                        rot *= quat([qpos[a], qpos[a + 1], qpos[a + 2], qpos[a + 3]]);
                        pos = anchor - rot * jt.pos;
                        out.anchor[j] = anchor;
                        out.axis[j] = Vector3::z();
                    }
                    JointType::Hinge => {
                        let anchor = pos + rot * jt.pos;
                        let axis = rot * jt.axis;
                        rot *= hinge_rotation(&jt.axis, qpos[a] - jt.qpos0);
                        pos = anchor - rot * jt.pos;
                        out.anchor[j] = anchor;
                        out.axis[j] = axis;
                    }
                    JointType::Slide => {
                        let axis = rot * jt.axis;
                        pos += axis * (qpos[a] - jt.qpos0);
                        out.anchor[j] = pos + rot * jt.pos;
                        out.axis[j] = axis;
                    }
                }
            }
            out.xpos[b] = pos;
            out.xrot[b] = rot;
        }
        for b in 0..self.parent.len() {
            out.subtree_mass[b] = self.mass[b];
            out.subtree_com[b] = (out.xpos[b] + out.xrot[b] * self.body_ipos[b]) * self.mass[b];
        }
        for b in (1..self.parent.len()).rev() {
            let p = self.parent[b];
            let (m, c) = (out.subtree_mass[b], out.subtree_com[b]);
            out.subtree_mass[p] += m;
            out.subtree_com[p] += c;
        }
        for b in 0..self.parent.len() {
            let m = out.subtree_mass[b];
            // A massless subtree's centre is its body's inertial frame, as in `mj_comPos`.
            out.subtree_com[b] =
                if m >= 1e-15 { out.subtree_com[b] / m } else { out.xpos[b] + out.xrot[b] * self.body_ipos[b] };
        }
    }

    /// Parent of body `b`.
    pub fn parent(&self, b: usize) -> usize {
        self.parent[b]
    }

    /// Whether body `b` is `ancestor` or below it.
    pub fn is_below(&self, mut b: usize, ancestor: usize) -> bool {
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
    pub fn joint_body(&self, joint: usize) -> usize {
        self.jnt_body[joint]
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
    /// Orientation of the IMU site in the frame of the body it is on.
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
    /// [`crate::robot::imus_of`]; none: the base orientation is used).
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
                .flat_map(|&b| tree.joints[b].iter().copied())
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
            let (bottom_z, half) = geom_bottom(model, &frames, g);
            let foot_rot = frames.xrot[foot];
            let centre_world = Vector3::new(frames.geom_center(model, g).x, frames.geom_center(model, g).y, bottom_z);
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
        let imus = crate::robot::imus_of(model);
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
            site_rot: quat(i.body_from_imu.1),
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
    match model.geom_type()[g] as u32 {
        mujoco_sys::mjtGeom_mjGEOM_BOX => (centre.z - extent(2, size), [extent(0, size), extent(1, size)]),
        mujoco_sys::mjtGeom_mjGEOM_SPHERE => (centre.z - size[0], [size[0], size[0]]),
        _ => {
            let r = model.geom_rbound()[g];
            (centre.z - r, [r * 0.5, r * 0.5])
        }
    }
}

/// Leg inverse kinematics: joint angles placing the foot frame at a pose in the pelvis frame.
#[derive(Debug, Clone)]
pub struct LegIk {
    /// Joint `qpos` addresses.
    qpos_adr: Vec<usize>,
    /// Joint ranges (radians).
    range: Vec<[f64; 2]>,
    /// Per body of the chain: its joints' indices into the chain.
    chain: Vec<(usize, Vec<usize>)>,
    qpos0: Vec<f64>,
    axis: Vec<Vector3<f64>>,
    pos: Vec<Vector3<f64>>,
    body_pos: Vec<Vector3<f64>>,
    body_rot: Vec<UnitQuaternion<f64>>,
    /// The knee: the chain joint farthest from both ends of the leg, and the sign of its
    /// larger range side (the way it bends).
    knee: (usize, f64),
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
        ik
    }

    /// Bends a (nearly) straight knee in the guess `q`: straight legs are singular for IK.
    pub fn bend_knee(&self, q: &mut [f64], angle: f64) {
        let (k, sign) = self.knee;
        if k < q.len() && (q[k] * sign) < angle {
            q[k] = (sign * angle).clamp(self.range[k][0], self.range[k][1]);
        }
    }

    /// Number of joints.
    pub fn len(&self) -> usize {
        self.qpos_adr.len()
    }

    /// Whether the chain is empty.
    pub fn is_empty(&self) -> bool {
        self.qpos_adr.is_empty()
    }

    /// `qpos` address of chain joint `k`.
    pub fn qpos_adr(&self, k: usize) -> usize {
        self.qpos_adr[k]
    }

    /// Foot pose in the pelvis frame for chain angles `q`, and each joint's anchor and axis.
    fn fk(
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

    /// Damped-least-squares IK: updates `q` (the chain's angles, warm start) toward the foot
    /// pose `target` in the pelvis frame, within the joint ranges.
    pub fn solve(
        &self,
        target: (Vector3<f64>, UnitQuaternion<f64>),
        q: &mut [f64],
        iterations: usize,
        damping: f64,
    ) -> IkResult {
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
            // J columns: [a × (p − anchor); a].
            let mut jjt = Matrix6::<f64>::identity() * (damping * damping);
            let mut cols = [Vector6::zeros(); 12];
            for k in 0..n {
                let lin = axes[k].cross(&(p - anchors[k]));
                cols[k] = Vector6::new(lin.x, lin.y, lin.z, axes[k].x, axes[k].y, axes[k].z);
                jjt += cols[k] * cols[k].transpose();
            }
            let Some(y) = jjt.cholesky().map(|c| c.solve(&e)) else { break };
            for k in 0..n {
                let step = cols[k].dot(&y).clamp(-0.5, 0.5);
                q[k] = (q[k] + step).clamp(self.range[k][0], self.range[k][1]);
            }
        }
        result
    }
}
