//! Policy files from real tch actors: round trip, inspect, metadata errors, and every
//! truncation and single-bit flip rejected with a typed error.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use tch::Device;
use tch::nn::VarStore;
use vge_export::{
    ActorSpec, ExportError, ObsNorm, ObsSlice, PolicyFile, PolicyMeta, PolicyTask, Provenance, WeightType,
    inspect,
};
use vge_export_tch::{build_actor, export_policy, extract_actor};
use vge_runtime::format::crc32;
use vge_runtime::{AlignedBytes, HandPolicy, PolicyError, RuntimeError};

const FINGERS: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];
const JOINTS: [&str; 3] = ["roll", "flex1", "flex2"];

/// The hand's 65-dim observation and 15 joint-target deltas.
fn hand_meta() -> PolicyMeta {
    let obs_layout = vec![
        ObsSlice::new("q", 0..15),
        ObsSlice::new("qd", 15..30),
        ObsSlice::new("q_target", 30..45),
        ObsSlice::new("fingertips", 45..60),
        ObsSlice::new("object_quat", 60..64),
        ObsSlice::new("object_wz", 64..65),
    ];
    let action_names = FINGERS.iter().flat_map(|f| JOINTS.iter().map(move |j| format!("{f}.{j}"))).collect();
    let mean = (0..65).map(|i| (i as f32 * 0.37).sin() * 0.5).collect();
    let std = (0..65).map(|i| 0.5 + (i as f32 * 0.11).cos().abs()).collect();
    PolicyMeta {
        obs_layout,
        action_names,
        obs_norm: ObsNorm { mean, std, clip: Some(5.0) },
        action_scale: (0..15).map(|i| 0.02 + 0.002 * i as f32).collect(),
        action_offset: vec![0.0; 15],
        control_hz: 20.0,
        provenance: Provenance {
            vge_version: "0.1.0".into(),
            config_hash: "3f2a9c0d5e6b7a81".into(),
            seed: 42,
            steps: 2_000_000,
        },
        task: None,
    }
}

fn actor_store(spec: &ActorSpec, seed: i64) -> VarStore {
    tch::manual_seed(seed);
    let vs = VarStore::new(Device::Cpu);
    build_actor(&(vs.root() / "actor"), spec).unwrap();
    vs
}

/// A real exported policy, small enough to flip every bit of: 65 -> 16 -> 15.
fn small_file() -> Vec<u8> {
    let spec = ActorSpec { obs_dim: 65, hidden: vec![16], act_dim: 15 };
    export_policy(&actor_store(&spec, 5), "actor", &spec, hand_meta()).unwrap()
}

fn big_file() -> Vec<u8> {
    let spec = ActorSpec { obs_dim: 65, hidden: vec![256, 256], act_dim: 15 };
    export_policy(&actor_store(&spec, 6), "actor", &spec, hand_meta()).unwrap()
}

