//! `twin-convert` on its own, without an engine: the emitted MJCF is read back with an
//! independent XML reader (roxmltree) and its numbers checked against hand computations. The
//! placement compiles are answered by [`BoxEngine`], which measures what an engine would for
//! a robot made of axis-aligned boxes (the only shapes these fixtures use) from the MJCF text
//! itself, so the values the converter writes back (root height, keyframe, contact solref)
//! can be checked against geometry.

use std::path::Path;
use twin_convert::{
    ActuatorMode, Compile, Compiler, ConvertOptions, ConvertedModel, Error, Interface, Probe, convert_urdf,
    convert_urdf_str,
};

/// Answers the converter's two compiles for a robot of unrotated boxes hanging from one root
/// body (child bodies at `pos` offsets, no joint rotation at the zero pose).
#[derive(Default)]
struct BoxEngine {
    /// Every MJCF the converter asked to compile, in order.
    compiled: Vec<String>,
    /// `body_invweight0` answered for each body asked for.
    invweight: f64,
    /// When set, the engine refuses every document with this message.
    refuse: Option<String>,
}

/// World z of every body and the collision boxes' lowest points, walking the MJCF's bodies.
fn lowest_box_z(mjcf: &str) -> Option<f64> {
    let doc = roxmltree::Document::parse(mjcf).expect("the converter writes well-formed XML");
    let num = |s: &str| s.split_whitespace().map(|x| x.parse::<f64>().unwrap()).collect::<Vec<_>>();
    let mut lowest: Option<f64> = None;
    for geom in doc.descendants().filter(|n| n.has_tag_name("geom")) {
        if geom.attribute("contype") == Some("0") && geom.attribute("conaffinity") == Some("0") {
            continue;
        }
        assert_eq!(geom.attribute("type"), Some("box"), "fixtures use boxes only");
        assert!(geom.attribute("quat").is_none(), "fixtures use unrotated boxes");
        let mut z = geom.attribute("pos").map_or(0.0, |p| num(p)[2]) - num(geom.attribute("size").unwrap())[2];
        for body in geom.ancestors().filter(|n| n.has_tag_name("body")) {
            assert!(body.attribute("quat").is_none(), "fixtures use unrotated bodies");
            z += body.attribute("pos").map_or(0.0, |p| num(p)[2]);
        }
        lowest = Some(lowest.map_or(z, |l: f64| l.min(z)));
    }
    lowest
}

/// qpos0 of a model whose root has a free joint followed by hinges: the root body's position,
/// the identity quaternion, then one zero per hinge.
fn qpos0(mjcf: &str) -> Vec<f64> {
    let doc = roxmltree::Document::parse(mjcf).unwrap();
    let root = doc.descendants().find(|n| n.has_tag_name("worldbody")).unwrap();
    let body = root.children().find(|n| n.has_tag_name("body")).unwrap();
    let mut q: Vec<f64> = match body.attribute("pos") {
        Some(p) => p.split_whitespace().map(|x| x.parse().unwrap()).collect(),
        None => vec![0.0; 3],
    };
    q.extend([1.0, 0.0, 0.0, 0.0]);
    q.extend(
        doc.descendants().filter(|n| n.has_tag_name("joint") && n.attribute("type") == Some("hinge")).map(|_| 0.0),
    );
    q
}

impl Compiler for BoxEngine {
    type Error = Error;

    fn probe(&mut self, mjcf: &str, bodies: &[&str], _pose: &[(String, f64)]) -> Result<Probe, Compile<Error>> {
        self.compiled.push(mjcf.to_string());
        if let Some(m) = &self.refuse {
            return Err(Compile::Rejected(m.clone()));
        }
        Ok(Probe {
            lowest_collision_z_m: lowest_box_z(mjcf),
            body_invweight: vec![Some(self.invweight); bodies.len()],
            ..Probe::default()
        })
    }

