//! Regression tests of issue 15 (a hostile user's bad inputs): each example ends in a clear
//! error or a correct result, within a bounded time, and leaves the user's files intact.

use super::common::{assert_untouched, output_of, repo_root, twin, write};
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

/// Starts `twin args` in `dir` with stdout and stderr piped.
fn spawn_in(dir: &Path, args: &[&str]) -> std::process::Child {
    twin()
        .current_dir(dir)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("twin starts")
}

/// Runs `twin args` in `dir`, killing it after `limit`: (status ok, stdout, stderr). Fails the
/// test when the command does not end in time (a hang).
fn run_in(dir: &Path, args: &[&str], limit: Duration) -> (bool, String, String) {
    let mut child = spawn_in(dir, args);
    // Drained while it runs: a child blocked on a full pipe would look like a hang.
    let drain = |mut r: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            let _ = r.read_to_end(&mut buf);
            buf
        })
    };
    let stdout = drain(Box::new(child.stdout.take().unwrap()));
    let stderr = drain(Box::new(child.stderr.take().unwrap()));
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            let out = std::process::Output { status, stdout: stdout.join().unwrap(), stderr: stderr.join().unwrap() };
            return output_of(out);
        }
        if started.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("twin {args:?} did not finish within {limit:?} (hang)");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

const QUICK: Duration = Duration::from_secs(60);

/// Runs `twin args` in `dir` (bounded by [`QUICK`]), asserts it failed and returns its stderr.
fn refused(dir: &Path, args: &[&str]) -> String {
    let (ok, _, err) = run_in(dir, args, QUICK);
    assert!(!ok, "{args:?} succeeded");
    err
}

/// Each of `cases` (`twin` arguments), run in `dir`, fails with `needle` in its message.
fn refused_naming(dir: &Path, cases: &[Vec<&str>], needle: &str) {
    for args in cases {
        let err = refused(dir, args);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

/// The shipped humanoid's URDF (absolute: the commands run in temporary folders).
const HUMANOID: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf");

fn mkfifo(path: &Path) {
    assert!(std::process::Command::new("mkfifo").arg(path).status().unwrap().success());
}

fn mjcf(timestep: &str, mass: &str) -> String {
    format!(
        r#"<mujoco model="box"><option timestep="{timestep}"/><worldbody>
<geom type="plane" size="5 5 0.1"/>
<body name="box" pos="0 0 0.5"><freejoint/><geom type="box" size="0.1 0.1 0.1" mass="{mass}"/></body>
</worldbody></mujoco>"#
    )
}

#[test]
fn fifos_as_inputs_are_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for name in ["m.urdf", "m.xml", "spec.toml", "traj.csv", "log.mcap", "log.csv"] {
        mkfifo(&d.join(name));
    }
    let h = HUMANOID;
    let cases: Vec<Vec<&str>> = vec![
        vec!["info", "m.urdf"],
        vec!["check", "m.xml"],
        vec!["convert", "m.urdf", "-o", "out.xml"],
        vec!["randomize", h, "--config", "spec.toml", "--episodes", "1"],
        vec!["sim", h, "--controller", "replay", "--trajectory", "traj.csv", "--duration", "0.01"],
        vec!["log", "info", "log.mcap"],
        vec!["sysid", "--log", "log.csv", "--update", "m.urdf"],
    ];
    refused_naming(d, &cases, "FIFO");
}

#[test]
fn bad_timesteps_and_masses_are_refused_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (ts, mass) in [("0", "1"), ("-0.002", "1"), ("10", "1"), ("nan", "1"), ("0.002", "nan")] {
        let model = write(d, "m.xml", &mjcf(ts, mass));
        let m = model.to_str().unwrap();
        for args in [
            vec!["info", m],
            vec!["check", m],
            vec!["sim", m, "--duration", "0.1"],
            vec!["randomize", m, "--episodes", "1", "--duration", "0.1"],
        ] {
            let (ok, out, err) = run_in(d, &args, QUICK);
            assert!(!ok, "timestep {ts}, mass {mass}: {args:?} succeeded: {out}");
            let expect = if mass == "nan" { "mass" } else { "timestep" };
            assert!(err.contains(expect), "{args:?}: {err}");
            if expect == "timestep" && ts != "nan" {
                assert!(err.contains("1e-6") || err.contains("0.000001"), "the range is in the message: {err}");
            }
        }
    }
    // The valid model still works.
    let model = write(d, "ok.xml", &mjcf("0.002", "1"));
    let (ok, out, err) = run_in(d, &["info", model.to_str().unwrap()], QUICK);
    assert!(ok, "{err}");
    assert!(out.contains("1.000") || out.contains("mass"), "{out}");
}