fn refix(bytes: &mut [u8]) {
    let n = bytes.len() - 4;
    let crc = crc32(&bytes[..n]);
    bytes[n..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn round_trip_write_read() {
    let spec = ActorSpec { obs_dim: 65, hidden: vec![32, 32], act_dim: 15 };
    let vs = actor_store(&spec, 1);
    let actor = extract_actor(&vs, "actor", &spec).unwrap();
    let file = PolicyFile::from_actor(&actor, hand_meta()).unwrap();
    let bytes = file.to_bytes().unwrap();
    assert_eq!(bytes, export_policy(&vs, "actor", &spec, hand_meta()).unwrap(), "deterministic bytes");
    assert_eq!(PolicyFile::from_bytes(&bytes).unwrap(), file);
    assert_eq!(file.actor().unwrap(), actor);

    let path = std::env::temp_dir().join(format!("vge-policy-{}.vgep", std::process::id()));
    file.write(&path).unwrap();
    assert_eq!(PolicyFile::read(&path).unwrap(), file);
    std::fs::remove_file(&path).unwrap();
    assert!(matches!(PolicyFile::read(&path), Err(ExportError::Io { .. })));

    // Every weight type and version decodes to the same model (quantised weights to what they
    // stand for), and f32 in both versions exactly.
    let v1 = file.to_bytes_v1().unwrap();
    assert_eq!(PolicyFile::decode(&v1, true).unwrap(), (file.clone(), WeightType::F32));
    for weights in [WeightType::F16, WeightType::I8] {
        let (back, stored) = PolicyFile::decode(&file.encode(weights).unwrap(), true).unwrap();
        assert_eq!(stored, weights);
        let max_err =
            back.layers.iter().zip(&file.layers).flat_map(|(a, b)| a.weights.iter().zip(&b.weights));
        let max_err = max_err.map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(max_err > 0.0 && max_err < 0.01, "{weights}: max weight error {max_err}");
        assert_eq!((back.obs_mean, &back.layers[0].bias), (file.obs_mean.clone(), &file.layers[0].bias));
    }

    // The no_std runtime sees the same metadata: version 3 in place from an aligned buffer,
    // version 1 copied into storage.
    let aligned = AlignedBytes::new(&bytes);
    let policy = HandPolicy::load(&aligned, &mut []).unwrap();
    let mut storage = vec![0.0f32; vge_runtime::storage_len(&[65, 32, 32, 15])];
    let storage_len = storage.len();
    let old = HandPolicy::load(&v1, &mut storage).unwrap();
    assert_eq!((old.info().format_version, old.info().storage_len), (1, storage_len));
    let info = policy.info();
    assert_eq!((info.obs_dim, info.act_dim, info.num_layers), (65, 15, 3));
    assert_eq!(info.num_params, file.num_params());
    assert_eq!((info.format_version, info.storage_len), (3, 0));
    assert_eq!(info.task, None, "no task given, none recorded");
    assert_eq!(info.control_hz, 20.0);
    assert_eq!(info.obs_clip, Some(5.0));
    assert_eq!(info.provenance.config_hash, "3f2a9c0d5e6b7a81");
    assert_eq!((info.provenance.seed, info.provenance.steps), (42, 2_000_000));
    let q = info.obs_layout.get("fingertips").unwrap();
    assert_eq!((q.start, q.end), (45, 60));
    let names: Vec<&str> = info.action_names.iter().collect();
    assert_eq!(names, file.action_names);
    assert_eq!(info.action_names.position("index.flex1"), Some(4));
}

#[test]
fn inspect_reports_everything() {
    let bytes = small_file();
    let r = inspect::report(&bytes).unwrap();
    assert!(r.checksum_ok() && r.is_valid());
    assert_eq!((r.format_version, r.file_len, r.num_params()), (3, bytes.len(), 65 * 16 + 16 + 16 * 15 + 15));
    let text = r.to_string();
    for needle in [
        "format version 3",
        "hand:       vge15 (no hand record), observation set: full",
        "weights:    f32",
        "runtime RAM for parameters: none",
        "ok (loadable by vge-runtime)",
        "seed 42, 2000000 steps",
        "65 -> 16 -> 15 (2 layers, 1311 parameters)",
        "layer 1: 16 -> 15 tanh",
        "q 0..15, qd 15..30",
        "little.flex2",
        "20 Hz",
    ] {
        assert!(text.contains(needle), "{needle:?} not in\n{text}");
    }
    // A flipped bit in a weight (the middle of the file): still described, flagged.
    let mut bad = bytes.clone();
    bad[bytes.len() / 2] ^= 0x10;
    let r = inspect::report(&bad).unwrap();
    assert!(!r.checksum_ok() && !r.is_valid());
    assert!(r.to_string().contains("CRC-32 MISMATCH"), "{r}");
    assert!(matches!(inspect::report(&bytes[..10]), Err(ExportError::Format(PolicyError::TooShort { .. }))));
}

fn allegro_task() -> PolicyTask {
    PolicyTask {
        hand: "allegro".into(),
        hand_sha256: std::array::from_fn(|i| (i * 7) as u8),
        observation_set: "proprio:4".into(),
        object: "cube".into(),
        orientation: String::new(),
    }
}

#[test]
fn the_task_record_round_trips_in_every_weight_type() {
    let spec = ActorSpec { obs_dim: 65, hidden: vec![16], act_dim: 15 };
    let vs = actor_store(&spec, 8);
    let meta = PolicyMeta { task: Some(allegro_task()), ..hand_meta() };
    let bytes = export_policy(&vs, "actor", &spec, meta).unwrap();
    let file = PolicyFile::from_bytes(&bytes).unwrap();
    assert_eq!(file.task, Some(allegro_task()));
    for weights in [WeightType::F16, WeightType::I8] {
        let (back, _) = PolicyFile::decode(&file.encode(weights).unwrap(), true).unwrap();
        assert_eq!(back.task, Some(allegro_task()), "{weights}");
    }
    let aligned = AlignedBytes::new(&bytes);
    let policy = HandPolicy::load(&aligned, &mut []).unwrap();
    let task = allegro_task();
    assert_eq!(policy.info().format_version, 3);
    assert_eq!(policy.info().task, Some(task.info()));
    // Without a record only its absent tag is written: still version 3, no task.
    let bare = PolicyFile { task: None, ..file.clone() }.to_bytes().unwrap();
    assert_eq!(vge_runtime::policy::inspect(&bare).unwrap().task, None);
    assert!(bare.len() < bytes.len());

    let text = inspect::report(&bytes).unwrap().to_string();
    let sha: String = task.hand_sha256.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(task.hand_sha256_hex(), sha);
    for needle in [
        format!("hand:       allegro (MJCF sha256 {sha})"),
        "task:       observation set proprio:4, object cube, orientation unspecified".to_owned(),
    ] {
        assert!(text.contains(&needle), "{needle:?} not in\n{text}");
    }
    // Version 1 cannot say which hand: refused rather than read back as vge15.
    assert!(matches!(file.to_bytes_v1(), Err(ExportError::InvalidSpec(m)) if m.contains("allegro")));
    assert!(PolicyFile { task: None, ..file }.to_bytes_v1().is_ok());
}

#[test]
fn a_malformed_task_is_rejected_when_encoding() {
    let spec = ActorSpec { obs_dim: 65, hidden: vec![8], act_dim: 15 };
    let vs = actor_store(&spec, 2);
    let enc =
        |task: PolicyTask| export_policy(&vs, "actor", &spec, PolicyMeta { task: Some(task), ..hand_meta() });
    let t = PolicyTask { hand: String::new(), ..allegro_task() };
    assert!(matches!(enc(t), Err(ExportError::Format(PolicyError::TaskName { field: "task.hand", len: 0 }))));
    let t = PolicyTask { hand: "h".repeat(65), ..allegro_task() };
    assert!(matches!(
        enc(t),
        Err(ExportError::Format(PolicyError::TaskName { field: "task.hand", len: 65 }))
    ));
    let t = PolicyTask { orientation: "o".repeat(200), ..allegro_task() };
    assert!(matches!(
        enc(t),
        Err(ExportError::Format(PolicyError::TaskName { field: "task.orientation", len: 200 }))
    ));
    for set in ["", "proprio:0", "proprio:65", "proprio:04", "FULL", "vision"] {
        let t = PolicyTask { observation_set: set.into(), ..allegro_task() };
        assert!(matches!(enc(t), Err(ExportError::Format(PolicyError::BadObservationSet { .. }))), "{set:?}");
    }
    let t = PolicyTask { observation_set: "full".into(), hand: "vge15".into(), ..allegro_task() };
    assert!(enc(t).is_ok());
}

/// Every policy file stored in the repository (the shipped policy, the results' and the
/// fixtures') still loads unchanged: those of version 1 or 2 as vge's own hand with the full
/// observation set (no task record), those of version 3 with theirs; re-encoded, an old file
/// becomes version 3 without a task record, same model.
#[test]
fn stored_policy_files_still_load_as_the_unrecorded_hand() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().nth(2).unwrap();
    let mut stack = vec![root.join("policies"), root.join("docs/results"), root.join("tests/fixtures")];
    let mut files = Vec::new();
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "vgep") {
                files.push(path);
            }
        }
    }
    assert!(files.len() > 100, "{} policy files found", files.len());
    for path in &files {
        let bytes = std::fs::read(path).unwrap();
        let info = vge_runtime::policy::inspect(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        match info.format_version {
            1 | 2 => assert!(info.task.is_none(), "{}", path.display()),
            3 => assert!(info.task.is_some(), "{}: version 3 without a task record", path.display()),
            v => panic!("{}: unknown format version {v}", path.display()),
        }
    }
    let shipped = std::fs::read(root.join("policies/cube.vgep")).unwrap();
    let text = inspect::report(&shipped).unwrap().to_string();
    assert!(text.contains("hand:       vge15 (file predates hand records), observation set: full"), "{text}");
    let file = PolicyFile::from_bytes(&shipped).unwrap();
    let again = file.to_bytes().unwrap();
    assert_eq!(vge_runtime::policy::inspect(&again).unwrap().format_version, 3);
    assert_eq!(PolicyFile::from_bytes(&again).unwrap(), file);
}

