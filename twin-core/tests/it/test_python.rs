//! The Python interpreter the cross-check tests run (independent readers and peers: `mcap`,
//! `mcap-ros2-support`, `rosbags`, `rerun-sdk`, Cyclone DDS, rclpy, PyYAML, pip for the URDF
//! corpus). The tests provision it themselves on first use, so `cargo test --release --workspace`
//! passes on a machine with only Python 3 and pip:
//!
//! 1. `TWIN_PYTHON`, when set, is used as it is (a venv the user made from `.ci/requirements.txt`).
//! 2. Otherwise the venv `target/test-venv` is created with `python3 -m venv` and filled with
//!    `pip install -r .ci/requirements.txt` (network access to PyPI the first time), then reused
//!    while `.ci/requirements.txt` stays byte for byte what it was built from (the copy in
//!    `target/test-venv/.twin-requirements.txt`, written last: a half-built venv is rebuilt).
//! 3. Test threads share one answer (a `OnceLock`); test processes share the venv through the file
//!    lock `target/test-venv.lock`: one builds it, the others wait for it, at most
//!    [`PROVISION_LIMIT`], saying what they wait for.
//!
//! When the venv cannot be made the calling test fails with what went wrong and what to do; it
//! never skips. One file, included with `#[path]` by the test binaries of twin-core, sysid and the
//! CLI.
#![allow(dead_code)]

use std::fs::{self, File};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The longest a test waits for the venv: creating it (pip downloads a few hundred MB once) or
/// waiting for another test process that creates it.
pub const PROVISION_LIMIT: Duration = Duration::from_secs(30 * 60);

/// The Python to run cross-check scripts with; panics (fails the test) when it cannot be made.
pub fn python() -> PathBuf {
    static PYTHON: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    match PYTHON.get_or_init(provision) {
        Ok(path) => path.clone(),
        Err(why) => panic!("the tests' Python cannot be provided: {why}"),
    }
}

/// Runs `script` with `args` on [`python`] and parses what it prints as JSON; a run that fails
/// fails the test with the script's stderr.
pub fn script_json(script: &str, args: &[&std::ffi::OsStr]) -> serde_json::Value {
    let exe = python();
    let out = Command::new(&exe).arg(script).args(args).output();
    let out = out.unwrap_or_else(|e| panic!("cannot run {}: {e}", exe.display()));
    assert!(
        out.status.success(),
        "{} {script} {args:?} failed:\n{}",
        exe.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("script prints JSON")
}

/// An executable installed next to [`python()`] by a requirement (`rerun` of rerun-sdk); panics
/// naming the requirement when it is not there.
pub fn python_tool(name: &str, requirement: &str) -> PathBuf {
    let python = python();
    let tool = python.parent().map(|d| d.join(name)).filter(|p| p.is_file());
    tool.unwrap_or_else(|| {
        panic!("no `{name}` next to {} ({requirement} from .ci/requirements.txt should install it)", python.display())
    })
}

/// `.ci/requirements.txt` of the workspace.
pub fn requirements_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|d| d.join(".ci/requirements.txt"))
        .find(|p| p.is_file())
        .expect(".ci/requirements.txt in the workspace")
}

/// Where the venv lives: `target/test-venv` (the parent of cargo's test tmp dir).
pub fn venv_dir() -> PathBuf {
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    tmp.parent().unwrap_or(tmp).join("test-venv")
}

fn provision() -> Result<PathBuf, String> {
    if let Some(python) = std::env::var_os("TWIN_PYTHON").filter(|p| !p.is_empty()) {
        return Ok(PathBuf::from(python));
    }
    let requirements_path = requirements_file();
    let requirements = fs::read_to_string(&requirements_path)
        .map_err(|e| format!("cannot read {}: {e}", requirements_path.display()))?;
    let venv = venv_dir();
    let python = venv.join("bin/python");
    let stamp = venv.join(".twin-requirements.txt");
    let current = || python.is_file() && fs::read_to_string(&stamp).is_ok_and(|s| s == requirements);
    if current() {
        return Ok(python);
    }

    let lock_path = venv.with_extension("lock");
    if let Some(dir) = lock_path.parent() {
        fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    let lock = File::create(&lock_path).map_err(|e| format!("cannot create {}: {e}", lock_path.display()))?;
    let started = Instant::now();
    let mut said = false;
    loop {
        match lock.try_lock() {
            Ok(()) => break,
            Err(fs::TryLockError::WouldBlock) => {
                if !said {
                    eprintln!(
                        "note: waiting (at most {} min) for {}: another test process is creating the test venv {}",
                        PROVISION_LIMIT.as_secs() / 60,
                        lock_path.display(),
                        venv.display()
                    );
                    said = true;
                }
                if started.elapsed() > PROVISION_LIMIT {
                    return Err(format!(
                        "waited {} s for the lock {} (another process creating {}); remove it if no test runs",
                        started.elapsed().as_secs(),
                        lock_path.display(),
                        venv.display()
                    ));
                }
                std::thread::sleep(Duration::from_millis(250));
            }
            Err(fs::TryLockError::Error(e)) => return Err(format!("cannot lock {}: {e}", lock_path.display())),
        }
    }
    // Another process may have built it while this one waited.
    if current() {
        return Ok(python);
    }

    eprintln!(
        "note: creating the tests' Python venv {} from {} (first run only; needs python3 with the venv \
         module and network access to PyPI)",
        venv.display(),
        requirements_path.display()
    );
    if venv.exists() {
        fs::remove_dir_all(&venv).map_err(|e| format!("cannot remove the stale venv {}: {e}", venv.display()))?;
    }
    let deadline = started + PROVISION_LIMIT;
    run(
        Command::new("python3").args(["-m", "venv"]).arg(&venv),
        deadline,
        "python3 -m venv (Python 3 with its venv module is needed; on Debian/Ubuntu: apt install python3-venv)",
    )?;
    run(
        Command::new(&python)
            .args(["-m", "pip", "install", "--disable-pip-version-check", "--no-input", "-q", "--timeout", "60", "-r"])
            .arg(&requirements_path),
        deadline,
        "pip install -r .ci/requirements.txt (needs network access to PyPI)",
    )?;
    fs::write(&stamp, &requirements).map_err(|e| format!("cannot write {}: {e}", stamp.display()))?;
    eprintln!("note: the tests' Python venv {} is ready ({} s)", venv.display(), started.elapsed().as_secs());
    Ok(python)
    // `lock` is released when dropped.
}

/// Runs `cmd` until it exits or `deadline` passes (then kills it); the error names `what`, the
/// exit status and the end of its stderr.
fn run(cmd: &mut Command, deadline: Instant, what: &str) -> Result<(), String> {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    let mut stderr = child.stderr.take().expect("piped stderr");
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if Instant::now() > deadline => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("{what}: still running after {} min; killed", PROVISION_LIMIT.as_secs() / 60));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(200)),
            Err(e) => return Err(format!("{what}: {e}")),
        }
    };
    let text = reader.join().unwrap_or_default();
    if status.success() {
        return Ok(());
    }
    let tail: Vec<&str> = text.lines().rev().take(20).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    Err(format!("{what} failed ({status}):\n{}", tail.join("\n")))
}
