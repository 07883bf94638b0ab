//! With the `tch` feature: embeds an rpath to libtorch so that tests and binaries run without
//! `LD_LIBRARY_PATH`, and passes its place on to the crates that depend on vge-export.
//!
//! torch-sys (`links = "tch"`) prints `cargo:libtorch_lib=<dir>`, which cargo hands to
//! crates depending on it directly as `DEP_TCH_LIBTORCH_LIB`. vge-export (`links =
//! "vge_export"`) prints it again for its own dependents (`DEP_VGE_EXPORT_LIBTORCH_LIB`):
//! vge-lab does not depend on tch, but its tests link libtorch through vge-export wherever a
//! workspace build turns the feature on for another crate.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    if std::env::var_os("CARGO_FEATURE_TCH").is_none() {
        return;
    }
    match std::env::var("DEP_TCH_LIBTORCH_LIB") {
        Ok(dir) if !dir.is_empty() => {
            println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
            println!("cargo:libtorch_lib={dir}");
        }
        _ => println!(
            "cargo:warning=DEP_TCH_LIBTORCH_LIB not set by torch-sys; set LD_LIBRARY_PATH to run tests"
        ),
    }
}
