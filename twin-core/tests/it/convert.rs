//! The URDF converter against MuJoCo's own URDF import, on malformed input, and on meshes.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use std::path::{Path, PathBuf};
use twin_core::convert::{ConvertOptions, convert_urdf, convert_urdf_str};
use twin_core::mj::Error;
use twin_core::mj::{Data, JointType, Model, ObjType};

fn humanoid() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/humanoid.urdf")
}

/// Body-frame inertia tensor of body `b` (from principal moments and `iquat`).
fn inertia_tensor(m: &Model, b: usize) -> Matrix3<f64> {
    let q = m.body_iquat()[b];
    let r = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3])).to_rotation_matrix();
    let d = Matrix3::from_diagonal(&Vector3::from(m.body_inertia()[b]));
    r.matrix() * d * r.matrix().transpose()
}

/// The humanoid's URDF text with the first `from` replaced by `to` (which must be there).
fn humanoid_edited(from: &str, to: &str) -> String {
    let text = std::fs::read_to_string(humanoid()).unwrap();
    assert!(text.contains(from), "the humanoid no longer has {from:?}");
    text.replacen(from, to, 1)
}

#[test]
fn humanoid_matches_mujoco_own_import_and_adds_actuators_sensors_friction() {
    // MuJoCo's importer fuses fixed children into their parent (fusestatic); twin lumps their
    // mass the same way but keeps their bodies: the moving bodies must agree exactly.
    let text = humanoid_edited(
        "<robot name=\"humanoid\">",
        "<robot name=\"humanoid\">\n<mujoco><compiler fusestatic=\"true\" discardvisual=\"false\"/></mujoco>",
    );
    let dir = tempfile::tempdir().unwrap();
    let urdf = dir.path().join("humanoid.urdf");
    std::fs::write(&urdf, &text).unwrap();
    let theirs = Model::from_mujoco_file(&urdf).unwrap();
    assert_eq!(theirs.nu(), 0, "MuJoCo's import has no actuators");
    assert_eq!(theirs.nsensor(), 0, "MuJoCo's import has no sensors");

    // Fixed base: MuJoCo welds the root too.
    let fixed =
        Model::from_urdf(humanoid(), &ConvertOptions { fixed_base: true, ..ConvertOptions::default() }).unwrap();
    let ours = Model::from_file(humanoid()).unwrap();
    assert!((ours.total_mass_kg() - 35.71).abs() < 1e-9, "{}", ours.total_mass_kg());
    assert_eq!(ours.joint_type(0), JointType::Free);

    let moving = |m: &Model| {
        (1..m.nbody())
            .filter(|&b| m.body_jntnum()[b] > 0 && m.joint_type(m.body_jntadr()[b] as usize) != JointType::Free)
            .count()
    };
    assert_eq!(moving(&fixed), moving(&theirs));
    assert_eq!(moving(&fixed), 23);

    let mut their_mass = 0.0;
    let mut compared = 0;
    for b in 1..theirs.nbody() {
        let name = theirs.name(ObjType::Body, b);
        let ob = ours.require_id(ObjType::Body, name).unwrap();
        their_mass += theirs.body_mass()[b];
        assert!((ours.body_mass()[ob] - theirs.body_mass()[b]).abs() < 1e-9, "{name} mass");
        for k in 0..3 {
            assert!((ours.body_ipos()[ob][k] - theirs.body_ipos()[b][k]).abs() < 1e-9, "{name} com");
        }
        let d = inertia_tensor(&ours, ob) - inertia_tensor(&theirs, b);
        assert!(d.abs().max() < 1e-9, "{name} inertia differs by {}", d.abs().max());
        compared += 1;
    }
    // 25 links: imu_link fused into torso_link, the welded root into the world.
    assert_eq!(compared, 23);
    let imu = ours.require_id(ObjType::Body, "imu_link").unwrap();
    assert_eq!(ours.body_mass()[imu], 0.0, "lumped into torso_link");
    // MuJoCo's fusestatic folds the welded root into the world, dropping its mass; twin keeps it.
    let root_mass = ours.body_mass()[1];
    assert!((their_mass + root_mass - ours.total_mass_kg()).abs() < 1e-9, "{their_mass} + {root_mass}");
    for j in 0..theirs.njnt() {
        let name = theirs.name(ObjType::Joint, j);
        let oj = ours.require_id(ObjType::Joint, name).unwrap();
        for k in 0..3 {
            assert!((ours.jnt_axis()[oj][k] - theirs.jnt_axis()[j][k]).abs() < 1e-9, "{name} axis");
        }
        for k in 0..2 {
            assert!((ours.jnt_range()[oj][k] - theirs.jnt_range()[j][k]).abs() < 1e-9, "{name} range");
        }
        let (od, td) = (ours.jnt_dofadr()[oj] as usize, theirs.jnt_dofadr()[j] as usize);
        assert!((ours.dof_damping()[od] - theirs.dof_damping()[td]).abs() < 1e-12);
        assert!((ours.dof_frictionloss()[od] - theirs.dof_frictionloss()[td]).abs() < 1e-12);
    }
    // What MuJoCo's import lacks.
    assert_eq!(ours.nu(), 23);
    let knee = ours.require_id(ObjType::Actuator, "left_knee_joint").unwrap();
    assert_eq!(ours.actuator_forcerange()[knee], [-120.0, 120.0]);
    assert_eq!(ours.actuator_ctrlrange()[knee], [-120.0, 120.0]);
    for s in ["imu_sensor_quat", "imu_sensor_gyro", "imu_sensor_accel", "left_knee_joint_pos"] {
        ours.require_id(ObjType::Sensor, s).unwrap();
    }
    let gyro = ours.require_id(ObjType::Sensor, "imu_sensor_gyro").unwrap();
    assert!((ours.sensor_noise()[gyro] - 0.002).abs() < 1e-12);
    ours.require_id(ObjType::Body, "imu_link").unwrap();
    // Foot friction from mu1/mu2, with priority so the min rule of Gazebo holds.
    let foot = ours.require_id(ObjType::Geom, "left_foot_link_collision_0").unwrap();
    assert_eq!(ours.geom_friction()[foot][0], 1.0);
    // Robot geoms don't collide with each other, but do with the floor.
    let floor = ours.require_id(ObjType::Geom, "floor").unwrap();
    let (ct, ca) = (ours.geom_contype(), ours.geom_conaffinity());
    assert_eq!(ct[foot] & ca[foot], 0);
    assert_ne!((ct[foot] & ca[floor]) | (ct[floor] & ca[foot]), 0);
}

