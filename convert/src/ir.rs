//! URDF (+ `<gazebo>`, `<transmission>`, `ros2_control`) parsed into a small intermediate
//! representation that remembers the line of every element, so later errors can name it.

use crate::error::{Error, Result};
use nalgebra::{UnitQuaternion, Vector3};
use roxmltree::{Document, Node};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// A rigid transform `parent_from_child`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Pose {
    pub xyz: Vector3<f64>,
    pub rot: UnitQuaternion<f64>,
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        xyz: Vector3::new(0.0, 0.0, 0.0),
        rot: UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(1.0, 0.0, 0.0, 0.0)),
    };

    /// From URDF/SDF `xyz` and fixed-axis `rpy` (R = Rz(yaw)·Ry(pitch)·Rx(roll)).
    pub fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Pose {
        Pose { xyz: Vector3::from(xyz), rot: UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]) }
    }

    /// `self * other`: `a_from_c = a_from_b * b_from_c`.
    pub fn then(&self, other: &Pose) -> Pose {
        Pose { xyz: self.xyz + self.rot * other.xyz, rot: self.rot * other.rot }
    }
}

#[derive(Debug, Clone)]
pub(crate) struct Inertial {
    /// `link_from_inertial`.
    pub pose: Pose,
    pub mass: f64,
    /// `[ixx, ixy, ixz, iyy, iyz, izz]` in the inertial frame, kg·m².
    pub inertia: [f64; 6],
    pub inertia_line: u32,
}

#[derive(Debug, Clone)]
pub(crate) enum Shape {
    Box([f64; 3]),
    Cylinder { radius: f64, length: f64 },
    Capsule { radius: f64, length: f64 },
    Sphere(f64),
    Mesh { filename: String, scale: [f64; 3], line: u32 },
}

#[derive(Debug, Clone)]
pub(crate) struct GeomIr {
    /// `link_from_geom`.
    pub pose: Pose,
    pub shape: Shape,
    pub rgba: Option<[f64; 4]>,
    pub line: u32,
}

#[derive(Debug, Clone)]
pub(crate) struct LinkIr {
    pub name: String,
    pub line: u32,
    pub inertial: Option<Inertial>,
    pub visuals: Vec<GeomIr>,
    pub collisions: Vec<GeomIr>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum JointKind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
    Floating,
    Planar,
    Spherical,
}

#[derive(Debug, Clone)]
pub(crate) struct Limit {
    pub lower: f64,
    pub upper: f64,
    pub effort: f64,
    pub velocity: f64,
}

#[derive(Debug, Clone)]
pub(crate) struct Mimic {
    pub joint: String,
    pub multiplier: f64,
    pub offset: f64,
    pub line: u32,
}

#[derive(Debug, Clone)]
pub(crate) struct JointIr {
    pub name: String,
    pub kind: JointKind,
    pub parent: String,
    pub child: String,
    /// `parent_from_joint` (= `parent_from_child`).
    pub origin: Pose,
    pub axis: Vector3<f64>,
    pub limit: Option<Limit>,
    pub damping: f64,
    pub friction: f64,
    pub mimic: Option<Mimic>,
    pub line: u32,
}

/// What a joint's controller commands (`hardwareInterface` / ros2_control `command_interface`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interface {
    /// Torque / force command → MuJoCo `motor`.
    Effort,
    /// Position command → MuJoCo `position` servo.
    Position,
    /// Velocity command → MuJoCo `velocity` servo.
    Velocity,
}

#[derive(Debug, Clone)]
pub(crate) struct Drive {
    pub interface: Interface,
    pub gear: f64,
    /// Command limits from ros2_control `<param name="min|max">`.
    pub cmd_range: Option<[f64; 2]>,
}

/// A `<sensor>` inside `<gazebo reference="…">`.
#[derive(Debug, Clone)]
pub(crate) struct SensorIr {
    pub name: String,
    pub kind: String,
    /// Link or joint named by the enclosing `<gazebo reference>`.
    pub reference: String,
    /// `reference_from_sensor`.
    pub pose: Pose,
    pub update_rate_hz: Option<f64>,
    pub line: u32,
    /// ROS topic from the sensor's plugin or `<topic>`.
    pub topic: Option<String>,
    /// The plugin's `frame_name`.
    pub frame_name: Option<String>,
    /// IMU gyroscope / accelerometer white-noise standard deviations (0 when none).
    pub gyro_noise_std: f64,
    pub accel_noise_std: f64,
    /// IMU gyroscope / accelerometer bias terms.
    pub gyro_bias: super::ImuBias,
    pub accel_bias: super::ImuBias,
    /// `<camera>` children.
    pub cameras: Vec<CameraIr>,
    /// `<ray>` / `<lidar>` scan.
    pub ray: Option<RayIr>,
    /// A contact sensor over every collision geom of its link, not the first alone (one asked
    /// for by `ConvertOptions::contact_sensors`).
    pub every_collision: bool,
}

#[derive(Debug, Clone)]
pub(crate) struct CameraIr {
    /// Horizontal field of view, radians.
    pub hfov: f64,
    pub width: f64,
    pub height: f64,
    /// `sensor_from_camera` (Gazebo convention: view along +X).
    pub pose: Pose,
    /// `<clip><near>`, `<far>`, metres.
    pub clip_m: Option<[f64; 2]>,
    /// `<noise><stddev>`, metres for depth, fraction of full scale for colour (0 when none).
    pub noise_std: f64,
    /// `<distortion>` k1 k2 k3 p1 p2 (Brown–Conrady), when given.
    pub distortion: Option<[f64; 5]>,
}