#[test]
fn absurd_numeric_options_are_refused_with_the_range() {
    let d = tempfile::tempdir().unwrap();
    let log = repo_root().join("data/humanoid_joint_states.mcap");
    let log = log.to_str().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["sim", "--duration", "1e300"], "--duration"),
        (vec!["sim", "--duration", "NaN"], "--duration"),
        (vec!["sim", "--rate", "inf"], "--rate"),
        (vec!["check", "--hold-secs", "inf"], "--hold-secs"),
        (vec!["check", "--hold-secs", "0"], "--hold-secs"),
        (vec!["check", "--hold-secs=-1"], "--hold-secs"),
        (vec!["check", "--hold-secs", "NaN"], "--hold-secs"),
        (vec!["view", log, "-o", "x.rrd", "--fps", "1e6"], "--fps"),
        (vec!["randomize", "--episodes", "0"], "--episodes"),
        (vec!["randomize", "--fall-tilt", "NaN", "--episodes", "1"], "--fall-tilt"),
        (vec!["randomize", "--duration", "inf", "--episodes", "1"], "--duration"),
    ];
    for (args, option) in cases {
        let err = refused(d.path(), &args);
        assert!(err.contains(option), "{args:?}: {err}");
        assert!(err.contains(" to "), "the range is in the message: {err}");
    }
}

#[test]
fn convert_never_damages_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let urdf = d.join("r.urdf");
    std::fs::copy(HUMANOID, &urdf).unwrap();
    let original = std::fs::read(&urdf).unwrap();
    // The input itself, directly or through a symlink.
    std::os::unix::fs::symlink("r.urdf", d.join("alias.xml")).unwrap();
    for out in ["r.urdf", "alias.xml"] {
        let (ok, _, err) = run_in(d, &["convert", "r.urdf", "-o", out], QUICK);
        assert!(!ok && err.contains("is the input"), "{out}: {err}");
    }
    assert_eq!(std::fs::read(&urdf).unwrap(), original);
    // A folder, a device, a FIFO.
    std::fs::create_dir(d.join("somedir")).unwrap();
    mkfifo(&d.join("pipe.xml"));
    for out in ["somedir", "/dev/null", "pipe.xml"] {
        let (ok, _, err) = run_in(d, &["convert", "r.urdf", "-o", out], QUICK);
        assert!(!ok && err.contains("twin writes only regular files"), "{out}: {err}");
    }
    assert!(d.join("somedir").is_dir());
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device_like());
    // A symlink to a real file: the target is rewritten, the link stays, the mode is kept.
    std::fs::write(d.join("target.xml"), "old").unwrap();
    std::fs::set_permissions(d.join("target.xml"), std::fs::Permissions::from_mode(0o664)).unwrap();
    std::os::unix::fs::symlink("target.xml", d.join("link.xml")).unwrap();
    let (ok, _, err) = run_in(d, &["convert", "r.urdf", "-o", "link.xml"], QUICK);
    assert!(ok, "{err}");
    assert!(std::fs::symlink_metadata(d.join("link.xml")).unwrap().file_type().is_symlink());
    assert!(std::fs::read_to_string(d.join("target.xml")).unwrap().contains("<mujoco"));
    assert_eq!(std::fs::metadata(d.join("target.xml")).unwrap().mode() & 0o777, 0o664);
    assert_eq!(std::fs::read_to_string(d.join("target.xml.bak")).unwrap(), "old");
    // A second conversion keeps the first backup.
    let (ok, _, err) = run_in(d, &["convert", "r.urdf", "-o", "link.xml"], QUICK);
    assert!(ok, "{err}");
    assert_eq!(std::fs::read_to_string(d.join("target.xml.bak")).unwrap(), "old");
    assert!(std::fs::read_to_string(d.join("target.xml.bak.1")).unwrap().contains("<mujoco"));
}

trait CharDevice {
    fn is_char_device_like(&self) -> bool;
}
impl CharDevice for std::fs::FileType {
    fn is_char_device_like(&self) -> bool {
        std::os::unix::fs::FileTypeExt::is_char_device(self)
    }
}

#[test]
fn sim_and_view_refuse_folders_devices_and_inputs_as_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("SOMEDIR")).unwrap();
    let h = HUMANOID;
    for args in [
        vec!["sim", h, "--duration", "0.01", "--record", "SOMEDIR"],
        vec!["sim", h, "--duration", "0.01", "--rerun", "SOMEDIR"],
        vec!["sim", h, "--duration", "0.01", "--record", "/dev/null"],
        vec!["sim", h, "--duration", "0.01", "--record", h],
    ] {
        let err = refused(d, &args);
        assert!(err.contains("twin writes only regular files") || err.contains("is the input"), "{args:?}: {err}");
    }
    assert!(d.join("SOMEDIR").is_dir());
    assert!(!d.join("SOMEDIR.bak").exists());
    let log = repo_root().join("data/humanoid_joint_states.mcap");
    let (ok, _, err) = run_in(d, &["view", log.to_str().unwrap(), "-o", "SOMEDIR"], QUICK);
    assert!(!ok && err.contains("twin writes only regular files"), "{err}");
    let (ok, _, err) = run_in(d, &["view", log.to_str().unwrap(), "-o", log.to_str().unwrap()], QUICK);
    assert!(!ok && err.contains("is the input"), "{err}");
}