#[test]
fn metadata_keeps_imu_topic_rates_limits_and_home_pose() {
    let c = convert_urdf(&humanoid(), &ConvertOptions::default()).unwrap();
    assert_eq!(c.meta.imus.len(), 1);
    let imu = &c.meta.imus[0];
    assert_eq!(imu.topic.as_deref(), Some("/humanoid/imu/data"));
    assert_eq!(imu.update_rate_hz, Some(200.0));
    assert_eq!(imu.gyro_noise_std, 0.002);
    assert_eq!(imu.accel_noise_std, 0.017);
    assert_eq!(imu.frame_id, "imu_link");
    let knee = c.meta.joints.iter().find(|j| j.name == "left_knee_joint").unwrap();
    assert_eq!(knee.velocity_limit, Some(10.0));
    assert_eq!(knee.effort_limit, Some(120.0));
    // Nominal standing height documented in models/README.md: 0.71 m.
    assert!((c.base_height_m - 0.71).abs() < 1e-9, "{}", c.base_height_m);
    let model = std::sync::Arc::new(Model::from_xml_str(&c.mjcf).unwrap());
    let key = model.require_id(ObjType::Key, "home").unwrap();
    assert!((model.key_qpos(key).unwrap()[2] - 0.71).abs() < 1e-9);
    // At home the soles touch the floor: the lowest foot point is at z = 0.
    let mut d = Data::new(model.clone()).unwrap();
    d.reset_to_keyframe(key).unwrap();
    d.forward().unwrap();
    let g = model.require_id(ObjType::Geom, "left_foot_link_collision_0").unwrap();
    let half_height = model.geom_size()[g][2];
    assert!((d.geom_xpos()[g][2] - half_height).abs() < 1e-9);
}

