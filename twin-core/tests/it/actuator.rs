//! The `<twin_actuator>` block of a URDF becomes MuJoCo's own drive mechanisms, and the physics
//! shows them at the joint: a torque command written the way every controller writes it
//! ([`Actuation::apply`]) reaches the joint exactly `delay_secs` later; a DC motor's torque falls
//! with speed along `stall_torque·(1 − ω/no_load_speed)`, clipped at the URDF effort; a position
//! drive runs the block's gains.

use std::sync::Arc;
use twin_core::mj::convert::{ConvertOptions, load_str};
use twin_core::mj::{Data, DynType, ObjType};
use twin_core::robot::Actuation;

/// A turntable (vertical axis: no gravity torque) with an effort-driven joint and a
/// position-driven one, each with a drive model in the block.
fn urdf(block: &str) -> String {
    format!(
        r#"<robot name="table">
  <link name="world"/>
  <joint name="fix" type="fixed"><parent link="world"/><child link="base"/></joint>
  <link name="base"><inertial><mass value="5"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="disk"/><axis xyz="0 0 1"/>
    <limit effort="8" velocity="6"/></joint>
  <link name="disk"><inertial><mass value="2"/><inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.1"/></inertial></link>
  <joint name="tilt" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit effort="30" velocity="4" lower="-2" upper="2"/></joint>
  <link name="arm"><inertial><mass value="1"/><inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.04"/></inertial></link>
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="spin"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
    <actuator name="spin_motor"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <transmission name="t2"><type>transmission_interface/SimpleTransmission</type>
    <joint name="tilt"><hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>
    <actuator name="tilt_servo"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
  <twin_sysid version="1"><joint name="tilt" armature="0.03"/></twin_sysid>
{block}
</robot>
"#
    )
}

fn load(block: &str) -> Data {
    let text = urdf(block);
    let loaded = load_str("table.urdf".as_ref(), &text, &ConvertOptions::default(), "").expect("converts");
    Data::new(Arc::new(loaded.model)).expect("data")
}

#[test]
fn command_delay_and_dc_motor_envelope_act_at_the_joint() {
    let block = r#"  <twin_actuator version="1">
    <joint name="spin" delay_secs="0.006" stall_torque="10" no_load_speed="5"/>
    <joint name="tilt" delay_secs="0.004" kp="50" kd="2"/>
  </twin_actuator>"#;
    let mut data = load(block);
    let model = data.model().clone();
    let dt = model.timestep_secs();
    assert_eq!(dt, 0.002);
    let spin = model.id(ObjType::Actuator, "spin").unwrap();
    let tilt = model.id(ObjType::Actuator, "tilt").unwrap();
    assert_eq!(model.actuator_delay()[spin], 0.006);
    assert_eq!(model.actuator_dyn(spin), DynType::Dcmotor);
    let (stall, no_load) = model.actuator_envelope(spin).unwrap();
    assert!((stall - 10.0).abs() < 1e-9 && (no_load - 5.0).abs() < 1e-9, "{stall} {no_load}");
    // The position drive's own gains; armature from <twin_sysid>.
    assert_eq!(model.actuator_gainprm()[tilt][0], 50.0);
    assert_eq!(model.actuator_biasprm()[tilt][1..3], [-50.0, -2.0]);
    let tilt_dof = model.jnt_dofadr()[model.id(ObjType::Joint, "tilt").unwrap()] as usize;
    assert_eq!(model.dof_armature()[tilt_dof], 0.03);

    // A 3 N·m step on the spin joint, written as every controller writes commands: the joint
    // feels nothing for 6 ms, then all of it.
    let spin_dof = model.jnt_dofadr()[model.id(ObjType::Joint, "spin").unwrap()] as usize;
    let act = Actuation::of(&model);
    let mut command = vec![0.0; model.nu()];
    let tilt_home = data.qpos()[model.jnt_qposadr()[model.id(ObjType::Joint, "tilt").unwrap()] as usize];
    command[tilt] = tilt_home;
    command[spin] = 3.0;
    act.apply(&mut data, &command);
    let t0 = data.time_secs();
    let mut first = None;
    for _ in 0..10 {
        data.step().unwrap();
        if first.is_none() && data.qfrc_actuator()[spin_dof].abs() > 1e-9 {
            first = Some(data.time_secs() - dt - t0);
            assert!((data.qfrc_actuator()[spin_dof] - 3.0).abs() < 1e-9, "{}", data.qfrc_actuator()[spin_dof]);
        }
    }
    let delay = first.expect("the torque arrives");
    assert!((delay - 0.006).abs() < 1e-9, "torque arrived after {delay} s");

    // The envelope: full command (clipped at the 8 N·m effort) while slow; at 2.5 rad/s half the
    // 10 N·m stall torque; braking against the motion stays at the effort clip.
    for (speed, cmd, want) in [(0.0, 100.0, 8.0), (2.5, 100.0, 5.0), (4.0, 100.0, 2.0), (2.5, -100.0, -8.0)] {
        command[spin] = cmd;
        act.apply(&mut data, &command);
        for _ in 0..5 {
            data.qvel_mut()[spin_dof] = speed;
            data.step().unwrap();
        }
        data.qvel_mut()[spin_dof] = speed;
        data.forward().unwrap();
        let got = data.qfrc_actuator()[spin_dof];
        assert!((got - want).abs() < 1e-6, "at {speed} rad/s command {cmd}: {got} N·m, want {want}");
    }
}

#[test]
fn without_a_block_the_drives_are_ideal_and_bad_entries_are_refused() {
    let data = load("");
    let model = data.model();
    assert!(model.actuator_delay().iter().all(|d| *d == 0.0));
    assert!((0..model.nu()).all(|a| model.actuator_dyn(a) == DynType::None));
    let bad = r#"  <twin_actuator version="1">
    <joint name="spinn" delay_secs="0.006"/>
  </twin_actuator>"#;
    let text = urdf(bad);
    let e = load_str("table.urdf".as_ref(), &text, &ConvertOptions::default(), "").unwrap_err().to_string();
    assert!(e.contains("table.urdf:") && e.contains("\"spinn\"") && e.contains("does not have"), "{e}");
}
