//! Puts `memory.x` on the linker path, the policy file in `OUT_DIR/policy.vgep` and its
//! sizes in `OUT_DIR/policy_sizes.rs`.
//!
//! The policy file comes from `VGE_POLICY` (a `.vgep` written by vge-export; the host test
//! `export/tests/cortex_m.rs` and `vge bench firmware` write them from a tch actor). Without
//! it, a deterministic stand-in 65 -> 256 -> 256 -> 15 policy file is encoded here (format
//! version 2, f32, see docs/policy-format.md) so that a plain `cargo build` / `cargo run` works.
//!
//! The weight storage the firmware hands to `Policy::load` is sized from the file with
//! `vge_runtime::policy::inspect`: `storage_len` f32, which is 0 for a version-2 file (its
//! arrays are read in place from flash). A file that does not validate
//! is still embedded, with zero storage and the default capacities, so that the firmware
//! itself reports the typed error and exits non-zero (the host test checks this); cargo
//! prints a warning.

use std::{env, fs, path::PathBuf};

use vge_runtime::format;

const DIMS: [usize; 4] = [65, 256, 256, 15];

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
        _ => default_policy(),
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

fn varint(buf: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        buf.push((v as u8) | 0x80);
        v >>= 7;
    }
    buf.push(v as u8);
}

fn string(buf: &mut Vec<u8>, s: &str) {
    varint(buf, s.len() as u64);
    buf.extend_from_slice(s.as_bytes());
}

/// Zero padding to the next 16-byte file offset, then the values (a version-2 array).
fn array(file: &mut Vec<u8>, values: impl Iterator<Item = f32>) {
    file.resize(file.len().next_multiple_of(vge_runtime::policy::TENSOR_ALIGN), 0);
    for v in values {
        file.extend_from_slice(&v.to_le_bytes());
    }
}

/// A stand-in version-2 policy file (f32 weights): tch-like `Linear` initialisation
/// U(-1/sqrt(in), 1/sqrt(in)) from a fixed xorshift seed, identity normalisation, unit action
/// scale. Written here because a build script cannot use vge-export (it links libtorch).
fn default_policy() -> Vec<u8> {
    let mut state = 0x9E37_79B9_u32;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    };
    let (obs, act) = (DIMS[0], DIMS[DIMS.len() - 1]);
    let mut meta = Vec::new();
    string(&mut meta, env!("CARGO_PKG_VERSION"));
    string(&mut meta, "firmware-m4-default");
    varint(&mut meta, 0); // seed
    varint(&mut meta, 0); // steps
    meta.extend_from_slice(&20.0f32.to_le_bytes()); // control_hz
    varint(&mut meta, obs as u64);
    varint(&mut meta, act as u64);
    varint(&mut meta, 1); // obs_layout: one slice "obs" 0..obs
    string(&mut meta, "obs");
    varint(&mut meta, 0);
    varint(&mut meta, obs as u64);
    meta.push(0); // obs_clip: None
    meta.push(0); // weight_type: f32
    varint(&mut meta, (DIMS.len() - 1) as u64);
    for (i, w) in DIMS.windows(2).enumerate() {
        varint(&mut meta, w[0] as u64);
        varint(&mut meta, w[1] as u64);
        meta.push(if i + 2 == DIMS.len() { format::ACT_TANH } else { format::ACT_RELU });
    }
    varint(&mut meta, act as u64); // action_names
    for i in 0..act {
        string(&mut meta, &format!("a{i}"));
    }

    let mut file = vec![0u8; format::HEADER_LEN];
    file.extend_from_slice(&u32::try_from(meta.len()).expect("small").to_le_bytes());
    file.extend_from_slice(&meta);
    array(&mut file, std::iter::repeat_n(0.0, obs)); // obs_mean
    array(&mut file, std::iter::repeat_n(1.0, obs)); // obs_std
    for w in DIMS.windows(2) {
        let (n_in, n_out) = (w[0], w[1]);
        let bound = 1.0 / (n_in as f32).sqrt();
        let weights: Vec<f32> = (0..n_in * n_out).map(|_| next() * bound).collect();
        let bias: Vec<f32> = (0..n_out).map(|_| next() * bound).collect();
        array(&mut file, weights.into_iter());
        array(&mut file, bias.into_iter());
    }
    array(&mut file, std::iter::repeat_n(1.0, act)); // action_scale
    array(&mut file, std::iter::repeat_n(0.0, act)); // action_offset
    let payload_len = u32::try_from(file.len() - format::HEADER_LEN).expect("payload < 4 GiB");
    file[..format::HEADER_LEN].copy_from_slice(&format::header(2, payload_len));
    let crc = format::crc32(&file);
    file.extend_from_slice(&crc.to_le_bytes());
    vge_runtime::policy::inspect(&file).expect("the stand-in policy file validates");
    file
}