#[test]
fn mimic_planar_prismatic_continuous_and_position_actuators() {
    let urdf = r#"<robot name="mix">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial>
    <collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision></link>
  <link name="a"><inertial><origin xyz="0 0 0.1" rpy="0.3 0.2 0.1"/><mass value="1"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0.002" iyy="0.03" iyz="0.003" izz="0.04"/></inertial></link>
  <link name="b"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial></link>
  <link name="c"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="3"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="3"/><mimic joint="j1" multiplier="-2" offset="0.1"/></joint>
  <joint name="j3" type="prismatic"><parent link="b"/><child link="c"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.3" effort="50" velocity="1"/></joint>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="j1"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>
    <actuator name="m1"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <transmission name="t3"><type>transmission_interface/SimpleTransmission</type>
    <joint name="j3"><hardwareInterface>hardware_interface/VelocityJointInterface</hardwareInterface></joint>
    <actuator name="m3"><mechanicalReduction>2</mechanicalReduction></actuator></transmission>
</robot>"#;
    let c = convert_urdf_str(Path::new("mix.urdf"), urdf, &ConvertOptions::default()).unwrap();
    let m = Model::from_xml_str(&c.mjcf).unwrap();
    assert_eq!(m.neq(), 1);
    assert_eq!(m.nu(), 2);
    let a1 = m.require_id(ObjType::Actuator, "j1").unwrap();
    assert_eq!(m.actuator_gainprm()[a1][0], 200.0); // 20 × 10 N·m
    let a3 = m.require_id(ObjType::Actuator, "j3").unwrap();
    assert_eq!(m.actuator_gear()[a3][0], 2.0);
    // Rotated inertial origin: the body-frame tensor is R I Rᵀ.
    let b = m.require_id(ObjType::Body, "a").unwrap();
    let i = Matrix3::new(0.02, 0.001, 0.002, 0.001, 0.03, 0.003, 0.002, 0.003, 0.04);
    let r = UnitQuaternion::from_euler_angles(0.3, 0.2, 0.1).to_rotation_matrix();
    let expected = r.matrix() * i * r.matrix().transpose();
    assert!((inertia_tensor(&m, b) - expected).abs().max() < 1e-12);
    // The mimic equality holds in simulation: j2 = 0.1 − 2·j1.
    let m = std::sync::Arc::new(m);
    let mut d = Data::new(m.clone()).unwrap();
    d.ctrl_mut()[a1] = 0.4;
    for _ in 0..1000 {
        d.step().unwrap();
    }
    let q1 = d.qpos()[m.jnt_qposadr()[m.require_id(ObjType::Joint, "j1").unwrap()] as usize];
    let q2 = d.qpos()[m.jnt_qposadr()[m.require_id(ObjType::Joint, "j2").unwrap()] as usize];
    assert!((q1 - 0.4).abs() < 0.05, "{q1}");
    assert!((q2 - (0.1 - 2.0 * q1)).abs() < 0.01, "{q1} {q2}");
}

fn expect_urdf_error(urdf: &str, line: u32, element: &str, needle: &str) {
    let err = convert_urdf_str(Path::new("bad.urdf"), urdf, &ConvertOptions::default()).unwrap_err();
    let text = err.to_string();
    match &err {
        Error::Convert(twin_convert::Error::Urdf { line: l, element: e, .. }) => {
            assert_eq!((*l, e.as_str()), (line, element), "{text}");
        }
        Error::Convert(twin_convert::Error::Xml { line: l, .. }) => assert_eq!(*l, line, "{text}"),
        other => panic!("unexpected error {other:?}"),
    }
    assert!(text.contains("bad.urdf"), "{text}");
    assert!(text.contains(needle), "{text}");
}

const LINK: &str = r#"<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial>"#;

