//! Puts `memory.x` on the linker path, the policy file in `OUT_DIR/policy.vgep` and its
//! sizes in `OUT_DIR/policy_sizes.rs`.
//!
//! The policy file comes from `VGE_POLICY` (a `.vgep` written by vge-export; the host test
//! `export/tests/cortex_m.rs` writes one from a tch actor). Without it, a deterministic
//! stand-in 65 -> 256 -> 256 -> 15 policy file is encoded here (same format, see
//! docs/policy-format.md) so that a plain `cargo build` / `cargo run` works.
//!
//! The weight storage the firmware hands to `Policy::load` is sized from the file with
//! `vge_runtime::policy::inspect` (exactly `storage_len` f32). A file that does not validate
//! is still embedded, with zero storage and the default capacities, so that the firmware
//! itself reports the typed error and exits non-zero (the host test checks this); cargo
//! prints a warning.

use std::{env, fs, path::PathBuf};

use vge_runtime::format;

const DIMS: [usize; 4] = [65, 256, 256, 15];

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=VGE_POLICY");

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

fn f32s(buf: &mut Vec<u8>, values: impl ExactSizeIterator<Item = f32>) {
    varint(buf, values.len() as u64);
    for v in values {
        buf.extend_from_slice(&v.to_le_bytes());
    }
}

/// A stand-in policy file: tch-like `Linear` initialisation U(-1/sqrt(in), 1/sqrt(in)) from a
/// fixed xorshift seed, identity normalisation, unit action scale.
fn default_policy() -> Vec<u8> {
    let mut state = 0x9E37_79B9_u32;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    };
    let (obs, act) = (DIMS[0], DIMS[DIMS.len() - 1]);
    let mut p = Vec::new();
    string(&mut p, env!("CARGO_PKG_VERSION"));
    string(&mut p, "firmware-m4-default");
    varint(&mut p, 0); // seed
    varint(&mut p, 0); // steps
    p.extend_from_slice(&20.0f32.to_le_bytes()); // control_hz
    varint(&mut p, obs as u64);
    varint(&mut p, act as u64);
    varint(&mut p, 1); // obs_layout: one slice "obs" 0..obs
    string(&mut p, "obs");
    varint(&mut p, 0);
    varint(&mut p, obs as u64);
    f32s(&mut p, std::iter::repeat_n(0.0, obs)); // obs_mean
    f32s(&mut p, std::iter::repeat_n(1.0, obs)); // obs_std
    p.push(0); // obs_clip: None
    varint(&mut p, (DIMS.len() - 1) as u64);
    for (i, w) in DIMS.windows(2).enumerate() {
        let (n_in, n_out) = (w[0], w[1]);
        varint(&mut p, n_in as u64);
        varint(&mut p, n_out as u64);
        p.push(if i + 2 == DIMS.len() { format::ACT_TANH } else { format::ACT_RELU });
        let bound = 1.0 / (n_in as f32).sqrt();
        let weights: Vec<f32> = (0..n_in * n_out).map(|_| next() * bound).collect();
        let bias: Vec<f32> = (0..n_out).map(|_| next() * bound).collect();
        f32s(&mut p, weights.into_iter());
        f32s(&mut p, bias.into_iter());
    }
    varint(&mut p, act as u64); // action_names
    for i in 0..act {
        string(&mut p, &format!("a{i}"));
    }
    f32s(&mut p, std::iter::repeat_n(1.0, act)); // action_scale
    f32s(&mut p, std::iter::repeat_n(0.0, act)); // action_offset

    let mut file = format::header(u32::try_from(p.len()).expect("payload < 4 GiB")).to_vec();
    file.extend_from_slice(&p);
    let crc = format::crc32(&file);
    file.extend_from_slice(&crc.to_le_bytes());
    vge_runtime::policy::inspect(&file).expect("the stand-in policy file validates");
    file
}
