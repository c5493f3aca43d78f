//! Analytic physics cases through the safe wrapper: if these drift, the wrapper (or the model
//! handling) is wrong, not the physics.

use std::f64::consts::PI;
use std::sync::Arc;
use twin_core::mj::{Data, Model, ObjType, StateSig};

const G: f64 = 9.81;

fn data_for(xml: &str) -> Data {
    let model = Arc::new(Model::from_xml_str(xml).expect("model compiles"));
    Data::new(model).expect("data")
}

/// A point mass on a massless rod of length `l` (inertia about the COM negligible), released at
/// a small angle: the period is 2π√(l/g) (plus θ₀²/16 ≈ 1.6e-4 relative for θ₀ = 0.05 rad).
#[test]
fn pendulum_small_angle_period_matches_theory() {
    let l = 0.8;
    let xml = format!(
        r#"<mujoco>
          <option timestep="0.0005" integrator="RK4" gravity="0 0 -{G}"/>
          <worldbody>
            <body name="bob_arm">
              <joint name="swing" type="hinge" axis="0 1 0" damping="0"/>
              <inertial pos="0 0 -{l}" mass="1.5" diaginertia="1e-9 1e-9 1e-9"/>
            </body>
          </worldbody>
        </mujoco>"#
    );
    let mut data = data_for(&xml);
    data.qpos_mut()[0] = 0.05;
    // Period from successive upward zero crossings of the angle, linearly interpolated.
    let mut crossings = Vec::new();
    let mut prev = (data.time_secs(), data.qpos()[0]);
    while crossings.len() < 4 {
        data.step().unwrap();
        let now = (data.time_secs(), data.qpos()[0]);
        if prev.1 < 0.0 && now.1 >= 0.0 {
            let frac = -prev.1 / (now.1 - prev.1);
            crossings.push(prev.0 + frac * (now.0 - prev.0));
        }
        prev = now;
        assert!(data.time_secs() < 20.0, "pendulum never crossed zero");
    }
    let measured = (crossings[3] - crossings[0]) / 3.0;
    let expected = 2.0 * PI * (l / G).sqrt();
    let rel = (measured - expected).abs() / expected;
    assert!(rel < 0.01, "period {measured:.6} s vs 2π√(l/g) = {expected:.6} s (rel {rel:.2e})");
    // The finite-amplitude correction is 1.6e-4: the integrator error must be well below 1 %.
    assert!(rel < 1e-3, "period error {rel:.2e} larger than the amplitude correction explains");
}

/// A free box released from rest falls ½gt² in t seconds (no floor to hit).
#[test]
fn free_falling_box_height_after_half_a_second() {
    let z0 = 10.0;
    let xml = format!(
        r#"<mujoco>
          <option timestep="0.0001" gravity="0 0 -{G}"/>
          <worldbody>
            <body name="box" pos="0 0 {z0}">
              <freejoint/>
              <geom type="box" size="0.1 0.1 0.1" mass="2"/>
            </body>
          </worldbody>
        </mujoco>"#
    );
    let mut data = data_for(&xml);
    let model = data.model().clone();
    let body = model.require_id(ObjType::Body, "box").unwrap();
    let steps = (0.5 / model.timestep_secs()).round() as u64;
    data.step_n(steps).unwrap();
    data.forward().unwrap();
    let t = data.time_secs();
    assert!((t - 0.5).abs() < 1e-9, "time {t}");
    let z = data.xpos()[body][2];
    let expected = z0 - 0.5 * G * t * t;
    assert!((z - expected).abs() < 1e-3, "height {z:.6} m vs z0 - ½gt² = {expected:.6} m");
    // Velocity is exact for constant acceleration with (semi-implicit) Euler.
    let vz = data.qvel()[2];
    assert!((vz + G * t).abs() < 1e-9, "vz {vz} vs {}", -G * t);
}