#[test]
fn malformed_input_gives_one_clear_error() {
    expect_urdf_error("<robot name=\"r\">\n<link name=\"a\">\n</robot>", 3, "", "not well-formed");
    expect_urdf_error(
        &format!(
            "<robot name=\"r\">\n<link name=\"a\">{LINK}</link>\n<joint name=\"j\" type=\"fixed\">\n<parent link=\"a\"/>\n<child link=\"ghost\"/>\n</joint>\n</robot>"
        ),
        5,
        "child",
        "child link \"ghost\" does not exist",
    );
    expect_urdf_error(
        &format!(
            "<robot name=\"r\">\n<link name=\"a\">{LINK}</link>\n<link name=\"b\">{LINK}</link>\n\
             <joint name=\"ab\" type=\"continuous\"><parent link=\"a\"/><child link=\"b\"/></joint>\n\
             <joint name=\"ba\" type=\"continuous\"><parent link=\"b\"/><child link=\"a\"/></joint>\n</robot>"
        ),
        4,
        "joint",
        "cycle",
    );
    expect_urdf_error(
        "<robot name=\"r\">\n<link name=\"a\">\n<collision><geometry>\n<mesh filename=\"meshes/nope.stl\"/>\n</geometry></collision>\n</link>\n</robot>",
        4,
        "mesh",
        "mesh file not found",
    );
    expect_urdf_error(
        "<robot name=\"r\">\n<link name=\"a\">\n<inertial>\n<mass value=\"-2\"/>\n</inertial>\n</link>\n</robot>",
        4,
        "mass",
        "negative mass",
    );
    expect_urdf_error(
        "<robot name=\"r\">\n<link name=\"a\">\n<collision><geometry>\n<mesh filename=\"package://nopkg/m.stl\"/>\n</geometry></collision>\n</link>\n</robot>",
        4,
        "mesh",
        "--package-path",
    );
    // Triangle inequality: repaired by default with a note naming the link, refused when strict.
    let bad = "<robot name=\"r\">\n<link name=\"a\">\n<inertial><mass value=\"1\"/>\n<inertia ixx=\"0.01\" iyy=\"0.01\" izz=\"0.05\"/>\n</inertial>\n</link>\n</robot>";
    let strict = ConvertOptions { strict_inertia: true, ..ConvertOptions::default() };
    let err = convert_urdf_str(Path::new("bad.urdf"), bad, &strict).unwrap_err().to_string();
    assert!(err.contains("bad.urdf:4") && err.contains("triangle") && err.contains("--strict-inertia"), "{err}");
    let c = convert_urdf_str(Path::new("bad.urdf"), bad, &ConvertOptions::default()).unwrap();
    assert!(
        c.notes.iter().any(|n| n.contains("link \"a\" (line 4)") && n.contains("repaired") && n.contains("→")),
        "{:?}",
        c.notes
    );
    let m = Model::from_xml_str(&c.mjcf).unwrap();
    let i = m.body_inertia()[1];
    let mut s = i;
    s.sort_by(f64::total_cmp);
    assert!(s[0] + s[1] >= s[2] * (1.0 - 1e-9), "{i:?}");
    // Smallest change: (0.05 − 0.02)/3 moved between moments.
    assert!((s[2] - 0.04).abs() < 1e-6, "{s:?}");
}

/// What ROS and Gazebo accept, the converter accepts, with a note saying what it assumed.
#[test]
fn gazebo_leftovers_and_noise_are_notes_not_errors() {
    let urdf = r#"<robot name="lenient">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial>
    <collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision></link>
  <link name="arm"><inertial><origin xyz="0 0 0.1"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="1e-19" izz="-2.220446e-16"/></inertial></link>
  <link name="tool_frame"><inertial><mass value="0.01"/><inertia ixx="0" iyy="0" izz="0"/></inertial></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="3"/></joint>
  <joint name="tool" type="fixed"><parent link="arm"/><child link="tool_frame"/><origin xyz="0 0 0.3"/></joint>
  <gazebo reference="base"><mu1></mu1><mu2>0.8</mu2></gazebo>
  <gazebo reference="wheel_{side}_joint"><mu1>1</mu1></gazebo>
  <gazebo reference="j"><implicitSpringDamper>1</implicitSpringDamper></gazebo>
  <transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="j"><hardwareInterface>hardware_interface/JointStateInterface</hardwareInterface>
      <hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
    <actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
</robot>"#;
    let c = convert_urdf_str(Path::new("lenient.urdf"), urdf, &ConvertOptions::default()).unwrap();
    let notes = c.notes.join("\n");
    assert!(notes.contains("<mu1></mu1> is not a number") && notes.contains("ignored"), "{notes}");
    assert!(notes.contains("wheel_{side}_joint") && notes.contains("unexpanded xacro"), "{notes}");
    assert!(notes.contains("tool_frame → arm"), "{notes}");
    let m = Model::from_xml_str(&c.mjcf).unwrap();
    // The 10 g tool frame keeps its body; its mass moved into the arm (parallel-axis theorem).
    let tool = m.require_id(ObjType::Body, "tool_frame").unwrap();
    let arm = m.require_id(ObjType::Body, "arm").unwrap();
    assert_eq!(m.body_mass()[tool], 0.0);
    assert!((m.body_mass()[arm] - 1.01).abs() < 1e-12);
    assert!((m.body_ipos()[arm][2] - (0.1 * 1.0 + 0.3 * 0.01) / 1.01).abs() < 1e-12);
    assert!((m.total_mass_kg() - 3.01).abs() < 1e-12);
    // The JointStateInterface is skipped, the effort interface drives the joint.
    let a = m.require_id(ObjType::Actuator, "j").unwrap();
    assert_eq!(m.actuator_gainprm()[a][0], 1.0, "a motor");
    // Friction from mu2 alone.
    let g = m.require_id(ObjType::Geom, "base_collision_0").unwrap();
    assert_eq!(m.geom_friction()[g][0], 0.8);
    // A file that is not a robot is still an error.
    expect_urdf_error("<robot name=\"r\">\n</robot>", 1, "robot", "no <link>");
}

