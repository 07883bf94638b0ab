//! The bridge never links libtorch, but its tests write policy files with vge-export, and a
//! workspace build turns vge-export's `tch` feature on for another crate: those test binaries
//! then link libtorch. An rpath to where scripts/setup-libtorch.sh puts it lets them run
//! without LD_LIBRARY_PATH (dev-dependencies pass no `DEP_*` to a build script, so the place
//! is the workspace's `.deps/libtorch/lib`, as `.cargo/config.toml` names it). Tests only.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if let Ok(manifest) = std::env::var("CARGO_MANIFEST_DIR") {
        let dir = std::path::Path::new(&manifest).join("../.deps/libtorch/lib");
        println!("cargo:rustc-link-arg-tests=-Wl,-rpath,{}", dir.display());
    }
}