/// Inverse dynamics of a static two-link arm equals the gravity torque computed by hand.
#[test]
fn inverse_dynamics_of_static_pose_is_gravity_torque() {
    let (m1, m2, l1, lc1, lc2) = (2.0, 1.25, 0.6, 0.25, 0.3);
    // Links extend along +x; hinges about +y. With q about y, the link direction is
    // (cos q, 0, -sin q), so a weight m·g at horizontal reach r_x exerts m·g·r_x about +y and
    // holding it takes -m·g·r_x.
    let xml = format!(
        r#"<mujoco>
          <option gravity="0 0 -{G}"/>
          <worldbody>
            <body name="upper">
              <joint name="shoulder" type="hinge" axis="0 1 0"/>
              <inertial pos="{lc1} 0 0" mass="{m1}" diaginertia="0.01 0.02 0.02"/>
              <body name="lower" pos="{l1} 0 0">
                <joint name="elbow" type="hinge" axis="0 1 0"/>
                <inertial pos="{lc2} 0 0" mass="{m2}" diaginertia="0.005 0.01 0.01"/>
              </body>
            </body>
          </worldbody>
        </mujoco>"#
    );
    let mut data = data_for(&xml);
    let (q1, q2): (f64, f64) = (0.4, -1.1);
    data.qpos_mut().copy_from_slice(&[q1, q2]);
    data.qvel_mut().fill(0.0);
    data.qacc_mut().fill(0.0);
    data.inverse().unwrap();
    let tau1 = -G * (m1 * lc1 * q1.cos() + m2 * (l1 * q1.cos() + lc2 * (q1 + q2).cos()));
    let tau2 = -G * m2 * lc2 * (q1 + q2).cos();
    let got = data.qfrc_inverse().to_vec();
    assert!((got[0] - tau1).abs() < 1e-9, "shoulder {} vs {tau1}", got[0]);
    assert!((got[1] - tau2).abs() < 1e-9, "elbow {} vs {tau2}", got[1]);

    // RNE without acceleration at zero velocity is the same gravity vector.
    data.forward().unwrap();
    let bias = data.rne(false).unwrap();
    assert!((bias[0] - tau1).abs() < 1e-9 && (bias[1] - tau2).abs() < 1e-9, "rne {bias:?}");
}

#[test]
fn state_save_and_restore_replays_bit_for_bit() {
    let mut data = data_for(
        r#"<mujoco><worldbody>
             <geom type="plane" size="5 5 0.1"/>
             <body pos="0 0 0.5"><freejoint/><geom type="box" size="0.1 0.2 0.05" mass="1"/></body>
           </worldbody></mujoco>"#,
    );
    data.qvel_mut()[..3].copy_from_slice(&[0.3, -0.2, 1.0]);
    data.step_n(50).unwrap();
    let saved = data.state(StateSig::INTEGRATION).unwrap();
    data.step_n(200).unwrap();
    let first = data.qpos().to_vec();
    data.set_state(&saved, StateSig::INTEGRATION).unwrap();
    data.step_n(200).unwrap();
    assert_eq!(first, data.qpos().to_vec());
    assert!(data.set_state(&saved[1..], StateSig::INTEGRATION).is_err(), "wrong length must be refused");

    // A cloned Data continues identically too.
    let mut copy = data.clone();
    data.step_n(10).unwrap();
    copy.step_n(10).unwrap();
    assert_eq!(data.qpos(), copy.qpos());
}

#[test]
fn model_edit_updates_derived_quantities() {
    let model = Model::from_xml_str(
        r#"<mujoco><worldbody>
             <body name="a"><joint type="hinge" axis="0 1 0"/><geom type="sphere" size="0.1" mass="1" pos="0.5 0 0"/>
               <body name="b" pos="1 0 0"><joint type="hinge" axis="0 1 0"/><geom type="sphere" size="0.1" mass="2" pos="0.5 0 0"/></body>
             </body></worldbody></mujoco>"#,
    )
    .unwrap();
    let a = model.require_id(ObjType::Body, "a").unwrap();
    let b = model.require_id(ObjType::Body, "b").unwrap();
    assert!((model.body_subtreemass()[a] - 3.0).abs() < 1e-12);

    let mut edit = model.edit().unwrap();
    edit.set_body_mass(b, 5.0).unwrap().set_dof_damping(1, 0.7).unwrap().set_dof_armature(0, 0.01).unwrap();
    let edited = edit.finish().unwrap();
    // mj_setConst recomputed the subtree mass that depends on body_mass.
    assert!((edited.body_subtreemass()[a] - 6.0).abs() < 1e-12, "{}", edited.body_subtreemass()[a]);
    assert_eq!(edited.dof_damping()[1], 0.7);
    assert_eq!(edited.dof_armature()[0], 0.01);
    // The original is untouched.
    assert_eq!(model.body_mass()[b], 2.0);

    // Scaling a mass scales its inertia with it.
    let mut edit = model.edit().unwrap();
    edit.scale_body_mass(b, 1.5).unwrap();
    let scaled = edit.finish().unwrap();
    assert!((scaled.body_mass()[b] - 3.0).abs() < 1e-12);
    for k in 0..3 {
        assert!((scaled.body_inertia()[b][k] - 1.5 * model.body_inertia()[b][k]).abs() < 1e-15);
    }

    // Invalid edits are refused with a message naming the body.
    let mut edit = model.edit().unwrap();
    let err = edit.set_body_mass(b, -1.0).err().expect("negative mass refused").to_string();
    assert!(err.contains("\"b\"") && err.contains("positive"), "{err}");
    let err = edit.set_body_inertia(a, [1.0, 1.0, 3.0]).err().expect("triangle violation refused").to_string();
    assert!(err.contains("triangle"), "{err}");
    assert!(edit.set_dof_frictionloss(9, 0.1).is_err(), "out-of-range dof refused");
}

