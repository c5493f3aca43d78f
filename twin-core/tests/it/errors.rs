//! MuJoCo errors come back as `Err` with MuJoCo's message, and the process keeps running.

use std::io::Write;
use std::sync::Arc;
use twin_core::mj::Error;
use twin_core::mj::{Data, Model, StateSig, Warning};

/// A model whose arena is too small: mj_step runs out of stack memory while adding contacts,
/// which MuJoCo reports with mju_user_error (by default: print and exit()).
const TINY_ARENA: &str = r#"<mujoco>
  <size memory="8K"/>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <body pos="0 0 0.05"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>
    <body pos="0 0 0.3"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>
  </worldbody>
</mujoco>"#;

#[test]
fn mujoco_error_in_step_is_returned_and_process_survives() {
    let model = Arc::new(Model::from_xml_str(TINY_ARENA).expect("compiles"));
    let mut data = Data::new(model.clone()).expect("data");
    let err = data.step().expect_err("an 8 KiB arena cannot hold a contact step");
    match &err {
        Error::MuJoCo { call, message } => {
            assert_eq!(*call, "mj_step");
            assert!(message.contains("mj_stackAlloc: out of memory"), "{message}");
        }
        other => panic!("unexpected error {other:?}"),
    }
    // Same again: the guard is re-armed and the mjData stack was reset.
    assert!(data.step().is_err());
    // And MuJoCo still works normally afterwards in this process.
    let ok = Arc::new(
        Model::from_xml_str("<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
            .unwrap(),
    );
    let mut d = Data::new(ok).unwrap();
    d.step_n(10).unwrap();
    assert!(d.time_secs() > 0.0);
}

#[test]
fn invalid_state_signature_is_an_error() {
    let model = Arc::new(
        Model::from_xml_str("<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
            .unwrap(),
    );
    let mut data = Data::new(model).unwrap();
    // Out-of-range signature bits: MuJoCo raises mju_user_error inside mj_setState.
    let err = data.set_state(&[0.0; 4], StateSig(1 << 20)).expect_err("bad signature");
    let text = err.to_string();
    assert!(text.contains("mj_setState") && text.to_lowercase().contains("signature"), "{text}");
    assert!(data.state(StateSig(1 << 20)).is_err());
}

#[test]
fn errors_on_several_threads_do_not_interfere() {
    let bad = Arc::new(Model::from_xml_str(TINY_ARENA).unwrap());
    let good = Arc::new(
        Model::from_xml_str("<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>")
            .unwrap(),
    );
    std::thread::scope(|s| {
        for i in 0..4 {
            let (bad, good) = (bad.clone(), good.clone());
            s.spawn(move || {
                for _ in 0..50 {
                    if i % 2 == 0 {
                        let mut d = Data::new(bad.clone()).unwrap();
                        assert!(matches!(d.step(), Err(Error::MuJoCo { .. })));
                    } else {
                        let mut d = Data::new(good.clone()).unwrap();
                        d.step_n(20).unwrap();
                        assert!((d.time_secs() - 20.0 * good.timestep_secs()).abs() < 1e-12);
                    }
                }
            });
        }
    });
}

#[test]
fn malformed_mjcf_reports_mujoco_message_with_line() {
    let err = Model::from_xml_str(
        "<mujoco>\n<worldbody>\n<body>\n<geom type='box' size='a b c'/>\n</body></worldbody></mujoco>",
    )
    .expect_err("bad size");
    let text = err.to_string();
    assert!(matches!(err, Error::Load { path: None, .. }), "{err:?}");
    assert!(text.contains("line 4"), "MuJoCo's message names the line: {text}");

    let err = Model::from_xml_str("<mujoco><worldbody><body>").expect_err("truncated XML");
    assert!(matches!(err, Error::Load { .. }), "{err:?}");
}

fn write(dir: &std::path::Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::File::create(&path).unwrap().write_all(text.as_bytes()).unwrap();
    path
}

#[test]
fn mjcf_file_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "broken.xml",
        "<mujoco>\n  <worldbody>\n    <geom type=\"sphere\" size=\"-1\"/>\n  </worldbody>\n</mujoco>\n",
    );
    let err = Model::from_file(&path).expect_err("negative size");
    let text = err.to_string();
    assert!(text.contains("broken.xml"), "{text}");
    let missing = Model::from_file(dir.path().join("nope.xml")).expect_err("missing file");
    assert!(
        matches!(missing, Error::File(twin_core::fsio::Error::Io { .. })) && missing.to_string().contains("nope.xml")
    );
}

const URDF_HEAD: &str = "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n  <link name=\"base\">\n    <inertial><mass value=\"1\"/><inertia ixx=\"0.01\" iyy=\"0.01\" izz=\"0.01\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial>\n  </link>\n";