#[test]
fn sim_refuses_unknown_topics() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, _, err) =
        run_in(dir.path(), &["sim", HUMANOID, "--duration", "0.01", "--record", "r.mcap", "--topics", "/nope"], QUICK);
    assert!(!ok, "{err}");
    assert!(err.contains("/nope") && err.contains("/joint_states"), "{err}");
    assert!(!dir.path().join("r.mcap").exists(), "no file is created");
}

#[test]
fn a_urdf_with_a_dtd_is_refused_the_same_way_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = std::fs::read_to_string(HUMANOID).unwrap();
    let body = text.trim_start_matches(|c| c != '<').replacen("<?xml version=\"1.0\"?>", "", 1);
    write(d, "dtd.urdf", &format!("<?xml version=\"1.0\"?>\n<!DOCTYPE robot [ <!ENTITY m \"1.0\"> ]>\n{body}"));
    let cases = [
        vec!["info", "dtd.urdf"],
        vec!["check", "dtd.urdf"],
        vec!["convert", "dtd.urdf", "-o", "x.xml"],
        vec!["sim", "dtd.urdf", "--duration", "0.01"],
        vec!["randomize", "dtd.urdf", "--episodes", "1", "--duration", "0.01"],
    ];
    refused_naming(d, &cases, "DOCTYPE");
}

#[test]
fn bad_randomize_specs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let h = HUMANOID;
    for (spec, expect) in [
        ("[friction]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = -0.5\nhigh = 1.0\n", "cannot be negative"),
        ("[latency_steps]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = -2\nhigh = 1\n", "cannot be negative"),
        (
            "[push.interval_secs]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = 0\nhigh = 0\n\
             [push.speed_mps]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = 0.1\nhigh = 0.2\n",
            "push interval",
        ),
        ("[mass]\ndist = \"uniform\"\nlow = 0.9\nhigh = 1.1\nselect = []\n", "select = []"),
    ] {
        write(d, "spec.toml", spec);
        let (ok, _, err) = run_in(d, &["randomize", h, "--config", "spec.toml", "--episodes", "1"], QUICK);
        assert!(!ok, "{spec} accepted");
        assert!(err.contains(expect), "{spec}: {err}");
    }
    // Error messages quote at most 200 characters of the bad input.
    std::fs::write(d.join("nul.toml"), vec![0u8; 1 << 20]).unwrap();
    let (ok, _, err) = run_in(d, &["randomize", h, "--config", "nul.toml", "--episodes", "1"], QUICK);
    assert!(!ok);
    assert!(err.len() < 2000, "{} bytes of error", err.len());
}

#[test]
fn randomize_merge_never_overwrites_a_shard() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let h = HUMANOID;
    for k in ["1", "2"] {
        let shard = format!("{k}/2");
        let out = format!("s{k}");
        let (ok, _, err) = run_in(
            d,
            &["randomize", h, "--episodes", "2", "--duration", "0.05", "--shard", &shard, "--out", &out],
            QUICK,
        );
        assert!(ok, "{err}");
    }
    let before = std::fs::read(d.join("s1/episodes.csv")).unwrap();
    let (ok, _, err) = run_in(d, &["randomize", "merge", "s1", "s2", "--out", "s1"], QUICK);
    assert!(!ok && err.contains("is the input"), "{err}");
    assert_eq!(std::fs::read(d.join("s1/episodes.csv")).unwrap(), before);
    let (ok, _, err) = run_in(d, &["randomize", "merge", "s1", "s2", "--out", "merged"], QUICK);
    assert!(ok, "{err}");
}

