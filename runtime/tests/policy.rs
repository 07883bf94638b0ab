//! Version-1 policy-file decoding against the byte-level test vector of
//! `docs/policy-format.md` (written by hand, independently of `vge-export`'s serde encoder),
//! and every framing error. Version 2: `policy_v2.rs`; version 3: `policy_v3.rs`.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use vge_runtime::format::{self, FORMAT_VERSION, crc32};
use vge_runtime::{HandPolicy, Policy, PolicyError, RuntimeError, storage_len};

/// The 101-byte example file of `docs/policy-format.md`: 2 -> 1 tanh.
const EXAMPLE: [u8; 101] = [
    0x56, 0x47, 0x45, 0x50, 0x4f, 0x4c, 0x43, 0x59, 0x01, 0x00, 0x00, 0x00, 0x51, 0x00, 0x00, 0x00, 0x05,
    0x30, 0x2e, 0x31, 0x2e, 0x30, 0x03, 0x61, 0x62, 0x63, 0x07, 0xe8, 0x07, 0x00, 0x00, 0x48, 0x42, 0x02,
    0x01, 0x02, 0x01, 0x71, 0x00, 0x01, 0x03, 0x6f, 0x62, 0x6a, 0x01, 0x02, 0x02, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x80, 0x3f, 0x02, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x01, 0x02, 0x01,
    0x02, 0x02, 0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x80, 0xbe, 0x01, 0x00, 0x00, 0x00, 0x3e, 0x01, 0x02,
    0x61, 0x30, 0x01, 0xcd, 0xcc, 0x4c, 0x3d, 0x01, 0x00, 0x00, 0x00, 0x00, 0xf1, 0x80, 0x9f, 0x86,
];

/// `bytes` with a recomputed CRC (to test checks behind the checksum).
fn refix(mut bytes: Vec<u8>) -> Vec<u8> {
    let n = bytes.len() - 4;
    let crc = crc32(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
    bytes
}

#[test]
fn crc32_test_vectors() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
    assert_eq!(crc32(&EXAMPLE[..97]), 0x869F_80F1);
    let mut c = format::Crc32::new();
    c.update(b"1234");
    c.update(b"56789");
    assert_eq!(c.finish(), 0xCBF4_3926);
}

#[test]
fn example_file_decodes_and_runs() {
    let info = vge_runtime::policy::inspect(&EXAMPLE).unwrap();
    assert_eq!((info.format_version, info.obs_dim, info.act_dim, info.num_layers), (1, 2, 1, 1));
    assert_eq!((info.num_params, info.storage_len, info.max_width), (3, 3 + 4 + 2, 2));
    assert_eq!(info.checksum, 0x869F_80F1);
    assert_eq!(info.control_hz, 50.0);
    assert_eq!(info.obs_clip, None);
    assert_eq!(info.task, None, "version 1 has no task record");
    let p = info.provenance;
    assert_eq!((p.vge_version, p.config_hash, p.seed, p.steps), ("0.1.0", "abc", 7, 1000));
    let layout: Vec<_> = info.obs_layout.iter().map(|s| (s.name, s.start, s.end)).collect();
    assert_eq!(layout, [("q", 0, 1), ("obj", 1, 2)]);
    assert_eq!(info.obs_layout.get("obj").map(|s| s.start), Some(1));
    assert_eq!(info.action_names.iter().collect::<Vec<_>>(), ["a0"]);
    assert_eq!(info.action_names.position("a0"), Some(0));
    assert_eq!(storage_len(&[2, 1]), info.storage_len);

    let mut storage = [0.0f32; 9];
    let policy = Policy::<'_, 2, 4>::load(&EXAMPLE, &mut storage).unwrap();
    let mut a = [0.0f32];
    // normalised obs: ((1 - 0) / 1, (3 - 1) / 2) = (1, 1); tanh(0.5 - 0.25 + 0.125) * 0.05
    policy.forward(&[1.0, 3.0], &mut a).unwrap();
    assert!((f64::from(a[0]) - 0.375f64.tanh() * 0.05).abs() < 1e-8, "{}", a[0]);
}

