#![doc = include_str!("../README.md")]
#![deny(unsafe_code)]

pub mod actuator;
mod error;
pub mod hfield;
mod home;
pub(crate) mod inertia;
mod ir;
pub mod mesh;
mod meta;
mod options;
mod sensors;
pub mod srdf;
mod transmission;
mod tree;
pub mod urdf;
mod world;

pub use error::{Error, Result};
pub use meta::RobotMeta;
pub use options::{ActuatorMode, ConvertOptions};

pub use ir::Interface;

use inertia::MassProps;
use ir::{Ctx, GeomIr, JointIr, JointKind, LinkIr, Pose, RobotIr, Shape};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tree::Tree;

/// What the converter needs of a physics engine: compiling the MJCF it generated and reading
/// back the few facts that place the robot. The converter itself runs no engine; `twin-core`
/// implements this with MuJoCo (`twin_core::convert::convert_urdf`).
pub trait Compiler {
    /// The engine's error for failures other than a refused document (those are
    /// [`Compile::Rejected`]); conversion errors turn into it too.
    type Error: From<Error>;

    /// Compiles `mjcf` and measures it at its home pose `pose` (as in [`Compiler::home_qpos`])
    /// ([`Probe`]); `bodies` are the bodies whose [`Probe::body_invweight`] is wanted, in that
    /// order.
    ///
    /// # Errors
    /// [`Compile::Rejected`] with the engine's message when it refuses the document.
    fn probe(&mut self, mjcf: &str, bodies: &[&str], pose: &[(String, f64)]) -> Result<Probe, Compile<Self::Error>>;

    /// Compiles `mjcf` and returns its home pose: `qpos0` with the joints named in `pose` (an
    /// SRDF's named pose, [`srdf`]) set to their values, then every limited hinge and slide
    /// clamped into its range (some URDFs put 0 outside the range, e.g. knees of quadrupeds).
    ///
    /// # Errors
    /// As [`Compiler::probe`].
    fn home_qpos(&mut self, mjcf: &str, pose: &[(String, f64)]) -> Result<Vec<f64>, Compile<Self::Error>>;
}

/// Why a [`Compiler`] gave no answer.
#[derive(Debug)]
pub enum Compile<E> {
    /// The engine refused the document; the message (which may name an element or a line of
    /// the generated MJCF) is translated back to the URDF's file, line and element.
    Rejected(String),
    /// Any other failure, passed on as it is.
    Other(E),
}

/// What a [`Compiler`] measured on a compiled model at its home pose.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Probe {
    /// Lowest world z of any collision geom (contype or conaffinity set, planes ignored),
    /// metres; `None` when the robot has none.
    pub lowest_collision_z_m: Option<f64>,
    /// Each collision geom (planes ignored): the world x-y box around it (centre x, y, half
    /// sizes x, y) and its lowest world z, m (what seats the robot on a world's heightmaps).
    pub collision_geoms_m: Vec<[f64; 5]>,
    /// Per body asked for: MuJoCo's `body_invweight0[0]` (inverse of the effective mass at the
    /// body, 1/kg), `None` when the model has no such body.
    pub body_invweight: Vec<Option<f64>>,
    /// Per body asked for: the lowest world z of its collision geoms at the home pose, m; `None`
    /// when it has none (or no such body).
    pub body_lowest_z_m: Vec<Option<f64>>,
}

/// How far a robot whose collision geoms are `geoms` ([`Probe::collision_geoms_m`], measured with
/// its base at z 0) placed at `base_z` must rise for none of them to be below the highest
/// ground of `heightfields` under its x-y box, m (0 when none is).
fn seat_lift_m(geoms: &[[f64; 5]], base_z: f64, heightfields: &[hfield::Heightfield]) -> f64 {
    let mut lift: f64 = 0.0;
    for &[x, y, hx, hy, lowest] in geoms {
        for h in heightfields {
            if let Some(ground) = h.highest_under(x, y, [hx, hy]) {
                lift = lift.max(ground - (lowest + base_z));
            }
        }
    }
    lift
}

/// An IMU of the robot, with what logging and noise models need.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuMeta {
    /// Gazebo sensor name; MuJoCo sensors are `<name>_quat`, `<name>_gyro`, `<name>_accel`.
    pub name: String,
    /// Link the IMU is mounted on.
    pub link: String,
    /// MuJoCo site at the IMU frame (named like the sensor).
    pub site: String,
    /// Publication rate, Hz, when the URDF gives one.
    pub update_rate_hz: Option<f64>,
    /// Gyroscope white-noise standard deviation, rad/s (0 when none).
    pub gyro_noise_std: f64,
    /// Accelerometer white-noise standard deviation, m/s² (0 when none).
    pub accel_noise_std: f64,
    /// Gyroscope bias terms, rad/s.
    pub gyro_bias: ImuBias,
    /// Accelerometer bias terms, m/s².
    pub accel_bias: ImuBias,
    /// ROS topic resolved from the plugin's namespace and remapping (e.g. `/humanoid/imu/data`).
    pub topic: Option<String>,
    /// `frame_id` of the messages (the plugin's `frame_name`, else the link).
    pub frame_id: String,
}

/// Bias terms of one IMU group (gyroscope or accelerometer) from Gazebo's `<noise>` tags, the
/// largest over its axes (like the white-noise stddev); all 0 when none. Units of the group.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ImuBias {
    /// `<bias_mean>`: constant turn-on bias magnitude (its sign drawn per axis, as Gazebo does).
    pub mean: f64,
    /// `<bias_stddev>`: spread of the constant turn-on bias, drawn once per axis.
    pub stddev: f64,
    /// `<dynamic_bias_stddev>` σ_b: drive of the first-order Gauss–Markov bias, per √s
    /// (Gazebo's convention: stationary deviation σ_b·√(τ/2), short-τ random walk σ_b).
    pub dynamic_stddev: f64,
    /// `<dynamic_bias_correlation_time>` τ, s; 0 (absent) makes the dynamic bias a pure random
    /// walk of density σ_b (the τ → ∞ limit) rather than Gazebo's "no dynamic bias".
    pub dynamic_correlation_time_secs: f64,
    /// `<bias_random_walk>` K (a twin extension Gazebo ignores), per √s: a second, pure random
    /// walk bias, so that a Gauss–Markov bias instability and a random walk can both be given.
    pub random_walk: f64,
}

impl ImuBias {
    /// Whether any bias term is set.
    pub fn is_zero(&self) -> bool {
        *self == ImuBias::default()
    }
}

/// A non-IMU sensor (camera, rangefinder, force/torque, contact).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorMeta {
    /// Gazebo sensor name.
    pub name: String,
    /// Gazebo sensor type (`camera`, `ray`, `force_torque`, `contact`, …).
    pub kind: String,
    /// Link (or joint, for force/torque) it refers to.
    pub reference: String,
    /// Publication rate, Hz.
    pub update_rate_hz: Option<f64>,
    /// ROS topic, when a plugin names one.
    pub topic: Option<String>,
    /// `frame_id` from the plugin's `frame_name`, when given.
    pub frame_id: Option<String>,
    /// Names of the MuJoCo sensors or cameras created for it (a ray sensor: its site).
    pub mujoco: Vec<String>,
    /// Range limits `[min, max]`, metres: a ray sensor's `<range>`, a camera's `<clip>`.
    pub range_m: Option<[f64; 2]>,
    /// Gaussian noise standard deviation, metres (ranges, depths); 0 for none.
    pub noise_std: f64,
    /// Beam pattern of a ray sensor.
    /// A camera's lens distortion, Gazebo's `<distortion>` k1 k2 k3 p1 p2 (Brown–Conrady), when
    /// given.
    pub distortion: Option<[f64; 5]>,
    pub scan: Option<ScanMeta>,
}

/// The beams of a Gazebo `ray`/`lidar` sensor: `(samples, min angle, max angle)` per axis,
/// radians; horizontal about the sensor's z from x, vertical up from its x–y plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanMeta {
    /// Horizontal samples and angle range.
    pub horizontal: (usize, f64, f64),
    /// Vertical samples (rings) and angle range.
    pub vertical: (usize, f64, f64),
}

