//! torch-sys (links = "tch") tells crates that depend on it directly where the libtorch it
//! linked lives; an rpath lets `vge`, tests and examples run without LD_LIBRARY_PATH.
//! `vge` exports its answer to MKL's vendor check (src/mkl.rs) so that libtorch's MKL
//! calls it instead of its own.
fn main() {
    println!("cargo:rustc-link-arg-bin=vge=-Wl,--export-dynamic-symbol=mkl_serv_intel_cpu_true");
    println!("cargo:rerun-if-env-changed=DEP_TCH_LIBTORCH_LIB");
    if let Ok(dir) = std::env::var("DEP_TCH_LIBTORCH_LIB") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