/// `--actuators`: auto motors for untransmitted joints with effort, none for mimics.
#[test]
fn actuator_modes() {
    use twin_core::convert::ActuatorMode;
    let urdf = r#"<robot name="acts">
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial></link>
  <link name="a"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial></link>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial></link>
  <link name="c"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial></link>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/><limit lower="-1" upper="1" effort="7" velocity="3"/></joint>
  <joint name="jb" type="revolute"><parent link="a"/><child link="b"/><limit lower="-1" upper="1" effort="5" velocity="3"/>
    <mimic joint="ja"/></joint>
  <joint name="jc" type="continuous"><parent link="b"/><child link="c"/></joint>
  <transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="ja"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>
    <actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
</robot>"#;
    let nu = |mode: ActuatorMode| {
        let c = convert_urdf_str(
            Path::new("acts.urdf"),
            urdf,
            &ConvertOptions { actuators: mode, ..ConvertOptions::default() },
        )
        .unwrap();
        let m = Model::from_xml_str(&c.mjcf).unwrap();
        (0..m.nu()).map(|a| (m.name(ObjType::Actuator, a).to_string(), m.actuator_biasprm()[a][1])).collect::<Vec<_>>()
    };
    // auto: ja's declared position servo (bias −kp); jb mimics; jc has no effort limit.
    assert_eq!(nu(ActuatorMode::Auto), vec![("ja".to_string(), -140.0)]);
    assert_eq!(nu(ActuatorMode::Transmissions), vec![("ja".to_string(), -140.0)]);
    assert_eq!(nu(ActuatorMode::Motor), vec![("ja".to_string(), 0.0), ("jc".to_string(), 0.0)]);
    assert_eq!(nu(ActuatorMode::Position).len(), 2);
    assert!(nu(ActuatorMode::None).is_empty());
}

/// Differential and half-differential transmissions: commanding the two actuators gives the
/// joint torques of ros_control's (and PAL's) actuator-to-joint effort maps.
#[test]
fn differential_transmissions_map_efforts_like_ros_control() {
    let link = |n: &str| {
        format!(
            r#"<link name="{n}"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial></link>"#
        )
    };
    let trans = |name: &str, ty: &str, j: [&str; 2], ar: [f64; 2], jr: [f64; 2]| {
        format!(
            r#"<transmission name="{name}"><type>transmission_interface/{ty}</type>
  <actuator name="{name}_m1"><role>actuator1</role><mechanicalReduction>{}</mechanicalReduction></actuator>
  <actuator name="{name}_m2"><role>actuator2</role><mechanicalReduction>{}</mechanicalReduction></actuator>
  <joint name="{}"><role>joint1</role><offset>0</offset><mechanicalReduction>{}</mechanicalReduction>
    <hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
  <joint name="{}"><role>joint2</role><mechanicalReduction>{}</mechanicalReduction>
    <hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint></transmission>"#,
            ar[0], ar[1], j[0], jr[0], j[1], jr[1]
        )
    };
    let joint = |n: &str, p: &str, c: &str, axis: &str| {
        format!(
            r#"<joint name="{n}" type="revolute"><parent link="{p}"/><child link="{c}"/><axis xyz="{axis}"/><limit lower="-1" upper="1" effort="1000" velocity="3"/></joint>"#
        )
    };
    let urdf = format!(
        "<robot name=\"diff\">{}{}{}{}{}{}{}{}{}{}{}</robot>",
        link("base"),
        link("a"),
        link("b"),
        link("c"),
        link("d"),
        joint("j1", "base", "a", "0 0 1"),
        joint("j2", "a", "b", "0 1 0"),
        joint("j3", "b", "c", "1 0 0"),
        joint("j4", "c", "d", "0 1 0"),
        trans("wrist", "DifferentialTransmission", ["j1", "j2"], [-1.5, 2.0], [3.0, 0.5]),
        trans("head", "HalfDifferentialTransmission", ["j3", "j4"], [1.25, -0.75], [1.0, 2.0]),
    );
    let c = convert_urdf_str(
        Path::new("diff.urdf"),
        &urdf,
        &ConvertOptions { fixed_base: true, ..ConvertOptions::default() },
    )
    .unwrap();
    assert_eq!(c.meta.differentials.len(), 2);
    let m = std::sync::Arc::new(Model::from_xml_str(&c.mjcf).unwrap());
    assert_eq!(m.nu(), 4);
    let mut d = Data::new(m.clone()).unwrap();
    let (ta1, ta2, ta3, ta4) = (0.7, -1.3, 2.1, 0.4);
    for (name, v) in [("wrist_m1", ta1), ("wrist_m2", ta2), ("head_m1", ta3), ("head_m2", ta4)] {
        d.ctrl_mut()[m.require_id(ObjType::Actuator, name).unwrap()] = v;
    }
    d.forward().unwrap();
    let tau = |j: &str| d.qfrc_actuator()[m.jnt_dofadr()[m.require_id(ObjType::Joint, j).unwrap()] as usize];
    // ros_control DifferentialTransmission::actuatorToJointEffort.
    let (ar1, ar2, jr1, jr2) = (-1.5, 2.0, 3.0, 0.5);
    assert!((tau("j1") - jr1 * (ta1 * ar1 + ta2 * ar2)).abs() < 1e-9, "{}", tau("j1"));
    assert!((tau("j2") - jr2 * (ta1 * ar1 - ta2 * ar2)).abs() < 1e-9, "{}", tau("j2"));
    // PAL HalfDifferentialTransmission::actuatorToJointEffort.
    let (ar1, ar2, jr1, jr2) = (1.25, -0.75, 1.0, 2.0);
    let tj3 = ta3 * ar1 * jr1;
    assert!((tau("j3") - tj3).abs() < 1e-9, "{}", tau("j3"));
    assert!((tau("j4") - (ta4 * ar2 + tj3 / jr1) * jr2).abs() < 1e-9, "{}", tau("j4"));
}