/// A folder with `arm6.urdf` (the shipped arm perturbed: the "CAD" to correct) and `train.csv`,
/// a synthetic log of the true arm.
#[test]
fn two_outputs_naming_one_file_are_refused_before_any_work() {
    let dir = sysid_setup();
    let d = dir.path();
    let h = HUMANOID;
    // `./` spells the same file differently; a symlink reaches an existing one.
    std::fs::write(d.join("old.json"), "keep").unwrap();
    std::os::unix::fs::symlink("old.json", d.join("link.svg")).unwrap();
    for (args, names) in [
        (vec!["sim", h, "--duration", "0.01", "--record", "o.mcap", "--rerun", "./o.mcap"], ["--record", "--rerun"]),
        (
            vec!["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--report", "r", "--mjcf", "./r"],
            ["--report", "--mjcf"],
        ),
        (
            vec!["sysid", "friction", "--log", "train.csv", "--report", "old.json", "--plot", "link.svg"],
            ["--report", "--plot"],
        ),
        (vec!["gap", "arm6.urdf", "--log", "train.csv", "--report", "g", "--plot", "./g"], ["--report", "--plot"]),
        (vec!["calibrate", "noise", "--log", "train.csv", "--report", "n", "--spec", "./n"], ["--report", "--spec"]),
    ] {
        let err = refused(d, &args);
        assert!(err.contains(names[0]) && err.contains(names[1]) && err.contains("its own file"), "{args:?}: {err}");
    }
    assert_eq!(std::fs::read_to_string(d.join("old.json")).unwrap(), "keep");
    for f in ["o.mcap", "r", "g", "n"] {
        assert!(!d.join(f).exists(), "{f} was written");
    }
}

fn sysid_setup() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let truth = repo_root().join("models/arm6.urdf");
    sysid::synth::perturbed_urdf(&truth, &dir.path().join("arm6.urdf"), 6).unwrap();
    let log = sysid::synth::simulate(&truth, &sysid::synth::SynthOptions { duration_secs: 8.0, ..Default::default() })
        .unwrap();
    log.write_csv(dir.path().join("train.csv")).unwrap();
    dir
}