    fn home_qpos(&mut self, mjcf: &str, _pose: &[(String, f64)]) -> Result<Vec<f64>, Compile<Error>> {
        self.compiled.push(mjcf.to_string());
        Ok(qpos0(mjcf))
    }
}

const INERTIA: &str = r#"<inertia ixx="0.01" iyy="0.02" izz="0.03" ixy="0" ixz="0" iyz="0"/>"#;

/// A 0.4 × 0.2 × 0.1 m box base (2 kg) with a fixed 1 kg payload 0.3 m above its origin, and
/// an arm on a revolute joint with a 50 N·m effort limit under a position interface.
fn robot_urdf() -> String {
    format!(
        r#"<?xml version="1.0"?>
<robot name="boxbot">
  <link name="base">
    <inertial><origin xyz="0 0 0"/><mass value="2"/>{INERTIA}</inertial>
    <collision><geometry><box size="0.4 0.2 0.1"/></geometry></collision>
  </link>
  <link name="payload">
    <inertial><origin xyz="0 0 0"/><mass value="1"/>{INERTIA}</inertial>
  </link>
  <joint name="mount" type="fixed"><parent link="base"/><child link="payload"/><origin xyz="0 0 0.3"/></joint>
  <link name="arm">
    <inertial><mass value="0.5"/>{INERTIA}</inertial>
    <collision><origin xyz="0 0 -0.1"/><geometry><box size="0.05 0.05 0.2"/></geometry></collision>
  </link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0.2 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="50" velocity="2"/></joint>
  <gazebo reference="arm"><kp>100000</kp><kd>100</kd></gazebo>
  <ros2_control name="hw" type="system">
    <joint name="shoulder"><command_interface name="position"/></joint>
  </ros2_control>
</robot>
"#
    )
}

fn convert(engine: &mut BoxEngine) -> ConvertedModel {
    convert_urdf_str(Path::new("boxbot.urdf"), &robot_urdf(), &ConvertOptions::default(), engine).unwrap()
}

fn attr_nums(node: roxmltree::Node<'_, '_>, attr: &str) -> Vec<f64> {
    node.attribute(attr)
        .unwrap_or_else(|| panic!("<{}> has no {attr}", node.tag_name().name()))
        .split_whitespace()
        .map(|x| x.parse().unwrap())
        .collect()
}

/// The lowest point is the arm's box bottom: 0.2 m below the base origin (its 0.2 m box hangs
/// from the joint, level with the base origin), below the base's own box (0.05 m), so the root
/// is placed 0.2 m up; the keyframe is the placed root with the identity orientation.
#[test]
fn the_robot_stands_on_the_floor_at_its_lowest_collision_point() {
    let mut engine = BoxEngine { invweight: 0.5, ..Default::default() };
    let out = convert(&mut engine);
    assert_eq!(engine.compiled.len(), 2, "a probe compile and a home compile");
    assert!((out.base_height_m - 0.2).abs() < 1e-12, "{}", out.base_height_m);
    assert!(out.meta.floating_base);
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let base = doc.descendants().find(|n| n.attribute("name") == Some("base")).unwrap();
    assert_eq!(attr_nums(base, "pos"), vec![0.0, 0.0, 0.2]);
    let key = doc.descendants().find(|n| n.has_tag_name("key")).unwrap();
    assert_eq!(key.attribute("name"), Some("home"));
    assert_eq!(attr_nums(key, "qpos"), vec![0.0, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0, 0.0]);
    // The placed model has the floor; the probe did not.
    assert!(doc.descendants().any(|n| n.attribute("name") == Some("floor")));
    assert!(!engine.compiled[0].contains("name=\"floor\""));
}

