//! `twin convert` and `twin check` end to end, including real public URDFs fetched from PyPI.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn twin(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).args(args).current_dir(cwd).output().expect("run twin")
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn convert_writes_mjcf_next_to_the_urdf_with_summary_and_backup() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = dir.path().join("humanoid.urdf");
    std::fs::copy(repo().join("models/humanoid.urdf"), &urdf).unwrap();
    let o = twin(&["convert", "humanoid.urdf"], dir.path());
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("23 actuators"), "{out}");
    assert!(out.contains("total mass 35.710 kg"), "{out}");
    assert!(out.contains("/humanoid/imu/data"), "{out}");
    let xml = dir.path().join("humanoid.xml");
    let first = std::fs::read_to_string(&xml).unwrap();
    assert!(first.contains("<freejoint name=\"floating_base\"/>"));
    // Converting again keeps the previous file as a backup; info loads the result.
    let o = twin(&["convert", "humanoid.urdf", "--fixed-base"], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(dir.path().join("humanoid.xml.bak")).unwrap(), first);
    let o = twin(&["info", "humanoid.xml"], dir.path());
    let info = text(&o);
    assert!(o.status.success(), "{info}");
    assert!(!info.contains(" free "), "fixed base has no free joint: {info}");
}

/// `twin convert models/humanoid.urdf --world WORLD` (paths from the repo root): its output
/// (asserted successful) and the MJCF it wrote.
fn convert_with_world(world: &str) -> (String, String) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene.xml");
    let o = twin(&["convert", "models/humanoid.urdf", "-o", out.to_str().unwrap(), "--world", world], &repo());
    assert!(o.status.success(), "{}", text(&o));
    (text(&o), std::fs::read_to_string(&out).unwrap())
}

#[test]
fn convert_with_table_cup_world() {
    let (said, xml) = convert_with_world("models/table_cup.world");
    assert!(said.contains("total mass 35.910 kg"), "{said}");
    assert!(xml.contains("<body name=\"cup\""));
    assert!(xml.contains("name=\"table_top_collision\""));
}

/// The README's Gazebo heightmap world: the PNG becomes a MuJoCo hfield with the elevations of
/// its pixels (black at −0.15 m, white 0.3 m above), the box a static geom, the texture a note
/// with its line.
#[test]
fn convert_with_heightmap_world() {
    let (said, xml) = convert_with_world("models/hills.world");
    assert!(said.contains("models/hills.world:30: <heightmap><texture> not converted"), "{said}");
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let hfield = doc.descendants().find(|n| n.has_tag_name("hfield")).unwrap();
    assert_eq!((hfield.attribute("nrow"), hfield.attribute("ncol")), (Some("65"), Some("65")));
    let geom = doc.descendants().find(|n| n.attribute("type") == Some("hfield")).unwrap();
    // Placed at the lowest pixel's elevation, its range the highest's minus the lowest's.
    let size: Vec<f64> = hfield.attribute("size").unwrap().split(' ').map(|v| v.parse().unwrap()).collect();
    let z: f64 = geom.attribute("pos").unwrap().split(' ').nth(2).unwrap().parse().unwrap();
    assert_eq!(&size[..2], &[4.0, 4.0]);
    assert!(z > -0.15 && z + size[2] < 0.15 && size[2] > 0.1, "{z} {size:?}");
    assert!(xml.contains("name=\"rock_collision\" type=\"box\""));
}

#[test]
fn convert_reports_bad_input_with_file_line_and_fix() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("bad.urdf"),
        "<robot name=\"r\">\n<link name=\"a\">\n<inertial>\n<mass value=\"-1\"/>\n</inertial>\n</link>\n</robot>\n",
    )
    .unwrap();
    let o = twin(&["convert", "bad.urdf"], dir.path());
    let out = text(&o);
    assert!(!o.status.success());
    assert!(out.contains("bad.urdf:4: <mass name=\"a\">: negative mass"), "{out}");
    assert!(!out.contains("panicked"), "{out}");
    assert!(!dir.path().join("r.xml").exists());
}

