//! Finds MuJoCo's shared library and headers, links the library dynamically and embeds nothing
//! else: dependents that build executables add the rpath from `DEP_MUJOCO_LIB_DIR`.
//!
//! Order of preference:
//! 1. `MUJOCO_DIR`: a MuJoCo tree with `lib/libmujoco.so*` and `include/mujoco/mujoco.h` (an
//!    official release tarball or your own build). Its header version must equal the pinned one,
//!    because the committed bindings describe that version's struct layouts.
//! 2. The pinned `mujoco-core` wheel from PyPI, fetched once with `python3 -m pip download`,
//!    checked against its sha256 and unpacked into a cache outside the source tree
//!    (`TWIN_MUJOCO_CACHE`, else `$XDG_CACHE_HOME/twin`, else `~/.cache/twin`).

use sha2::{Digest, Sha256};
use std::env;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

const VERSION: &str = "4.0.1";
const VERSION_HEADER: u32 = 4000001;
const LIB_NAME: &str = "libmujoco.so.4.0.1";

struct Wheel {
    platform: &'static str,
    file: &'static str,
    sha256: &'static str,
}

const WHEELS: &[(&str, Wheel)] = &[(
    "x86_64",
    Wheel {
        platform: "manylinux_2_28_x86_64",
        file: "mujoco_core-4.0.1-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl",
        sha256: "be28c0c7587347ef996b4de0487264e9da296282082b092bae211a9163e9aed6",
    },
)];

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    for var in ["MUJOCO_DIR", "TWIN_MUJOCO_CACHE", "XDG_CACHE_HOME", "HOME", "PYTHON"] {
        println!("cargo::rerun-if-env-changed={var}");
    }
    let (lib_dir, include_dir, lib_file) = match env::var_os("MUJOCO_DIR") {
        Some(dir) if !dir.is_empty() => from_mujoco_dir(Path::new(&dir)),
        _ => from_wheel(),
    };
    println!("cargo::rustc-link-search=native={}", lib_dir.display());
    println!("cargo::rustc-link-lib=dylib:+verbatim={lib_file}");
    println!("cargo::metadata=lib_dir={}", lib_dir.display());
    println!("cargo::metadata=include={}", include_dir.display());
    println!("cargo::metadata=version={VERSION}");
}

fn fail(msg: impl AsRef<str>) -> ! {
    // A build script's panic message is what the user sees; keep it actionable.
    panic!("\n\nmujoco-sys: {}\n\n", msg.as_ref());
}

fn from_mujoco_dir(dir: &Path) -> (PathBuf, PathBuf, String) {
    let lib_dir = dir.join("lib");
    let include_dir = dir.join("include");
    let header = include_dir.join("mujoco").join("mujoco.h");
    let text = fs::read_to_string(&header).unwrap_or_else(|e| {
        fail(format!(
            "MUJOCO_DIR={} has no readable {} ({e}). Point MUJOCO_DIR at a MuJoCo {VERSION} tree \
             with lib/ and include/mujoco/, or unset it to fetch MuJoCo automatically with pip.",
            dir.display(),
            header.display()
        ))
    });
    let found = header_version(&text);
    if found != Some(VERSION_HEADER) {
        fail(format!(
            "MUJOCO_DIR={} holds MuJoCo with mjVERSION_HEADER {:?}, but twin's bindings are for \
             {VERSION} ({VERSION_HEADER}). Install MuJoCo {VERSION} there, or unset MUJOCO_DIR to \
             fetch it automatically with pip.",
            dir.display(),
            found
        ));
    }
    // Prefer the unversioned name of release tarballs; fall back to any versioned file.
    let mut candidates: Vec<String> = fs::read_dir(&lib_dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n == "libmujoco.so" || n.starts_with("libmujoco.so."))
                .collect()
        })
        .unwrap_or_default();
    candidates.sort_by_key(|n| (n != "libmujoco.so", n.clone()));
    let Some(lib_file) = candidates.into_iter().next() else {
        fail(format!(
            "MUJOCO_DIR={}: no libmujoco.so* in {}. Point MUJOCO_DIR at a tree with lib/ and \
             include/mujoco/, or unset it to fetch MuJoCo automatically with pip.",
            dir.display(),
            lib_dir.display()
        ))
    };
    (lib_dir, include_dir, lib_file)
}

fn header_version(text: &str) -> Option<u32> {
    text.lines().find_map(|l| l.trim().strip_prefix("#define mjVERSION_HEADER")).and_then(|v| v.trim().parse().ok())
}

fn cache_root() -> PathBuf {
    if let Some(dir) = env::var_os("TWIN_MUJOCO_CACHE").filter(|d| !d.is_empty()) {
        return PathBuf::from(dir);
    }
    if let Some(dir) = env::var_os("XDG_CACHE_HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(dir).join("twin");
    }
    if let Some(home) = env::var_os("HOME").filter(|d| !d.is_empty()) {
        return PathBuf::from(home).join(".cache").join("twin");
    }
    fail("cannot choose a cache folder for MuJoCo: set TWIN_MUJOCO_CACHE (or HOME), or set MUJOCO_DIR")
}

