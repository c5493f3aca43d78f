//! `twin sysid`: identification from a ROS 2 bag or a CSV log, URDF write-back, reports, and
//! refusals that leave the URDF untouched.

use super::common::assert_untouched;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use sysid::JointLog;
use sysid::synth::{SynthOptions, simulate};

fn arm_urdf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/arm6.urdf")
}

fn twin(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twin")).current_dir(dir).args(args).output().expect("twin runs")
}

/// A temp dir with `arm6.urdf` (a copy of the true arm) and its simulation as `train.csv` and
/// as a ROS 2 bag `train.mcap` (`/joint_states`).
fn setup(train_secs: f64) -> (tempfile::TempDir, JointLog) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(arm_urdf(), dir.path().join("arm6.urdf")).unwrap();
    let log = simulate(&arm_urdf(), &SynthOptions { duration_secs: train_secs, ..Default::default() }).unwrap();
    log.write_csv(dir.path().join("train.csv")).unwrap();
    log.write_mcap(dir.path().join("train.mcap"), "/joint_states").unwrap();
    (dir, log)
}

/// [`setup`], with `arm6.urdf` replaced by the arm perturbed with `seed` (the "CAD" to
/// correct): the folder and that file.
fn setup_perturbed(train_secs: f64, seed: u64) -> (tempfile::TempDir, PathBuf) {
    let (dir, _) = setup(train_secs);
    let start = dir.path().join("arm6.urdf");
    sysid::synth::perturbed_urdf(&arm_urdf(), &start, seed).unwrap();
    (dir, start)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn sysid_updates_the_urdf_and_writes_report_and_mjcf() {
    let (dir, start) = setup_perturbed(12.0, 5);
    let original = std::fs::read_to_string(&start).unwrap();
    let val = simulate(&arm_urdf(), &SynthOptions { duration_secs: 6.0, seed: 9, ..Default::default() }).unwrap();
    val.write_mcap(dir.path().join("val.mcap"), "/joint_states").unwrap();
    let out = twin(
        dir.path(),
        &[
            "sysid",
            "--log",
            "train.mcap",
            "--update",
            "arm6.urdf",
            "--validate",
            "val.mcap",
            "--report",
            "r.json",
            "--mjcf",
            "out.xml",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("torque NRMSE on the held-out log"), "{stdout}");
    assert!(stdout.contains("fixed base"), "{stdout}");
    assert_eq!(std::fs::read_to_string(dir.path().join("arm6.urdf.bak")).unwrap(), original);
    assert_ne!(std::fs::read_to_string(&start).unwrap(), original);

    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("r.json")).unwrap()).unwrap();
    assert_eq!(report["base"], "fixed");
    let validation = report["validation_nrmse"].as_array().unwrap();
    assert_eq!(validation.len(), 6);
    for row in validation {
        let (before, after) = (row["before"].as_f64().unwrap(), row["after"].as_f64().unwrap());
        assert!(after < 0.02 && after < before / 5.0, "{row}");
    }
    // The MJCF carries what URDF can't: armature (true value 0.02 on every joint).
    let model = twin_core::mj::Model::from_file(dir.path().join("out.xml")).unwrap();
    let elbow = model.require_id(twin_core::mj::ObjType::Joint, "elbow_joint").unwrap();
    let armature = model.dof_armature()[model.jnt_dofadr()[elbow] as usize];
    assert!((armature - 0.02).abs() < 0.005, "elbow armature {armature}");
}