/// `twin convert --contact-sensor LINK`: the humanoid's feet get touch sensors over their
/// soles (read back by `twin info`); a link the robot does not have is refused, naming the
/// URDF, the flag and the links there are, and nothing is written.
#[test]
fn convert_adds_contact_sensors_on_named_links() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("feet.xml");
    let args = ["convert", "models/humanoid.urdf", "-o", out.to_str().unwrap()];
    let o = twin(
        &[&args[..], &["--contact-sensor", "left_foot_link", "--contact-sensor", "right_foot_link"]].concat(),
        &repo(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let xml = std::fs::read_to_string(&out).unwrap();
    for side in ["left", "right"] {
        assert!(
            xml.contains(&format!("<touch name=\"{side}_foot_link_contact\" site=\"{side}_foot_link_contact_site\"/>")),
            "{xml}"
        );
    }
    let o = twin(&["info", out.to_str().unwrap()], &repo());
    let info = text(&o);
    assert!(o.status.success() && info.contains("left_foot_link_contact"), "{info}");
    let bad = dir.path().join("bad.xml");
    let o = twin(
        &["convert", "models/humanoid.urdf", "-o", bad.to_str().unwrap(), "--contact-sensor", "left_foot"],
        &repo(),
    );
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(said.contains("models/humanoid.urdf") && said.contains("no link \"left_foot\""), "{said}");
    assert!(said.contains("--contact-sensor") && said.contains("left_foot_link"), "{said}");
    assert!(!said.contains("panicked") && !bad.exists(), "{said}");
}

#[test]
fn check_passes_the_humanoid_and_fails_a_falling_one() {
    let o = twin(&["check"], &repo());
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    for step in ["PASS physics", "PASS sensors", "PASS control", "PASS integration"] {
        assert!(out.contains(step), "{out}");
    }
    // The torso's mass moved 0.6 m forward: the centre of mass leaves the feet.
    let dir = tempfile::tempdir().unwrap();
    let t = std::fs::read_to_string(repo().join("models/humanoid.urdf")).unwrap();
    let t = t.replacen(
        "<origin xyz=\"0 0 0.17\" rpy=\"0 0 0\"/>\n      <mass value=\"8\"/>",
        "<origin xyz=\"0.6 0 0.17\" rpy=\"0 0 0\"/>\n      <mass value=\"8\"/>",
        1,
    );
    std::fs::write(dir.path().join("heavy_front.urdf"), t).unwrap();
    let o = twin(&["check", "heavy_front.urdf", "--hold-secs", "2"], dir.path());
    let out = text(&o);
    assert!(!o.status.success(), "{out}");
    assert!(out.contains("FAIL physics"), "{out}");
    assert!(out.contains("likely cause: falls forward"), "{out}");
}

/// The humanoid on a 3° slope (gravity tilted) with feet almost frictionless: it stays upright
/// but slides, and `check` blames the friction, not the controller.
#[test]
fn check_names_low_friction_when_the_feet_slide() {
    let dir = tempfile::tempdir().unwrap();
    let o = twin(&["convert", repo().join("models/humanoid.urdf").to_str().unwrap(), "-o", "h.xml"], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let mjcf = std::fs::read_to_string(dir.path().join("h.xml")).unwrap();
    assert!(mjcf.contains("friction=\"1 0.005 0.0001\"") && mjcf.contains("gravity=\"0 0 -9.81\""));
    let slope = mjcf
        .replace("friction=\"1 0.005 0.0001\"", "friction=\"0.02 0.005 0.0001\"")
        .replace("gravity=\"0 0 -9.81\"", "gravity=\"0.49 0 -9.80\"");
    std::fs::write(dir.path().join("slope.xml"), slope).unwrap();
    let o = twin(&["check", "slope.xml"], dir.path());
    let out = text(&o);
    assert!(!o.status.success(), "{out}");
    // Sliding down a slope of tan θ = 0.05 with μ = 0.02: a = g(sin θ − μ cos θ) ≈ 0.29 m/s²,
    // about 3.7 m in the 5 s hold; it must not be reported as a fall.
    let slide: f64 = out
        .lines()
        .find(|l| l.contains("base horizontal slide"))
        .and_then(|l| l.split_whitespace().rev().nth(1))
        .and_then(|v| v.parse().ok())
        .expect("slide metric");
    assert!((2.5..4.5).contains(&slide), "slide {slide} m\n{out}");
    assert!(
        out.contains("likely cause: foot sliding while commanded still") && out.contains("friction too low"),
        "{out}"
    );
}

/// Real robot descriptions from PyPI (example-robot-data ships URDFs with package:// meshes,
/// Collada, Gazebo tags, transmissions and mimic joints). Downloaded once into a cache (see
/// twin-core's corpus test, which converts all of them); fails when pip cannot fetch it.
#[test]
fn real_public_urdfs_convert_load_and_stand() {
    let robots = crate::example_robot_data::example_robot_data();
    let pkg = robots.to_str().unwrap();
    // (URDF, extra flags): a humanoid with Gazebo tags, mimic joints and package:// meshes;
    // a quadruped with Collada meshes; arms on a world link or welded.
    let cases: [(&str, &[&str]); 6] = [
        ("talos_data/robots/talos_reduced.urdf", &[]),
        ("anymal_b_simple_description/robots/anymal.urdf", &[]),
        ("solo_description/robots/solo12.urdf", &[]),
        ("ur_description/urdf/ur5_robot.urdf", &[]),
        ("baxter_description/urdf/baxter.urdf", &[]),
        ("panda_description/urdf/panda.urdf", &["--fixed-base"]),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (rel, flags) in cases {
        let urdf = robots.join(rel);
        let out = dir.path().join(format!("{}.xml", urdf.file_stem().unwrap().to_str().unwrap()));
        let mut args = vec!["convert", urdf.to_str().unwrap(), "-o", out.to_str().unwrap(), "--package-path", pkg];
        args.extend_from_slice(flags);
        let o = twin(&args, dir.path());
        assert!(o.status.success(), "{rel}: {}", text(&o));
        let o = twin(&["info", out.to_str().unwrap()], dir.path());
        assert!(o.status.success(), "{rel} does not load: {}", text(&o));
        let mut args = vec!["check", urdf.to_str().unwrap(), "--package-path", pkg];
        args.extend_from_slice(flags);
        let o = twin(&args, dir.path());
        let out = text(&o);
        assert!(out.contains("PASS physics"), "{rel}: {out}");
        if rel.contains("talos") {
            // Mimic joints, Gazebo IMU and transmissions all made it through.
            let xml = std::fs::read_to_string(dir.path().join("talos_reduced.xml")).unwrap();
            assert!(xml.contains("<position name=\"leg_left_4_joint\""));
            assert!(xml.contains("imu_sensor_accel"));
        }
    }
    let panda = std::fs::read_to_string(dir.path().join("panda.xml")).unwrap();
    assert!(panda.contains("<equality>"), "panda's finger mimic");
}

/// `twin convert` then `twin sim robot.xml` publishes exactly what `twin sim robot.urdf` does:
/// the ROS side (robot name, IMU topic, rate, noise, frame) travels inside the MJCF.
#[test]
fn sim_of_the_converted_mjcf_publishes_what_the_urdf_does() {
    let dir = tempfile::tempdir().unwrap();
    // A seed-style robot: one link, an IMU at 100 Hz with noise, a namespaced topic.
    let urdf = r#"<robot name="humanoid_robot">
  <link name="torso"><inertial><mass value="3"/><inertia ixx="0.05" iyy="0.05" izz="0.05"/></inertial>
    <collision><geometry><box size="0.3 0.2 0.4"/></geometry></collision></link>
  <gazebo reference="torso"><sensor name="torso_imu" type="imu"><update_rate>100</update_rate>
    <imu><angular_velocity><x><noise type="gaussian"><stddev>0.003</stddev></noise></x></angular_velocity>
      <linear_acceleration><x><noise type="gaussian"><stddev>0.02</stddev></noise></x></linear_acceleration></imu>
    <plugin name="imu" filename="libgazebo_ros_imu_sensor.so"><ros><namespace>/humanoid</namespace>
      <remapping>~/out:=imu/data</remapping></ros><frame_name>imu_frame</frame_name></plugin></sensor></gazebo>
</robot>"#;
    std::fs::write(dir.path().join("seed.urdf"), urdf).unwrap();
    let o = twin(&["convert", "seed.urdf", "-o", "seed.xml"], dir.path());
    assert!(o.status.success(), "{}", text(&o));
    let mut infos = Vec::new();
    for model in ["seed.urdf", "seed.xml"] {
        let mcap = format!("{model}.mcap");
        let o = twin(&["sim", model, "--duration", "1", "--record", &mcap, "--seed", "1"], dir.path());
        assert!(o.status.success(), "{model}: {}", text(&o));
        let o = twin(&["log", "info", &mcap], dir.path());
        assert!(o.status.success(), "{}", text(&o));
        infos.push(String::from_utf8_lossy(&o.stdout).into_owned());
    }
    // Everything but the file name line agrees.
    let strip = |s: &str| s.lines().filter(|l| !l.contains(".mcap")).collect::<Vec<_>>().join("\n");
    assert_eq!(strip(&infos[0]), strip(&infos[1]));
    assert!(infos[1].contains("/humanoid/imu/data"), "{}", infos[1]);
    assert!(
        infos[1].contains("/humanoid_robot/joint_commands") || !infos[0].contains("joint_commands"),
        "{}",
        infos[1]
    );
    // 100 messages in 1 s on the IMU topic.
    let imu_line = infos[1].lines().find(|l| l.contains("/humanoid/imu/data")).unwrap();
    assert!(imu_line.split_whitespace().any(|w| w == "100" || w == "101"), "{imu_line}");
}