/// The fixed payload's mass is lumped into the base by the parallel-axis theorem: 3 kg, centre
/// of mass 0.1 m up, each own tensor plus m·r² about the combined centre for the x and y axes.
#[test]
fn fixed_links_are_lumped_by_the_parallel_axis_theorem() {
    let out = convert(&mut BoxEngine { invweight: 0.5, ..Default::default() });
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let base = doc.descendants().find(|n| n.attribute("name") == Some("base")).unwrap();
    let inertial = base.children().find(|n| n.has_tag_name("inertial")).unwrap();
    let (m1, m2, d) = (2.0, 1.0, 0.3);
    let m = m1 + m2;
    let com = m2 * d / m;
    assert_eq!(attr_nums(inertial, "mass"), vec![m]);
    assert!((attr_nums(inertial, "pos")[2] - com).abs() < 1e-12);
    // About the combined centre: each part's own tensor plus m·r² for the x and y axes.
    let shift = m1 * com * com + m2 * (d - com) * (d - com);
    let fi = attr_nums(inertial, "fullinertia");
    let expected = [0.02 + shift, 0.04 + shift, 0.06, 0.0, 0.0, 0.0];
    for (got, want) in fi.iter().zip(expected) {
        assert!((got - want).abs() < 1e-12, "fullinertia {fi:?}, expected {expected:?}");
    }
    assert!(out.notes.iter().any(|n| n.contains("payload → base")), "{:?}", out.notes);
}

/// ros2_control's position interface becomes a `position` actuator with kp = 20 N·m/rad per
/// N·m of effort (the default `position_kp_per_effort`) and kv = kp·`position_kv_per_kp`.
#[test]
fn a_position_interface_gets_a_position_servo_scaled_by_effort() {
    let out = convert(&mut BoxEngine { invweight: 0.5, ..Default::default() });
    let opts = ConvertOptions::default();
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let servo = doc.descendants().find(|n| n.has_tag_name("position")).expect("a position actuator");
    assert_eq!(servo.attribute("joint"), Some("shoulder"));
    let kp = opts.position_kp_per_effort * 50.0;
    assert_eq!(attr_nums(servo, "kp"), vec![kp]);
    assert_eq!(attr_nums(servo, "kv"), vec![kp * opts.position_kv_per_kp]);
    assert_eq!(attr_nums(servo, "ctrlrange"), vec![-1.0, 1.0]);
    let joint = out.meta.joints.iter().find(|j| j.name == "shoulder").unwrap();
    assert_eq!(joint.actuator, Some(("shoulder".into(), Interface::Position)));
    assert_eq!(joint.velocity_limit, Some(2.0));
    // Forced motors instead: a motor within ±effort.
    let motors = ConvertOptions { actuators: ActuatorMode::Motor, ..Default::default() };
    let out = convert_urdf_str(Path::new("boxbot.urdf"), &robot_urdf(), &motors, &mut BoxEngine::default()).unwrap();
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let motor = doc.descendants().find(|n| n.has_tag_name("motor")).expect("a motor");
    assert_eq!(attr_nums(motor, "ctrlrange"), vec![-50.0, 50.0]);
}

/// Gazebo kp/kd become a direct-form solref from the effective mass the engine measured
/// (1 / body_invweight0): K = (1 − d)·kp/m, scaled by the pyramid factor μ²(1 + μ²)/2 at μ = 1.
#[test]
fn gazebo_contact_stiffness_uses_the_measured_effective_mass() {
    let invweight = 0.25; // 4 kg
    let out = convert(&mut BoxEngine { invweight, ..Default::default() });
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let geom = doc.descendants().find(|n| n.attribute("name") == Some("arm_collision_0")).unwrap();
    let solref = attr_nums(geom, "solref");
    let d = 0.9;
    let mass = 1.0 / invweight;
    let k = (1.0 - d) * 100_000.0 / mass;
    let cone = 1.0 * (1.0 + 1.0) / 2.0;
    assert!((solref[0] + k * cone).abs() < 1e-9 * k, "{solref:?} vs K = {k}");
    let b = f64::sqrt(1.0 - d) * 100.0 / mass;
    let b = b.max(2.0 * (k / d).sqrt());
    assert!((solref[1] + b * cone.sqrt()).abs() < 1e-9 * b, "{solref:?} vs B = {b}");
}