#[test]
fn sysid_dry_run_prints_a_diff_and_writes_nothing() {
    let (dir, start) = setup_perturbed(8.0, 6);
    let original = std::fs::read(&start).unwrap();
    let out = twin(dir.path(), &["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--dry-run"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("--- ") && stdout.contains("@@") && stdout.contains("+      <mass value="), "{stdout}");
    assert_untouched(&start, &original);
}

/// Runs `twin sysid` on a bad `log`: it must fail with `expected` in the message and leave the
/// URDF byte-identical, with no backup.
fn refuses(dir: &Path, log: &JointLog, extra: &[&str], expected: &str) {
    log.write_csv(dir.join("bad.csv")).unwrap();
    let urdf = dir.join("arm6.urdf");
    let before = std::fs::read(&urdf).unwrap();
    let mut args = vec!["sysid", "--log", "bad.csv", "--update", "arm6.urdf"];
    args.extend_from_slice(extra);
    let out = twin(dir, &args);
    let err = stderr(&out);
    assert!(!out.status.success(), "accepted a bad log: {err}");
    assert!(err.contains(expected), "expected `{expected}` in: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_untouched(&urdf, &before);
}

#[test]
fn sysid_refuses_bad_logs_and_leaves_the_urdf_untouched() {
    let (dir, log) = setup(6.0);
    let d = dir.path();

    let mut no_effort = log.clone();
    for e in &mut no_effort.effort {
        e.fill(f64::NAN);
    }
    refuses(d, &no_effort, &[], "no effort (torque) for joint(s)");

    let mut renamed = log.clone();
    renamed.joint_names[2] = "joint_3".into();
    refuses(d, &renamed, &["--strict"], "the robot's joint(s) \"elbow_joint\" are not in the log");

    let mut still = log.clone();
    for (j, q) in still.position.iter_mut().enumerate() {
        q.fill(0.1 * j as f64);
    }
    refuses(d, &still, &[], "the robot stood still");

    let mut nan = log.clone();
    nan.position[1][1234] = f64::NAN;
    refuses(d, &nan, &[], "position value(s) of joint \"shoulder_lift_joint\" are NaN");

    refuses(d, &log, &["--base", "floating"], "--base floating needs the base motion");

    // Strict: an effort logged with the opposite sign convention is a refusal.
    let mut flipped = log.clone();
    for e in &mut flipped.effort[2] {
        *e = -*e;
    }
    refuses(d, &flipped, &["--strict"], "\"elbow_joint\": the logged effort has the opposite sign");

    // Strict: a joint that barely moved is a refusal, not a warning.
    let mut lazy = log.clone();
    let q0 = lazy.position[5][0];
    lazy.position[5].fill(q0);
    refuses(d, &lazy, &["--strict"], "\"wrist_3_joint\" barely moved");
}

/// `--base floating` on a bag with `/joint_states`, `/odom` and contact wrench topics updates
/// the URDF (pelvis included) and says so; the same joints without `/odom` are refused, the
/// topics that are there named, and the URDF untouched.
#[test]
fn sysid_floating_base_from_a_bag_and_refusal_without_odometry() {
    use sysid::synth::{FloatingSynthOptions, simulate_floating};
    let truth = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/humanoid.urdf");
    let dir = tempfile::tempdir().unwrap();
    let start = dir.path().join("humanoid.urdf");
    sysid::synth::perturbed_urdf(&truth, &start, 4).unwrap();
    let fopts = FloatingSynthOptions {
        wrench_links: vec!["left_foot_link".into(), "right_foot_link".into()],
        ..Default::default()
    };
    let log = simulate_floating(&truth, &SynthOptions { duration_secs: 10.0, ..Default::default() }, &fopts).unwrap();
    log.write_mcap(dir.path().join("float.mcap"), "/joint_states").unwrap();
    let mut joints_only = log.clone();
    joints_only.base = None;
    joints_only.wrenches.clear();
    joints_only.write_mcap(dir.path().join("joints.mcap"), "/joint_states").unwrap();

    let original = std::fs::read(&start).unwrap();
    let out = twin(dir.path(), &["sysid", "--log", "joints.mcap", "--update", "humanoid.urdf", "--base", "floating"]);
    let err = stderr(&out);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("the bag has no topic /odom") && err.contains("/joint_states"), "{err}");
    assert_untouched(&start, &original);

    let out = twin(
        dir.path(),
        &["sysid", "--log", "float.mcap", "--update", "humanoid.urdf", "--base", "floating", "--report", "r.json"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("floating base (base motion from /odom, 2 contact wrench topics)"), "{stdout}");
    assert!(stdout.contains("base force z (N)"), "{stdout}");
    let updated = std::fs::read_to_string(&start).unwrap();
    assert_ne!(updated.as_bytes(), original.as_slice());
    assert_eq!(std::fs::read(dir.path().join("humanoid.urdf.bak")).unwrap(), original);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("r.json")).unwrap()).unwrap();
    assert_eq!(report["base"], "floating");
    assert!(report["links"].as_array().unwrap().iter().any(|l| l["name"] == "pelvis" && l["physically_valid"] == true));
    for row in report["training_nrmse"].as_array().unwrap() {
        let (before, after) = (row["before"].as_f64().unwrap(), row["after"].as_f64().unwrap());
        assert!(after < before && after < 0.1, "{row}");
    }
    twin_core::mj::Model::from_file(&start).unwrap();
}