/// A URDF joint as converted.
#[derive(Debug, Clone, PartialEq)]
pub struct JointMeta {
    /// URDF joint name (MuJoCo joint of the same name; planar joints add `_tx`, `_ty`).
    pub name: String,
    /// URDF type (`revolute`, `continuous`, `prismatic`, `fixed`, `floating`, `planar`, `spherical`).
    pub urdf_type: String,
    /// Effort limit, N·m or N (`None` when absent or 0).
    pub effort_limit: Option<f64>,
    /// Velocity limit, rad/s or m/s (`None` when absent or 0).
    pub velocity_limit: Option<f64>,
    /// Position range, when limited.
    pub range: Option<[f64; 2]>,
    /// Actuator driving it (named after the joint), and its command interface.
    pub actuator: Option<(String, Interface)>,
    /// Gear of that actuator (`mechanicalReduction`).
    pub gear: f64,
    /// Leader joint when this joint mimics another.
    pub mimic_of: Option<String>,
    /// Differential transmission driving it (through fixed tendons), if any.
    pub transmission: Option<String>,
}

/// A differential transmission as converted: two fixed tendons (named like the actuators),
/// each driven by one actuator of the same name.
#[derive(Debug, Clone, PartialEq)]
pub struct DifferentialMeta {
    /// Transmission name.
    pub name: String,
    /// PAL's half differential rather than ros_control's differential.
    pub half: bool,
    /// Actuator (and tendon) names, by role.
    pub actuators: [String; 2],
    /// Joint names, by role.
    pub joints: [String; 2],
    /// `coefficients[a][j]`: joint `j` torque per unit effort of actuator `a`.
    pub coefficients: [[f64; 2]; 2],
    /// Command interface of the actuators.
    pub interface: Interface,
}

/// The result of a conversion.
#[derive(Debug, Clone)]
pub struct ConvertedModel {
    /// What twin publishes the robot by (also inside [`ConvertedModel::mjcf`]): its name, floating
    /// base, IMUs, other sensors, joints in URDF order (fixed joints included) and differential
    /// transmissions (converted to tendons).
    pub meta: RobotMeta,
    /// The MJCF document (mesh files referenced by absolute path).
    pub mjcf: String,
    /// Height of the root link origin in the `home` pose, metres.
    pub base_height_m: f64,
    /// Everything that was approximated, repaired or dropped, one line each.
    pub notes: Vec<String>,
    /// Mesh files written by the conversion (ASCII STL / Collada → OBJ).
    pub converted_meshes: Vec<PathBuf>,
}

/// Converts the URDF file at `path`, compiling with `compiler`.
///
/// # Errors
/// [`Error::File`] if it can't be read; [`Error::Xml`] for malformed XML; [`Error::Urdf`] naming
/// the file, line and element for invalid content (missing link, cycle, negative mass, bad
/// inertia, missing mesh …); [`Error::Load`] if the engine rejects the result; the compiler's
/// own errors as they are.
pub fn convert_urdf<C: Compiler>(
    path: &Path,
    opts: &ConvertOptions,
    compiler: &mut C,
) -> Result<ConvertedModel, C::Error> {
    let text = twin_fsio::read_to_string(path).map_err(Error::from)?;
    convert_urdf_str(path, &text, opts, compiler)
}

/// Adds a contact sensor on each link of [`ConvertOptions::contact_sensors`] that has none.
fn add_contact_sensors(path: &Path, robot: &mut ir::RobotIr, links: &[String]) -> Result<()> {
    for link in links {
        if !robot.links.iter().any(|l| &l.name == link) {
            return Err(Error::NoSuchLink {
                path: path.to_path_buf(),
                link: link.clone(),
                links: robot.links.iter().map(|l| l.name.clone()).collect(),
            });
        }
        if robot.sensors.iter().any(|s| s.kind == "contact" && &s.reference == link) {
            continue;
        }
        robot.sensors.push(ir::SensorIr {
            name: format!("{link}_contact"),
            kind: "contact".into(),
            reference: link.clone(),
            pose: ir::Pose::IDENTITY,
            update_rate_hz: None,
            line: 0,
            topic: None,
            frame_name: None,
            gyro_noise_std: 0.0,
            accel_noise_std: 0.0,
            gyro_bias: ImuBias::default(),
            accel_bias: ImuBias::default(),
            cameras: Vec::new(),
            ray: None,
            every_collision: true,
        });
    }
    Ok(())
}

/// Converts URDF `text`; `path` names it in errors and anchors relative mesh paths.
///
/// # Errors
/// As [`convert_urdf`].
pub fn convert_urdf_str<C: Compiler>(
    path: &Path,
    text: &str,
    opts: &ConvertOptions,
    compiler: &mut C,
) -> Result<ConvertedModel, C::Error> {
    let doc = urdf::parse(path, text)?;
    let ctx = Ctx { path, doc: &doc };
    let mut robot = ir::parse_robot(&ctx)?;
    add_contact_sensors(path, &mut robot, &opts.contact_sensors)?;
    // Armature identified by `twin sysid` (its `<twin_sysid>` block), where the caller gave none.
    let with_block;
    let opts = match urdf::sysid_armature(&ctx)? {
        block if block.is_empty() => opts,
        block => {
            let mut o = opts.clone();
            for (joint, armature) in block {
                o.joint_armature.entry(joint).or_insert(armature);
            }
            with_block = o;
            &with_block
        }
    };
    // Drive models of the `<twin_actuator>` block, where the caller gave none.
    let with_drives;
    let opts = match actuator::read_block(path, &doc)? {
        block if block.is_empty() => opts,
        block => {
            let mut o = opts.clone();
            for m in block {
                o.joint_drive.entry(m.joint.clone()).or_insert(m);
            }
            with_drives = o;
            &with_drives
        }
    };
    let tree = Tree::build(&robot)?;
    let mut conv = Converter::new(&robot, &tree, opts)?;
    conv.prepare()?;
    let pose = conv.named_pose(path)?;

    let world = match &opts.world {
        Some(w) => Some(world::load(w)?),
        None => None,
    };

    // Pass 1: robot alone, to find the lowest collision point at the zero pose.
    let (mut base_height_m, placed_geoms) = if conv.placed {
        let probe = conv.emit(0.0, false, None, None)?;
        let bodies = conv.contact_bodies();
        let measured = conv.compile(&probe, |mjcf| compiler.probe(mjcf, &bodies, &pose))?;
        conv.contact_solrefs(&measured);
        let base = match measured.lowest_collision_z_m {
            Some(z) if conv.world_root => (-z).max(0.0),
            Some(z) => -z,
            None => 0.0,
        };
        (base, measured.collision_geoms_m)
    } else {
        (0.0, Vec::new())
    };
    // A world's heightmaps: the robot rises until no collision geom is below the ground under it
    // (the highest ground under each geom's x-y box), seated on the terrain, never inside it.
    if conv.placed && !conv.world_root && world.as_ref().is_some_and(|w| !w.heightfields.is_empty()) {
        let w = world.as_ref().map_or(&[][..], |w| &w.heightfields[..]);
        base_height_m += seat_lift_m(&placed_geoms, base_height_m, w);
    }
    // Pass 2: the real model; its qpos0 is the home pose.
    let mjcf = conv.emit(base_height_m, true, world.as_ref(), None)?;
    let home = conv.compile(&mjcf, |mjcf| compiler.home_qpos(mjcf, &pose))?;
    let mjcf = conv.emit(base_height_m, true, world.as_ref(), Some(&home))?;
    let mut notes = robot.notes.clone();
    notes.append(&mut conv.notes);
    if let Some(w) = &world {
        notes.extend(w.notes.iter().cloned());
    }
    Ok(ConvertedModel { meta: conv.meta(), mjcf, base_height_m, notes, converted_meshes: conv.converted })
}

/// Deepest element nesting MuJoCo's XML parser (tinyxml2, `TINYXML2_MAX_ELEMENT_DEPTH`)
/// accepts is one less than this: a 496-link chain is refused with "Element nesting is too
/// deep", a 495-link one loads.
pub const MAX_XML_DEPTH: usize = 500;

/// The deepest body of a generated MJCF (one element per line, as twin writes them).
struct Nesting {
    /// Bodies from the root body down to `body`, both included.
    bodies: usize,
    /// Element depth of `body`'s children (`<mujoco>` is depth 1).
    element_depth: usize,
    body: String,
    root: String,
}