#[test]
fn urdf_with_bad_inertia_names_file_link_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = format!(
        "{URDF_HEAD}  <link name=\"arm\">\n    <inertial>\n      <mass value=\"1\"/>\n      <inertia ixx=\"0.01\" iyy=\"0.01\" izz=\"0.05\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/>\n    </inertial>\n  </link>\n  <joint name=\"j\" type=\"revolute\"><parent link=\"base\"/><child link=\"arm\"/><axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/></joint>\n</robot>\n"
    );
    let path = write(dir.path(), "bad_inertia.urdf", &urdf);
    // As ROS/Gazebo, the default repairs it (smallest change, listed in the notes); strict
    // conversion refuses it with the file, line and link.
    let repaired = Model::from_file(&path).expect("repaired by default");
    assert_eq!(repaired.nbody(), 3);
    let strict = twin_core::convert::ConvertOptions { strict_inertia: true, ..Default::default() };
    let err = twin_core::convert::convert_urdf(&path, &strict).expect_err("triangle inequality");
    let Error::Convert(twin_convert::Error::Urdf { line, element, name, message, .. }) = &err else {
        panic!("{err:?}")
    };
    assert_eq!((*line, element.as_str(), name.as_deref()), (9, "inertia", Some("arm")));
    assert!(message.contains("triangle"), "{message}");
    let text = err.to_string();
    assert!(text.starts_with(&format!("{}:9: <inertia name=\"arm\">", path.display())), "{text}");
}

#[test]
fn urdf_with_missing_mesh_names_file_link_and_line() {
    // A missing collision mesh changes the physics: an error (a missing visual mesh is a note).
    let dir = tempfile::tempdir().unwrap();
    let urdf = format!(
        "{URDF_HEAD}  <link name=\"shell\">\n    <collision>\n      <geometry>\n        <mesh filename=\"meshes/shell.stl\"/>\n      </geometry>\n    </collision>\n  </link>\n  <joint name=\"j\" type=\"fixed\"><parent link=\"base\"/><child link=\"shell\"/></joint>\n</robot>\n"
    );
    let path = write(dir.path(), "missing_mesh.urdf", &urdf);
    let err = Model::from_file(&path).expect_err("missing mesh");
    let Error::Convert(twin_convert::Error::Urdf { line, element, name, message, .. }) = &err else {
        panic!("{err:?}")
    };
    assert_eq!((*line, element.as_str(), name.as_deref()), (9, "mesh", Some("shell")));
    assert!(message.contains("meshes/shell.stl") && message.contains("not found"), "{message}");
}

#[test]
fn urdf_with_negative_mass_and_broken_xml() {
    let dir = tempfile::tempdir().unwrap();
    let neg = URDF_HEAD.replace("<mass value=\"1\"/>", "<mass value=\"-2\"/>") + "</robot>\n";
    let err = Model::from_file(write(dir.path(), "neg.urdf", &neg)).expect_err("negative mass");
    assert!(
        matches!(&err, Error::Convert(twin_convert::Error::Urdf { line: 4, element, .. }) if element == "mass"),
        "{err:?}"
    );
    assert!(err.to_string().contains("negative mass"));

    let broken = format!("{URDF_HEAD}  <link name=\"x\">\n</robot>\n");
    let err = Model::from_file(write(dir.path(), "broken.urdf", &broken)).expect_err("broken XML");
    assert!(matches!(err, Error::Convert(twin_convert::Error::Xml { .. })), "{err:?}");
    assert!(err.to_string().contains("broken.urdf:"), "{err}");
}

#[test]
fn warnings_are_counted_not_printed() {
    // With a 2 KiB arena MuJoCo does not raise but warns: contact and constraint buffers full.
    let model = Arc::new(Model::from_xml_str(&TINY_ARENA.replace("8K", "2K")).unwrap());
    let mut data = Data::new(model).unwrap();
    let (before, _) = twin_core::mj::thread_warnings();
    data.step().unwrap();
    assert_eq!(data.warning_count(Warning::ContactFull), 1);
    assert_eq!(data.warning_count(Warning::ConstraintFull), 1);
    assert!(!data.diverged());
    let (after, last) = twin_core::mj::thread_warnings();
    assert_eq!(after - before, 2, "two warnings raised on this thread");
    assert!(last.contains("arena memory"), "{last}");
}

#[test]
fn diverging_simulation_is_flagged() {
    // A huge force on a light body: qacc blows up, MuJoCo warns and resets the state.
    let model = Arc::new(Model::from_xml_str("<mujoco><worldbody><body><joint type='slide' axis='1 0 0'/><geom size='0.1' mass='1e-3'/></body></worldbody></mujoco>").unwrap());
    let mut data = Data::new(model).unwrap();
    data.qfrc_applied_mut()[0] = f64::NAN;
    data.step().unwrap();
    assert!(data.diverged(), "NaN force must be reported as diverged");
    assert_eq!(data.warning_count(Warning::BadQacc), 1);
}