#[test]
fn invalid_metadata_is_rejected_when_encoding() {
    let spec = ActorSpec { obs_dim: 65, hidden: vec![8], act_dim: 15 };
    let vs = actor_store(&spec, 2);
    let enc = |meta: PolicyMeta| export_policy(&vs, "actor", &spec, meta);
    let mut m = hand_meta();
    m.obs_layout.pop();
    assert!(matches!(enc(m), Err(ExportError::Format(PolicyError::BadLayout { index: 5 }))));
    let mut m = hand_meta();
    m.obs_norm.std[3] = 0.0;
    assert!(matches!(
        enc(m),
        Err(ExportError::Format(PolicyError::NotPositive { field: "obs_std", index: 3 }))
    ));
    let mut m = hand_meta();
    m.action_names.pop();
    assert!(matches!(enc(m), Err(ExportError::Format(PolicyError::Len { field: "action_names", .. }))));
    let mut m = hand_meta();
    m.action_scale[2] = f32::NAN;
    assert!(matches!(
        enc(m),
        Err(ExportError::Format(PolicyError::NonFinite { field: "action_scale", index: 2 }))
    ));
    let mut m = hand_meta();
    m.control_hz = 0.0;
    assert!(matches!(enc(m), Err(ExportError::Format(PolicyError::NotPositive { field: "control_hz", .. }))));
    let wrong_obs = ActorSpec { obs_dim: 64, ..spec.clone() };
    let vs64 = actor_store(&wrong_obs, 2);
    assert!(matches!(
        export_policy(&vs64, "actor", &wrong_obs, hand_meta()),
        Err(ExportError::Format(PolicyError::BadLayout { index: 5 }))
    ));
}

