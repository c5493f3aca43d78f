//! The example-robot-data 6.0.0 wheel (PyPI) as test input: downloaded once into
//! `TWIN_URDF_CACHE` (default: the target's tmp dir) with the pip of the tests' Python
//! (`test_python.rs`); without network the calling test fails. One file, included by the test binaries of twin-core, sysid and
//! the CLI (`#[path]`), so that whichever runs first fetches it: `cargo test --workspace` runs
//! sysid's tests before the others.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The extracted robots folder (`…/share/example-robot-data/robots`).
pub fn example_robot_data() -> PathBuf {
    fetch("fetch_example_robot_data.py", "example-robot-data 6.0.0")
        .join("cmeel.prefix/share/example-robot-data/robots")
}

/// The icub-models 3.2.0 wheel (PyPI), fetched as [`example_robot_data`] is: the `share` folder
/// holding the package `iCub` (`iCub/robots/NAME/model.urdf`, meshes as `package://iCub/…`).
#[allow(dead_code)]
pub fn icub_models() -> PathBuf {
    fetch("fetch_icub_models.py", "icub-models 3.2.0").join("icub-models/share")
}

/// Runs the fetch script `script` of `twin-core/tests/python` on the cache; returns the cache.
fn fetch(script: &str, what: &str) -> PathBuf {
    let cache = std::env::var_os("TWIN_URDF_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("urdf-cache"));
    let python = crate::test_python::python();
    let script = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|d| d.join("twin-core/tests/python").join(script))
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("twin-core/tests/python/{script} in the workspace"));
    let status = Command::new(&python).arg(&script).arg(&cache).status();
    assert!(
        status.as_ref().is_ok_and(|s| s.success()),
        "could not fetch {what} with {} {} ({status:?}): it needs network access to PyPI",
        python.display(),
        script.display()
    );
    cache
}