fn body_nesting(mjcf: &str) -> Option<Nesting> {
    let mut stack: Vec<String> = Vec::new();
    let mut deepest: Option<Nesting> = None;
    for l in mjcf.lines().map(str::trim_start) {
        if let Some(rest) = l.strip_prefix("<body") {
            let name = rest.split("name=\"").nth(1).and_then(|r| r.split('"').next()).unwrap_or("").to_string();
            if !l.ends_with("/>") {
                stack.push(name);
            }
            if deepest.as_ref().is_none_or(|d| stack.len() > d.bodies) {
                deepest = Some(Nesting {
                    bodies: stack.len(),
                    // <mujoco>, <worldbody>, the bodies, and a child element of the deepest.
                    element_depth: stack.len() + 3,
                    body: stack.last().cloned().unwrap_or_default(),
                    root: stack.first().cloned().unwrap_or_default(),
                });
            }
        } else if l.starts_with("</body>") {
            stack.pop();
        }
    }
    deepest
}

/// Constant impedance of contacts converted from Gazebo kp/kd (`solimp="d d …"`).
const CONTACT_IMPEDANCE: f64 = 0.9;

/// A collision or visual geom resolved for output.
struct MeshAsset {
    name: String,
    file: PathBuf,
    scale: [f64; 3],
}

/// Centre of mass (body frame), `fullinertia` (Ixx Iyy Izz Ixy Ixz Iyz, body frame), mass.
type BodyInertial = ([f64; 3], [f64; 6], f64);

struct Converter<'a> {
    robot: &'a RobotIr,
    tree: &'a Tree,
    opts: &'a ConvertOptions,
    /// Root link is a `world` link: its children hang from the world body.
    world_root: bool,
    floating: bool,
    /// Whether the root is placed on the floor.
    placed: bool,
    /// Per link: inertial as `(pos, fullinertia [Ixx Iyy Izz Ixy Ixz Iyz], mass)`.
    inertials: Vec<Option<BodyInertial>>,
    /// Mesh asset index per (link, visual?, geom index).
    mesh_of: HashMap<(usize, bool, usize), usize>,
    meshes: Vec<MeshAsset>,
    /// Friction per link.
    mu: Vec<f64>,
    /// Gazebo contact `kp`, `kd` and line per link.
    gazebo_contact: Vec<Option<(f64, f64, u32)>>,
    /// Direct-form contact `solref` per link, from Gazebo kp/kd (set after the probe compile).
    contact: Vec<Option<[f64; 2]>>,
    /// Lowest friction among the world's geoms (set by `emit`).
    world_min_mu: f64,
    priority: BTreeMap<u64, i32>,
    imus: Vec<ImuMeta>,
    sensor_meta: Vec<SensorMeta>,
    joint_meta: Vec<JointMeta>,
    notes: Vec<String>,
    /// Where the home pose comes from ([`RobotMeta::home_pose`]).
    home_pose: String,
    converted: Vec<PathBuf>,
    converted_from: HashMap<PathBuf, PathBuf>,
    sensor_names: std::collections::HashSet<String>,
    /// Per link: sites (XML lines) to put in its body.
    sites: Vec<Vec<String>>,
    /// Per link: cameras.
    cameras: Vec<Vec<String>>,
    sensor_xml: Vec<String>,
    /// Fixed tendons of differential transmissions, and their actuators.
    tendon_xml: Vec<String>,
    tendon_act_xml: Vec<String>,
    differential_meta: Vec<DifferentialMeta>,
}

fn f(x: f64) -> String {
    if x == 0.0 { "0".into() } else { format!("{x}") }
}

fn fv(v: &[f64]) -> String {
    v.iter().map(|x| f(*x)).collect::<Vec<_>>().join(" ")
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;").replace('>', "&gt;")
}

fn quat_attr(q: &UnitQuaternion<f64>) -> String {
    if q.angle() == 0.0 { String::new() } else { format!(" quat=\"{}\"", fv(&[q.w, q.i, q.j, q.k])) }
}

fn pose_attrs(p: &Pose) -> String {
    let mut s = String::new();
    if p.xyz.norm() != 0.0 {
        s.push_str(&format!(" pos=\"{}\"", fv(p.xyz.as_slice())));
    }
    s.push_str(&quat_attr(&p.rot));
    s
}

/// Gazebo classic material colours (diffuse).
fn gazebo_rgba(name: &str) -> Option<[f64; 4]> {
    let n = name.trim().trim_start_matches("Gazebo/");
    let rgb = match n {
        "Black" | "FlatBlack" => [0.05, 0.05, 0.05],
        "White" => [1.0, 1.0, 1.0],
        "Grey" | "Gray" => [0.7, 0.7, 0.7],
        "DarkGrey" | "DarkGray" => [0.175, 0.175, 0.175],
        "LightGrey" | "LightGray" => [0.83, 0.83, 0.83],
        "Red" => [1.0, 0.0, 0.0],
        "Green" => [0.0, 1.0, 0.0],
        "Blue" => [0.0, 0.0, 1.0],
        "Yellow" => [1.0, 1.0, 0.0],
        "Orange" => [1.0, 0.5088, 0.0468],
        "Purple" => [1.0, 0.0, 1.0],
        "Turquoise" => [0.0, 1.0, 1.0],
        "Gold" => [0.8, 0.6, 0.2],
        "Indigo" => [0.33, 0.0, 0.5],
        "Wood" => [0.55, 0.35, 0.2],
        "SkyBlue" => [0.53, 0.81, 0.92],
        _ => return None,
    };
    Some([rgb[0], rgb[1], rgb[2], 1.0])
}

