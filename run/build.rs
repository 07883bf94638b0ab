//! vge-run never needs libtorch, but a workspace build that turns on vge-export's `tch`
//! feature for another crate links it into this crate's tests too: vge-export then says where
//! it lives (`DEP_VGE_EXPORT_LIBTORCH_LIB`, see export/build.rs), and an rpath lets those
//! tests run without `LD_LIBRARY_PATH`. Built alone, the crate links no libtorch and this
//! does nothing.
fn main() {
    println!("cargo:rerun-if-env-changed=DEP_VGE_EXPORT_LIBTORCH_LIB");
    if let Ok(dir) = std::env::var("DEP_VGE_EXPORT_LIBTORCH_LIB") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
