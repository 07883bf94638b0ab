//! Puts `memory.x` on the linker path, the policy file in `OUT_DIR/policy.vgep` and its
//! sizes in `OUT_DIR/policy_sizes.rs`.
//!
//! The policy file comes from `VGE_POLICY` (a `.vgep` written by vge-export; the host test
//! `export/tch/tests/cortex_m.rs` and `vge bench firmware` write them from a tch actor). Without
//! it, the shipped cube policy (`policies/cube.vgep`, format version 2, f32) is embedded, so
//! that a plain `cargo build` / `cargo run` works with a real actor of a real hand's shape.
//!
//! The weight storage the firmware hands to `Policy::load` is sized from the file with
//! `vge_runtime::policy::inspect`: `storage_len` f32, which is 0 for a version-2 file (its
//! arrays are read in place from flash). A file that does not validate
//! is still embedded, with zero storage and the default capacities, so that the firmware
//! itself reports the typed error and exits non-zero (the host test checks this); cargo
//! prints a warning.

use std::{env, fs, path::PathBuf};

/// The policy embedded when `VGE_POLICY` is unset, relative to this crate.
const SHIPPED_POLICY: &str = "../../policies/cube.vgep";

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    let memory = match env::var("VGE_MEMORY_MAP").as_deref() {
        Ok("stm32f405") => "memory-stm32f405.x",
        Ok("") | Ok("qemu") | Err(_) => "memory.x",
        Ok(other) => panic!("VGE_MEMORY_MAP={other}: expected `qemu` (default) or `stm32f405`"),
    };
    fs::copy(memory, out.join("memory.x")).expect("copy the memory map");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=memory-stm32f405.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=VGE_POLICY");
    println!("cargo:rerun-if-env-changed=VGE_MEMORY_MAP");

    let bytes = match env::var_os("VGE_POLICY") {
        Some(path) if !path.is_empty() => {
            let path = PathBuf::from(path);
            println!("cargo:rerun-if-changed={}", path.display());
            fs::read(&path).unwrap_or_else(|e| panic!("VGE_POLICY={}: {e}", path.display()))
        }
        _ => {
            println!("cargo:rerun-if-changed={SHIPPED_POLICY}");
            fs::read(SHIPPED_POLICY).unwrap_or_else(|e| panic!("{SHIPPED_POLICY} (set VGE_POLICY to another): {e}"))
        }
    };
    // (storage f32s, layer capacity, width capacity)
    let (storage, max_layers, max_width) = match vge_runtime::policy::inspect(&bytes) {
        Ok(info) => (info.storage_len, info.num_layers, info.max_width),
        Err(e) => {
            println!(
                "cargo:warning=VGE_POLICY does not validate ({e}); the firmware will report it and exit 1"
            );
            (0, 4, 256)
        }
    };
    fs::write(out.join("policy.vgep"), &bytes).expect("write policy.vgep");
    let sizes = format!(
        "/// `f32`s of weight storage `Policy::load` needs for the embedded file.\n\
         const STORAGE_LEN: usize = {storage};\n\
         /// Layer capacity of the firmware's `Policy`.\n\
         const MAX_LAYERS: usize = {max_layers};\n\
         /// Width capacity of the firmware's `Policy` (its forward buffers).\n\
         const MAX_WIDTH: usize = {max_width};\n"
    );
    fs::write(out.join("policy_sizes.rs"), sizes).expect("write policy_sizes.rs");
}