impl<'a> Converter<'a> {
    fn new(robot: &'a RobotIr, tree: &'a Tree, opts: &'a ConvertOptions) -> Result<Converter<'a>> {
        let root = &robot.links[tree.root];
        let world_root = root.name == "world";
        if world_root && (root.inertial.is_some() || !root.collisions.is_empty()) {
            return Err(Error::Urdf {
                path: robot.path.clone(),
                line: root.line,
                element: "link".into(),
                name: Some("world".into()),
                message: "the \"world\" link must have no inertial or collision: it stands for the fixed world".into(),
            });
        }
        let floating = !world_root && !opts.fixed_base;
        let n = robot.links.len();
        Ok(Converter {
            robot,
            tree,
            opts,
            world_root,
            floating,
            placed: true,
            inertials: vec![None; n],
            mesh_of: HashMap::new(),
            meshes: Vec::new(),
            mu: vec![1.0; n],
            gazebo_contact: vec![None; n],
            contact: vec![None; n],
            world_min_mu: 1.0,
            priority: BTreeMap::new(),
            imus: Vec::new(),
            sensor_meta: Vec::new(),
            joint_meta: Vec::new(),
            notes: Vec::new(),
            home_pose: String::new(),
            converted: Vec::new(),
            converted_from: HashMap::new(),
            sensor_names: std::collections::HashSet::new(),
            sites: vec![Vec::new(); n],
            cameras: vec![Vec::new(); n],
            sensor_xml: Vec::new(),
            tendon_xml: Vec::new(),
            tendon_act_xml: Vec::new(),
            differential_meta: Vec::new(),
        })
    }

    fn urdf_err(&self, line: u32, element: &str, name: &str, message: String) -> Error {
        Error::Urdf { path: self.robot.path.clone(), line, element: element.into(), name: Some(name.into()), message }
    }

    /// Everything that does not depend on the placement: inertias, meshes, friction, sensors,
    /// joint metadata.
    fn prepare(&mut self) -> Result<()> {
        let robot = self.robot;
        self.inertials()?;
        // Meshes.
        let (abs_dir, search) = mesh::search_paths(&robot.path, &self.opts.package_paths);
        let mut by_key: HashMap<(PathBuf, [u64; 3]), usize> = HashMap::new();
        let mut used_names: HashMap<String, usize> = HashMap::new();
        for (li, link) in robot.links.iter().enumerate() {
            let visuals = if self.opts.visuals { &link.visuals[..] } else { &[] };
            for (visual, geoms) in [(false, &link.collisions[..]), (true, visuals)] {
                for (gi, g) in geoms.iter().enumerate() {
                    let Shape::Mesh { filename, scale, line } = &g.shape else {
                        continue;
                    };
                    // A visual only draws: one that cannot be read is skipped with a note, as
                    // rviz and Gazebo go on without it. A collision mesh is physics: an error.
                    let resolved = mesh::resolve(filename, &abs_dir, &search)
                        .map(|file| std::path::absolute(&file).unwrap_or(file))
                        .and_then(|file| {
                            let key = (file.clone(), scale.map(f64::to_bits));
                            if by_key.contains_key(&key) {
                                Ok((key, None))
                            } else {
                                self.native_mesh(&file).map(|n| (key, Some(n)))
                            }
                        });
                    let (key, native) = match resolved {
                        Ok(r) => r,
                        Err(m) if visual => {
                            self.notes.push(format!("link \"{}\" (line {line}): visual mesh skipped: {m}", link.name));
                            continue;
                        }
                        Err(m) => return Err(self.urdf_err(*line, "mesh", &link.name, m)),
                    };
                    let idx = match (by_key.get(&key), native) {
                        (Some(&i), _) => i,
                        (None, native) => {
                            let file = native.unwrap_or_else(|| key.0.clone());
                            let stem: String = key
                                .0
                                .file_stem()
                                .and_then(|s| s.to_str())
                                .unwrap_or("mesh")
                                .chars()
                                .map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' })
                                .collect();
                            let count = used_names.entry(stem.clone()).or_insert(0);
                            *count += 1;
                            let name = if *count == 1 { stem } else { format!("{stem}_{count}") };
                            self.meshes.push(MeshAsset { name, file, scale: *scale });
                            by_key.insert(key, self.meshes.len() - 1);
                            self.meshes.len() - 1
                        }
                    };
                    self.mesh_of.insert((li, visual, gi), idx);
                }
            }
        }
        // Friction from <gazebo reference> (links only).
        for (li, link) in robot.links.iter().enumerate() {
            if let Some(g) = robot.gazebo.get(&link.name) {
                let mu = match (g.mu1, g.mu2) {
                    (Some(a), Some(b)) => {
                        if a != b {
                            self.notes.push(format!(
                                "link \"{}\": mu1 {a} ≠ mu2 {b}: MuJoCo friction is isotropic, the smaller ({}) is used",
                                link.name,
                                a.min(b)
                            ));
                        }
                        Some(a.min(b))
                    }
                    (Some(a), None) | (None, Some(a)) => Some(a),
                    (None, None) => None,
                };
                if let Some(mu) = mu {
                    if mu < 0.0 {
                        return Err(self.urdf_err(
                            g.line,
                            "gazebo",
                            &link.name,
                            format!("friction mu {mu} must be ≥ 0"),
                        ));
                    }
                    self.mu[li] = mu;
                }
                if let Some(f1) = &g.fdir1 {
                    self.notes.push(format!(
                        "link \"{}\" (line {}): fdir1 \"{f1}\" (anisotropic friction direction) has no MuJoCo geom equivalent: isotropic friction used",
                        link.name, g.line
                    ));
                }
                if let Some(d) = g.min_depth.filter(|d| *d > 0.0) {
                    self.notes.push(format!(
                        "link \"{}\" (line {}): Gazebo minDepth {d} m not converted (MuJoCo's soft contacts have no dead band)",
                        link.name, g.line
                    ));
                }
                if let Some(kp) = g.kp.filter(|k| *k > 0.0) {
                    self.gazebo_contact[li] = Some((kp, g.kd.unwrap_or(0.0).max(0.0), g.line));
                } else if g.kd.is_some() {
                    self.notes.push(format!(
                        "link \"{}\" (line {}): Gazebo kd without kp: not converted (MuJoCo's default soft contact is used)",
                        link.name, g.line
                    ));
                }
            }
        }
        // Joint metadata and actuators.
        let mode = self.opts.actuators;
        let differential_joints: HashMap<&str, &str> =
            if matches!(mode, ActuatorMode::Auto | ActuatorMode::Transmissions) {
                robot
                    .differentials
                    .iter()
                    .flat_map(|d| d.joints.iter().map(move |j| (j.0.as_str(), d.name.as_str())))
                    .collect()
            } else {
                HashMap::new()
            };
        let mut passive = Vec::new();
        let mut auto_motors = 0usize;
        for j in &robot.joints {
            let one_dof = matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic);
            let drive = robot.drives.get(&j.name);
            let effort = j.limit.as_ref().map(|l| l.effort).filter(|e| *e > 0.0);
            let mut actuator = None;
            let mut gear = 1.0;
            if drive.is_some() && !one_dof {
                self.notes.push(format!(
                    "transmission on {} joint \"{}\": not converted (only 1-DOF joints take actuators)",
                    format!("{:?}", j.kind).to_lowercase(),
                    j.name
                ));
            } else if one_dof && j.mimic.is_some() {
                if drive.is_some() {
                    self.notes.push(format!(
                        "joint \"{}\" mimics another joint: its transmission is not converted (the equality drives it)",
                        j.name
                    ));
                }
            } else if one_dof && !differential_joints.contains_key(j.name.as_str()) && mode != ActuatorMode::None {
                let interface = match (mode, drive) {
                    (ActuatorMode::Motor | ActuatorMode::Position, _) => mode.forced(),
                    (_, Some(d)) => Some(d.interface),
                    (ActuatorMode::Auto, None) if effort.is_some() => {
                        auto_motors += 1;
                        Some(Interface::Effort)
                    }
                    _ => None,
                };
                match interface {
                    Some(i) => {
                        actuator = Some((j.name.clone(), i));
                        gear = drive.map_or(1.0, |d| d.gear);
                    }
                    None => passive.push(j.name.clone()),
                }
            }
            let nz = |x: f64| if x > 0.0 { Some(x) } else { None };
            self.joint_meta.push(JointMeta {
                name: j.name.clone(),
                urdf_type: format!("{:?}", j.kind).to_lowercase(),
                effort_limit: effort,
                velocity_limit: j.limit.as_ref().and_then(|l| nz(l.velocity)),
                range: match (j.kind, &j.limit) {
                    (JointKind::Revolute | JointKind::Prismatic, Some(l)) => Some([l.lower, l.upper]),
                    _ => None,
                },
                actuator,
                gear,
                mimic_of: j.mimic.as_ref().map(|m| m.joint.clone()),
                transmission: differential_joints.get(j.name.as_str()).map(|s| s.to_string()),
            });
        }
        if auto_motors > 0 {
            self.notes.push(format!(
                "{auto_motors} movable joint(s) without a transmission or ros2_control entry got a motor within ±effort (--actuators auto; `transmissions` keeps them passive)"
            ));
        }
        self.check_drives()?;
        if !differential_joints.is_empty() {
            self.differentials()?;
        }
        for j in &robot.joints {
            if let Some(m) = &j.mimic {
                let movable = |n: &str| {
                    robot.joints.iter().any(|k| {
                        k.name == n
                            && matches!(k.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic)
                    })
                };
                if !movable(&j.name) || !movable(&m.joint) {
                    self.notes.push(format!(
                        "mimic of joint \"{}\" (line {}) on \"{}\": one of them is not a 1-DOF joint; no equality added",
                        j.name, m.line, m.joint
                    ));
                }
            }
        }
        if !passive.is_empty() {
            self.notes.push(format!(
                "{} movable joint(s) stay passive (no actuator under --actuators {:?}, or no effort limit for auto): {}",
                passive.len(),
                self.opts.actuators,
                passive.join(", ")
            ));
        }
        if robot.joints.iter().any(|j| j.limit.as_ref().is_some_and(|l| l.velocity > 0.0)) {
            self.notes.push(
                "joint velocity limits have no MuJoCo equivalent: kept as metadata for controllers and checks".into(),
            );
        }
        self.sensors()?;
        Ok(())
    }