#[test]
fn sysid_outputs_are_transactional_backed_up_and_keep_links_and_mode() {
    let dir = sysid_setup();
    let d = dir.path();
    let urdf = d.join("arm6.urdf");
    let original = std::fs::read(&urdf).unwrap();
    // A failing second output: nothing is written, the URDF is byte-identical.
    let (ok, _, err) =
        run_in(d, &["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--mjcf", "/nonexistent/x.xml"], QUICK);
    assert!(!ok && err.contains("does not exist"), "{err}");
    assert_untouched(&urdf, &original);
    // Outputs that are folders, devices or the log are refused before any work.
    std::fs::create_dir(d.join("rep")).unwrap();
    for args in [
        vec!["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--report", "rep"],
        vec!["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--report", "/dev/null"],
        vec!["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--mjcf", "train.csv"],
        vec!["sysid", "--log", "train.csv", "--update", "arm6.urdf", "--report", "arm6.urdf"],
    ] {
        let (ok, _, err) = run_in(d, &args, QUICK);
        assert!(!ok, "{args:?}");
        assert!(err.contains("regular files") || err.contains("is the input"), "{args:?}: {err}");
    }
    assert_eq!(std::fs::read(&urdf).unwrap(), original);

    // Through a symlink to a hard-linked file with mode 0664: link, hard link and mode kept.
    std::fs::rename(&urdf, d.join("real.urdf")).unwrap();
    std::fs::hard_link(d.join("real.urdf"), d.join("other_name.urdf")).unwrap();
    std::os::unix::fs::symlink("real.urdf", &urdf).unwrap();
    std::fs::set_permissions(d.join("real.urdf"), std::fs::Permissions::from_mode(0o664)).unwrap();
    let (ok, _, err) = run_in(d, &["sysid", "--log", "train.csv", "--update", "arm6.urdf"], QUICK);
    assert!(ok, "{err}");
    let first = std::fs::read(d.join("real.urdf")).unwrap();
    assert_ne!(first, original);
    assert!(std::fs::symlink_metadata(&urdf).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(d.join("other_name.urdf")).unwrap(), first, "the hard link sees the update");
    assert_eq!(std::fs::metadata(d.join("real.urdf")).unwrap().mode() & 0o777, 0o664);
    assert_eq!(std::fs::read(d.join("real.urdf.bak")).unwrap(), original);
    // A second run keeps the original in .bak and the first result in .bak.1.
    let (ok, _, err) = run_in(d, &["sysid", "--log", "train.csv", "--update", "arm6.urdf"], QUICK);
    assert!(ok, "{err}");
    assert!(err.contains("real.urdf.bak.1"), "{err}");
    assert_eq!(std::fs::read(d.join("real.urdf.bak")).unwrap(), original);
    assert_eq!(std::fs::read(d.join("real.urdf.bak.1")).unwrap(), first);
    // No temp files are left behind.
    let leftovers: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn concurrent_sysid_runs_never_lose_a_result_silently() {
    let dir = sysid_setup();
    let d = dir.path();
    let original = std::fs::read(d.join("arm6.urdf")).unwrap();
    let spawn = || {
        twin()
            .current_dir(d)
            .args(["sysid", "--log", "train.csv", "--update", "arm6.urdf"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let outs = [output_of(a.wait_with_output().unwrap()), output_of(b.wait_with_output().unwrap())];
    let succeeded = outs.iter().filter(|o| o.0).count();
    for (ok, _, err) in &outs {
        assert!(*ok || err.contains("changed while twin worked"), "{err}");
    }
    assert!(succeeded >= 1);
    assert_eq!(std::fs::read(d.join("arm6.urdf.bak")).unwrap(), original, "the original is kept");
    if succeeded == 2 {
        // The second read the first one's result: that result is its backup.
        assert!(d.join("arm6.urdf.bak.1").exists());
    } else {
        assert!(!d.join("arm6.urdf.bak.1").exists());
    }
}

/// The README's `twin sysid` example runs on the shipped bag and recovers the real arm's joint
/// friction (the bag's robot is `models/arm6.urdf` perturbed with seed 11, see
/// `sysid/examples/make_id_bag.rs`).
#[test]
fn readme_sysid_example_recovers_the_real_arm() {
    let readme = std::fs::read_to_string(repo_root().join("README.md")).unwrap();
    let line = readme
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("cargo run --release -- sysid "))
        .expect("README has a sysid example");
    let args: Vec<&str> = line.trim_start_matches("cargo run --release -- ").split_whitespace().collect();
    assert!(args.contains(&"data/arm6_identification.mcap") && args.contains(&"--dry-run"), "{line}");
    let bag = std::fs::metadata(repo_root().join("data/arm6_identification.mcap")).unwrap().len();
    assert!(bag <= 2 << 20, "the shipped bag is {bag} bytes");
    let before = std::fs::read(repo_root().join("models/arm6.urdf")).unwrap();
    let (ok, out, err) = run_in(&repo_root(), &args, Duration::from_secs(300));
    assert!(ok, "{err}");
    assert_eq!(std::fs::read(repo_root().join("models/arm6.urdf")).unwrap(), before, "--dry-run writes nothing");
    // Torque error on the log after identification, per joint.
    let nrmse: Vec<f64> = out
        .lines()
        .skip_while(|l| !l.starts_with("torque NRMSE on the identification log"))
        .skip(2)
        .take(6)
        .map(|l| l.split_whitespace().last().unwrap().trim_end_matches('%').parse::<f64>().unwrap())
        .collect();
    assert_eq!(nrmse.len(), 6, "{out}");
    assert!(nrmse.iter().all(|&e| e < 2.0), "NRMSE after {nrmse:?} %");
    // Friction within 10 % of the real robot's.
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.urdf");
    sysid::synth::perturbed_urdf(&repo_root().join("models/arm6.urdf"), &real, 11).unwrap();
    let real = sysid::RobotModel::from_urdf(&real).unwrap();
    for joint in &real.joints {
        for (what, want) in [("viscous", joint.damping), ("coulomb", joint.friction)] {
            let key = format!("{}.{what}", joint.name);
            let row = out.lines().find(|l| l.split_whitespace().next() == Some(key.as_str())).expect(&key);
            let got: f64 = row.split_whitespace().nth(2).unwrap().parse().unwrap();
            assert!((got / want - 1.0).abs() < 0.10, "{key}: identified {got}, real {want}");
        }
    }
}

/// One sample whose header stamp jumps a year ahead (a flipped bit): `twin view` and a replay
/// refuse the log with the place of the jump instead of posing a year of frames.
#[test]
fn time_jumps_in_a_log_are_reported_not_rendered() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let arm = repo_root().join("models/arm6.urdf");
    let mut log =
        sysid::synth::simulate(&arm, &sysid::synth::SynthOptions { duration_secs: 0.5, ..Default::default() }).unwrap();
    let k = log.t_nanos.len() / 2;
    log.t_nanos[k] += 365 * 86_400 * 1_000_000_000;
    log.write_mcap(d.join("jump.mcap"), "/joint_states").unwrap();
    let a = arm.to_str().unwrap();
    for args in [
        vec!["view", "jump.mcap", "--model", a, "-o", "jump.rrd"],
        vec!["sim", a, "--controller", "replay", "--trajectory", "jump.mcap", "--duration", "0.1"],
    ] {
        let err = refused(d, &args);
        // Samples are ordered by time, so the year-late one comes last: the jump is named there.
        assert!(err.contains("clock is broken") && err.contains("31536000."), "{args:?}: {err}");
    }
    assert!(!d.join("jump.rrd").exists() || std::fs::metadata(d.join("jump.rrd")).unwrap().len() < 1 << 20);
}

/// Waits (bounded) until `ready` holds, then sends SIGINT to `child` and waits (bounded) for
/// it: (exit code, stdout, stderr).
fn interrupt_when(
    mut child: std::process::Child,
    what: &str,
    ready: impl Fn() -> bool,
) -> (Option<i32>, String, String) {
    let started = Instant::now();
    while !ready() {
        if started.elapsed() > Duration::from_secs(240) || child.try_wait().unwrap().is_some() {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!("{what}: not ready to interrupt in time or ended early:\n{}", String::from_utf8_lossy(&out.stderr));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let kill = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let stopping = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if stopping.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("{what}: did not stop within 60 s of Ctrl-C");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    let code = out.status.code();
    let (_, stdout, stderr) = output_of(out);
    (code, stdout, stderr)
}

fn file_len(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

/// Ctrl-C during `twin sim --record --rerun` and `twin view`: the run stops after the current
/// step (frame), the MCAP is complete (summary, footer: `log info --strict` accepts it) and holds
/// exactly the steps the printed summary counts, the `.rrd` files verify, the summary is printed
/// and the exit status is 130.
#[test]
fn ctrl_c_in_sim_and_view_closes_the_files_and_prints_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (mcap, rrd) = (d.join("run.mcap"), d.join("run.rrd"));
    let child = spawn_in(d, &["sim", "--duration", "3600", "--record", "run.mcap", "--rerun", "run.rrd"]);
    // A few seconds of simulated time are in the file (8 MB ≈ 17 s at 500 Hz).
    let (code, out, err) = interrupt_when(child, "twin sim", || file_len(&mcap) > 8 << 20);
    assert_eq!(code, Some(130), "{out}\n{err}");
    assert!(err.contains("interrupted: simulated"), "{err}");
    let stopped_secs: f64 = out
        .split("stopped by Ctrl-C at ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no summary line:\n{out}"));
    assert!(stopped_secs > 1.0 && stopped_secs < 3600.0, "{out}");
    let printed: u64 = out
        .lines()
        .find_map(|l| l.trim().strip_prefix("/joint_states").map(|n| n.trim().parse().unwrap()))
        .unwrap_or_else(|| panic!("no topic counts:\n{out}"));
    // One /joint_states per 2 ms step, stamped from 0 to the last step's start.
    assert_eq!(printed, (stopped_secs / 0.002).round() as u64, "{out}");
    let (ok, info, err) = run_in(d, &["log", "info", "--strict", "run.mcap"], QUICK);
    assert!(ok, "{err}");
    assert!(
        info.contains(&format!("messages: {}", out.split("run.mcap: ").nth(1).unwrap().split(' ').next().unwrap()))
    );
    let log = twin_core::log::Log::open(&mcap, twin_core::log::ReadOptions { strict: true }).unwrap();
    let (states, report) = log.read_typed::<twin_core::log::JointState>("/joint_states").unwrap();
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    assert_eq!(states.len() as u64, printed);
    let last_secs = states.last().unwrap().1.header.stamp_nanos as f64 * 1e-9;
    assert!((last_secs - (stopped_secs - 0.002)).abs() < 1e-6, "last stamp {last_secs} s, stopped at {stopped_secs} s");
    super::sim::rerun_verify(&rrd);

    // `twin view` of that log at 1000 frames/s runs for minutes: stop it once it writes.
    let view = d.join("view.rrd");
    let child = spawn_in(d, &["view", "run.mcap", "-o", "view.rrd", "--fps", "1000"]);
    let (code, out, err) = interrupt_when(child, "twin view", || file_len(&view) > 0);
    assert_eq!(code, Some(130), "{out}\n{err}");
    assert!(err.contains("interrupted:") && err.contains("frames recorded"), "{err}");
    assert!(out.contains("run.mcap: ") && out.contains("view.rrd: "), "{out}");
    super::sim::rerun_verify(&view);
}

/// `twin log info --strict` refuses a shipped log cut inside its summary, its footer or its end
/// magic (each cut keeps every message; the lenient reading says the file was not closed).
/// Every byte position of the tail is covered by twin-core's
/// `cuts_anywhere_in_the_summary_footer_or_magic_are_not_complete`.
#[test]
fn log_info_strict_refuses_files_cut_in_the_summary_footer_or_magic() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(repo_root().join("data/humanoid_joint_states.mcap")).unwrap();
    let n = bytes.len();
    // 1 000 bytes from the end: inside the summary; 20: inside the footer; 3: inside the magic.
    for cut in [n - 1000, n - 20, n - 3] {
        std::fs::write(dir.path().join("cut.mcap"), &bytes[..cut]).unwrap();
        let (ok, out, err) = run_in(dir.path(), &["log", "info", "--strict", "cut.mcap"], QUICK);
        assert!(!ok, "cut at {cut} of {n} accepted:\n{out}");
        assert!(err.contains("not closed cleanly") && err.contains("--strict"), "cut at {cut}: {err}");
        let (ok, out, err) = run_in(dir.path(), &["log", "info", "cut.mcap"], QUICK);
        assert!(ok, "{err}");
        assert!(format!("{out}{err}").contains("not closed cleanly"), "cut at {cut}: {out}{err}");
    }
}

/// A URDF chain of `n` revolute joints.
fn chain_urdf(n: usize) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n<robot name=\"chain\">\n");
    for i in 0..=n {
        out.push_str(&format!(
            "  <link name=\"l{i}\"><inertial><mass value=\"0.1\"/><inertia ixx=\"1e-4\" iyy=\"1e-4\" izz=\"1e-4\" \
             ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial><visual><geometry><box size=\"0.01 0.01 0.01\"/></geometry>\
             </visual></link>\n"
        ));
    }
    for i in 0..n {
        out.push_str(&format!(
            "  <joint name=\"j{i}\" type=\"revolute\"><parent link=\"l{i}\"/><child link=\"l{}\"/><origin \
             xyz=\"0 0 0.01\"/><axis xyz=\"0 1 0\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/>\
             </joint>\n",
            i + 1
        ));
    }
    out + "</robot>\n"
}

