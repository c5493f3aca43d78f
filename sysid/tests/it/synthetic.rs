//! The synthetic benchmark: the twin simulates a known robot (a 6-DOF arm; the shipped humanoid
//! hung on a gantry) with MuJoCo, logs it with a 17-bit encoder, velocity noise and 1 % effort
//! noise, and `sysid` starts from a URDF whose inertias and friction are off by 20–40 %.

use std::path::{Path, PathBuf};
use sysid::JointLog;
use sysid::synth::{SynthOptions, perturbed_urdf, simulate};
use sysid::{RobotModel, SysidOptions, identify, urdf_updates, validate};

fn models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

/// Replaces the values of the attributes write-back may change with `#`, so that two URDFs
/// compare equal exactly when they differ only inside those attributes.
fn mask_rewritable(text: &str) -> String {
    let doc = roxmltree::Document::parse(text).unwrap();
    let mut ranges = Vec::new();
    for node in doc.descendants().filter(|n| n.is_element()) {
        let parent = node.parent_element().map(|p| p.tag_name().name()).unwrap_or("");
        let names: &[&str] = match (parent, node.tag_name().name()) {
            ("inertial", "origin") => &["xyz"],
            ("inertial", "mass") => &["value"],
            ("inertial", "inertia") => &["ixx", "ixy", "ixz", "iyy", "iyz", "izz"],
            ("joint", "dynamics") => &["damping", "friction"],
            _ => &[],
        };
        for name in names {
            if let Some(a) = node.attribute_node(*name) {
                ranges.push(a.range_value());
            }
        }
    }
    let mut out = text.to_string();
    ranges.sort_by_key(|r| std::cmp::Reverse(r.start));
    for r in ranges {
        out.replace_range(r, "#");
    }
    out
}

struct Outcome {
    worst_nrmse: f64,
    worst_friction_error: f64,
}

fn run_benchmark(truth_name: &str, train_secs: f64) -> Outcome {
    run_benchmark_on(&models_dir().join(truth_name), train_secs)
}