/// Gazebo contact stiffness: a ball resting on the floor sinks m·g/kp, as in Gazebo; a box on
/// its four corners m·g/(4·kp), as in Gazebo (ODE applies kp at each contact point).
#[test]
fn gazebo_kp_kd_become_direct_solref() {
    let (mass, kp) = (2.0_f64, 2.0e4);
    let kd = 2.0 * (kp * mass).sqrt();
    for (shape, contacts, half_height) in
        [("<sphere radius=\"0.1\"/>", 1.0, 0.1), ("<box size=\"0.2 0.2 0.2\"/>", 4.0, 0.1)]
    {
        let urdf = format!(
            r#"<robot name="body"><link name="body"><inertial><mass value="{mass}"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/></inertial>
  <collision><geometry>{shape}</geometry></collision></link>
  <gazebo reference="body"><kp>{kp}</kp><kd>{kd}</kd><mu1>0.9</mu1><mu2>0.9</mu2></gazebo></robot>"#
        );
        let c = convert_urdf_str(Path::new("body.urdf"), &urdf, &ConvertOptions::default()).unwrap();
        let m = std::sync::Arc::new(Model::from_xml_str(&c.mjcf).unwrap());
        let g = m.require_id(ObjType::Geom, "body_collision_0").unwrap();
        assert!(m.geom_solref()[g][0] < 0.0, "direct form");
        let mut d = Data::new(m.clone()).unwrap();
        d.reset_to_keyframe(m.require_id(ObjType::Key, "home").unwrap()).unwrap();
        for _ in 0..2000 {
            d.step().unwrap();
        }
        let penetration = -(d.qpos()[2] - half_height);
        let expected = mass * 9.81 / (contacts * kp);
        assert!(
            (penetration - expected).abs() < 0.05 * expected,
            "{shape}: penetration {penetration} m, Gazebo {expected} m"
        );
    }
}

fn cube_ascii_stl(half: f64) -> String {
    let mut s = String::from("solid cube\n");
    let v = |x: f64, y: f64, z: f64| format!("vertex {} {} {}\n", x * half, y * half, z * half);
    // Two triangles per face, 6 faces.
    let faces = [
        [[-1., -1., -1.], [1., -1., -1.], [1., 1., -1.], [-1., 1., -1.]],
        [[-1., -1., 1.], [1., -1., 1.], [1., 1., 1.], [-1., 1., 1.]],
        [[-1., -1., -1.], [1., -1., -1.], [1., -1., 1.], [-1., -1., 1.]],
        [[-1., 1., -1.], [1., 1., -1.], [1., 1., 1.], [-1., 1., 1.]],
        [[-1., -1., -1.], [-1., 1., -1.], [-1., 1., 1.], [-1., -1., 1.]],
        [[1., -1., -1.], [1., 1., -1.], [1., 1., 1.], [1., -1., 1.]],
    ];
    for f in faces {
        for t in [[0, 1, 2], [0, 2, 3]] {
            s.push_str("facet normal 0 0 0\nouter loop\n");
            for k in t {
                s.push_str(&v(f[k][0], f[k][1], f[k][2]));
            }
            s.push_str("endloop\nendfacet\n");
        }
    }
    s.push_str("endsolid cube\n");
    s
}

