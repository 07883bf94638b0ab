//! Version-2 policy files against the byte-level test vector of `docs/policy-format.md`
//! (written by hand, independently of `vge-export`'s encoder): arrays used in place from an
//! aligned buffer, `f16` and `i8` weights, alignment and padding errors, and every truncation
//! and bit flip.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use vge_runtime::format::crc32;
use vge_runtime::{HandPolicy, Policy, PolicyError, RuntimeError, WeightType};

/// The 152-byte version-2 example of `docs/policy-format.md`: the version-1 example's 2 -> 1
/// tanh network (same values), arrays at 16-byte aligned offsets.
const EXAMPLE_V2: [u8; 152] = [
    0x56, 0x47, 0x45, 0x50, 0x4f, 0x4c, 0x43, 0x59, 0x02, 0x00, 0x00, 0x00, 0x84, 0x00, 0x00,
    0x00, // header
    0x28, 0x00, 0x00, 0x00, 0x05, 0x30, 0x2e, 0x31, 0x2e, 0x30, 0x03, 0x61, 0x62, 0x63, 0x07,
    0xe8, // meta
    0x07, 0x00, 0x00, 0x48, 0x42, 0x02, 0x01, 0x02, 0x01, 0x71, 0x00, 0x01, 0x03, 0x6f, 0x62, 0x6a, 0x01,
    0x02, 0x00, 0x00, 0x01, 0x02, 0x01, 0x02, 0x01, 0x02, 0x61, 0x30, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // 0x40 obs_mean
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0x50 obs_std
    0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x80, 0xbe, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0x60 W
    0x00, 0x00, 0x00, 0x3e, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0x70 b
    0xcd, 0xcc, 0x4c, 0x3d, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0x80 scale
    0x00, 0x00, 0x00, 0x00, 0x42, 0x50, 0xf9, 0x39, // 0x90 offset, CRC-32
];

/// Bytes at a 16-byte aligned address, as a firmware's `#[repr(align(16))]` static holds them.
#[repr(C, align(16))]
struct Aligned<const N: usize>([u8; N]);

static ALIGNED_EXAMPLE: Aligned<152> = Aligned(EXAMPLE_V2);

/// An aligned copy of `bytes` (with room for the variants below).
fn aligned(bytes: &[u8]) -> Box<Aligned<256>> {
    let mut a = Box::new(Aligned([0u8; 256]));
    a.0[..bytes.len()].copy_from_slice(bytes);
    a
}

/// `bytes` with the header's payload length and the CRC recomputed (after an edit).
fn refix(mut bytes: Vec<u8>) -> Vec<u8> {
    bytes.truncate(bytes.len() - 4);
    let n = u32::try_from(bytes.len() - 16).unwrap();
    bytes[12..16].copy_from_slice(&n.to_le_bytes());
    let crc = crc32(&bytes);
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes
}

/// The example with its weight array (file 0x60..0x68) replaced by `weights` of type `code`
/// (and, for `i8`, a row-scale array after it), re-padded and re-checksummed.
fn with_weights(code: u8, weights: &[u8], row_scale: Option<f32>) -> Vec<u8> {
    let mut b = EXAMPLE_V2[..0x60].to_vec();
    b[0x33] = code; // weight_type, the metadata byte after obs_clip
    b.extend_from_slice(weights);
    let pad = |b: &mut Vec<u8>| b.resize(b.len().next_multiple_of(16), 0);
    if let Some(s) = row_scale {
        pad(&mut b);
        b.extend_from_slice(&s.to_le_bytes());
    }
    for array in [&EXAMPLE_V2[0x70..0x74], &EXAMPLE_V2[0x80..0x84], &EXAMPLE_V2[0x90..0x94]] {
        pad(&mut b);
        b.extend_from_slice(array);
    }
    b.extend_from_slice(&[0; 4]);
    refix(b)
}

const OBS: [f32; 2] = [1.0, 3.0];

fn run(bytes: &[u8]) -> f32 {
    let a = aligned(bytes);
    let policy = Policy::<'_, 2, 4>::load(&a.0[..bytes.len()], &mut []).unwrap();
    let mut action = [0.0f32];
    policy.forward(&OBS, &mut action).unwrap();
    action[0]
}

#[test]
fn example_decodes_and_runs_in_place() {
    assert_eq!(crc32(&EXAMPLE_V2[..148]), 0x39F9_5042);
    let info = vge_runtime::policy::inspect(&EXAMPLE_V2).unwrap();
    assert_eq!((info.format_version, info.obs_dim, info.act_dim, info.num_layers), (2, 2, 1, 1));
    assert_eq!((info.num_params, info.storage_len, info.weight_type), (3, 0, WeightType::F32));
    let p = info.provenance;
    assert_eq!((p.vge_version, p.config_hash, p.seed, p.steps), ("0.1.0", "abc", 7, 1000));
    let layout: Vec<_> = info.obs_layout.iter().map(|s| (s.name, s.start, s.end)).collect();
    assert_eq!(layout, [("q", 0, 1), ("obj", 1, 2)]);
    assert_eq!(info.action_names.iter().collect::<Vec<_>>(), ["a0"]);
    assert_eq!(info.task, None, "version 2 has no task record");

    // No storage: every array is borrowed from the static.
    let policy = HandPolicy::load(&ALIGNED_EXAMPLE.0, &mut []).unwrap();
    let mut a = [0.0f32];
    policy.forward(&OBS, &mut a).unwrap();
    // Same network as the version-1 example: tanh(0.5 - 0.25 + 0.125) * 0.05.
    assert!((f64::from(a[0]) - 0.375f64.tanh() * 0.05).abs() < 1e-8, "{}", a[0]);
}

