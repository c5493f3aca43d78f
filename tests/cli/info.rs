//! `twin info` and the top-level flags.

use crate::common::{output_of, repo_root, run, twin, write};

#[test]
fn version_names_mujoco() {
    let (ok, out, _) = run(&["--version"]);
    assert!(ok);
    assert!(out.starts_with("twin ") && out.contains("MuJoCo 4.0.1"), "{out}");
}

#[test]
fn help_lists_info() {
    let (ok, out, _) = run(&["--help"]);
    assert!(ok);
    assert!(out.contains("info"), "{out}");
}

#[test]
fn info_reports_masses_ranges_and_gear_of_an_mjcf() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "arm.xml",
        r#"<mujoco model="arm">
             <compiler angle="radian"/>
             <option timestep="0.001"/>
             <worldbody>
               <body name="upper"><joint name="shoulder" type="hinge" axis="0 1 0" range="-1.5 1.5" damping="0.25" frictionloss="0.125"/>
                 <inertial pos="0.2 0 0" mass="1.5" diaginertia="0.01 0.01 0.01"/>
                 <body name="lower" pos="0.4 0 0"><joint name="elbow" type="hinge" axis="0 1 0"/>
                   <inertial pos="0.2 0 0" mass="0.75" diaginertia="0.01 0.01 0.01"/></body>
               </body>
             </worldbody>
             <actuator><motor name="shoulder_motor" joint="shoulder" gear="50" ctrlrange="-1 1"/></actuator>
             <sensor><jointpos name="shoulder_pos" joint="shoulder"/></sensor>
           </mujoco>"#,
    );
    let (ok, out, err) = run(&["info", path.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(out.contains("timestep 0.001 s"), "{out}");
    assert!(out.contains("total mass: 2.2500 kg"), "{out}");
    let shoulder = out.lines().find(|l| l.trim_start().starts_with("shoulder ")).expect("joint line");
    assert!(shoulder.contains("hinge") && shoulder.contains("[-1.5000, 1.5000]"), "{shoulder}");
    assert!(shoulder.contains("0.2500") && shoulder.contains("0.1250"), "{shoulder}");
    let elbow = out.lines().find(|l| l.trim_start().starts_with("elbow ")).expect("joint line");
    assert!(elbow.contains("unlimited"), "{elbow}");
    assert!(out.contains("actuators (1):") && out.contains("gear 50"), "{out}");
    assert!(out.contains("drive: ideal"), "{out}");
    assert!(out.contains("sensors (1):") && out.contains("shoulder_pos"), "{out}");
}

#[test]
fn info_shows_each_joint_drive_model_from_the_urdf_block() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "pair.urdf",
        r#"<robot name="pair">
  <link name="world"/>
  <joint name="fix" type="fixed"><parent link="world"/><child link="base"/></joint>
  <link name="base"><inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="a" type="revolute"><parent link="base"/><child link="la"/><axis xyz="0 0 1"/><limit effort="20" velocity="3" lower="-1" upper="1"/></joint>
  <link name="la"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="b" type="revolute"><parent link="base"/><child link="lb"/><origin xyz="0 0 0.2"/><axis xyz="0 0 1"/><limit effort="20" velocity="3" lower="-1" upper="1"/></joint>
  <link name="lb"><inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <twin_actuator version="1"><joint name="b" delay_secs="0.012" stall_torque="30" no_load_speed="6"/></twin_actuator>
</robot>
"#,
    );
    let (ok, out, err) = run(&["info", path.to_str().unwrap()]);
    assert!(ok, "{err}");
    let line =
        |name: &str| out.lines().find(|l| l.trim_start().starts_with(&format!("{name} ")) && l.contains("drive:"));
    assert!(line("a").expect("actuator a").ends_with("drive: ideal"), "{out}");
    let b = line("b").expect("actuator b");
    assert!(b.contains("delay 12.00 ms") && b.contains("DC motor stall 30.0000 no-load 6.0000"), "{b}");
}

#[test]
fn info_on_the_default_humanoid_lists_every_urdf_joint() {
    let (ok, out, err) = run(&["info"]);
    assert!(ok, "{err}");
    let urdf = std::fs::read_to_string(repo_root().join("models/humanoid.urdf")).unwrap();
    let doc = roxmltree::Document::parse(&urdf).unwrap();
    let moving: Vec<&str> = doc
        .root_element()
        .children()
        .filter(|n| n.has_tag_name("joint") && n.attribute("type") != Some("fixed"))
        .filter_map(|n| n.attribute("name"))
        .collect();
    assert_eq!(moving.len(), 23);
    for name in moving {
        assert!(out.lines().any(|l| l.trim_start().starts_with(&format!("{name} "))), "joint {name} missing:\n{out}");
    }
}

#[test]
fn info_errors_name_the_file_and_element() {
    let (ok, _, err) = run(&["info", "does/not/exist.urdf"]);
    assert!(!ok);
    assert!(err.contains("does/not/exist.urdf"), "{err}");

    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "neg.urdf",
        "<robot name=\"r\">\n  <link name=\"base\">\n    <inertial>\n      <mass value=\"-3\"/>\n      <inertia ixx=\"1\" iyy=\"1\" izz=\"1\"/>\n    </inertial>\n  </link>\n</robot>\n",
    );
    let (ok, _, err) = run(&["info", path.to_str().unwrap()]);
    assert!(!ok);
    assert!(
        err.contains("neg.urdf:4") && err.contains("<mass name=\"base\">") && err.contains("negative mass"),
        "{err}"
    );
}

/// Every ```console block of README.md is real: each `$ target/release/twin ...` line is run
/// with this build's binary (in a scratch folder that sees the repository's `models/` and
/// `data/`), and the lines shown under it (up to a `...`) must be what it prints.
#[test]
fn readme_console_examples_print_what_they_show() {
    let readme = std::fs::read_to_string(repo_root().join("README.md")).unwrap();
    let scratch = tempfile::tempdir().unwrap();
    for folder in ["models", "data"] {
        std::os::unix::fs::symlink(repo_root().join(folder), scratch.path().join(folder)).unwrap();
    }
    let mut commands = 0;
    let mut lines = readme.lines();
    while let Some(line) = lines.next() {
        if line.trim() != "```console" {
            continue;
        }
        let block: Vec<&str> = lines.by_ref().take_while(|l| l.trim() != "```").collect();
        let mut k = 0;
        while k < block.len() {
            let command = block[k].strip_prefix("$ target/release/twin ").expect("examples run target/release/twin");
            let expected: Vec<&str> = block[k + 1..].iter().take_while(|l| !l.starts_with("$ ")).copied().collect();
            k += 1 + expected.len();
            let shown: Vec<&str> = expected.iter().take_while(|l| l.trim() != "...").copied().collect();
            let args: Vec<&str> = command.split_whitespace().collect();
            let out = twin().current_dir(scratch.path()).args(&args).output().expect("twin runs");
            let (ok, out, err) = output_of(out);
            assert!(ok, "README example `{command}` failed: {err}");
            let got: Vec<&str> = out.lines().take(shown.len()).collect();
            assert_eq!(got, shown, "README example `{command}` prints something else");
            commands += 1;
        }
    }
    assert!(commands > 0, "README has no console example");
}