/// A valid 600-link chain is deeper than MuJoCo's XML parser nests (tinyxml2's element depth
/// limit): refused before MuJoCo sees it, naming the URDF, the deepest link and its line, the
/// depth and the limit, instead of "Element nesting is too deep" at a line of a generated file.
/// The deepest chain MuJoCo accepts (496 bodies) still loads, with every joint.
#[test]
fn a_600_link_chain_is_refused_with_the_depth_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "chain600.urdf", &chain_urdf(600));
    for args in [vec!["info", "chain600.urdf"], vec!["convert", "chain600.urdf", "-o", "chain600.xml"]] {
        let (ok, _, err) = run_in(d, &args, QUICK);
        assert!(!ok, "{args:?}");
        // The deepest link, l600, is on line 603 of the URDF.
        assert!(err.contains("chain600.urdf:603") && err.contains("l600"), "{err}");
        assert!(err.contains("601 bodies deep") && err.contains("at most 496 nested bodies"), "{err}");
        assert!(!err.contains("Line number="), "{err}");
    }
    assert!(!d.join("chain600.xml").exists());
    write(d, "chain495.urdf", &chain_urdf(495));
    let (ok, out, err) = run_in(d, &["info", "chain495.urdf"], QUICK);
    assert!(ok, "{err}");
    // A floating base (7 + 495 positions) and one actuator per joint.
    assert!(out.contains("nq 502") && out.contains("nu 495"), "{out}");
}