#[derive(Debug, Clone)]
pub(crate) struct RayIr {
    /// (samples, min angle, max angle), radians.
    pub horizontal: (usize, f64, f64),
    pub vertical: (usize, f64, f64),
    pub min_range_m: f64,
    pub max_range_m: f64,
    /// `<noise><stddev>`, metres (0 when none).
    pub noise_std: f64,
}

/// A ros_control `DifferentialTransmission` or PAL's `HalfDifferentialTransmission`.
#[derive(Debug, Clone)]
pub(crate) struct DifferentialIr {
    pub name: String,
    /// Half differential: joint 1 is driven by actuator 1 alone.
    pub half: bool,
    /// (joint, mechanical reduction, offset) by role (joint1, joint2).
    pub joints: [(String, f64, f64); 2],
    /// (actuator, mechanical reduction) by role (actuator1, actuator2).
    pub actuators: [(String, f64); 2],
    pub interface: Interface,
    pub line: u32,
}

impl DifferentialIr {
    /// `coef[a][j]`: torque on joint `j` per unit effort of actuator `a`, as ros_control maps it
    /// (`actuatorToJointEffort`). Differential: τj1 = jr1·(ar1·τa1 + ar2·τa2),
    /// τj2 = jr2·(ar1·τa1 − ar2·τa2). Half differential: τj1 = jr1·ar1·τa1,
    /// τj2 = jr2·(ar1·τa1 + ar2·τa2).
    pub fn coefficients(&self) -> [[f64; 2]; 2] {
        let (jr1, jr2) = (self.joints[0].1, self.joints[1].1);
        let (ar1, ar2) = (self.actuators[0].1, self.actuators[1].1);
        if self.half {
            [[jr1 * ar1, jr2 * ar1], [0.0, jr2 * ar2]]
        } else {
            [[jr1 * ar1, jr2 * ar1], [jr1 * ar2, -jr2 * ar2]]
        }
    }
}

#[derive(Debug, Clone, Default)]
pub(crate) struct GazeboLink {
    pub mu1: Option<f64>,
    pub mu2: Option<f64>,
    pub kp: Option<f64>,
    pub kd: Option<f64>,
    pub material: Option<String>,
    pub self_collide: Option<bool>,
    /// Gazebo `minDepth`, metres.
    pub min_depth: Option<f64>,
    /// Gazebo `fdir1` (first friction direction), as written.
    pub fdir1: Option<String>,
    /// The reference names a joint, not a link.
    pub is_joint: bool,
    pub line: u32,
}

#[derive(Debug)]
pub(crate) struct RobotIr {
    pub path: PathBuf,
    pub name: String,
    pub links: Vec<LinkIr>,
    pub joints: Vec<JointIr>,
    pub gazebo: HashMap<String, GazeboLink>,
    pub sensors: Vec<SensorIr>,
    pub drives: HashMap<String, Drive>,
    pub differentials: Vec<DifferentialIr>,
    pub notes: Vec<String>,
}

/// Error helper bound to one file.
pub(crate) struct Ctx<'a, 'i> {
    pub path: &'a Path,
    pub doc: &'a Document<'i>,
}

impl<'a, 'i> Ctx<'a, 'i> {
    pub fn line(&self, node: Node<'_, '_>) -> u32 {
        self.doc.text_pos_at(node.range().start).row
    }

    pub fn err(&self, node: Node<'_, '_>, message: impl Into<String>) -> Error {
        let owner = node
            .ancestors()
            .find(|n| {
                n.has_tag_name("link") || n.has_tag_name("joint") || n.has_tag_name("model") || n.has_tag_name("sensor")
            })
            .and_then(|n| n.attribute("name"))
            .map(str::to_string);
        Error::Urdf {
            path: self.path.to_path_buf(),
            line: self.line(node),
            element: node.tag_name().name().to_string(),
            name: owner,
            message: message.into(),
        }
    }

    /// The `name` of a `<link>` or `<joint>` (`node`), and its line, recorded in `seen` (name →
    /// line); an element without a name, or with one already in `seen`, is an error naming both
    /// lines.
    pub fn unique_name(&self, node: Node<'_, '_>, seen: &mut HashMap<String, u32>) -> Result<(String, u32)> {
        let tag = node.tag_name().name();
        let name = node
            .attribute("name")
            .ok_or_else(|| self.err(node, format!("<{tag}> without name: every {tag} needs a unique name")))?
            .to_string();
        let line = self.line(node);
        if let Some(prev) = seen.insert(name.clone(), line) {
            return Err(self.err(node, format!("duplicate {tag} name \"{name}\" (first at line {prev}): rename one")));
        }
        Ok((name, line))
    }

    /// A finite number attribute, or `default` when absent.
    pub fn num(&self, node: Node<'_, '_>, attr: &str, default: Option<f64>) -> Result<f64> {
        match node.attribute(attr) {
            Some(v) => parse_num(v).ok_or_else(|| {
                self.err(node, format!("attribute {attr}=\"{v}\" is not a finite number{}", xacro_hint(v)))
            }),
            None => default.ok_or_else(|| self.err(node, format!("missing required attribute {attr}"))),
        }
    }

    /// A whitespace-separated vector attribute of length `N`.
    pub fn vec<const N: usize>(&self, node: Node<'_, '_>, attr: &str, default: [f64; N]) -> Result<[f64; N]> {
        match node.attribute(attr) {
            Some(v) => parse_vec::<N>(v).ok_or_else(|| {
                self.err(node, format!("attribute {attr}=\"{v}\" must be {N} finite numbers{}", xacro_hint(v)))
            }),
            None => Ok(default),
        }
    }