    /// Body inertials: each link's own tensor checked (noise tolerated, real violations
    /// repaired or, with `strict_inertia`, refused), fixed-joint links lumped into the body
    /// that moves them, bodies MuJoCo would refuse made admissible with the smallest change.
    fn inertials(&mut self) -> Result<()> {
        let robot = self.robot;
        let n = robot.links.len();
        let mut own: Vec<Option<MassProps>> = vec![None; n];
        for (li, link) in robot.links.iter().enumerate() {
            let Some(i) = &link.inertial else { continue };
            if i.mass <= 0.0 {
                continue;
            }
            let mut t = inertia::tensor(i.inertia);
            if let Err(problem) = inertia::check(&t) {
                if self.opts.strict_inertia {
                    return Err(self.urdf_err(
                        i.inertia_line,
                        "inertia",
                        &link.name,
                        format!("{problem}; or convert without --strict-inertia to apply the smallest fix"),
                    ));
                }
                let (fixed, fix) = inertia::admissible(&t, 0.0);
                if let inertia::Fix::Repaired(how) = fix {
                    self.notes.push(format!("link \"{}\" (line {}): {how}", link.name, i.inertia_line));
                }
                t = fixed;
            }
            let r = i.pose.rot.to_rotation_matrix();
            own[li] =
                Some(MassProps { mass: i.mass, com: i.pose.xyz, inertia: r.matrix() * t * r.matrix().transpose() });
        }
        // Lump fixed-joint links into the nearest body that moves (or the root / a body welded
        // to the world link): Gazebo and MuJoCo's fusestatic do the same.
        let mut lumped: Vec<Option<MassProps>> = own.clone();
        let mut moved: Vec<String> = Vec::new();
        for li in 0..n {
            let Some(p) = own[li] else { continue };
            let mut target = li;
            let mut target_from_link = Pose::IDENTITY;
            while let Some(j) = self.tree.parent_joint[target] {
                let joint = &robot.joints[j];
                let parent = self.tree.link_index[&joint.parent];
                if joint.kind != JointKind::Fixed || (self.world_root && parent == self.tree.root) {
                    break;
                }
                target_from_link = joint.origin.then(&target_from_link);
                target = parent;
            }
            if target == li {
                continue;
            }
            let r = target_from_link.rot.to_rotation_matrix();
            let moved_props = MassProps {
                mass: p.mass,
                com: target_from_link.xyz + r * p.com,
                inertia: r.matrix() * p.inertia * r.matrix().transpose(),
            };
            lumped[li] = None;
            lumped[target] = Some(match lumped[target] {
                Some(t) => t.lump(&moved_props),
                None => moved_props,
            });
            moved.push(format!("{} → {}", robot.links[li].name, robot.links[target].name));
        }
        if !moved.is_empty() {
            self.notes.push(format!(
                "mass of {} fixed-joint link(s) lumped into the body that moves them (parallel-axis theorem, as Gazebo does; the links keep their bodies, frames, geoms and sensors): {}",
                moved.len(),
                moved.join(", ")
            ));
        }
        // Bodies that move need mass and inertia (MuJoCo refuses them otherwise): a massless
        // one gets a negligible mass, 1e-12 of the robot's, so the total stays the URDF's.
        let total: f64 = own.iter().flatten().map(|p| p.mass).sum();
        let eps_mass = (total * 1e-12).max(1e-12);
        let eps_inertia = (eps_mass * 1e-2).max(1e-13);
        let moves = |li: usize| -> bool {
            match self.tree.parent_joint[li] {
                None => self.floating,
                Some(j) => robot.joints[j].kind != JointKind::Fixed,
            }
        };
        let mut massless = Vec::new();
        for (li, slot) in lumped.iter_mut().enumerate() {
            if slot.is_none() && moves(li) {
                *slot = Some(MassProps { mass: eps_mass, com: Vector3::zeros(), inertia: Matrix3::zeros() });
                massless.push(robot.links[li].name.clone());
            }
        }
        if !massless.is_empty() {
            self.notes.push(format!(
                "{} moving link(s) without mass given {eps_mass:.1e} kg (MuJoCo needs mass on every moving body; the total mass is unchanged to 1e-12): {}",
                massless.len(),
                massless.join(", ")
            ));
        }
        for (li, p) in lumped.iter().enumerate() {
            let Some(p) = p else { continue };
            let (t, fix) = inertia::admissible(&p.inertia, eps_inertia);
            if let inertia::Fix::Noise(how) | inertia::Fix::Repaired(how) = &fix
                && !massless.contains(&robot.links[li].name)
            {
                self.notes.push(format!(
                    "link \"{}\" (line {}): zero or rounding-level principal moments made positive for MuJoCo: {how}",
                    robot.links[li].name, robot.links[li].line
                ));
            }
            self.inertials[li] = Some((
                [p.com.x, p.com.y, p.com.z],
                [t[(0, 0)], t[(1, 1)], t[(2, 2)], t[(0, 1)], t[(0, 2)], t[(1, 2)]],
                p.mass,
            ));
        }
        Ok(())
    }

    /// What twin publishes the robot by, as it travels inside the MJCF.
    fn meta(&self) -> RobotMeta {
        RobotMeta {
            name: self.robot.name.clone(),
            floating_base: self.floating,
            imus: self.imus.clone(),
            sensors: self.sensor_meta.clone(),
            joints: self.joint_meta.clone(),
            differentials: self.differential_meta.clone(),
            home_pose: self.home_pose.clone(),
        }
    }

