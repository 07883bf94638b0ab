//! Puts `memory.x` on the linker path and the policy blob in `OUT_DIR/policy.bin`.
//!
//! The blob comes from the file named by `VGE_POLICY` (the host test writes one from a tch
//! actor); without it, a deterministic stand-in is generated here so that a plain
//! `cargo build` / `cargo run` works. Blob layout (little-endian f32, no header): for each
//! layer of 65 -> 256 -> 256 -> 15, the row-major `out × in` weights then the `out` biases.

use std::{env, fs, path::PathBuf};

const DIMS: [usize; 4] = [65, 256, 256, 15];

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=VGE_POLICY");

    let blob = match env::var_os("VGE_POLICY") {
        Some(path) if !path.is_empty() => {
            println!("cargo:rerun-if-changed={}", PathBuf::from(&path).display());
            fs::read(&path).unwrap_or_else(|e| panic!("VGE_POLICY={}: {e}", PathBuf::from(&path).display()))
        }
        _ => default_blob(),
    };
    fs::write(out.join("policy.bin"), blob).expect("write policy.bin");
}

/// tch-like `Linear` initialisation, U(-1/sqrt(in), 1/sqrt(in)), from a fixed xorshift seed.
fn default_blob() -> Vec<u8> {
    let mut state = 0x9E37_79B9_u32;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    };
    let mut blob = Vec::new();
    for w in DIMS.windows(2) {
        let (n_in, n_out) = (w[0], w[1]);
        let bound = 1.0 / (n_in as f32).sqrt();
        for _ in 0..n_out * n_in + n_out {
            blob.extend_from_slice(&(next() * bound).to_le_bytes());
        }
    }
    blob
}