fn run_benchmark_on(truth: &Path, train_secs: f64) -> Outcome {
    let truth_name = truth.file_name().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let start = dir.path().join(truth_name);
    let [train_seed, held_out_seed, start_seed] = crate::seeds("TWIN_SYNTH_SEEDS", [1, 2, 3]);
    perturbed_urdf(truth, &start, start_seed).unwrap();
    let original = std::fs::read_to_string(&start).unwrap();

    let train =
        simulate(truth, &SynthOptions { duration_secs: train_secs, seed: train_seed, ..Default::default() }).unwrap();
    let held_out =
        simulate(truth, &SynthOptions { duration_secs: 8.0, seed: held_out_seed, ..Default::default() }).unwrap();
    // The logs go through ROS 2 bags (/joint_states), as a real robot's would.
    let bags = tempfile::tempdir().unwrap();
    let through_bag = |mut log: JointLog, name: &str| {
        // Stamped in wall-clock time as a robot would (a zero stamp means "unset" in ROS).
        log.t_nanos.iter_mut().for_each(|t| *t += 1_700_000_000_000_000_000);
        let path = bags.path().join(name);
        log.write_mcap(&path, "/joint_states").unwrap();
        let (back, warnings) = JointLog::read_mcap(&path, None).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        back
    };
    let train = through_bag(train, "train.mcap");
    let held_out = through_bag(held_out, "held_out.mcap");

    let robot = RobotModel::from_urdf(&start).unwrap();
    let true_robot = RobotModel::from_urdf(truth).unwrap();
    let opts = SysidOptions::default();
    let ident = identify(&robot, &train, &opts).unwrap();
    eprintln!("{}", ident.report.table());

    // Held-out torque NRMSE ≤ 2 % on every joint, and much better than the starting URDF.
    let truth_params = crate::truth_params(&true_robot, &ident.layout);
    let nrmse = validate(&robot, &held_out, &opts, &[&ident.before, &ident.after, &truth_params]).unwrap();
    let mut worst_nrmse: f64 = 0.0;
    for (j, joint) in robot.joints.iter().enumerate() {
        let (before, after) = (nrmse[0][j], nrmse[1][j]);
        eprintln!(
            "{:<30} held-out NRMSE after {:5.2} % truth {:5.2} %",
            joint.name,
            100.0 * after,
            100.0 * nrmse[2][j]
        );
        assert!(
            after <= 0.02,
            "{}: held-out NRMSE {:.2} % > 2 % (before {:.2} %)",
            joint.name,
            100.0 * after,
            100.0 * before
        );
        assert!(after < 0.5 * before, "{}: {after} not better than {before}", joint.name);
        worst_nrmse = worst_nrmse.max(after);
    }
    // Viscous and Coulomb friction within 10 % of the truth.
    let mut worst_friction_error: f64 = 0.0;
    for (j, joint) in true_robot.joints.iter().enumerate() {
        let (viscous, coulomb, _) = ident.joint_friction(j);
        for (k, (what, got, want)) in
            [("viscous", viscous, joint.damping), ("Coulomb", coulomb, joint.friction)].into_iter().enumerate()
        {
            let err = (got / want - 1.0).abs();
            let sigmas = (got - want).abs() / ident.std[ident.layout.joint_col(j) + k];
            eprintln!("{:<30} {what:<8} friction error {:5.1} % ({sigmas:.1} σ)", joint.name, 100.0 * err);
            assert!(err <= 0.10, "{}: {what} {got} vs true {want} ({:.1} %)", joint.name, 100.0 * err);
            worst_friction_error = worst_friction_error.max(err);
        }
    }
    // Every identified link physically valid.
    for (l, link) in robot.links.iter().enumerate() {
        assert!(sysid::model::physically_valid(&ident.link_params(l)), "{} not physically valid", link.name);
        assert!(ident.report.links[l].physically_valid);
    }

    // Write-back: MuJoCo loads the updated URDF as it is (twin-core's URDF checks included), and
    // it holds the identified values.
    let (links, joints) = urdf_updates(&robot, &ident);
    assert!(!links.is_empty() && joints.len() == robot.joints.len());
    let outcome = sysid::writeback::update_urdf_file(&start, &links, &joints, false).unwrap();
    let backup = outcome.backup.unwrap();
    assert_eq!(std::fs::read_to_string(&backup).unwrap(), original);
    twin_core::mj::Model::from_file(&start).unwrap();
    let updated = RobotModel::from_urdf(&start).unwrap();
    for (l, link) in updated.links.iter().enumerate() {
        let written = link.cad;
        let identified = ident.link_params(l);
        for k in 0..10 {
            let scale = identified[0].abs().max(1e-3) * if k == 0 { 1.0 } else { 1e-2 };
            assert!(
                (written[k] - identified[k]).abs() <= 1e-5 * scale.max(identified[k].abs()),
                "{} parameter {k}: written {} vs identified {}",
                link.name,
                written[k],
                identified[k]
            );
        }
    }
    // Only the rewritten attributes differ.
    let new_text = std::fs::read_to_string(&start).unwrap();
    assert_ne!(new_text, original);
    assert_eq!(mask_rewritable(&new_text), mask_rewritable(&original));
    // Links that are no identified body (fixed-joint links lumped into one) keep their bytes.
    let inertial_of = |text: &str, name: &str| -> Option<String> {
        let doc = roxmltree::Document::parse(text).unwrap();
        let link =
            doc.root_element().children().find(|n| n.has_tag_name("link") && n.attribute("name") == Some(name))?;
        link.children().find(|c| c.has_tag_name("inertial")).map(|i| text[i.range()].to_string())
    };
    let doc = roxmltree::Document::parse(&original).unwrap();
    for name in doc.root_element().children().filter(|n| n.has_tag_name("link")).filter_map(|n| n.attribute("name")) {
        if !robot.links.iter().any(|l| l.name == name) {
            assert_eq!(inertial_of(&new_text, name), inertial_of(&original, name), "{name}");
        }
    }
    Outcome { worst_nrmse, worst_friction_error }
}

#[test]
fn arm_identification_meets_the_benchmark() {
    let o = run_benchmark("arm6.urdf", 20.0);
    eprintln!(
        "arm: worst held-out NRMSE {:.2} %, worst friction error {:.1} %",
        100.0 * o.worst_nrmse,
        100.0 * o.worst_friction_error
    );
}

