//! Helpers shared by the end-to-end tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository root (where `models/` is).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A `twin` command run from the repository root with a clean environment for MuJoCo.
pub fn twin() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_twin"));
    cmd.current_dir(repo_root()).env_remove("LD_LIBRARY_PATH");
    cmd
}

/// Runs `twin` with `args`, returning (status ok, stdout, stderr).
pub fn run(args: &[&str]) -> (bool, String, String) {
    output_of(twin().args(args).output().expect("twin runs"))
}

pub fn output_of(out: Output) -> (bool, String, String) {
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    // Whatever the outcome, the binary never panics on user input.
    assert!(!stderr.contains("panicked"), "twin panicked:\n{stderr}");
    (out.status.success(), stdout, stderr)
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// `file` is byte for byte `original` and no backup (`FILE.bak`) was made: a refused or dry run
/// left the user's file alone.
pub fn assert_untouched(file: &Path, original: &[u8]) {
    assert!(std::fs::read(file).unwrap() == original, "{} changed", file.display());
    let mut backup = file.as_os_str().to_owned();
    backup.push(".bak");
    assert!(!Path::new(&backup).exists(), "{} was written", Path::new(&backup).display());
}
