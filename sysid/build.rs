//! Gives the `twin` binary, its tests and benches an rpath to MuJoCo's library folder, so
//! `target/release/twin` runs without LD_LIBRARY_PATH.
fn main() {
    if let Ok(dir) = std::env::var("DEP_TWIN_SHIM_LIB_DIR") {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