#[test]
fn humanoid_on_a_gantry_meets_the_benchmark() {
    let o = run_benchmark("humanoid.urdf", 20.0);
    eprintln!(
        "humanoid: worst held-out NRMSE {:.2} %, worst friction error {:.1} %",
        100.0 * o.worst_nrmse,
        100.0 * o.worst_friction_error
    );
}

/// A fixed-joint link with mass (a camera on the flange) and a massless frame (a TCP): the
/// twin's converter lumps the camera into the flange's body, which sysid identifies as the twin
/// runs it; the write-back puts the flange's own share back on `tool_link` and leaves the
/// camera's `<inertial>` as it was.
#[test]
fn arm_with_a_fixed_camera_identifies_the_lumped_body_and_writes_back_per_link() {
    let text = std::fs::read_to_string(models_dir().join("arm6.urdf")).unwrap();
    let camera = r#"  <joint name="camera_mount" type="fixed">
    <origin xyz="0.03 0 0.04" rpy="0 0.3 0"/>
    <parent link="tool_link"/>
    <child link="camera_link"/>
  </joint>
  <link name="camera_link">
    <inertial>
      <origin xyz="0.01 0 0.02" rpy="0 0 0"/>
      <mass value="0.35"/>
      <inertia ixx="0.0004" ixy="0" ixz="0" iyy="0.0003" iyz="0" izz="0.0005"/>
    </inertial>
  </link>
  <joint name="tcp_joint" type="fixed">
    <origin xyz="0 0.1 0" rpy="0 0 0"/>
    <parent link="tool_link"/>
    <child link="tcp"/>
  </joint>
  <link name="tcp"/>

"#;
    let at = text.find("  <gazebo reference=\"tool_link\">").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let truth = dir.path().join("arm_camera.urdf");
    std::fs::write(&truth, format!("{}{camera}{}", &text[..at], &text[at..])).unwrap();

    let robot = RobotModel::from_urdf(&truth).unwrap();
    let names: Vec<&str> = robot.links.iter().map(|l| l.name.as_str()).collect();
    assert!(!names.contains(&"camera_link") && !names.contains(&"tcp"), "{names:?}");
    let tool = robot.links.iter().find(|l| l.name == "tool_link").unwrap();
    // The body holds flange + camera (0.9 + 0.35 kg); the camera's share is 0.35 kg.
    assert!((tool.cad[0] - 1.25).abs() < 1e-9, "{}", tool.cad[0]);
    assert!((tool.welded[0] - 0.35).abs() < 1e-9, "{}", tool.welded[0]);
    assert!((tool.own_params(&tool.cad)[0] - 0.9).abs() < 1e-9);

    let o = run_benchmark_on(&truth, 20.0);
    eprintln!("arm with camera: worst held-out NRMSE {:.2} %", 100.0 * o.worst_nrmse);
}

/// What one glitched sample does to identification on arm6 (perturbed start, 20 s log): the
/// largest shift of an identifiable parameter in standard deviations, the warnings of the
/// glitched and of the clean run, and when the glitch was (s from the start).
struct GlitchOutcome {
    worst_shift_sigma: f64,
    warnings: Vec<String>,
    clean_warnings: Vec<String>,
    glitch_secs: f64,
}