fn cube_collada(half_mm: f64) -> String {
    // 8 corners in millimetres, <unit meter="0.001">, a node translation of 10 mm in z.
    let mut pos = Vec::new();
    for z in [-1.0, 1.0] {
        for y in [-1.0, 1.0] {
            for x in [-1.0, 1.0] {
                pos.extend([x * half_mm, y * half_mm, z * half_mm]);
            }
        }
    }
    let p: Vec<String> = pos.iter().map(|v| v.to_string()).collect();
    let quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]];
    let idx: Vec<String> = quads.iter().flatten().map(|i| i.to_string()).collect();
    format!(
        r##"<?xml version="1.0"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="millimeter" meter="0.001"/><up_axis>Z_UP</up_axis></asset>
  <library_geometries><geometry id="cube"><mesh>
    <source id="cube-pos"><float_array id="cube-pos-array" count="24">{}</float_array>
      <technique_common><accessor source="#cube-pos-array" count="8" stride="3"/></technique_common></source>
    <vertices id="cube-verts"><input semantic="POSITION" source="#cube-pos"/></vertices>
    <polylist count="6"><input semantic="VERTEX" source="#cube-verts" offset="0"/>
      <vcount>4 4 4 4 4 4</vcount><p>{}</p></polylist>
  </mesh></geometry></library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n"><translate>0 0 10</translate>
    <instance_geometry url="#cube"/></node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>"##,
        p.join(" "),
        idx.join(" ")
    )
}

#[test]
fn ascii_stl_and_collada_meshes_convert_and_load() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("ws/my_robot_description");
    std::fs::create_dir_all(pkg.join("meshes")).unwrap();
    std::fs::write(pkg.join("meshes/cube.stl"), cube_ascii_stl(0.05)).unwrap();
    std::fs::write(pkg.join("meshes/cube.dae"), cube_collada(30.0)).unwrap();
    let urdf = format!(
        r#"<robot name="meshy">
  <link name="base">{LINK}
    <collision><geometry><mesh filename="package://my_robot_description/meshes/cube.stl"/></geometry></collision>
    <visual><geometry><mesh filename="package:///my_robot_description/meshes/cube.dae"/></geometry></visual>
  </link>
  <link name="arm">{LINK}
    <collision><origin xyz="0 0 -0.5"/><geometry><mesh filename="package://my_robot_description/meshes/cube.dae" scale="2 2 2"/></geometry></collision>
  </link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="5" velocity="1"/></joint>
</robot>"#
    );
    let urdf_path = dir.path().join("meshy.urdf");
    std::fs::write(&urdf_path, urdf).unwrap();
    let out = dir.path().join("out");
    let opts = ConvertOptions {
        package_paths: vec![dir.path().join("ws")],
        mesh_dir: Some(out.clone()),
        ..ConvertOptions::default()
    };
    let c = convert_urdf(&urdf_path, &opts).unwrap();
    assert_eq!(c.converted_meshes.len(), 2, "{:?}", c.notes);
    assert!(c.converted_meshes.iter().all(|p| p.starts_with(&out)));
    let m = Model::from_xml_str(&c.mjcf).unwrap();
    assert_eq!(m.nmesh(), 3);
    // The lowest collision point is the scaled Collada cube of the arm: 0.5 m below the joint,
    // centre 2 × 10 mm up, half size 2 × 30 mm.
    let expected = 0.5 - 0.02 + 0.06;
    assert!((c.base_height_m - expected).abs() < 1e-6, "{}", c.base_height_m);
}