/// `twin randomize --record-worst` run twice (1 and 2 threads) writes the same worst episodes:
/// byte-identical CSV and MCAP, and `.rrd` recordings with the same data (`rerun rrd compare`;
/// their bytes differ only by rerun's own wall-clock row ids, as the README says).
#[test]
fn randomize_worst_recordings_are_the_same_run_to_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let model = repo_root().join("randomize/tests/fixtures/humanoid.xml");
    let model = model.to_str().unwrap();
    for (out, threads) in [("a", "1"), ("b", "2")] {
        let args = ["randomize", model, "--episodes", "4", "--duration", "0.3", "--seed", "5", "--record-worst", "2"];
        let (ok, _, err) = run_in(d, &[&args[..], &["--threads", threads, "--out", out]].concat(), QUICK);
        assert!(ok, "{err}");
    }
    let mut names: Vec<String> =
        std::fs::read_dir(d.join("a/worst")).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    for ext in ["csv", "mcap", "rrd"] {
        assert_eq!(names.iter().filter(|n| n.ends_with(ext)).count(), 2, "{names:?}");
    }
    let rerun = crate::test_python::python_tool("rerun", "rerun-sdk");
    for name in &names {
        let (a, b) = (d.join("a/worst").join(name), d.join("b/worst").join(name));
        if a.is_dir() {
            // `twin log analyze`'s plots of the episode: the same SVGs.
            for e in std::fs::read_dir(&a).unwrap() {
                let f = e.unwrap().file_name();
                assert!(
                    std::fs::read(a.join(&f)).unwrap() == std::fs::read(b.join(&f)).unwrap(),
                    "{name}/{f:?} differs"
                );
            }
            continue;
        }
        if name.contains(".analysis.") {
            // The analysis names the recording it read: the same up to the output folder.
            let a_text = std::fs::read_to_string(&a).unwrap().replace("a/worst/", "OUT/worst/");
            let b_text = std::fs::read_to_string(&b).unwrap().replace("b/worst/", "OUT/worst/");
            assert_eq!(a_text, b_text, "{name} differs");
            continue;
        }
        if !name.ends_with(".rrd") {
            assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "{name} differs");
            continue;
        }
        let out = std::process::Command::new(&rerun).args(["rrd", "compare"]).arg(&a).arg(&b).output().unwrap();
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
    }
}