    /// Bodies (links) with collision geoms or Gazebo kp/kd, whose effective mass the probe
    /// measures.
    fn contact_bodies(&self) -> Vec<&'a str> {
        let robot = self.robot;
        (0..robot.links.len())
            .filter(|&li| self.gazebo_contact[li].is_some() || !robot.links[li].collisions.is_empty())
            .map(|li| robot.links[li].name.as_str())
            .collect()
    }

    /// Contact `solref`s from the compiled probe: each link's effective mass at its contacts is
    /// `1 / body_invweight0` (the bodies in the order of [`Converter::contact_bodies`]). Links
    /// with Gazebo kp/kd get Gazebo's stiffness ([`Converter::direct_solref`]); other links keep
    /// MuJoCo's default contact unless they are feet (within [`home::FOOT_BAND_M`] of the lowest point
    /// in the home pose) that the robot's whole weight would sink more than [`home::MAX_SINK_M`]
    /// ([`Converter::weight_solref`]).
    fn contact_solrefs(&mut self, probe: &Probe) {
        let total: f64 = self.inertials.iter().flatten().map(|i| i.2).sum::<f64>().max(1e-9);
        let bodies = self.contact_bodies();
        let lowest = probe.lowest_collision_z_m.unwrap_or(f64::NEG_INFINITY);
        let mut measured =
            probe.body_invweight.iter().zip(probe.body_lowest_z_m.iter().chain(std::iter::repeat(&None)));
        for li in 0..self.robot.links.len() {
            if !bodies.contains(&self.robot.links[li].name.as_str()) {
                continue;
            }
            let name = &self.robot.links[li].name;
            let (inv, low) = measured.next().map_or((0.0, None), |(i, z)| (i.unwrap_or(0.0), *z));
            let mass = if inv > 0.0 { 1.0 / inv } else { total };
            // A foot: its collision geoms reach within FOOT_BAND_M of the robot's lowest point.
            let foot = low.is_some_and(|z| z <= lowest + home::FOOT_BAND_M);
            self.contact[li] = match self.gazebo_contact[li] {
                Some((kp, kd, line)) => Some(self.direct_solref(name, line, kp, kd, mass)),
                None if self.opts.fixed_base || !foot || inv <= 0.0 => None,
                None => self.weight_solref(name, mass, total),
            };
        }
    }

    /// MuJoCo's direct-form `solref = (−K, −B)` reproducing Gazebo's contact `kp` (N/m) and
    /// `kd` (N·s/m) on a contact whose effective mass is `mass`: with a constant impedance `d`
    /// (`solimp d d`), a contact carrying force `f` settles where `(1 − d)·f/(mass·K)` (measured
    /// on resting bodies: independent of the contact count and of the friction cone once the
    /// pyramid's factor is applied at emission), so `K = (1 − d)·kp/mass` gives Gazebo's
    /// `f/kp` per contact point (ODE applies `kp` at each). `B = sqrt(1 − d)·kd/mass` keeps the
    /// damping ratio. Stiffness beyond what the timestep integrates stably, and damping below
    /// critical, are clamped, with a note.
    fn direct_solref(&mut self, link: &str, line: u32, kp: f64, kd: f64, mass: f64) -> [f64; 2] {
        let d = CONTACT_IMPEDANCE;
        let dt = self.opts.timestep_secs;
        let mut k = (1.0 - d) * kp / mass;
        // Natural frequency ω² = K/d; keep ω·dt ≤ 1.
        let k_max = d / (dt * dt);
        if k > k_max {
            self.notes.push(format!(
                "link \"{link}\" (line {line}): Gazebo kp {kp} N/m is too stiff for a {dt} s step on a contact of effective mass {mass:.3} kg: contact stiffness clamped to {:.4e} N/m",
                k_max * mass / (1.0 - d)
            ));
            k = k_max;
        }
        let omega = (k / d).sqrt();
        // Damping ratio B/(2ω) equal to Gazebo's kd/(2·sqrt(kp·m)).
        let b_crit = 2.0 * omega;
        let mut b = (1.0 - d).sqrt() * kd / mass;
        if b < b_crit {
            if kd > 0.0 {
                self.notes.push(format!(
                    "link \"{link}\" (line {line}): Gazebo kd {kd} N·s/m is below critical damping for this stiffness: raised to critical (ODE's implicit step damps likewise)"
                ));
            }
            b = b_crit;
        }
        [-k, -b]
    }

    /// Path of a mesh MuJoCo can read: the file itself, or a converted OBJ.
    fn native_mesh(&mut self, file: &Path) -> std::result::Result<PathBuf, String> {
        let kind = mesh::classify(file)?;
        if kind == mesh::MeshKind::Native {
            return Ok(file.to_path_buf());
        }
        if let Some(done) = self.converted_from.get(file) {
            return Ok(done.clone());
        }
        let bytes = std::fs::read(file).map_err(|e| format!("{}: {e}", file.display()))?;
        let mut key = file.as_os_str().as_encoded_bytes().to_vec();
        key.extend_from_slice(&bytes);
        let hash = mesh::fnv1a(&key);
        let stem = file.file_stem().and_then(|s| s.to_str()).unwrap_or("mesh");
        let dir = match &self.opts.mesh_dir {
            Some(d) => d.clone(),
            None => std::env::temp_dir().join("twin-meshes"),
        };
        let out = dir.join(format!("{stem}-{hash:016x}.obj"));
        if self.opts.mesh_dir.is_none() && out.is_file() {
            return Ok(out);
        }
        let tris = match kind {
            mesh::MeshKind::AsciiStl => mesh::read_ascii_stl(file)?,
            _ => mesh::read_collada(file)?,
        };
        std::fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
        // Atomic: parallel conversions of the same mesh never see a half-written file.
        twin_fsio::write_atomic(&out, &mesh::obj(&tris), twin_fsio::Backup::None).map_err(|e| {
            match std::error::Error::source(&e) {
                Some(source) => format!("writing converted mesh {e}: {source}"),
                None => format!("writing converted mesh: {e}"),
            }
        })?;
        self.notes.push(format!(
            "mesh {} ({}) converted to OBJ {} ({} triangles)",
            file.display(),
            if kind == mesh::MeshKind::AsciiStl { "ASCII STL" } else { "Collada" },
            out.display(),
            tris.len()
        ));
        self.converted.push(out.clone());
        self.converted_from.insert(file.to_path_buf(), out.clone());
        Ok(out)
    }

    /// The URDF element a name of the generated MJCF stands for: (URDF line, kind, name).
    fn urdf_element(&self, name: &str) -> Option<(u32, &'static str, String)> {
        self.robot
            .links
            .iter()
            .find(|l| l.name == name)
            .map(|l| (l.line, "link", l.name.clone()))
            .or_else(|| self.robot.joints.iter().find(|j| j.name == name).map(|j| (j.line, "joint", j.name.clone())))
    }

    /// Compiles the generated MJCF with `compile` (a [`Compiler`] call). The engine's errors
    /// name the generated document (a line the user never sees) or one of its elements: they
    /// are translated back to the URDF's file, line and element, or explained.
    fn compile<T, E: From<Error>>(
        &self,
        mjcf: &str,
        compile: impl FnOnce(&str) -> Result<T, Compile<E>>,
    ) -> Result<T, E> {
        if let Some(deep) = body_nesting(mjcf)
            && deep.element_depth >= MAX_XML_DEPTH
        {
            let (line, _, _) = self.urdf_element(&deep.body).unwrap_or((0, "link", String::new()));
            return Err(Error::Urdf {
                path: self.robot.path.clone(),
                line,
                element: "link".into(),
                name: Some(deep.body.clone()),
                message: format!(
                    "the kinematic tree is {} bodies deep here (from link \"{}\"), but MuJoCo's XML parser \
                     accepts at most {} nested bodies (its element nesting limit is {MAX_XML_DEPTH}, counting \
                     <mujoco>, <worldbody> and the elements inside a body); shorten the chain or join links \
                     with fixed joints (merged into one body)",
                    deep.bodies,
                    deep.root,
                    MAX_XML_DEPTH - 4,
                ),
            }
            .into());
        }
        compile(mjcf).map_err(|e| match e {
            Compile::Rejected(message) => self.translate(mjcf, message).into(),
            Compile::Other(other) => other,
        })
    }

    fn translate(&self, mjcf: &str, message: String) -> Error {
        // MuJoCo names the element ("Element name 'X'"): point at the URDF line.
        let named = message.split("name '").nth(1).and_then(|r| r.split('\'').next());
        if let Some((line, element, name)) = named.and_then(|n| self.urdf_element(n)) {
            return Error::Urdf {
                path: self.robot.path.clone(),
                line,
                element: element.into(),
                name: Some(name),
                message: format!("MuJoCo rejected the converted {element}: {message}"),
            };
        }
        // Or a line of the generated document (twin writes one element per line): the URDF
        // joint or link named on it, else the link whose body holds it.
        let generated_line = ["Line number=", "line "].iter().find_map(|key| {
            message.split(key).nth(1).and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next()?.parse::<usize>().ok())
        });
        if let Some(n) = generated_line.filter(|&n| n >= 1) {
            let lines: Vec<&str> = mjcf.lines().collect();
            let name_on = |l: &str| l.split(" name=\"").nth(1)?.split('"').next().map(str::to_string);
            // The element on that line (a joint, a link's body), else the body it is inside.
            let hit = lines.get(n - 1).and_then(|l| self.urdf_element(&name_on(l)?)).or_else(|| {
                // Upwards, skipping bodies closed before that line.
                let mut closed = 0usize;
                for l in lines[..(n - 1).min(lines.len())].iter().rev().map(|l| l.trim_start()) {
                    if l.starts_with("</body>") {
                        closed += 1;
                    } else if l.starts_with("<body") && !l.ends_with("/>") {
                        if closed == 0 {
                            return self.urdf_element(&name_on(l)?);
                        }
                        closed -= 1;
                    }
                }
                None
            });
            let text = lines.get(n - 1).map_or(String::new(), |l| twin_fsio::excerpt(l.trim(), 120));
            if let Some((line, element, name)) = hit {
                return Error::Urdf {
                    path: self.robot.path.clone(),
                    line,
                    element: element.into(),
                    name: Some(name),
                    message: format!("MuJoCo rejected what twin generated for this {element} (`{text}`): {message}"),
                };
            }
            return Error::Load {
                path: Some(self.robot.path.clone()),
                message: format!(
                    "MuJoCo rejected the model twin generated from it, at `{text}` (line {n} of the MJCF; see it \
                     with `twin convert {} -o model.xml`): {message}",
                    self.robot.path.display()
                ),
            };
        }
        Error::Load {
            path: Some(self.robot.path.clone()),
            message: format!("MuJoCo rejected the converted model: {message}"),
        }
    }

    fn contype(&self, link: &LinkIr) -> (i32, i32) {
        let selfc =
            self.opts.self_collision || self.robot.gazebo.get(&link.name).and_then(|g| g.self_collide).unwrap_or(false);
        if selfc { (6, 5) } else { (2, 1) }
    }

    fn priority_of(&self, mu: f64) -> i32 {
        self.priority.get(&mu.to_bits()).copied().unwrap_or(0)
    }

    /// Writes the MJCF. `base_z`: height of the root; `home`: qpos of keyframe `home`.
    fn emit(&mut self, base_z: f64, scene: bool, world: Option<&world::World>, home: Option<&[f64]>) -> Result<String> {
        // Friction priorities: lower mu ranks higher, so pairs take the min as Gazebo does.
        let mut mus: Vec<f64> = self.mu.clone();
        mus.push(1.0);
        if let Some(w) = world {
            mus.extend(w.mus.iter().copied());
        }
        self.world_min_mu = world.map_or(1.0, |w| w.mus.iter().copied().fold(1.0, f64::min));
        mus.sort_by(|a, b| b.total_cmp(a));
        mus.dedup();
        self.priority = mus.iter().enumerate().map(|(i, m)| (m.to_bits(), i as i32)).collect();

        let robot = self.robot;
        let mut x = String::with_capacity(64 * 1024);
        let _ = writeln!(x, "<mujoco model=\"{}\">", esc(&robot.name));
        let _ = writeln!(
            x,
            "  <!-- converted by twin {} from {} -->",
            env!("CARGO_PKG_VERSION"),
            esc(&robot.path.display().to_string()).replace("--", "- -")
        );
        let _ = writeln!(
            x,
            "  <compiler angle=\"radian\" autolimits=\"true\" inertiafromgeom=\"false\" fusestatic=\"false\" discardvisual=\"false\"/>"
        );
        let timestep = world.and_then(|w| w.timestep_secs).unwrap_or(self.opts.timestep_secs);
        let gravity = world.and_then(|w| w.gravity).unwrap_or([0.0, 0.0, -9.81]);
        let _ = writeln!(
            x,
            "  <option timestep=\"{}\" gravity=\"{}\" integrator=\"implicitfast\"/>",
            f(timestep),
            fv(&gravity)
        );
        let _ = writeln!(x, "  <asset>");
        for m in &self.meshes {
            let scale = if m.scale == [1.0; 3] { String::new() } else { format!(" scale=\"{}\"", fv(&m.scale)) };
            let _ = writeln!(
                x,
                "    <mesh name=\"{}\" file=\"{}\"{scale} inertia=\"shell\"/>",
                esc(&m.name),
                esc(&m.file.display().to_string())
            );
        }
        if let (true, Some(w)) = (scene, world) {
            x.push_str(&w.assets);
        } else if scene && self.opts.floor {
            let _ = writeln!(
                x,
                "    <texture name=\"twin_grid\" type=\"2d\" builtin=\"checker\" width=\"512\" height=\"512\" rgb1=\"0.2 0.3 0.4\" rgb2=\"0.1 0.2 0.3\"/>"
            );
            let _ = writeln!(
                x,
                "    <material name=\"twin_grid\" texture=\"twin_grid\" texrepeat=\"1 1\" texuniform=\"true\" reflectance=\"0.2\"/>"
            );
        }
        let _ = writeln!(x, "  </asset>");
        let _ = writeln!(x, "  <worldbody>");
        let root = self.tree.root;
        if self.world_root {
            // Children of the world link hang from the world body.
            for &j in &self.tree.children[root] {
                self.emit_body(&mut x, j, 2, base_z)?;
            }
        } else {
            self.emit_root(&mut x, root, base_z)?;
        }
        if scene {
            if let Some(w) = world {
                let mut body = w.worldbody.clone();
                for mu in &w.mus {
                    body = body.replace(&world::prio_tag(*mu), &self.priority_of(*mu).to_string());
                }
                x.push_str(&body);
            } else if self.opts.floor {
                let _ = writeln!(
                    x,
                    "    <light name=\"twin_sun\" directional=\"true\" pos=\"0 0 5\" dir=\"0 0 -1\" diffuse=\"0.8 0.8 0.8\"/>"
                );
                let _ = writeln!(
                    x,
                    "    <geom name=\"floor\" type=\"plane\" size=\"0 0 0.05\" material=\"twin_grid\" contype=\"1\" conaffinity=\"1\" friction=\"1 0.005 0.0001\" priority=\"{}\"/>",
                    self.priority_of(1.0)
                );
            }
        }
        let _ = writeln!(x, "  </worldbody>");

        let one_dof = |name: &str| {
            robot.joints.iter().any(|j| {
                j.name == name && matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic)
            })
        };
        let mimics: Vec<&JointIr> = robot
            .joints
            .iter()
            .filter(|j| j.mimic.as_ref().is_some_and(|m| one_dof(&j.name) && one_dof(&m.joint)))
            .collect();
        if !mimics.is_empty() {
            let _ = writeln!(x, "  <equality>");
            for j in mimics {
                let m = j.mimic.as_ref().expect("filtered");
                let _ = writeln!(
                    x,
                    "    <joint name=\"{}_mimic\" joint1=\"{}\" joint2=\"{}\" polycoef=\"{} {} 0 0 0\"/>",
                    esc(&j.name),
                    esc(&j.name),
                    esc(&m.joint),
                    f(m.offset),
                    f(m.multiplier)
                );
            }
            let _ = writeln!(x, "  </equality>");
        }

        let mut act = String::new();
        for (meta, j) in self.joint_meta.iter().zip(&robot.joints) {
            let Some((name, iface)) = &meta.actuator else {
                continue;
            };
            let g = meta.gear;
            let effort = meta.effort_limit;
            let drive = robot.drives.get(&j.name);
            let fr =
                effort.map(|e| format!(" forcerange=\"{} {}\"", f(-e / g.abs()), f(e / g.abs()))).unwrap_or_default();
            let gear = if g == 1.0 { String::new() } else { format!(" gear=\"{}\"", f(g)) };
            let drive_model = self.opts.joint_drive.get(&j.name);
            let delay =
                actuator::delay_attrs(drive_model.map_or(0.0, |m| m.delay_secs), timestep, self.opts.delay_buffer_secs);
            let gear = format!("{gear}{delay}");
            let line = match (iface, drive_model.and_then(|m| m.envelope())) {
                (Interface::Effort | Interface::Position, Some(envelope)) => {
                    let m = drive_model.expect("an envelope comes with its model");
                    self.dcmotor_xml(name, &j.name, *iface, m, envelope, meta, &gear, effort)
                }
                (Interface::Effort, None) => {
                    let range = drive
                        .filter(|d| d.interface == *iface)
                        .and_then(|d| d.cmd_range)
                        .map(|r| [r[0] / g.abs(), r[1] / g.abs()])
                        .or(effort.map(|e| [-e / g.abs(), e / g.abs()]));
                    let cr = range.map(|r| format!(" ctrlrange=\"{}\"", fv(&r))).unwrap_or_default();
                    format!("<motor name=\"{}\" joint=\"{}\"{gear}{cr}{fr}/>", esc(name), esc(&j.name))
                }
                (Interface::Position, None) => {
                    let kp = effort.map_or(100.0, |e| self.opts.position_kp_per_effort * e);
                    let kv = kp * self.opts.position_kv_per_kp;
                    // The drive's own gains (joint space) in actuator space: τ = g²·kp_a·(q* − q).
                    let kp = drive_model.and_then(|m| m.kp).map_or(kp, |k| k / (g * g));
                    let kv = drive_model.and_then(|m| m.kd).map_or(kv, |k| k / (g * g));
                    let cr = meta
                        .range
                        .map(|r| format!(" ctrlrange=\"{} {}\"", f(r[0] * g), f(r[1] * g)))
                        .unwrap_or_default();
                    format!(
                        "<position name=\"{}\" joint=\"{}\"{gear} kp=\"{}\" kv=\"{}\"{cr}{fr}/>",
                        esc(name),
                        esc(&j.name),
                        f(kp),
                        f(kv)
                    )
                }
                (Interface::Velocity, _) => {
                    let kv = effort.map_or(10.0, |e| self.opts.velocity_kv_per_effort * e);
                    let kv = drive_model.and_then(|m| m.kd).map_or(kv, |k| k / (g * g));
                    let cr = meta
                        .velocity_limit
                        .map(|v| format!(" ctrlrange=\"{} {}\"", f(-v * g.abs()), f(v * g.abs())))
                        .unwrap_or_default();
                    format!(
                        "<velocity name=\"{}\" joint=\"{}\"{gear} kv=\"{}\"{cr}{fr}/>",
                        esc(name),
                        esc(&j.name),
                        f(kv)
                    )
                }
            };
            let _ = writeln!(act, "    {line}");
        }
        for line in &self.tendon_act_xml {
            let _ = writeln!(act, "    {line}");
        }
        if !self.tendon_xml.is_empty() {
            let _ = writeln!(x, "  <tendon>");
            for t in &self.tendon_xml {
                let _ = writeln!(x, "    {t}");
            }
            let _ = writeln!(x, "  </tendon>");
        }
        if !act.is_empty() {
            let _ = writeln!(x, "  <actuator>\n{act}  </actuator>");
        }

        let mut sens = String::new();
        if self.opts.joint_sensors {
            for j in &robot.joints {
                if matches!(j.kind, JointKind::Revolute | JointKind::Continuous | JointKind::Prismatic) {
                    let n = esc(&j.name);
                    let _ = writeln!(sens, "    <jointpos name=\"{n}_pos\" joint=\"{n}\"/>");
                    let _ = writeln!(sens, "    <jointvel name=\"{n}_vel\" joint=\"{n}\"/>");
                }
            }
        }
        for s in &self.sensor_xml {
            let _ = writeln!(sens, "    {s}");
        }
        if !sens.is_empty() {
            let _ = writeln!(x, "  <sensor>\n{sens}  </sensor>");
        }
        if let Some(q) = home {
            let _ = writeln!(x, "  <keyframe>\n    <key name=\"home\" qpos=\"{}\"/>\n  </keyframe>", fv(q));
        }
        x.push_str(&self.meta().to_custom_xml());
        let _ = writeln!(x, "</mujoco>");
        Ok(x)
    }

    fn emit_root(&self, x: &mut String, link: usize, base_z: f64) -> Result<()> {
        let name = esc(&self.robot.links[link].name);
        let pos = if base_z != 0.0 { format!(" pos=\"0 0 {}\"", f(base_z)) } else { String::new() };
        let _ = writeln!(x, "    <body name=\"{name}\"{pos}>");
        if self.floating {
            let _ = writeln!(x, "      <freejoint name=\"floating_base\"/>");
        }
        self.emit_link_content(x, link, 3)?;
        let _ = writeln!(x, "    </body>");
        Ok(())
    }

    fn emit_body(&self, x: &mut String, joint: usize, depth: usize, lift_z: f64) -> Result<()> {
        let j = &self.robot.joints[joint];
        let link = self.tree.link_index[&j.child];
        let ind = "  ".repeat(depth);
        let mut origin = j.origin;
        origin.xyz.z += lift_z;
        let _ = writeln!(x, "{ind}<body name=\"{}\"{}>", esc(&j.child), pose_attrs(&origin));
        let ji = format!("{ind}  ");
        let n = esc(&j.name);
        let axis = fv(j.axis.as_slice());
        let mut dyn_attrs = String::new();
        if j.damping > 0.0 {
            let _ = write!(dyn_attrs, " damping=\"{}\"", f(j.damping));
        }
        if j.friction > 0.0 {
            let _ = write!(dyn_attrs, " frictionloss=\"{}\"", f(j.friction));
        }
        let armature = self.opts.joint_armature.get(&j.name).copied().unwrap_or(self.opts.armature);
        if armature > 0.0 {
            let _ = write!(dyn_attrs, " armature=\"{}\"", f(armature));
        }
        if let Some(l) = &j.limit
            && l.effort > 0.0
        {
            let _ = write!(dyn_attrs, " actuatorfrcrange=\"{} {}\"", f(-l.effort), f(l.effort));
        }
        match j.kind {
            JointKind::Fixed => {}
            JointKind::Revolute | JointKind::Prismatic => {
                let ty = if j.kind == JointKind::Revolute { "hinge" } else { "slide" };
                let range =
                    j.limit.as_ref().map(|l| format!(" range=\"{} {}\"", f(l.lower), f(l.upper))).unwrap_or_default();
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"{ty}\" axis=\"{axis}\"{range}{dyn_attrs}/>");
            }
            JointKind::Continuous => {
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"hinge\" axis=\"{axis}\"{dyn_attrs}/>");
            }
            JointKind::Spherical => {
                let range = j
                    .limit
                    .as_ref()
                    .filter(|l| l.upper > 0.0)
                    .map(|l| format!(" range=\"0 {}\"", f(l.upper)))
                    .unwrap_or_default();
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"ball\"{range}{dyn_attrs}/>");
            }
            JointKind::Planar => {
                let normal = j.axis;
                let u = if normal.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
                let u = (u - normal * normal.dot(&u)).normalize();
                let v = normal.cross(&u);
                let _ =
                    writeln!(x, "{ji}<joint name=\"{n}_tx\" type=\"slide\" axis=\"{}\"{dyn_attrs}/>", fv(u.as_slice()));
                let _ =
                    writeln!(x, "{ji}<joint name=\"{n}_ty\" type=\"slide\" axis=\"{}\"{dyn_attrs}/>", fv(v.as_slice()));
                let _ = writeln!(x, "{ji}<joint name=\"{n}\" type=\"hinge\" axis=\"{axis}\"{dyn_attrs}/>");
            }
            JointKind::Floating => {
                let parent = self.tree.link_index[&j.parent];
                if !(self.world_root && parent == self.tree.root) {
                    return Err(self.urdf_err(
                        j.line,
                        "joint",
                        &j.name,
                        "a floating joint is only supported between the world link and the robot's base (MuJoCo free joints belong to top-level bodies)".into(),
                    ));
                }
                let _ = writeln!(x, "{ji}<freejoint name=\"{n}\"/>");
            }
        }
        self.emit_link_content(x, link, depth + 1)?;
        let _ = writeln!(x, "{ind}</body>");
        Ok(())
    }

    fn emit_link_content(&self, x: &mut String, li: usize, depth: usize) -> Result<()> {
        let ind = "  ".repeat(depth);
        let link = &self.robot.links[li];
        if let Some((pos, fi, mass)) = &self.inertials[li] {
            let p = format!(" pos=\"{}\"", fv(pos));
            let _ = writeln!(x, "{ind}<inertial{p} mass=\"{}\" fullinertia=\"{}\"/>", f(*mass), fv(fi));
        }
        let gz_rgba = self.robot.gazebo.get(&link.name).and_then(|g| g.material.as_deref()).and_then(gazebo_rgba);
        let (ct, ca) = self.contype(link);
        let mut mu = self.mu[li];
        let mut prio = self.priority_of(mu);
        let mut solref = String::new();
        if let Some([k, b]) = self.contact[li] {
            // Highest priority, so this geom's solref/solimp are the contact's; its friction
            // is then the contact's too: take Gazebo's min with the world's.
            prio = self.priority.len() as i32;
            mu = mu.min(self.world_min_mu);
            // MuJoCo's pyramidal friction cone carries the normal force on edges n ± μ·t, which
            // scales the contact's constraint-space stiffness by 2/(μ²(1 + μ²)) (measured: exact
            // for the resting penetration); compensate so the penetration stays Gazebo's.
            let cone = if mu > 0.0 { mu * mu * (1.0 + mu * mu) / 2.0 } else { 1.0 };
            solref = format!(
                " solref=\"{} {}\" solimp=\"{d} {d} 0.001\"",
                f(k * cone),
                f(b * cone.sqrt()),
                d = CONTACT_IMPEDANCE
            );
        }
        let prio = if prio != 0 { format!(" priority=\"{prio}\"") } else { String::new() };
        let rgba_c = link.visuals.first().and_then(|v| v.rgba).or(gz_rgba);
        // Zero friction: frictionless contacts (a zero-width friction cone is degenerate).
        let condim = if mu <= 0.0 { " condim=\"1\"" } else { "" };
        for (gi, g) in link.collisions.iter().enumerate() {
            let rgba = rgba_c.map(|c| format!(" rgba=\"{}\"", fv(&c))).unwrap_or_default();
            let _ = writeln!(
                x,
                "{ind}<geom name=\"{}_collision_{gi}\"{} contype=\"{ct}\" conaffinity=\"{ca}\" group=\"3\" friction=\"{} 0.005 0.0001\"{condim}{prio}{solref}{rgba}/>",
                esc(&link.name),
                self.geom_attrs(li, false, gi, g),
                f(mu)
            );
        }
        if self.opts.visuals {
            for (gi, g) in link.visuals.iter().enumerate() {
                if matches!(g.shape, Shape::Mesh { .. }) && !self.mesh_of.contains_key(&(li, true, gi)) {
                    continue;
                }
                let rgba = g.rgba.or(gz_rgba).map(|c| format!(" rgba=\"{}\"", fv(&c))).unwrap_or_default();
                let _ = writeln!(
                    x,
                    "{ind}<geom name=\"{}_visual_{gi}\"{} contype=\"0\" conaffinity=\"0\" group=\"2\"{rgba}/>",
                    esc(&link.name),
                    self.geom_attrs(li, true, gi, g)
                );
            }
        }
        for s in &self.sites[li] {
            let _ = writeln!(x, "{ind}{s}");
        }
        for c in &self.cameras[li] {
            let _ = writeln!(x, "{ind}{c}");
        }
        for &j in &self.tree.children[li] {
            self.emit_body(x, j, depth, 0.0)?;
        }
        Ok(())
    }

    fn geom_attrs(&self, li: usize, visual: bool, gi: usize, g: &GeomIr) -> String {
        let shape = match &g.shape {
            Shape::Box(s) => format!(" type=\"box\" size=\"{}\"", fv(&[s[0] / 2.0, s[1] / 2.0, s[2] / 2.0])),
            Shape::Cylinder { radius, length } => {
                format!(" type=\"cylinder\" size=\"{} {}\"", f(*radius), f(length / 2.0))
            }
            Shape::Capsule { radius, length } => {
                format!(" type=\"capsule\" size=\"{} {}\"", f(*radius), f(length / 2.0))
            }
            Shape::Sphere(r) => format!(" type=\"sphere\" size=\"{}\"", f(*r)),
            Shape::Mesh { .. } => {
                let m = &self.meshes[self.mesh_of[&(li, visual, gi)]];
                format!(" type=\"mesh\" mesh=\"{}\"", esc(&m.name))
            }
        };
        format!("{shape}{}", pose_attrs(&g.pose))
    }
}

#[cfg(test)]
mod tests;