#[test]
fn policy_storage_len_for_hand_actor() {
    // 65*256 + 256 + 256*256 + 256 + 256*15 + 15 + 2*65 + 2*15
    const N: usize = storage_len(&[65, 256, 256, 15]);
    assert_eq!(N, 86_543 + 160);
    assert_eq!(storage_len(&[]), 0);
    assert_eq!(storage_len(&[usize::MAX, 2]), usize::MAX);
}

#[test]
fn forward_rejects_bad_observations() {
    let mut storage = [0.0f32; 16];
    let policy = HandPolicy::load(&EXAMPLE, &mut storage).unwrap();
    let mut a = [7.0f32];
    for (obs, index) in [([f32::NAN, 0.0], 0), ([0.0, f32::INFINITY], 1), ([f32::NEG_INFINITY, 0.0], 0)] {
        assert_eq!(
            policy.forward(&obs, &mut a),
            Err(PolicyError::Runtime(RuntimeError::NonFiniteObs { index }))
        );
    }
    assert_eq!(
        policy.forward(&[0.0], &mut a),
        Err(PolicyError::Runtime(RuntimeError::ObsLen { expected: 2, got: 1 }))
    );
    assert_eq!(
        policy.forward(&[0.0, 0.0], &mut [0.0; 2]),
        Err(PolicyError::Runtime(RuntimeError::ActionLen { expected: 1, got: 2 }))
    );
    assert_eq!(a, [7.0]);
    // Huge but finite observations saturate tanh instead of failing.
    policy.forward(&[f32::MAX, -f32::MAX], &mut a).unwrap();
    assert!(a[0].is_finite());
}

#[test]
fn framing_errors_are_typed() {
    let ok = EXAMPLE.to_vec();
    let load = |b: &[u8]| vge_runtime::policy::inspect(b).map(|_| ());
    assert_eq!(load(&ok[..19]), Err(PolicyError::TooShort { len: 19, min: 20 }));
    let mut bad = ok.clone();
    bad[0] = b'X';
    assert_eq!(load(&bad), Err(PolicyError::BadMagic));
    for version in [0, 4] {
        let mut bad = ok.clone();
        bad[8] = version;
        assert_eq!(
            load(&refix(bad)),
            Err(PolicyError::UnsupportedVersion { found: u16::from(version), supported: FORMAT_VERSION })
        );
    }
    let mut bad = ok.clone();
    bad[11] = 0x80;
    assert_eq!(load(&refix(bad)), Err(PolicyError::UnsupportedFlags { flags: 0x8000 }));
    assert_eq!(load(&ok[..100]), Err(PolicyError::LengthMismatch { payload_len: 81, file_len: 100 }));
    let mut long = ok.clone();
    long.push(0);
    assert_eq!(load(&long), Err(PolicyError::LengthMismatch { payload_len: 81, file_len: 102 }));
    let mut bad = ok.clone();
    bad[50] ^= 1;
    assert!(matches!(load(&bad), Err(PolicyError::ChecksumMismatch { stored: 0x869F_80F1, .. })));
}

#[test]
fn field_errors_behind_a_valid_checksum_are_typed() {
    let load = |b: Vec<u8>| vge_runtime::policy::inspect(&refix(b)).map(|_| ());
    // control_hz (payload offset 13..17, file 29..33) = NaN, then 0
    let mut b = EXAMPLE.to_vec();
    b[29..33].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(load(b), Err(PolicyError::NonFinite { field: "control_hz", index: 0 }));
    let mut b = EXAMPLE.to_vec();
    b[29..33].copy_from_slice(&0.0f32.to_le_bytes());
    assert_eq!(load(b), Err(PolicyError::NotPositive { field: "control_hz", index: 0 }));
    // obs_std[1] (file 0x3c..0x40) = -2
    let mut b = EXAMPLE.to_vec();
    b[0x3c..0x40].copy_from_slice(&(-2.0f32).to_le_bytes());
    assert_eq!(load(b), Err(PolicyError::NotPositive { field: "obs_std", index: 1 }));
    // activation code (file 0x44) = 9
    let mut b = EXAMPLE.to_vec();
    b[0x44] = 9;
    assert_eq!(load(b), Err(PolicyError::UnknownActivation { layer: 0, code: 9 }));
    // weight 1 (file 0x4a..0x4e) = inf
    let mut b = EXAMPLE.to_vec();
    b[0x4a..0x4e].copy_from_slice(&f32::INFINITY.to_le_bytes());
    assert_eq!(load(b), Err(PolicyError::Runtime(RuntimeError::NonFiniteWeight { layer: 0, index: 1 })));
    // layout "obj" starts at 0 instead of 1 (file 0x2c)
    let mut b = EXAMPLE.to_vec();
    b[0x2c] = 0;
    assert_eq!(load(b), Err(PolicyError::BadLayout { index: 1 }));
    // one payload byte too many, declared in the header
    let mut b = EXAMPLE.to_vec();
    b.insert(97, 0);
    b[12] += 1;
    assert_eq!(load(b), Err(PolicyError::TrailingPayload { unused: 1 }));
    // invalid UTF-8 in vge_version
    let mut b = EXAMPLE.to_vec();
    b[17] = 0xff;
    assert_eq!(load(b), Err(PolicyError::Malformed { field: "vge_version", offset: 0 }));
}