/// `twin sysid` refuses what every other command refuses (one URDF loader): duplicate joint
/// names, two root links and a NaN inertial origin, with the same message as `twin info`, and
/// leaves the URDF untouched.
#[test]
fn sysid_refuses_urdfs_that_the_other_commands_refuse() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = std::fs::read_to_string(repo_root().join("models/arm6.urdf")).unwrap();
    let inertial = text.find("<inertial>").unwrap();
    let origin = inertial + text[inertial..].find("<origin").unwrap();
    let end = origin + text[origin..].find("/>").unwrap();
    let cases = [
        (
            "dup.urdf",
            text.replacen("<joint name=\"shoulder_lift_joint\"", "<joint name=\"shoulder_pan_joint\"", 1),
            "duplicate joint name",
        ),
        (
            "roots.urdf",
            text.replacen("<link name=\"base_link\">", "<link name=\"extra_root\"/>\n  <link name=\"base_link\">", 1),
            "2 root links",
        ),
        ("nan.urdf", format!("{}<origin xyz=\"nan 0 0\" rpy=\"0 0 0\"{}", &text[..origin], &text[end..]), "finite"),
    ];
    let bag = repo_root().join("data/arm6_identification.mcap");
    for (name, urdf, expect) in cases {
        write(d, name, &urdf);
        let (ok, _, info_err) = run_in(d, &["info", name], QUICK);
        assert!(!ok && info_err.contains(expect), "{name}: {info_err}");
        let (ok, _, err) = run_in(d, &["sysid", "--log", bag.to_str().unwrap(), "--update", name], QUICK);
        assert!(!ok, "sysid accepted {name}");
        let line = |e: &str| e.lines().find(|l| l.contains(expect)).map(|l| l[l.find(name).unwrap()..].to_string());
        assert_eq!(line(&err), line(&info_err), "{name}: the same message");
        assert_eq!(std::fs::read_to_string(d.join(name)).unwrap(), urdf);
        assert!(!d.join(format!("{name}.bak")).exists());
    }
}

/// A replay trajectory whose time jumps 15 s backwards is refused, naming the place of the
/// jump, instead of being replayed silently: in a CSV (the line) and in a bag (the sample).
#[test]
fn a_replay_trajectory_jumping_backwards_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut csv = String::from("time_sec,left_knee_joint\n");
    for k in 0..50 {
        csv.push_str(&format!("{},{}\n", 20.0 + k as f64 * 0.01, 0.2));
    }
    csv.push_str("5.5,0.2\n5.51,0.2\n");
    write(d, "traj.csv", &csv);
    let args = ["sim", HUMANOID, "--controller", "replay", "--trajectory", "traj.csv", "--duration", "0.1"];
    let (ok, out, err) = run_in(d, &args, QUICK);
    assert!(!ok, "replayed: {out}");
    assert!(err.contains("traj.csv:52") && err.contains("does not increase"), "{err}");

    let arm = repo_root().join("models/arm6.urdf");
    let mut log =
        sysid::synth::simulate(&arm, &sysid::synth::SynthOptions { duration_secs: 0.5, ..Default::default() }).unwrap();
    let k = log.t_nanos.len() / 2;
    log.t_nanos[k] -= 15_000_000_000;
    log.write_mcap(d.join("back.mcap"), "/joint_states").unwrap();
    let a = arm.to_str().unwrap();
    let args = ["sim", a, "--controller", "replay", "--trajectory", "back.mcap", "--duration", "0.1"];
    let (ok, out, err) = run_in(d, &args, QUICK);
    assert!(!ok, "replayed: {out}");
    // Samples are ordered by stamp, so the one 15 s early comes first: the jump is named there.
    assert!(err.contains("back.mcap") && err.contains("clock is broken") && err.contains("14.75"), "{err}");
}

/// `.rrd` outputs keep what they replace like every other output: numbered backups, the oldest
/// never overwritten (they were renamed to `NAME.bak`, losing an older `.bak`).
#[test]
fn rerun_outputs_keep_numbered_backups() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut versions = Vec::new();
    for _ in 0..3 {
        let (ok, _, err) = run_in(d, &["sim", "--duration", "0.01", "--rerun", "r.rrd"], QUICK);
        assert!(ok, "{err}");
        versions.push(std::fs::read(d.join("r.rrd")).unwrap());
    }
    assert_eq!(std::fs::read(d.join("r.rrd.bak")).unwrap(), versions[0], "the first recording");
    assert_eq!(std::fs::read(d.join("r.rrd.bak.1")).unwrap(), versions[1]);
    assert!(!d.join("r.rrd.bak.2").exists());
}