    /// Text of a child element as a number.
    pub fn child_num(&self, node: Node<'_, '_>, tag: &str) -> Result<Option<f64>> {
        match child(node, tag) {
            Some(c) => {
                let t = c.text().unwrap_or("").trim();
                parse_num(t).map(Some).ok_or_else(|| self.err(c, format!("<{tag}>{t}</{tag}> is not a finite number")))
            }
            None => Ok(None),
        }
    }

    /// `<origin xyz rpy>` child, identity when absent.
    pub fn origin(&self, node: Node<'_, '_>) -> Result<Pose> {
        match child(node, "origin") {
            Some(o) => Ok(Pose::from_xyz_rpy(self.vec(o, "xyz", [0.0; 3])?, self.vec(o, "rpy", [0.0; 3])?)),
            None => Ok(Pose::IDENTITY),
        }
    }
}

fn xacro_hint(v: &str) -> &'static str {
    if v.contains("${") || v.contains("$(") {
        "; this looks like unexpanded xacro: run `xacro robot.urdf.xacro > robot.urdf` first"
    } else {
        ""
    }
}

pub(crate) fn parse_num(v: &str) -> Option<f64> {
    v.trim().parse::<f64>().ok().filter(|x| x.is_finite())
}

pub(crate) fn parse_vec<const N: usize>(v: &str) -> Option<[f64; N]> {
    let mut out = [0.0; N];
    let mut it = v.split_whitespace();
    for slot in &mut out {
        *slot = parse_num(it.next()?)?;
    }
    if it.next().is_some() {
        return None;
    }
    Some(out)
}

pub(crate) fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|n| n.has_tag_name(tag))
}

pub(crate) fn children<'a, 'i>(node: Node<'a, 'i>, tag: &'static str) -> impl Iterator<Item = Node<'a, 'i>> {
    node.children().filter(move |n| n.has_tag_name(tag))
}

pub(crate) fn child_text<'a>(node: Node<'a, '_>, tag: &str) -> Option<&'a str> {
    child(node, tag).and_then(|c| c.text()).map(str::trim)
}

fn parse_geometry(ctx: &Ctx<'_, '_>, g: Node<'_, '_>) -> Result<Shape> {
    let geometry = child(g, "geometry")
        .ok_or_else(|| ctx.err(g, "missing <geometry>: add <geometry> with a box, cylinder, sphere or mesh"))?;
    let shape = geometry
        .children()
        .find(|n| n.is_element())
        .ok_or_else(|| ctx.err(geometry, "empty <geometry>: add a box, cylinder, sphere or mesh"))?;
    let positive = |node: Node<'_, '_>, attr: &str| -> Result<f64> {
        let v = ctx.num(node, attr, None)?;
        if v > 0.0 { Ok(v) } else { Err(ctx.err(node, format!("{attr}=\"{v}\" must be > 0 (metres)"))) }
    };
    Ok(match shape.tag_name().name() {
        "box" => {
            let size = ctx.vec(shape, "size", [f64::NAN; 3])?;
            if size.iter().any(|s| s.is_nan() || *s <= 0.0) {
                return Err(ctx.err(shape, "box needs size=\"x y z\" with three positive lengths (metres)"));
            }
            Shape::Box(size)
        }
        "cylinder" => Shape::Cylinder { radius: positive(shape, "radius")?, length: positive(shape, "length")? },
        "capsule" => Shape::Capsule { radius: positive(shape, "radius")?, length: positive(shape, "length")? },
        "sphere" => Shape::Sphere(positive(shape, "radius")?),
        "mesh" => {
            let filename = shape
                .attribute("filename")
                .ok_or_else(|| ctx.err(shape, "<mesh> without filename attribute: give the mesh file (package://pkg/path or a path relative to the URDF)"))?
                .trim()
                .to_string();
            let scale = match shape.attribute("scale") {
                None => [1.0; 3],
                Some(s) => match parse_vec::<3>(s) {
                    Some(v) => v,
                    // A single number is accepted by some tools.
                    None => match parse_num(s) {
                        Some(x) => [x; 3],
                        None => {
                            return Err(ctx.err(shape, format!("scale=\"{s}\" must be three numbers")));
                        }
                    },
                },
            };
            Shape::Mesh { filename, scale, line: ctx.line(shape) }
        }
        other => {
            return Err(ctx.err(shape, format!("unknown geometry <{other}>: use box, cylinder, sphere or mesh")));
        }
    })
}

fn parse_rgba(ctx: &Ctx<'_, '_>, material: Node<'_, '_>) -> Result<Option<[f64; 4]>> {
    match child(material, "color") {
        Some(c) => Ok(Some(ctx.vec(c, "rgba", [0.5, 0.5, 0.5, 1.0])?)),
        None => Ok(None),
    }
}

