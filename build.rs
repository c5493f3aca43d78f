//! Makes the `twin` binary relocatable: MuJoCo's library is copied beside the binary
//! (`target/<profile>/libmujoco.so.*`) and the binary looks for it first in its own folder
//! (`$ORIGIN` rpath), then in the folder it was built against. So `target/release/twin` runs
//! without `LD_LIBRARY_PATH`, and `twin` plus `libmujoco.so.<version>` copied together into any
//! folder run for any user.
use std::path::{Path, PathBuf};

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rustc-link-arg-bins=-Wl,-rpath,$ORIGIN");
    let Ok(dir) = std::env::var("DEP_TWIN_SHIM_LIB_DIR") else { return };
    println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    // OUT_DIR is target/<profile>/build/twin-<hash>/out: the binaries go three levels up.
    let Some(profile_dir) =
        std::env::var_os("OUT_DIR").map(PathBuf::from).and_then(|o| o.ancestors().nth(3).map(Path::to_path_buf))
    else {
        return;
    };
    let Ok(entries) = std::fs::read_dir(&dir) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        if name.to_string_lossy().starts_with("libmujoco.so") {
            let dst = profile_dir.join(&name);
            // Copy through a temp name: a concurrent build never sees half a library.
            let tmp = profile_dir.join(format!(".{}.tmp{}", name.to_string_lossy(), std::process::id()));
            if std::fs::copy(entry.path(), &tmp).is_ok() && std::fs::rename(&tmp, &dst).is_err() {
                let _ = std::fs::remove_file(&tmp);
            }
        }
    }
}
