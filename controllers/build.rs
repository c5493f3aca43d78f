//! Gives this crate's tests and benches an rpath to MuJoCo's library folder (published by
//! `twin-mj`), so they run without LD_LIBRARY_PATH.
fn main() {
    if let Ok(dir) = std::env::var("DEP_TWIN_SHIM_LIB_DIR") {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