#[test]
fn names_and_ids_round_trip() {
    let model = Model::from_xml_str(
        r#"<mujoco><worldbody><body name="link"><joint name="j" type="slide" axis="1 0 0" range="-0.5 0.5"/>
           <geom type="box" size="0.1 0.1 0.1"/><site name="tip"/></body></worldbody>
           <actuator><motor name="push" joint="j" gear="2"/></actuator>
           <sensor><jointpos name="jpos" joint="j"/></sensor></mujoco>"#,
    )
    .unwrap();
    for (kind, name) in [
        (ObjType::Body, "link"),
        (ObjType::Joint, "j"),
        (ObjType::Site, "tip"),
        (ObjType::Actuator, "push"),
        (ObjType::Sensor, "jpos"),
    ] {
        let id = model.require_id(kind, name).unwrap();
        assert_eq!(model.name(kind, id), name);
    }
    assert!(model.id(ObjType::Body, "nope").is_none());
    assert_eq!(
        model.require_id(ObjType::Joint, "nope").unwrap_err().to_string(),
        "the model has no joint named \"nope\""
    );
    assert_eq!(model.name(ObjType::Body, 99), "");
    assert_eq!(model.jnt_range()[0], [-0.5, 0.5]);
    assert_eq!(model.actuator_gear()[0][0], 2.0);

    // The sensor reads what physics says.
    let mut data = Data::new(Arc::new(model)).unwrap();
    data.qpos_mut()[0] = 0.123;
    data.forward().unwrap();
    assert_eq!(data.sensordata()[0], 0.123);
}

#[test]
fn model_is_send_sync_and_data_is_send() {
    fn send_sync<T: Send + Sync>() {}
    fn send<T: Send>() {}
    send_sync::<Model>();
    send::<Data>();
}

/// A 2 kg box resting on the floor, and a 1 kg box stacked on it: `contact_wrench_world`
/// gives the force on each contact's second geom, so summing per body (+ on geom2's body, − on
/// geom1's) gives the support forces m·g whatever order MuJoCo lists the geoms in.
#[test]
fn contact_wrenches_carry_the_weight_of_resting_boxes() {
    let mut data = data_for(&format!(
        r#"<mujoco>
          <option timestep="0.002" gravity="0 0 -{G}"/>
          <worldbody>
            <geom name="floor" type="plane" size="2 2 0.1"/>
            <body name="low" pos="0 0 0.1"><freejoint/>
              <geom type="box" size="0.2 0.2 0.1" mass="2"/></body>
            <body name="high" pos="0.05 0 0.25"><freejoint/>
              <geom type="box" size="0.1 0.1 0.05" mass="1"/></body>
          </worldbody>
        </mujoco>"#
    ));
    for _ in 0..1000 {
        data.step().unwrap();
    }
    data.forward().unwrap();
    let model = data.model().clone();
    let (low, high) = (model.id(ObjType::Body, "low").unwrap(), model.id(ObjType::Body, "high").unwrap());
    let mut force_z = vec![0.0; model.nbody()];
    let mut torque_about_origin_y = vec![0.0; model.nbody()];
    for i in 0..data.ncon() {
        let c = data.contact_wrench_world(i).unwrap();
        for (k, sign) in [(0, -1.0), (1, 1.0)] {
            let body = model.geom_bodyid()[c.geoms[k] as usize] as usize;
            force_z[body] += sign * c.force_n[2];
            // Moment about the body origin of a vertical force at the contact point: −x · F_z.
            let r_x = c.position[0] - data.xpos()[body][0];
            torque_about_origin_y[body] += -r_x * sign * c.force_n[2] + sign * c.torque_nm[1];
        }
    }
    // The floor pushes the lower box up with the weight of both; the upper box pushes it down
    // with its own; the upper box is held up by its weight.
    assert!((force_z[high] - 1.0 * G).abs() < 1e-3 * G, "{}", force_z[high]);
    assert!((force_z[low] - 2.0 * G).abs() < 1e-3 * G, "net on the low box: {}", force_z[low]);
    assert!((force_z[0] + 3.0 * G).abs() < 1e-3 * G, "the floor gets the reaction: {}", force_z[0]);
    // The upper box rests 5 cm off the lower's centre: its weight's moment about the lower
    // box's origin is balanced by the floor's contact forces (net moment ≈ 0).
    assert!(torque_about_origin_y[low].abs() < 1e-2, "{}", torque_about_origin_y[low]);
    assert!(data.contact_wrench_world(data.ncon()).is_none());
}