#[test]
fn a_misaligned_buffer_is_a_typed_error_naming_the_array() {
    let mut buf = Aligned([0u8; 160]);
    buf.0[1..153].copy_from_slice(&EXAMPLE_V2);
    let misaligned = &buf.0[1..153];
    assert!(vge_runtime::policy::inspect(misaligned).is_ok(), "validation needs no alignment");
    assert_eq!(
        HandPolicy::load(misaligned, &mut []).unwrap_err(),
        PolicyError::Misaligned { field: "layer.weights", file_offset: 0x60, align: 4 }
    );
}

#[test]
fn f16_weights_are_widened_exactly() {
    // 0.5 = 0x3800, -0.25 = 0xb400: exact in binary16, so the action is the f32 one.
    let b = with_weights(WeightType::F16.code(), &[0x00, 0x38, 0x00, 0xb4], None);
    assert_eq!(vge_runtime::policy::inspect(&b).unwrap().weight_type, WeightType::F16);
    assert_eq!(run(&b), run(&EXAMPLE_V2));
    // An infinite f16 weight (0x7c00) is refused at load.
    let inf = with_weights(WeightType::F16.code(), &[0x00, 0x7c, 0x00, 0xb4], None);
    assert_eq!(
        vge_runtime::policy::inspect(&inf).unwrap_err(),
        PolicyError::Runtime(RuntimeError::NonFiniteWeight { layer: 0, index: 0 })
    );
}

#[test]
fn i8_weights_follow_the_documented_scheme() {
    // Row scale 0.5 / 127: 0.5 -> 127, -0.25 -> -63.5 -> -64. Normalised input (1, 1)
    // quantises to (32767, 32767) with scale 1 / 32767, so the sum is 63 * 32767 and the
    // affine output 0.125 + (0.5 / 127) * (1 / 32767) * 63 * 32767 = 0.125 + 31.5 / 127.
    let s = 0.5f32 / 127.0;
    let b = with_weights(WeightType::I8.code(), &[127, (-64i8).to_le_bytes()[0]], Some(s));
    assert_eq!(vge_runtime::policy::inspect(&b).unwrap().weight_type, WeightType::I8);
    let expected = (0.125f64 + 31.5 / 127.0).tanh() * 0.05;
    assert!((f64::from(run(&b)) - expected).abs() < 1e-7, "{} vs {expected}", run(&b));
    // Within the quantisation error of the f32 policy.
    assert!((run(&b) - run(&EXAMPLE_V2)).abs() < 1e-3);
    let zero_scale = with_weights(WeightType::I8.code(), &[127, 0xc0], Some(0.0));
    assert_eq!(
        vge_runtime::policy::inspect(&zero_scale).unwrap_err(),
        PolicyError::Runtime(RuntimeError::BadScale { layer: 0, index: 0 })
    );
}

#[test]
fn structural_errors_are_typed() {
    let inspect = |b: &[u8]| vge_runtime::policy::inspect(b).map(|_| ());
    // The weight array written f32 but declared i8: the arrays no longer line up.
    assert!(inspect(&with_weights(WeightType::I8.code(), &EXAMPLE_V2[0x60..0x68], Some(1.0))).is_err());
    let mut b = EXAMPLE_V2.to_vec();
    b[0x33] = 9;
    assert_eq!(inspect(&refix(b)), Err(PolicyError::UnknownWeightType { code: 9 }));
    let mut b = EXAMPLE_V2.to_vec();
    b[0x3c] = 1; // padding after the metadata
    assert_eq!(inspect(&refix(b)), Err(PolicyError::NonZeroPadding { offset: 0x3c - 16 }));
    let mut b = EXAMPLE_V2.to_vec();
    b[0x10] = 0x27; // metadata length one short
    assert_eq!(inspect(&refix(b)), Err(PolicyError::Malformed { field: "meta_len", offset: 0 }));
    let mut b = EXAMPLE_V2.to_vec();
    b.truncate(148);
    b.extend_from_slice(&[0; 4]); // one extra array's worth of bytes before the CRC
    b.extend_from_slice(&[0; 4]);
    assert_eq!(inspect(&refix(b)), Err(PolicyError::TrailingPayload { unused: 4 }));
}

#[test]
fn every_truncation_and_bit_flip_is_rejected() {
    for n in 0..EXAMPLE_V2.len() {
        let a = aligned(&EXAMPLE_V2[..n]);
        assert!(HandPolicy::load(&a.0[..n], &mut []).is_err(), "truncation to {n}");
    }
    for bit in 0..EXAMPLE_V2.len() * 8 {
        let mut b = EXAMPLE_V2;
        b[bit / 8] ^= 1 << (bit % 8);
        let a = aligned(&b);
        assert!(HandPolicy::load(&a.0[..b.len()], &mut []).is_err(), "bit {bit}");
    }
}