#[test]
fn capacity_and_storage_errors() {
    let mut small = [0.0f32; 8];
    assert_eq!(
        Policy::<'_, 2, 4>::load(&EXAMPLE, &mut small).unwrap_err(),
        PolicyError::StorageTooSmall { needed: 9, got: 8 }
    );
    let mut storage = [0.0f32; 9];
    assert_eq!(
        Policy::<'_, 0, 4>::load(&EXAMPLE, &mut storage).unwrap_err(),
        PolicyError::Runtime(RuntimeError::TooManyLayers { count: 1, max: 0 })
    );
    let mut storage = [0.0f32; 9];
    assert_eq!(
        Policy::<'_, 2, 1>::load(&EXAMPLE, &mut storage).unwrap_err(),
        PolicyError::Runtime(RuntimeError::WidthExceedsCapacity { layer: 0, dim: 2, max: 1 })
    );
}

#[test]
fn every_truncation_and_bit_flip_of_the_example_is_rejected() {
    let mut storage = [0.0f32; 16];
    for n in 0..EXAMPLE.len() {
        assert!(HandPolicy::load(&EXAMPLE[..n], &mut storage).is_err(), "truncation to {n}");
    }
    for bit in 0..EXAMPLE.len() * 8 {
        let mut b = EXAMPLE;
        b[bit / 8] ^= 1 << (bit % 8);
        assert!(HandPolicy::load(&b, &mut storage).is_err(), "bit {bit}");
    }
}

#[test]
fn errors_display() {
    assert_eq!(PolicyError::BadMagic.to_string(), "not a vge policy file (bad magic)");
    assert_eq!(
        PolicyError::ChecksumMismatch { stored: 1, computed: 2 }.to_string(),
        "checksum mismatch: stored 0x00000001, computed 0x00000002"
    );
    assert_eq!(
        PolicyError::Runtime(RuntimeError::NonFiniteObs { index: 3 }).to_string(),
        "observation 3 is not finite"
    );
}

/// A file that passes every load check (valid CRC, finite weights) but whose layer overflows
/// at run time: weights 0 and 1 (file 0x46..0x4e) = 3e38, so the normalised obs (1, 1) gives
/// 6e38 = inf before the tanh, which would turn it into a plausible-looking 1 x 0.05 rad.
#[test]
fn a_valid_file_whose_layer_overflows_is_refused_at_run_time() {
    let mut b = EXAMPLE.to_vec();
    b[0x46..0x4a].copy_from_slice(&3.0e38f32.to_le_bytes());
    b[0x4a..0x4e].copy_from_slice(&3.0e38f32.to_le_bytes());
    let b = refix(b);
    let mut storage = [0.0f32; 9];
    let policy = Policy::<'_, 2, 4>::load(&b, &mut storage).unwrap();
    let mut a = [0.5f32];
    let err = policy.forward(&[1.0, 3.0], &mut a).unwrap_err();
    assert_eq!(err, PolicyError::Runtime(RuntimeError::NonFiniteActivation { layer: 0, index: 0 }));
    assert_eq!(a, [0.5], "the action is left untouched");
    // Small inputs through the same weights stay finite and run.
    policy.forward(&[0.0, 1.0], &mut a).unwrap();
}