/// Adds `by` to one sample of the elbow's `field` (position or effort), 1/`part` into the log.
fn identify_with_one_glitch(field: fn(&mut JointLog) -> &mut Vec<Vec<f64>>, part: usize, by: f64) -> GlitchOutcome {
    let truth = models_dir().join("arm6.urdf");
    let dir = tempfile::tempdir().unwrap();
    let start = dir.path().join("arm6.urdf");
    perturbed_urdf(&truth, &start, 3).unwrap();
    let clean = simulate(&truth, &SynthOptions { duration_secs: 20.0, seed: 1, ..Default::default() }).unwrap();
    let mut glitched = clean.clone();
    let j = glitched.joint_names.iter().position(|n| n == "elbow_joint").unwrap();
    let k = glitched.t_nanos.len() / part;
    field(&mut glitched)[j][k] += by;
    let glitch_secs = (glitched.t_nanos[k] - glitched.t_nanos[0]) as f64 * 1e-9;

    let robot = RobotModel::from_urdf(&start).unwrap();
    let opts = SysidOptions::default();
    let a = identify(&robot, &clean, &opts).unwrap();
    let b = identify(&robot, &glitched, &opts).unwrap();
    let mut worst: f64 = 0.0;
    for i in 0..a.after.len() {
        if a.identifiability[i] == sysid::estimate::Identifiability::Identifiable {
            worst = worst.max((b.after[i] - a.after[i]).abs() / a.std[i].max(1e-300));
        }
    }
    GlitchOutcome {
        worst_shift_sigma: worst,
        warnings: b.report.warnings,
        clean_warnings: a.report.warnings,
        glitch_secs,
    }
}

impl GlitchOutcome {
    /// Asserts the `what` glitch moved no identifiable parameter by `sigmas` standard
    /// deviations or more (and prints by how much it did).
    fn assert_moved_less_than(&self, sigmas: f64, what: &str) {
        eprintln!("{what}: worst shift of an identifiable parameter {:.2}σ", self.worst_shift_sigma);
        assert!(self.worst_shift_sigma < sigmas, "{what} moved a parameter by {:.1}σ", self.worst_shift_sigma);
    }

    /// Asserts the clean log's fit warned of nothing that contains `kind`.
    fn assert_clean_warns_of_no(&self, kind: &str) {
        assert!(!self.clean_warnings.iter().any(|w| w.contains(kind)), "{:?}", self.clean_warnings);
    }

    /// The elbow's warning that contains `kind`, after checking it names the glitch's time.
    fn warning_at_the_glitch(&self, kind: &str) -> &str {
        let warning = self.warnings.iter().find(|w| w.contains("elbow_joint") && w.contains(kind));
        let warning = warning.unwrap_or_else(|| panic!("no outlier warning: {:?}", self.warnings));
        let at = number_after(warning, "at t = ");
        assert!((at - self.glitch_secs).abs() < 1e-3, "{warning} (glitch at {:.3} s)", self.glitch_secs);
        warning
    }
}

/// The number after `key` in a warning.
fn number_after(warning: &str, key: &str) -> f64 {
    warning.split(key).nth(1).unwrap().split(' ').next().unwrap().parse().unwrap()
}

/// Issue 15: one glitched encoder reading (0.125 rad for one sample, as a flipped bit would
/// give) must not move an identifiable parameter: conditioning replaces the spike (Hampel
/// filter) before it becomes a burst of accelerations, and the report names joint and time.
#[test]
fn one_glitched_position_sample_is_reported_and_does_not_move_the_fit() {
    let o = identify_with_one_glitch(|l| &mut l.position, 2, 0.125);
    o.assert_moved_less_than(3.0, "one glitched position sample");
    // The glitched sample itself, by how much it was off its neighbours.
    let warning = o.warning_at_the_glitch("Hampel");
    assert!(warning.contains("+0.12"), "{warning}");
    o.assert_clean_warns_of_no("Hampel");
}

/// Issue 15: one glitched torque reading (a bit flip in the effort field: +200 N·m for one
/// sample at the elbow) must not move an identifiable parameter by a standard deviation, and
/// is reported with its joint, count and time. Without outlier handling it is smeared by the
/// low-pass filter over a few regressor rows and pulls the fit by many σ.
#[test]
fn one_glitched_torque_sample_is_reported_and_does_not_move_the_fit() {
    let o = identify_with_one_glitch(|l| &mut l.effort, 3, 200.0);
    o.assert_moved_less_than(1.0, "one glitched torque sample");
    let warning = o.warning_at_the_glitch("effort");
    assert!(warning.contains("1 effort sample(s)"), "{warning}");
    // By how much it was off its neighbours: the glitch, up to the torque's change over 3 ms.
    let off = number_after(warning, "worst ");
    assert!((off - 200.0).abs() < 1.0, "{warning}");
    o.assert_clean_warns_of_no("effort sample");
}
