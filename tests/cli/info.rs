//! `twin info` and the top-level flags.

use crate::common::{repo_root, run, write};

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
    assert!(out.contains("sensors (1):") && out.contains("shoulder_pos"), "{out}");
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

/// Every ```console block of README.md is a real command: its `$ target/release/twin ...` line
/// is run with this build's binary and the lines shown (up to a `...`) must be what it prints.
#[test]
fn readme_console_examples_print_what_they_show() {
    let readme = std::fs::read_to_string(repo_root().join("README.md")).unwrap();
    let mut blocks = 0;
    let mut lines = readme.lines();
    while let Some(line) = lines.next() {
        if line.trim() != "```console" {
            continue;
        }
        let block: Vec<&str> = lines.by_ref().take_while(|l| l.trim() != "```").collect();
        let command = block[0].strip_prefix("$ target/release/twin ").expect("examples run target/release/twin");
        let args: Vec<&str> = command.split_whitespace().collect();
        let (ok, out, err) = run(&args);
        assert!(ok, "README example `{command}` failed: {err}");
        let expected: Vec<&str> = block[1..].iter().take_while(|l| l.trim() != "...").copied().collect();
        let got: Vec<&str> = out.lines().take(expected.len()).collect();
        assert_eq!(got, expected, "README example `{command}` prints something else");
        blocks += 1;
    }
    assert!(blocks > 0, "README has no console example");
}