fn from_wheel() -> (PathBuf, PathBuf, String) {
    let os = env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    let arch = env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let wheel = WHEELS.iter().find(|(a, _)| *a == arch).map(|(_, w)| w);
    let Some(wheel) = wheel.filter(|_| os == "linux") else {
        fail(format!(
            "no pinned MuJoCo wheel for {os}/{arch}. Download MuJoCo {VERSION} \
             (lib/ + include/mujoco/) and set MUJOCO_DIR to its folder."
        ))
    };
    let dest = cache_root().join(format!("mujoco-{VERSION}-{arch}"));
    let lib_dir = dest.join("lib");
    let include_dir = dest.join("include");
    let stamp = dest.join(".sha256");
    if fs::read_to_string(&stamp).is_ok_and(|s| s.trim() == wheel.sha256)
        && lib_dir.join(LIB_NAME).is_file()
        && include_dir.join("mujoco").join("mujoco.h").is_file()
    {
        return (lib_dir, include_dir, LIB_NAME.to_string());
    }

    let parent = dest.parent().expect("cache path has a parent");
    fs::create_dir_all(parent).unwrap_or_else(|e| {
        fail(format!(
            "cannot create the MuJoCo cache {} ({e}); set TWIN_MUJOCO_CACHE to a writable folder",
            parent.display()
        ))
    });
    // Unique scratch folder next to the destination so the final rename is atomic and two
    // concurrent builds cannot see a half-unpacked tree.
    let scratch = parent.join(format!(".mujoco-{VERSION}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&scratch);
    fs::create_dir_all(&scratch).unwrap_or_else(|e| fail(format!("cannot create {} ({e})", scratch.display())));

    let python = env::var("PYTHON").unwrap_or_else(|_| "python3".to_string());
    let status = Command::new(&python)
        .args(["-m", "pip", "download", &format!("mujoco-core=={VERSION}"), "--no-deps", "--only-binary=:all:"])
        .args(["--platform", wheel.platform, "--python-version", "3.11", "--disable-pip-version-check", "-q"])
        .arg("-d")
        .arg(&scratch)
        .status();
    match status {
        Ok(s) if s.success() => {}
        Ok(s) => fail(format!(
            "`{python} -m pip download mujoco-core=={VERSION}` failed ({s}). Check that pip can reach \
             PyPI, or download MuJoCo {VERSION} yourself and set MUJOCO_DIR to it."
        )),
        Err(e) => fail(format!(
            "cannot run `{python}` ({e}): Python 3 with pip is needed to fetch MuJoCo {VERSION} \
             (install python3-pip, or set PYTHON), or set MUJOCO_DIR to a MuJoCo {VERSION} tree."
        )),
    }
    let wheel_path = scratch.join(wheel.file);
    let bytes =
        fs::read(&wheel_path).unwrap_or_else(|e| fail(format!("pip did not leave {} ({e})", wheel_path.display())));
    let digest: String = Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect();
    if digest != wheel.sha256 {
        fail(format!(
            "{} has sha256 {digest}, expected {}: refusing to link an unverified library. \
             Remove {} and retry, or set MUJOCO_DIR.",
            wheel.file,
            wheel.sha256,
            scratch.display()
        ));
    }
    // The wheel is a zip; Python (already required for pip) unpacks just the library and headers.
    let unpack = r#"
import sys, zipfile, os
whl, out, lib = sys.argv[1], sys.argv[2], sys.argv[3]
with zipfile.ZipFile(whl) as z:
    for n in z.namelist():
        if n == 'mujoco/' + lib:
            dst = os.path.join(out, 'lib', lib)
        elif n.startswith('mujoco/include/mujoco/') and not n.endswith('/'):
            dst = os.path.join(out, 'include', n[len('mujoco/include/'):])
        else:
            continue
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        with z.open(n) as src, open(dst, 'wb') as f:
            f.write(src.read())
"#;
    let tree = scratch.join("tree");
    let ok = Command::new(&python)
        .args(["-c", unpack])
        .arg(&wheel_path)
        .arg(&tree)
        .arg(LIB_NAME)
        .status()
        .is_ok_and(|s| s.success());
    if !ok || !tree.join("lib").join(LIB_NAME).is_file() {
        fail(format!("unpacking {} failed; remove {} and retry, or set MUJOCO_DIR", wheel.file, scratch.display()));
    }
    fs::write(tree.join(".sha256"), wheel.sha256).unwrap_or_else(|e| fail(format!("cannot write stamp ({e})")));
    let _ = fs::remove_dir_all(&dest);
    if fs::rename(&tree, &dest).is_err() && !dest.join("lib").join(LIB_NAME).is_file() {
        fail(format!("cannot move MuJoCo into {}", dest.display()));
    }
    let _ = fs::remove_dir_all(&scratch);
    (lib_dir, include_dir, LIB_NAME.to_string())
}