/// `twin sysid --update` on a real arm whose URDF uses `package://` meshes, STL and Collada (the
/// UR5 of example-robot-data, cached by `convert::real_public_urdfs_convert_load_and_stand`):
/// the model is built by twin's converter, as every command builds it, and the write-back only
/// touches the identified numbers.
#[test]
fn sysid_updates_a_urdf_with_package_meshes() {
    let robots = crate::example_robot_data::example_robot_data();
    let share = robots.parent().and_then(Path::parent).expect("…/share/example-robot-data/robots");
    let truth = robots.join("ur_description/urdf/ur5_robot.urdf");
    assert!(truth.is_file(), "{} is missing: fetch example-robot-data into TWIN_URDF_CACHE", truth.display());
    let text = std::fs::read_to_string(&truth).unwrap();
    assert!(text.contains("package://") && text.contains(".dae") && text.contains(".stl"));
    // The same package layout in a temp dir (meshes linked), so package:// resolves there too.
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("share/example-robot-data/robots/ur_description");
    std::fs::create_dir_all(pkg.join("urdf")).unwrap();
    std::os::unix::fs::symlink(share.join("example-robot-data/robots/ur_description/meshes"), pkg.join("meshes"))
        .unwrap();
    let urdf = pkg.join("urdf/ur5_robot.urdf");
    sysid::synth::perturbed_urdf(&truth, &urdf, 3).unwrap();
    let before = std::fs::read_to_string(&urdf).unwrap();
    for (name, seed, secs) in [("train.mcap", 1, 12.0), ("val.mcap", 9, 6.0)] {
        let log = simulate(&truth, &SynthOptions { duration_secs: secs, seed, ..Default::default() }).unwrap();
        log.write_mcap(dir.path().join(name), "/joint_states").unwrap();
    }
    let urdf_arg = urdf.to_str().unwrap();
    let out = twin(
        dir.path(),
        &["sysid", "--log", "train.mcap", "--update", urdf_arg, "--validate", "val.mcap", "--report", "r.json"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let after = std::fs::read_to_string(&urdf).unwrap();
    assert_ne!(after, before);
    // The <twin_sysid> friction block (and its comment) is added before </robot>.
    let block_start = after.find("  <!-- twin sysid:").expect("friction block");
    let block_end = after.find("</twin_sysid>\n").expect("friction block end") + "</twin_sysid>\n".len();
    let after = format!("{}{}", &after[..block_start], &after[block_end..]);
    // Outside the identified numbers (inertial blocks, joint dynamics) the bytes are unchanged.
    let (a, b): (Vec<&str>, Vec<&str>) = (before.lines().collect(), after.lines().collect());
    assert_eq!(a.len(), b.len());
    let mut in_inertial = false;
    for (x, y) in a.iter().zip(&b) {
        let t = x.trim_start();
        in_inertial = (in_inertial || t.starts_with("<inertial")) && !t.starts_with("</inertial");
        if x != y {
            let identified = t.starts_with("<dynamics")
                || (in_inertial && (t.starts_with("<mass") || t.starts_with("<inertia") || t.starts_with("<origin")));
            assert!(identified, "a line outside the identified numbers changed:\n{x}\n{y}");
        }
    }
    // The identified model predicts held-out torques better than the perturbed one.
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("r.json")).unwrap()).unwrap();
    for row in report["validation_nrmse"].as_array().unwrap() {
        let (before, after) = (row["before"].as_f64().unwrap(), row["after"].as_f64().unwrap());
        assert!(after < 0.05 && after < before, "{row}");
    }
}

