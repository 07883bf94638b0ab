//! Embeds an rpath to libtorch so that this crate's tests run without `LD_LIBRARY_PATH`.
//! torch-sys (`links = "tch"`) prints `cargo:libtorch_lib=<dir>`, which cargo hands to crates
//! depending on it directly as `DEP_TCH_LIBTORCH_LIB`.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    match std::env::var("DEP_TCH_LIBTORCH_LIB") {
        Ok(dir) if !dir.is_empty() => println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}"),
        _ => println!(
            "cargo:warning=DEP_TCH_LIBTORCH_LIB not set by torch-sys; set LD_LIBRARY_PATH to run tests"
        ),
    }
}