#[test]
fn wrong_magic_and_version_are_rejected() {
    let bytes = small_file();
    let mut bad = bytes.clone();
    bad[..8].copy_from_slice(b"VGEPOLCZ");
    assert!(matches!(PolicyFile::from_bytes(&bad), Err(ExportError::Format(PolicyError::BadMagic))));
    let mut bad = bytes.clone();
    bad[8..10].copy_from_slice(&4u16.to_le_bytes());
    refix(&mut bad);
    assert!(matches!(
        PolicyFile::from_bytes(&bad),
        Err(ExportError::Format(PolicyError::UnsupportedVersion { found: 4, supported: 3 }))
    ));
    let mut storage = vec![0.0f32; 4096];
    assert_eq!(
        HandPolicy::load(&bad, &mut storage).unwrap_err(),
        PolicyError::UnsupportedVersion { found: 4, supported: 3 }
    );
}

#[test]
fn nan_observation_is_an_error() {
    let bytes = AlignedBytes::new(&small_file());
    let policy = HandPolicy::load(&bytes, &mut []).unwrap();
    let mut obs = vec![0.1f32; 65];
    let mut action = [9.0f32; 15];
    policy.forward(&obs, &mut action).unwrap();
    assert!(action.iter().zip(policy.info().action_names.iter()).all(|(a, _)| a.abs() <= 0.05));
    obs[17] = f32::NAN;
    let before = action;
    assert_eq!(
        policy.forward(&obs, &mut action),
        Err(PolicyError::Runtime(RuntimeError::NonFiniteObs { index: 17 }))
    );
    obs[17] = f32::NEG_INFINITY;
    assert_eq!(
        policy.forward(&obs, &mut action),
        Err(PolicyError::Runtime(RuntimeError::NonFiniteObs { index: 17 }))
    );
    assert_eq!(action, before);
}