/// The UR5 of example-robot-data (`package://` STL and Collada meshes) loads for
/// identification through twin's converter: six joints, and the links carry the URDF's masses.
#[test]
fn sysid_loads_a_urdf_with_package_meshes_through_the_converter() {
    let truth = crate::example_robot_data::example_robot_data().join("ur_description/urdf/ur5_robot.urdf");
    let robot = sysid::RobotModel::from_urdf(&truth).unwrap();
    let names: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(
        names,
        ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
    );
    // <link name="upper_arm_link"> … <mass value="8.393"/> in the URDF.
    let upper = robot.links.iter().find(|l| l.name == "upper_arm_link").unwrap();
    assert!((upper.cad[0] - 8.393).abs() < 1e-9, "{}", upper.cad[0]);
    // A synthetic log of it simulates (the model the twin runs).
    let log = simulate(&truth, &SynthOptions { duration_secs: 1.0, ..Default::default() }).unwrap();
    assert_eq!(log.joint_names.len(), 6);
}

/// `twin sysid --update URDF --report JSON` with the URDF and the report in one folder, spelled
/// `urdf` and `report` (relative, absolute, through `..`, through a symlink to the folder): the
/// command ends within 5 s (the folder's write lock is taken once, whatever the spelling) with
/// the URDF updated and the report written.
fn sysid_ends_with_spellings(urdf: impl Fn(&Path) -> String, report: impl Fn(&Path) -> String) {
    let (dir, _) = setup(6.0);
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    std::os::unix::fs::symlink(dir.path(), dir.path().join("here")).unwrap();
    let (urdf, report) = (urdf(dir.path()), report(dir.path()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_twin"))
        .current_dir(dir.path())
        // Cut-off and friction model given, no held-out part: the run is the one fit, not the
        // cross-validation of the defaults, so 5 s bounds the lock's handling alone.
        .args(["sysid", "--log", "train.mcap", "--update", &urdf, "--report", &report])
        .args(["--cutoff-hz", "20", "--offset", "--held-out", "0"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if started.elapsed() > std::time::Duration::from_secs(5) {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!("twin sysid --update {urdf} --report {report} still running after 5 s:\n{}", stderr(&out));
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let out = child.wait_with_output().unwrap();
    assert!(status.success(), "{}", stderr(&out));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("rep.json")).unwrap()).unwrap();
    assert_eq!(report["base"], "fixed");
    assert!(dir.path().join("arm6.urdf.bak").is_file());
}

fn absolute(dir: &Path, name: &str) -> String {
    dir.join(name).to_str().unwrap().to_string()
}

#[test]
fn sysid_update_absolute_report_relative_ends() {
    sysid_ends_with_spellings(|d| absolute(d, "arm6.urdf"), |_| "rep.json".into());
}

#[test]
fn sysid_update_relative_report_absolute_ends() {
    sysid_ends_with_spellings(|_| "arm6.urdf".into(), |d| absolute(d, "rep.json"));
}

#[test]
fn sysid_update_through_dotdot_ends() {
    sysid_ends_with_spellings(|_| "sub/../arm6.urdf".into(), |d| absolute(d, "rep.json"));
}

#[test]
fn sysid_update_through_a_symlinked_folder_ends() {
    sysid_ends_with_spellings(|d| absolute(d, "here/arm6.urdf"), |_| "rep.json".into());
}
