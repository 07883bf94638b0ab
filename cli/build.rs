//! With the `train` feature: torch-sys (links = "tch") tells crates that depend on it directly
//! where the libtorch it linked lives, and an rpath lets `vge` and its tests run without
//! LD_LIBRARY_PATH; `vge` exports its answer to MKL's vendor check (vge_trainer::mkl) so that
//! libtorch's MKL calls it instead of its own.
fn main() {
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    if std::env::var_os("CARGO_FEATURE_TRAIN").is_some() {
        println!("cargo:rustc-link-arg-bin=vge=-Wl,--export-dynamic-symbol=mkl_serv_intel_cpu_true");
    }
    if let Ok(dir) = std::env::var("DEP_TCH_LIBTORCH_LIB") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