/// Every truncation and every single-bit flip of a real exported policy file is rejected
/// with a typed error (a panic fails the test).
#[test]
fn every_truncation_and_bit_flip_is_rejected() {
    let bytes = small_file();
    let mut storage = vec![0.0f32; vge_runtime::storage_len(&[65, 16, 15])];
    HandPolicy::load(&bytes, &mut storage).unwrap();
    for n in 0..bytes.len() {
        let err = HandPolicy::load(&bytes[..n], &mut storage).unwrap_err();
        assert!(
            matches!(err, PolicyError::TooShort { .. } | PolicyError::LengthMismatch { .. }),
            "{n}: {err}"
        );
    }
    let mut flipped = bytes.clone();
    for bit in 0..bytes.len() * 8 {
        let (i, mask) = (bit / 8, 1u8 << (bit % 8));
        flipped[i] ^= mask;
        let err = HandPolicy::load(&flipped, &mut storage).unwrap_err();
        match i {
            0..8 => assert_eq!(err, PolicyError::BadMagic),
            // Version 3 with bit 0 or 1 flipped is 2 or 1, versions this reader knows: the
            // checksum catches those.
            8 if mask <= 2 => {
                assert!(matches!(err, PolicyError::ChecksumMismatch { .. }), "bit {bit}: {err}")
            }
            8..10 => assert!(matches!(err, PolicyError::UnsupportedVersion { .. }), "bit {bit}: {err}"),
            10..12 => assert!(matches!(err, PolicyError::UnsupportedFlags { .. })),
            12..16 => assert!(matches!(err, PolicyError::LengthMismatch { .. })),
            _ => assert!(matches!(err, PolicyError::ChecksumMismatch { .. }), "bit {bit}: {err}"),
        }
        flipped[i] ^= mask;
    }
    eprintln!(
        "{} truncations and {} bit flips of a {}-byte file rejected",
        bytes.len(),
        bytes.len() * 8,
        bytes.len()
    );
}

/// Every truncation of the full-size policy, and bit flips spread over it.
#[test]
fn full_size_truncations_and_sampled_flips_are_rejected() {
    let bytes = big_file();
    let mut storage = vec![0.0f32; vge_runtime::storage_len(&[65, 256, 256, 15])];
    HandPolicy::load(&bytes, &mut storage).unwrap();
    for n in 0..bytes.len() {
        assert!(HandPolicy::load(&bytes[..n], &mut storage).is_err(), "truncation to {n}");
    }
    let mut flipped = bytes.clone();
    let mut state = 0x9E37_79B9_u64;
    for _ in 0..300 {
        state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
        let bit = (state >> 16) as usize % (bytes.len() * 8);
        flipped[bit / 8] ^= 1 << (bit % 8);
        assert!(HandPolicy::load(&flipped, &mut storage).is_err(), "bit {bit}");
        flipped[bit / 8] ^= 1 << (bit % 8);
    }
}

/// Single-bit flips of the payload with the CRC recomputed, so that they reach the decoder:
/// each is either still a valid policy (a changed weight or name) that runs without panicking,
/// or a typed error.
#[test]
fn every_payload_bit_flip_behind_a_valid_crc_decodes_or_errors() {
    let bytes = small_file();
    let mut storage = vec![0.0f32; 4096];
    let obs = [0.3f32; 65];
    let mut action = [0.0f32; 15];
    let (mut accepted, mut rejected) = (0usize, 0usize);
    let mut flipped = bytes.clone();
    for bit in 16 * 8..(bytes.len() - 4) * 8 {
        let (i, mask) = (bit / 8, 1u8 << (bit % 8));
        flipped[i] ^= mask;
        refix(&mut flipped);
        match HandPolicy::load(&flipped, &mut storage) {
            Ok(p) => {
                accepted += 1;
                let _ = p.forward(&obs, &mut action);
            }
            Err(e) => {
                rejected += 1;
                assert!(!e.to_string().is_empty());
            }
        }
        flipped[i] ^= mask;
    }
    eprintln!("payload flips with valid CRC: {accepted} still valid, {rejected} rejected");
    assert!(rejected > 0 && accepted > 0);
}