/// Parses a URDF document.
pub(crate) fn parse_robot(ctx: &Ctx<'_, '_>) -> Result<RobotIr> {
    let root = ctx.doc.root_element();
    if !root.has_tag_name("robot") {
        return Err(ctx.err(root, "the root element must be <robot>: this is not a URDF file"));
    }
    let mut notes = Vec::new();
    // Global materials.
    let mut materials: HashMap<String, [f64; 4]> = HashMap::new();
    for m in children(root, "material") {
        if let (Some(name), Some(rgba)) = (m.attribute("name"), parse_rgba(ctx, m)?) {
            materials.insert(name.to_string(), rgba);
        }
    }
    let geom_rgba = |g: Node<'_, '_>| -> Result<Option<[f64; 4]>> {
        let Some(m) = child(g, "material") else {
            return Ok(None);
        };
        if let Some(rgba) = parse_rgba(ctx, m)? {
            return Ok(Some(rgba));
        }
        Ok(m.attribute("name").and_then(|n| materials.get(n).copied()))
    };

    let mut links = Vec::new();
    let mut seen_links: HashMap<String, u32> = HashMap::new();
    for l in children(root, "link") {
        let (name, line) = ctx.unique_name(l, &mut seen_links)?;
        let inertial = match child(l, "inertial") {
            None => None,
            Some(i) => {
                let mass_node = child(i, "mass")
                    .ok_or_else(|| ctx.err(i, "<inertial> without <mass value=…>: add the link's mass in kg"))?;
                let mass = ctx.num(mass_node, "value", None)?;
                if mass < 0.0 {
                    return Err(
                        ctx.err(mass_node, format!("negative mass {mass} kg; give the link's real mass in kg (> 0)"))
                    );
                }
                let (inertia, inertia_line) = match child(i, "inertia") {
                    Some(t) => {
                        let mut v = [0.0; 6];
                        for (slot, attr) in v.iter_mut().zip(["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]) {
                            *slot = ctx.num(t, attr, Some(0.0))?;
                        }
                        (v, ctx.line(t))
                    }
                    None => ([0.0; 6], ctx.line(i)),
                };
                Some(Inertial { pose: ctx.origin(i)?, mass, inertia, inertia_line })
            }
        };
        let mut visuals = Vec::new();
        for v in children(l, "visual") {
            match parse_geometry(ctx, v) {
                Ok(shape) => {
                    visuals.push(GeomIr { pose: ctx.origin(v)?, shape, rgba: geom_rgba(v)?, line: ctx.line(v) })
                }
                // A degenerate visual (zero size, a "virtual link" marker) shows nothing: skip.
                Err(Error::Urdf { message, line, .. })
                    if message.contains("must be > 0") || message.contains("three positive") =>
                {
                    notes.push(format!("link \"{name}\" (line {line}): degenerate visual skipped ({message})"));
                }
                Err(e) => return Err(e),
            }
        }
        let mut collisions = Vec::new();
        for c in children(l, "collision") {
            collisions.push(GeomIr {
                pose: ctx.origin(c)?,
                shape: parse_geometry(ctx, c)?,
                rgba: None,
                line: ctx.line(c),
            });
        }
        links.push(LinkIr { name, line, inertial, visuals, collisions });
    }
    if links.is_empty() {
        return Err(ctx.err(root, "the robot has no <link>: a URDF needs at least one link"));
    }

    let mut joints = Vec::new();
    let mut seen_joints: HashMap<String, u32> = HashMap::new();
    for j in children(root, "joint") {
        let (name, line) = ctx.unique_name(j, &mut seen_joints)?;
        let ty = j.attribute("type").unwrap_or("");
        let kind = match ty {
            "revolute" => JointKind::Revolute,
            "continuous" => JointKind::Continuous,
            "prismatic" => JointKind::Prismatic,
            "fixed" => JointKind::Fixed,
            "floating" => JointKind::Floating,
            "planar" => JointKind::Planar,
            "spherical" | "ball" => JointKind::Spherical,
            other => {
                return Err(ctx.err(
                    j,
                    format!(
                        "unknown joint type \"{other}\": use revolute, continuous, prismatic, fixed, floating or planar"
                    ),
                ));
            }
        };
        let link_ref = |tag: &str| -> Result<String> {
            let n =
                child(j, tag).ok_or_else(|| ctx.err(j, format!("joint has no <{tag} link=…>: name the {tag} link")))?;
            let l = n.attribute("link").ok_or_else(|| ctx.err(n, format!("<{tag}> without link attribute")))?;
            if !seen_links.contains_key(l) {
                return Err(ctx
                    .err(n, format!("{tag} link \"{l}\" does not exist: define <link name=\"{l}\"> or fix the name")));
            }
            Ok(l.to_string())
        };
        let parent = link_ref("parent")?;
        let child_link = link_ref("child")?;
        let axis = match child(j, "axis") {
            Some(a) => {
                let v = Vector3::from(ctx.vec(a, "xyz", [1.0, 0.0, 0.0])?);
                let n = v.norm();
                if n < 1e-12 && !matches!(kind, JointKind::Fixed | JointKind::Floating) {
                    return Err(ctx.err(a, "joint axis is zero: give a non-zero axis xyz"));
                }
                if n > 0.0 { v / n } else { v }
            }
            None => Vector3::new(1.0, 0.0, 0.0),
        };
        let limit = match child(j, "limit") {
            Some(l) => {
                let lim = Limit {
                    lower: ctx.num(l, "lower", Some(0.0))?,
                    upper: ctx.num(l, "upper", Some(0.0))?,
                    effort: ctx.num(l, "effort", Some(0.0))?,
                    velocity: ctx.num(l, "velocity", Some(0.0))?,
                };
                if matches!(kind, JointKind::Revolute | JointKind::Prismatic) && lim.lower > lim.upper {
                    return Err(
                        ctx.err(l, format!("lower limit {} is above upper limit {}: swap them", lim.lower, lim.upper))
                    );
                }
                if lim.effort < 0.0 || lim.velocity < 0.0 {
                    return Err(ctx.err(l, "effort and velocity limits must be ≥ 0"));
                }
                Some(lim)
            }
            None => {
                if matches!(kind, JointKind::Revolute | JointKind::Prismatic) {
                    notes.push(format!(
                        "joint \"{name}\" (line {line}) is {ty} but has no <limit>: converted unlimited"
                    ));
                }
                None
            }
        };
        let (damping, friction) = match child(j, "dynamics") {
            Some(d) => (ctx.num(d, "damping", Some(0.0))?, ctx.num(d, "friction", Some(0.0))?),
            None => (0.0, 0.0),
        };
        if damping < 0.0 || friction < 0.0 {
            return Err(ctx.err(child(j, "dynamics").unwrap_or(j), "damping and friction must be ≥ 0"));
        }
        let mimic = match child(j, "mimic") {
            Some(m) => Some(Mimic {
                joint: m
                    .attribute("joint")
                    .ok_or_else(|| ctx.err(m, "<mimic> without joint attribute: name the leader joint"))?
                    .to_string(),
                multiplier: ctx.num(m, "multiplier", Some(1.0))?,
                offset: ctx.num(m, "offset", Some(0.0))?,
                line: ctx.line(m),
            }),
            None => None,
        };
        joints.push(JointIr {
            name,
            kind,
            parent,
            child: child_link,
            origin: ctx.origin(j)?,
            axis,
            limit,
            damping,
            friction,
            mimic,
            line,
        });
    }
    // A mimic of a joint that does not exist (often a missing xacro prefix): the joint moves
    // on its own, as robot_state_publisher and Gazebo treat it.
    for j in &mut joints {
        if let Some(m) = &j.mimic
            && !seen_joints.contains_key(&m.joint)
        {
            notes.push(format!(
                "joint \"{}\": <mimic joint=\"{}\"> (line {}) names no joint of this robot: mimic ignored, the joint moves on its own",
                j.name, m.joint, m.line
            ));
            j.mimic = None;
        }
    }

    // <gazebo> extensions. Gazebo ignores what it does not understand: so does the converter,
    // with a note each.
    let mut gazebo: HashMap<String, GazeboLink> = HashMap::new();
    let mut sensors = Vec::new();
    for g in children(root, "gazebo") {
        match g.attribute("reference") {
            None => {
                for p in children(g, "plugin") {
                    let file = p.attribute("filename").unwrap_or("");
                    if file.contains("ros2_control") || file.contains("ros_control") {
                        notes.push(format!(
                            "<gazebo> plugin {file} (line {}): replaced by MuJoCo actuators from the transmissions / ros2_control",
                            ctx.line(p)
                        ));
                    } else {
                        notes.push(format!(
                            "<gazebo> plugin {file} (line {}) has no MuJoCo equivalent: ignored",
                            ctx.line(p)
                        ));
                    }
                }
            }
            Some(reference) => {
                let is_link = seen_links.contains_key(reference);
                let is_joint = seen_joints.contains_key(reference);
                if !is_link && !is_joint {
                    let why = if reference.contains('{') || reference.contains('$') {
                        "an unexpanded xacro name"
                    } else {
                        "no link or joint of this robot"
                    };
                    notes.push(format!(
                        "<gazebo reference=\"{reference}\"> (line {}) names {why}: ignored, as Gazebo does",
                        ctx.line(g)
                    ));
                    continue;
                }
                let entry = gazebo.entry(reference.to_string()).or_default();
                entry.line = ctx.line(g);
                entry.is_joint = !is_link;
                let mut num = |tag: &str| -> Option<f64> {
                    let c = child(g, tag)?;
                    let t = c.text().unwrap_or("").trim();
                    match parse_num(t) {
                        Some(v) => Some(v),
                        None => {
                            notes.push(format!(
                                "<gazebo reference=\"{reference}\"> (line {}): <{tag}>{t}</{tag}> is not a number{}: ignored (Gazebo's default applies)",
                                ctx.line(c),
                                xacro_hint(t)
                            ));
                            None
                        }
                    }
                };
                if let Some(v) = num("mu1") {
                    entry.mu1 = Some(v);
                }
                if let Some(v) = num("mu2") {
                    entry.mu2 = Some(v);
                }
                if let Some(v) = num("kp") {
                    entry.kp = Some(v);
                }
                if let Some(v) = num("kd") {
                    entry.kd = Some(v);
                }
                if let Some(v) = num("minDepth") {
                    entry.min_depth = Some(v);
                }
                if let Some(f) = child_text(g, "fdir1") {
                    entry.fdir1 = Some(f.to_string());
                }
                if let Some(m) = child(g, "material") {
                    let text = m.text().unwrap_or("").trim();
                    if !text.is_empty() {
                        entry.material = Some(text.to_string());
                    } else if let Some(n) =
                        child_text(m, "name").or_else(|| child(m, "script").and_then(|s| child_text(s, "name")))
                    {
                        entry.material = Some(n.to_string());
                    }
                }
                if let Some(t) = child_text(g, "selfCollide") {
                    entry.self_collide = Some(t == "true" || t == "1");
                }
                for s in children(g, "sensor") {
                    sensors.push(parse_sensor(ctx, s, reference)?);
                }
            }
        }
    }

    // Transmissions (ROS 1 and ROS 2 style) and ros2_control.
    let mut drives: HashMap<String, Drive> = HashMap::new();
    let interface_of = |text: &str| -> Option<Interface> {
        let t = text.to_ascii_lowercase();
        if t.contains("effort") {
            Some(Interface::Effort)
        } else if t.contains("position") {
            Some(Interface::Position)
        } else if t.contains("velocity") {
            Some(Interface::Velocity)
        } else {
            None
        }
    };
    let mut differentials: Vec<DifferentialIr> = Vec::new();
    // The command interface named by a transmission joint/actuator: the first one that
    // commands something (ROS 1 `JointStateInterface` only reads state).
    let command_interface = |nodes: &[Node<'_, '_>]| -> (Option<Interface>, Vec<String>) {
        let mut unknown = Vec::new();
        for n in nodes {
            for h in children(*n, "hardwareInterface") {
                let text = h.text().unwrap_or("").trim();
                match interface_of(text) {
                    Some(i) => return (Some(i), unknown),
                    None => unknown.push(text.to_string()),
                }
            }
        }
        (None, unknown)
    };
    let reduction = |n: Node<'_, '_>| -> Result<f64> {
        let Some(r) = child(n, "mechanicalReduction") else { return Ok(1.0) };
        let text = r.text().unwrap_or("").trim();
        let g = parse_num(text)
            .ok_or_else(|| ctx.err(r, format!("mechanicalReduction \"{text}\" is not a number{}", xacro_hint(text))))?;
        if g == 0.0 {
            return Err(ctx.err(r, "mechanicalReduction must not be 0: give the gear ratio (1 for direct drive)"));
        }
        Ok(g)
    };
    for t in children(root, "transmission") {
        let tname = t.attribute("name").unwrap_or("").to_string();
        let tline = ctx.line(t);
        let ty = child_text(t, "type").or(t.attribute("type")).unwrap_or("").to_string();
        let tjoints: Vec<Node<'_, '_>> = children(t, "joint").collect();
        let tacts: Vec<Node<'_, '_>> = children(t, "actuator").collect();
        let mut known_joints = Vec::new();
        for tj in &tjoints {
            let jname = tj.attribute("name").ok_or_else(|| ctx.err(*tj, "transmission <joint> without name"))?;
            if seen_joints.contains_key(jname) {
                known_joints.push(*tj);
            } else {
                notes.push(format!(
                    "transmission \"{tname}\" (line {}) names joint \"{jname}\", which does not exist{}: ignored",
                    ctx.line(*tj),
                    if jname.contains("${") || jname.contains('{') { " (unexpanded xacro name)" } else { "" }
                ));
            }
        }
        if known_joints.len() != tjoints.len() || tjoints.is_empty() {
            if tjoints.is_empty() {
                notes.push(format!("transmission \"{tname}\" (line {tline}) of type {ty} names no <joint>: ignored"));
            }
            continue;
        }
        let (iface, unknown) = command_interface(&[tjoints.as_slice(), tacts.as_slice()].concat());
        for u in unknown {
            if !u.contains("JointStateInterface") {
                notes.push(format!(
                    "transmission \"{tname}\" (line {tline}): hardwareInterface \"{u}\" is not a command interface twin knows (Effort/Position/Velocity); skipped"
                ));
            }
        }
        let Some(interface) = iface else {
            notes.push(format!(
                "transmission \"{tname}\" (line {tline}) declares no command interface (only state interfaces): no actuator from it"
            ));
            continue;
        };
        let is_diff = ty.ends_with("DifferentialTransmission");
        if is_diff && tjoints.len() == 2 && tacts.len() == 2 {
            let role = |n: Node<'_, '_>, base: &str, k: usize| -> usize {
                match child_text(n, "role") {
                    Some(r) if r == format!("{base}1") => 0,
                    Some(r) if r == format!("{base}2") => 1,
                    _ => k,
                }
            };
            let mut joints_d: [(String, f64, f64); 2] = Default::default();
            let mut acts_d: [(String, f64); 2] = Default::default();
            for (k, tj) in tjoints.iter().enumerate() {
                let offset = match child(*tj, "offset") {
                    Some(o) => {
                        let text = o.text().unwrap_or("").trim();
                        parse_num(text).ok_or_else(|| ctx.err(o, format!("<offset>{text}</offset> is not a number")))?
                    }
                    None => 0.0,
                };
                joints_d[role(*tj, "joint", k)] =
                    (tj.attribute("name").unwrap_or("").to_string(), reduction(*tj)?, offset);
            }
            for (k, ta) in tacts.iter().enumerate() {
                acts_d[role(*ta, "actuator", k)] = (
                    ta.attribute("name").map(str::to_string).unwrap_or_else(|| format!("{tname}_actuator{}", k + 1)),
                    reduction(*ta)?,
                );
            }
            differentials.push(DifferentialIr {
                name: tname,
                half: ty.ends_with("HalfDifferentialTransmission"),
                joints: joints_d,
                actuators: acts_d,
                interface,
                line: tline,
            });
            continue;
        }
        if tjoints.len() != 1 || tacts.len() > 1 {
            notes.push(format!(
                "transmission \"{tname}\" (line {tline}) of type {ty} with {} joints and {} actuators is not converted; its joints get the actuators that --actuators gives untransmitted joints",
                tjoints.len(),
                tacts.len()
            ));
            continue;
        }
        if !ty.contains("SimpleTransmission") {
            notes.push(format!(
                "transmission \"{tname}\" (line {tline}) of type {ty}: one joint, one actuator: converted as a SimpleTransmission (reducer)"
            ));
        }
        let tj = tjoints[0];
        let jname = tj.attribute("name").unwrap_or("");
        let reduction_node = tacts.first().copied().filter(|a| child(*a, "mechanicalReduction").is_some()).unwrap_or(t);
        let gear = reduction(reduction_node)?;
        drives.insert(jname.to_string(), Drive { interface, gear, cmd_range: None });
    }
    for rc in children(root, "ros2_control") {
        for j in children(rc, "joint") {
            let Some(jname) = j.attribute("name") else {
                continue;
            };
            if !seen_joints.contains_key(jname) {
                notes.push(format!(
                    "ros2_control joint \"{jname}\" (line {}) does not exist in the URDF: ignored",
                    ctx.line(j)
                ));
                continue;
            }
            let cmds: Vec<Node<'_, '_>> = children(j, "command_interface").collect();
            let Some(cmd) = cmds.first() else { continue };
            let iname = cmd.attribute("name").unwrap_or("");
            let Some(interface) = interface_of(iname) else {
                notes.push(format!("ros2_control joint \"{jname}\": command interface \"{iname}\" not converted"));
                continue;
            };
            if cmds.len() > 1 {
                notes.push(format!(
                    "ros2_control joint \"{jname}\" has {} command interfaces: the first ({iname}) becomes its actuator",
                    cmds.len()
                ));
            }
            let mut lo = None;
            let mut hi = None;
            for p in children(*cmd, "param") {
                let v = p.text().and_then(parse_num);
                match p.attribute("name") {
                    Some("min") => lo = v,
                    Some("max") => hi = v,
                    _ => {}
                }
            }
            let cmd_range = match (lo, hi) {
                (Some(a), Some(b)) if a < b => Some([a, b]),
                _ => None,
            };
            let entry = drives.entry(jname.to_string()).or_insert(Drive { interface, gear: 1.0, cmd_range: None });
            if entry.interface != interface {
                notes.push(format!(
                    "joint \"{jname}\": ros2_control commands {interface:?} but its transmission says {:?}; ros2_control wins",
                    entry.interface
                ));
                entry.interface = interface;
            }
            entry.cmd_range = cmd_range;
        }
    }

    Ok(RobotIr {
        path: ctx.path.to_path_buf(),
        name: root.attribute("name").unwrap_or("robot").to_string(),
        links,
        joints,
        gazebo,
        sensors,
        drives,
        differentials,
        notes,
    })
}
/// A Gazebo `<sensor>` with everything the conversion needs from it.
fn parse_sensor(ctx: &Ctx<'_, '_>, s: Node<'_, '_>, reference: &str) -> Result<SensorIr> {
    let kind = s.attribute("type").unwrap_or("").to_string();
    let name = s.attribute("name").map(str::to_string).unwrap_or_else(|| format!("{reference}_{kind}"));
    let pose = match child_text(s, "pose") {
        Some(t) => {
            let v = parse_vec::<6>(t).ok_or_else(|| {
                ctx.err(child(s, "pose").unwrap_or(s), "<pose> must be 6 numbers: x y z roll pitch yaw")
            })?;
            Pose::from_xyz_rpy([v[0], v[1], v[2]], [v[3], v[4], v[5]])
        }
        None => Pose::IDENTITY,
    };
    let update_rate_hz = match child(s, "update_rate") {
        Some(c) => {
            let t = c.text().unwrap_or("").trim();
            Some(parse_num(t).ok_or_else(|| {
                ctx.err(c, format!("<update_rate>{t}</update_rate> is not a number: give the rate in Hz"))
            })?)
        }
        None => None,
    };
    let (gyro_noise_std, accel_noise_std) = imu_noise(s);
    let (gyro_bias, accel_bias) = imu_bias(s);
    let frame_name = child(s, "plugin")
        .and_then(|p| child_text(p, "frame_name").or_else(|| child_text(p, "frameName")))
        .map(str::to_string);
    let cameras = children(s, "camera")
        .map(|cam| {
            let img = child(cam, "image");
            CameraIr {
                hfov: child_text(cam, "horizontal_fov").and_then(parse_num).unwrap_or(1.047),
                width: img.and_then(|i| child_text(i, "width")).and_then(parse_num).unwrap_or(320.0),
                height: img.and_then(|i| child_text(i, "height")).and_then(parse_num).unwrap_or(240.0),
                pose: match child_text(cam, "pose").and_then(parse_vec::<6>) {
                    Some(v) => Pose::from_xyz_rpy([v[0], v[1], v[2]], [v[3], v[4], v[5]]),
                    None => Pose::IDENTITY,
                },
                clip_m: child(cam, "clip").and_then(|c| {
                    Some([child_text(c, "near").and_then(parse_num)?, child_text(c, "far").and_then(parse_num)?])
                }),
                noise_std: child(cam, "noise").and_then(|n| child_text(n, "stddev")).and_then(parse_num).unwrap_or(0.0),
                distortion: child(cam, "distortion").map(|d| {
                    ["k1", "k2", "k3", "p1", "p2"].map(|k| child_text(d, k).and_then(parse_num).unwrap_or(0.0))
                }),
            }
        })
        .collect();
    let ray = child(s, "ray").or_else(|| child(s, "lidar")).map(|r| {
        let scan = child(r, "scan");
        let axis = |tag: &str| -> (usize, f64, f64) {
            let a = scan.and_then(|s| child(s, tag));
            let samples = a.and_then(|a| child_text(a, "samples")).and_then(parse_num).unwrap_or(1.0).max(1.0) as usize;
            let lo = a.and_then(|a| child_text(a, "min_angle")).and_then(parse_num).unwrap_or(0.0);
            let hi = a.and_then(|a| child_text(a, "max_angle")).and_then(parse_num).unwrap_or(0.0);
            (samples, lo, hi)
        };
        RayIr {
            horizontal: axis("horizontal"),
            vertical: axis("vertical"),
            min_range_m: child(r, "range").and_then(|r| child_text(r, "min")).and_then(parse_num).unwrap_or(0.0),
            max_range_m: child(r, "range").and_then(|r| child_text(r, "max")).and_then(parse_num).unwrap_or(10.0),
            noise_std: child(r, "noise").and_then(|n| child_text(n, "stddev")).and_then(parse_num).unwrap_or(0.0),
        }
    });
    Ok(SensorIr {
        name,
        kind,
        reference: reference.to_string(),
        pose,
        update_rate_hz,
        line: ctx.line(s),
        topic: resolve_topic(s),
        frame_name,
        gyro_noise_std,
        accel_noise_std,
        gyro_bias,
        accel_bias,
        cameras,
        ray,
        every_collision: false,
    })
}

/// Gyro and accelerometer noise standard deviations of a Gazebo `<sensor type="imu">`.
fn imu_noise(sensor: Node<'_, '_>) -> (f64, f64) {
    let Some(imu) = child(sensor, "imu") else {
        return (0.0, 0.0);
    };
    let stddev_under = |n: Option<Node<'_, '_>>| -> f64 {
        n.map(|n| {
            n.descendants()
                .filter(|d| d.has_tag_name("stddev"))
                .filter_map(|d| d.text().and_then(parse_num))
                .fold(0.0, f64::max)
        })
        .unwrap_or(0.0)
    };
    let mut gyro = stddev_under(child(imu, "angular_velocity"));
    let mut accel = stddev_under(child(imu, "linear_acceleration"));
    // Gazebo classic's older form: <imu><noise><rate><stddev>, <accel><stddev>.
    if let Some(n) = child(imu, "noise") {
        gyro = gyro.max(stddev_under(child(n, "rate")));
        accel = accel.max(stddev_under(child(n, "accel")));
    }
    (gyro, accel)
}

/// Gazebo IMU bias tags (`bias_mean`, `bias_stddev`, `dynamic_bias_stddev`,
/// `dynamic_bias_correlation_time`, and twin's `bias_random_walk`) of the gyroscope and the
/// accelerometer, the largest over the axes; leniently like Gazebo: an unparsable or negative
/// value counts as absent.
fn imu_bias(sensor: Node<'_, '_>) -> (super::ImuBias, super::ImuBias) {
    let Some(imu) = child(sensor, "imu") else {
        return Default::default();
    };
    let under = |groups: &[Option<Node<'_, '_>>]| -> super::ImuBias {
        let max = |tag: &str| -> f64 {
            groups
                .iter()
                .flatten()
                .flat_map(|n| n.descendants())
                .filter(|d| d.has_tag_name(tag))
                .filter_map(|d| d.text().and_then(parse_num))
                .map(f64::abs)
                .fold(0.0, f64::max)
        };
        super::ImuBias {
            mean: max("bias_mean"),
            stddev: max("bias_stddev"),
            dynamic_stddev: max("dynamic_bias_stddev"),
            dynamic_correlation_time_secs: max("dynamic_bias_correlation_time"),
            random_walk: max("bias_random_walk"),
        }
    };
    // Gazebo classic's older form: <imu><noise><rate>, <accel>.
    let old = child(imu, "noise");
    (
        under(&[child(imu, "angular_velocity"), old.and_then(|n| child(n, "rate"))]),
        under(&[child(imu, "linear_acceleration"), old.and_then(|n| child(n, "accel"))]),
    )
}

/// ROS topic of a Gazebo sensor from its plugin: ROS 2 `<ros><namespace>` + `<remapping>`
/// (`~/out:=imu/data`), ROS 1 `<robotNamespace>` + `<topicName>`, or the sensor's `<topic>`.
pub(crate) fn resolve_topic(sensor: Node<'_, '_>) -> Option<String> {
    let join = |ns: &str, rel: &str| -> String {
        if rel.starts_with('/') {
            rel.to_string()
        } else {
            let ns = ns.trim_end_matches('/');
            let ns = if ns.starts_with('/') || ns.is_empty() { ns.to_string() } else { format!("/{ns}") };
            format!("{ns}/{rel}")
        }
    };
    if let Some(p) = child(sensor, "plugin") {
        let plugin_name = p.attribute("name").unwrap_or("plugin");
        if let Some(ros) = child(p, "ros") {
            let ns = child_text(ros, "namespace").unwrap_or("");
            let mut out = None;
            for r in children(ros, "remapping") {
                let t = r.text().unwrap_or("").trim();
                if let Some((from, to)) = t.split_once(":=")
                    && (from == "~/out" || from == "out")
                {
                    out = Some(to.to_string());
                }
            }
            let topic = match out {
                Some(to) if to.starts_with("~/") => join(ns, &format!("{plugin_name}/{}", &to[2..])),
                Some(to) => join(ns, &to),
                None => join(ns, &format!("{plugin_name}/out")),
            };
            return Some(topic);
        }
        if let Some(t) = child_text(p, "topicName").or_else(|| child_text(p, "topic_name")) {
            let ns = child_text(p, "robotNamespace").unwrap_or("");
            return Some(join(ns, t));
        }
    }
    child_text(sensor, "topic").map(|t| join("", t))
}
