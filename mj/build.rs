//! Compiles the C shim that catches `mju_user_error` (see `csrc/shim.c`) against the headers
//! `mujoco-sys` found, and republishes MuJoCo's library folder for dependents' rpaths.
use std::env;

fn main() {
    println!("cargo::rerun-if-changed=csrc/shim.c");
    let include = env::var("DEP_MUJOCO_INCLUDE").expect("mujoco-sys publishes its include folder");
    let lib_dir = env::var("DEP_MUJOCO_LIB_DIR").expect("mujoco-sys publishes its library folder");
    cc::Build::new().file("csrc/shim.c").include(&include).opt_level(2).warnings(true).compile("twin_shim");
    // Executables built from this crate (its tests) find libmujoco without LD_LIBRARY_PATH.
    println!("cargo::rustc-link-arg=-Wl,-rpath,{lib_dir}");
    println!("cargo::metadata=lib_dir={lib_dir}");
    println!("cargo::metadata=include={include}");
}