/// An engine's refusal that names an element of the generated MJCF is reported at the URDF
/// line of that element; bad XML and missing files name the file.
#[test]
fn errors_name_the_urdf_file_line_and_element() {
    let mut engine =
        BoxEngine { refuse: Some("Error: mass too small\nElement name 'arm', id 2".into()), ..Default::default() };
    let err =
        convert_urdf_str(Path::new("boxbot.urdf"), &robot_urdf(), &ConvertOptions::default(), &mut engine).unwrap_err();
    match &err {
        Error::Urdf { path, line, element, name, message } => {
            assert_eq!(path, Path::new("boxbot.urdf"));
            assert_eq!(*line, 11, "the line of <link name=\"arm\">");
            assert_eq!(element, "link");
            assert_eq!(name.as_deref(), Some("arm"));
            assert!(message.contains("mass too small"), "{message}");
        }
        other => panic!("not translated: {other}"),
    }
    let err = convert_urdf_str(
        Path::new("bad.urdf"),
        "<robot name=\"x\">\n<link name=\"a\"></robot>\n",
        &Default::default(),
        &mut engine,
    )
    .unwrap_err();
    assert!(matches!(err, Error::Xml { line: 2, .. }), "{err}");
    assert!(err.to_string().starts_with("bad.urdf:2:"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.urdf");
    let err = convert_urdf(&missing, &Default::default(), &mut engine).unwrap_err();
    assert!(matches!(err, Error::File(twin_fsio::Error::Io { .. })), "{err}");
    assert!(err.to_string().contains("missing.urdf"), "{err}");
    let err =
        convert_urdf_str(Path::new("empty.urdf"), "<robot name=\"x\"/>", &Default::default(), &mut engine).unwrap_err();
    assert!(matches!(err, Error::Urdf { .. }), "{err}");
}

/// What twin publishes the robot by travels in `<custom><text>` and reads back unchanged.
#[test]
fn metadata_round_trips_through_the_custom_texts() {
    let out = convert(&mut BoxEngine { invweight: 0.5, ..Default::default() });
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let texts: Vec<(&str, &str)> = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| (n.attribute("name").unwrap(), n.attribute("data").unwrap()))
        .collect();
    let meta = twin_convert::RobotMeta::from_custom_texts(&texts).expect("twin metadata");
    assert_eq!(meta, out.meta);
    assert_eq!(meta.name, "boxbot");
    assert!(twin_convert::RobotMeta::from_custom_texts(&[("other", "x")]).is_none());
}

/// `ConvertOptions::contact_sensors`: a link named there gets what a Gazebo contact sensor on it
/// would: a `touch` sensor `LINK_contact` on a box site covering the link's collision box 5 %
/// larger (the arm's 0.05 × 0.05 × 0.2 m box: half sizes 0.02625 × 0.02625 × 0.105 m, at the
/// collision's origin 0.1 m down); a name that is no link is refused, naming the URDF, the
/// option and the link, and listing the links there are.
#[test]
fn contact_sensors_put_a_touch_sensor_over_a_links_collision() {
    let opts = ConvertOptions { contact_sensors: vec!["arm".into()], ..Default::default() };
    let mut engine = BoxEngine { invweight: 0.5, ..Default::default() };
    let out = convert_urdf_str(Path::new("boxbot.urdf"), &robot_urdf(), &opts, &mut engine).unwrap();
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let touch: Vec<_> = doc.descendants().filter(|n| n.has_tag_name("touch")).collect();
    assert_eq!(touch.len(), 1, "{}", out.mjcf);
    assert_eq!(touch[0].attribute("name"), Some("arm_contact"));
    let site_name = touch[0].attribute("site").unwrap();
    let site = doc.descendants().find(|n| n.has_tag_name("site") && n.attribute("name") == Some(site_name)).unwrap();
    assert_eq!(site.parent().unwrap().attribute("name"), Some("arm"), "the site is on the arm's body");
    assert_eq!(site.attribute("type"), Some("box"));
    let size = attr_nums(site, "size");
    for (got, want) in size.iter().zip([0.02625, 0.02625, 0.105]) {
        assert!((got - want).abs() < 1e-9, "site size {size:?}");
    }
    assert!((attr_nums(site, "pos")[2] + 0.1).abs() < 1e-9, "at the collision's origin");
    let without = convert(&mut BoxEngine { invweight: 0.5, ..Default::default() });
    assert!(!without.mjcf.contains("<touch"), "no sensor unless asked for");
    // A link of two collision geoms (a foot of several contact shapes): a touch sensor over each
    // (a Gazebo contact sensor in the URDF covers its first collision only).
    let two = robot_urdf().replace(
        "<geometry><box size=\"0.05 0.05 0.2\"/></geometry></collision>",
        "<geometry><box size=\"0.05 0.05 0.2\"/></geometry></collision>\n    \
         <collision><origin xyz=\"0 0 -0.2\"/><geometry><box size=\"0.04 0.04 0.04\"/></geometry></collision>",
    );
    let opts = ConvertOptions { contact_sensors: vec!["arm".into()], ..Default::default() };
    let out = convert_urdf_str(Path::new("boxbot.urdf"), &two, &opts, &mut engine).unwrap();
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let names: Vec<_> = doc.descendants().filter(|n| n.has_tag_name("touch")).map(|n| n.attribute("name")).collect();
    assert_eq!(names, [Some("arm_contact"), Some("arm_contact_2")]);
    let site = doc.descendants().find(|n| n.attribute("name") == Some("arm_contact_2_site")).unwrap();
    assert!((attr_nums(site, "size")[0] - 0.021).abs() < 1e-9 && (attr_nums(site, "pos")[2] + 0.2).abs() < 1e-9);

    let opts = ConvertOptions { contact_sensors: vec!["foot".into()], ..Default::default() };
    let err = convert_urdf_str(Path::new("boxbot.urdf"), &robot_urdf(), &opts, &mut engine).unwrap_err();
    let text = err.to_string();
    assert!(text.starts_with("boxbot.urdf:"), "{text}");
    assert!(text.contains("no link \"foot\"") && text.contains("contact_sensors"), "{text}");
    assert!(text.contains("base, payload, arm"), "{text}");
}

/// The `<twin_sysid>` block `twin sysid` writes: its armature becomes the joint's MuJoCo
/// `armature` unless the caller gives one; a bad value names the line.
#[test]
fn the_sysid_block_gives_the_joint_its_armature() {
    let block = "<twin_sysid version=\"1\">\n    <joint name=\"shoulder\" offset=\"0.1\" coulomb=\"0.2\" armature=\"0.035\"/>\n  </twin_sysid>\n</robot>";
    let urdf = robot_urdf().replace("</robot>", block);
    let out = convert_urdf_str(Path::new("boxbot.urdf"), &urdf, &ConvertOptions::default(), &mut BoxEngine::default())
        .unwrap();
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let joint = doc.descendants().find(|n| n.has_tag_name("joint") && n.attribute("name") == Some("shoulder")).unwrap();
    assert_eq!(attr_nums(joint, "armature"), vec![0.035]);
    let mut given = ConvertOptions::default();
    given.joint_armature.insert("shoulder".into(), 0.5);
    let out = convert_urdf_str(Path::new("boxbot.urdf"), &urdf, &given, &mut BoxEngine::default()).unwrap();
    let doc = roxmltree::Document::parse(&out.mjcf).unwrap();
    let joint = doc.descendants().find(|n| n.has_tag_name("joint") && n.attribute("name") == Some("shoulder")).unwrap();
    assert_eq!(attr_nums(joint, "armature"), vec![0.5]);
    let bad = urdf.replace("armature=\"0.035\"", "armature=\"-1\"");
    let err = convert_urdf_str(Path::new("boxbot.urdf"), &bad, &ConvertOptions::default(), &mut BoxEngine::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("boxbot.urdf") && err.contains("armature=\"-1\""), "{err}");
}