#[test]
fn table_cup_world_composes_with_the_robot() {
    let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/table_cup.world");
    let c = convert_urdf(&humanoid(), &ConvertOptions { world: Some(world), ..ConvertOptions::default() }).unwrap();
    let m = std::sync::Arc::new(Model::from_xml_str(&c.mjcf).unwrap());
    assert_eq!(m.joint_type(0), JointType::Free, "robot's free joint first");
    let cup = m.require_id(ObjType::Body, "cup").unwrap();
    assert!((m.body_mass()[cup] - 0.2).abs() < 1e-12);
    assert!((m.timestep_secs() - 0.002).abs() < 1e-15);
    // The cup rests on the table: after 1 s it is still at z ≈ 0.80.
    let mut d = Data::new(m.clone()).unwrap();
    d.reset_to_keyframe(0).unwrap();
    for _ in 0..500 {
        d.step().unwrap();
    }
    let z = d.xpos()[cup][2];
    assert!((z - 0.80).abs() < 0.005, "cup at z = {z}");
}

#[test]
fn humanoid_passes_check() {
    let floating = Model::from_file(humanoid()).unwrap();
    let fixed =
        Model::from_urdf(humanoid(), &ConvertOptions { fixed_base: true, floor: false, ..ConvertOptions::default() })
            .unwrap();
    let report = twin_core::check::check(&floating, Some(&fixed), &Default::default()).unwrap();
    for s in &report.steps {
        assert!(s.passed, "{} failed: {:?} {:?}", s.name, s.metrics, s.cause);
    }
    let drift = &report.steps[0].metrics[0];
    assert!(drift.value < 0.01, "{drift:?}");
}

#[test]
fn check_names_the_cause_when_a_robot_falls_forward() {
    // Move the torso's mass far forward: the CoM leaves the support polygon.
    let text = humanoid_edited(
        "<origin xyz=\"0 0 0.17\" rpy=\"0 0 0\"/>\n      <mass value=\"8\"/>",
        "<origin xyz=\"0.6 0 0.17\" rpy=\"0 0 0\"/>\n      <mass value=\"8\"/>",
    );
    let c = convert_urdf_str(&humanoid(), &text, &ConvertOptions::default()).unwrap();
    let m = Model::from_xml_str(&c.mjcf).unwrap();
    let opts = twin_core::check::CheckOptions { hold_secs: 2.0, ..Default::default() };
    let report = twin_core::check::check(&m, None, &opts).unwrap();
    let physics = &report.steps[0];
    assert!(!physics.passed);
    assert!(physics.cause.as_deref().unwrap().contains("falls forward"), "{:?}", physics.cause);
}

#[test]
fn imu_bias_tags_reach_the_metadata_and_survive_the_mjcf_round_trip() {
    // What `twin calibrate noise` writes (per axis, SDF 1.5+ form) plus Gazebo's turn-on bias;
    // the largest value over the axes is kept, an unparsable one is ignored like Gazebo does.
    let urdf = r#"<robot name="b">
  <link name="world"/>
  <link name="block"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4"/></inertial></link>
  <joint name="mount" type="fixed"><parent link="world"/><child link="block"/></joint>
  <gazebo reference="block"><sensor name="imu" type="imu"><update_rate>100</update_rate><imu>
    <angular_velocity>
      <x><noise type="gaussian"><stddev>0.003</stddev><bias_mean>0.001</bias_mean><bias_stddev>0.0005</bias_stddev>
        <dynamic_bias_stddev>2e-4</dynamic_bias_stddev><dynamic_bias_correlation_time>0.7</dynamic_bias_correlation_time>
        <bias_random_walk>3e-5</bias_random_walk></noise></x>
      <y><noise type="gaussian"><stddev>0.002</stddev><dynamic_bias_stddev>1e-4</dynamic_bias_stddev>
        <dynamic_bias_correlation_time>oops</dynamic_bias_correlation_time></noise></y>
    </angular_velocity>
    <linear_acceleration><z><noise type="gaussian"><stddev>0.02</stddev><bias_random_walk>4e-3</bias_random_walk></noise></z></linear_acceleration>
  </imu></sensor></gazebo>
</robot>"#;
    let c = convert_urdf_str(Path::new("b.urdf"), urdf, &ConvertOptions::default()).unwrap();
    let imu = &c.meta.imus[0];
    let g = imu.gyro_bias;
    assert_eq!(
        (g.mean, g.stddev, g.dynamic_stddev, g.dynamic_correlation_time_secs, g.random_walk),
        (0.001, 0.0005, 2e-4, 0.7, 3e-5)
    );
    let a = imu.accel_bias;
    assert_eq!((a.random_walk, a.dynamic_stddev, a.mean), (4e-3, 0.0, 0.0));
    let model = Model::from_xml_str(&c.mjcf).unwrap();
    let meta = twin_core::convert::robot_meta(&model).unwrap();
    assert_eq!(meta.imus[0], *imu);
}
