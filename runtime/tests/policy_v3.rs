//! Version-3 policy files against the byte-level test vector of `docs/policy-format.md`
//! (written by hand, independently of `vge-export`'s encoder): the task record read back,
//! arrays still used in place, every malformed record a typed error, random records accepted
//! exactly when they keep the rules, and every truncation and bit flip rejected.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use vge_runtime::format::{FORMAT_VERSION, crc32};
use vge_runtime::policy::{
    MAX_PROPRIO_HISTORY, MAX_TASK_NAME_LEN, TaskInfo, UNRECORDED_HAND, UNRECORDED_OBSERVATION_SET,
    check_task_name, is_observation_set,
};
use vge_runtime::{HandPolicy, Policy, PolicyError};

/// The 216-byte version-3 example of `docs/policy-format.md`: the version-2 example (same
/// network and values) with a task record (hand `allegro`, MJCF sha256 bytes 0x00..0x1f,
/// observation set `proprio:4`, object `cube`, orientation `palm_down`) ending its metadata.
const EXAMPLE_V3: [u8; 216] = [
    0x56, 0x47, 0x45, 0x50, 0x4f, 0x4c, 0x43, 0x59, 0x03, 0x00, 0x00, 0x00, 0xc4, 0x00, 0x00,
    0x00, // header: version 3, N = 196
    0x6a, 0x00, 0x00, 0x00, 0x05, 0x30, 0x2e, 0x31, 0x2e, 0x30, 0x03, 0x61, 0x62, 0x63, 0x07,
    0xe8, // meta_len 106, version 2's metadata...
    0x07, 0x00, 0x00, 0x48, 0x42, 0x02, 0x01, 0x02, 0x01, 0x71, 0x00, 0x01, 0x03, 0x6f, 0x62, 0x6a, 0x01,
    0x02, 0x00, 0x00, 0x01, 0x02, 0x01, 0x02, 0x01, 0x02, 0x61, 0x30, // ...up to ["a0"]
    0x01, 0x07, 0x61, 0x6c, // task present, hand "allegro"...
    0x6c, 0x65, 0x67, 0x72, 0x6f, 0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09,
    0x0a, // ...hand_sha256...
    0x0b, 0x0c, 0x0d, 0x0e, 0x0f, 0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1a, 0x1b,
    0x1c, 0x1d, 0x1e, 0x1f, 0x09, 0x70, 0x72, 0x6f, 0x70, 0x72, 0x69, 0x6f, 0x3a, 0x34,
    0x04, // ..., "proprio:4", ...
    0x63, 0x75, 0x62, 0x65, 0x09, 0x70, 0x61, 0x6c, 0x6d, 0x5f, 0x64, 0x6f, 0x77, 0x6e, 0x00,
    0x00, // "cube", "palm_down", padding
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0x80 obs_mean
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0x90 obs_std
    0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x80, 0xbe, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0xa0 W
    0x00, 0x00, 0x00, 0x3e, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0xb0 b
    0xcd, 0xcc, 0x4c, 0x3d, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, // 0xc0 scale
    0x00, 0x00, 0x00, 0x00, 0x16, 0x7e, 0x81, 0x89, // 0xd0 offset, CRC-32
];

/// Version 2's metadata (file 0x14..0x3c of both examples), before the task record.
const META_V2: std::ops::Range<usize> = 0x14..0x3c;
/// The task record in the example (file 0x3c..0x7e).
const TASK: std::ops::Range<usize> = 0x3c..0x7e;
/// Payload offset of the task record.
const TASK_AT: usize = 0x3c - 16;
/// The arrays' bytes in the example, in order: mean, std, weights, bias, scale, offset.
const ARRAYS: [std::ops::Range<usize>; 6] =
    [0x80..0x88, 0x90..0x98, 0xa0..0xa8, 0xb0..0xb4, 0xc0..0xc4, 0xd0..0xd4];

/// Bytes at a 16-byte aligned address, as a firmware's `#[repr(align(16))]` static holds them.
#[repr(C, align(16))]
struct Aligned<const N: usize>([u8; N]);

static ALIGNED_EXAMPLE: Aligned<216> = Aligned(EXAMPLE_V3);

/// A well-framed file of `version` whose metadata is the example's followed by `task` (the
/// record's bytes, tag included), with the example's arrays at aligned offsets.
fn file_with(version: u16, task: &[u8]) -> Vec<u8> {
    let meta: Vec<u8> = EXAMPLE_V3[META_V2].iter().chain(task).copied().collect();
    let mut b = vge_runtime::format::header(version, 0).to_vec();
    b.extend_from_slice(&u32::try_from(meta.len()).unwrap().to_le_bytes());
    b.extend_from_slice(&meta);
    for array in ARRAYS {
        b.resize(b.len().next_multiple_of(16), 0);
        b.extend_from_slice(&EXAMPLE_V3[array]);
    }
    let n = u32::try_from(b.len() - 16).unwrap();
    b[12..16].copy_from_slice(&n.to_le_bytes());
    let crc = crc32(&b);
    b.extend_from_slice(&crc.to_le_bytes());
    b
}

fn str_bytes(s: &[u8]) -> Vec<u8> {
    // Names here are under 128 bytes: a one-byte varint length.
    let mut v = vec![u8::try_from(s.len()).unwrap()];
    v.extend_from_slice(s);
    v
}

/// A task record (tag `01` and its fields) as bytes.
fn record(hand: &[u8], sha: &[u8; 32], set: &[u8], object: &[u8], orientation: &[u8]) -> Vec<u8> {
    let mut v = vec![1];
    v.extend(str_bytes(hand));
    v.extend_from_slice(sha);
    for s in [set, object, orientation] {
        v.extend(str_bytes(s));
    }
    v
}

const SHA: [u8; 32] = {
    let mut s = [0u8; 32];
    let mut i = 0;
    while i < 32 {
        s[i] = i as u8;
        i += 1;
    }
    s
};

fn inspect(b: &[u8]) -> Result<Option<TaskInfo<'_>>, PolicyError> {
    vge_runtime::policy::inspect(b).map(|info| info.task)
}

#[test]
fn example_decodes_and_runs_in_place() {
    assert_eq!(FORMAT_VERSION, 3);
    assert_eq!(crc32(&EXAMPLE_V3[..212]), 0x8981_7E16);
    assert_eq!(file_with(3, &EXAMPLE_V3[TASK]), EXAMPLE_V3, "the test's builder makes the example");
    let info = vge_runtime::policy::inspect(&EXAMPLE_V3).unwrap();
    assert_eq!((info.format_version, info.obs_dim, info.act_dim, info.num_layers), (3, 2, 1, 1));
    assert_eq!((info.num_params, info.storage_len), (3, 0));
    let task = info.task.unwrap();
    assert_eq!(
        task,
        TaskInfo {
            hand: "allegro",
            hand_sha256: &SHA,
            observation_set: "proprio:4",
            object: "cube",
            orientation: "palm_down"
        }
    );
    assert_eq!(info.action_names.iter().collect::<Vec<_>>(), ["a0"]);

    let policy = HandPolicy::load(&ALIGNED_EXAMPLE.0, &mut []).unwrap();
    assert_eq!(policy.info().task, Some(task));
    let mut a = [0.0f32];
    policy.forward(&[1.0, 3.0], &mut a).unwrap();
    // Same network as the version-1 and -2 examples: tanh(0.5 - 0.25 + 0.125) * 0.05.
    assert!((f64::from(a[0]) - 0.375f64.tanh() * 0.05).abs() < 1e-8, "{}", a[0]);
}

#[test]
fn a_file_without_a_task_record_is_the_unrecorded_hand() {
    // Version 3 with the record absent (tag 00): a generic MLP, read as version 2's files are.
    let bare = file_with(3, &[0]);
    let info = vge_runtime::policy::inspect(&bare).unwrap();
    assert_eq!((info.format_version, info.task), (3, None));
    // Version 2's metadata ends at the action names: no task.
    let v2 = file_with(2, &[]);
    assert_eq!(vge_runtime::policy::inspect(&v2).unwrap().task, None);
    assert_eq!((UNRECORDED_HAND, UNRECORDED_OBSERVATION_SET), ("vge15", "full"));
}

#[test]
fn metadata_of_the_wrong_version_is_refused() {
    // Version 2's metadata labelled 3 (no tag), and version 3's labelled 2 (a tag too many):
    // the metadata no longer ends at `meta_len`.
    let meta_len = Err(PolicyError::Malformed { field: "meta_len", offset: 0 });
    assert_eq!(inspect(&file_with(3, &[])), meta_len);
    assert_eq!(inspect(&file_with(2, &EXAMPLE_V3[TASK])), meta_len);
    assert_eq!(inspect(&file_with(2, &[0])), meta_len);
}

#[test]
fn malformed_records_are_typed_errors() {
    let set_at = TASK_AT + 1 + 8 + 32;
    let too_long = [b'x'; MAX_TASK_NAME_LEN + 1];
    let longest = [b'x'; MAX_TASK_NAME_LEN];
    let cases: [(Vec<u8>, PolicyError); 9] = [
        (vec![2], PolicyError::Malformed { field: "task", offset: TASK_AT }),
        (record(b"", &SHA, b"full", b"", b""), PolicyError::TaskName { field: "task.hand", len: 0 }),
        (
            record(&too_long, &SHA, b"full", b"", b""),
            PolicyError::TaskName { field: "task.hand", len: MAX_TASK_NAME_LEN + 1 },
        ),
        (
            record(b"vge15", &SHA, b"full", &too_long, b""),
            PolicyError::TaskName { field: "task.object", len: MAX_TASK_NAME_LEN + 1 },
        ),
        (
            record(b"vge15", &SHA, b"full", b"", &too_long),
            PolicyError::TaskName { field: "task.orientation", len: MAX_TASK_NAME_LEN + 1 },
        ),
        (record(b"allegro", &SHA, b"proprio:0", b"", b""), PolicyError::BadObservationSet { offset: set_at }),
        (record(b"allegro", &SHA, b"Full", b"", b""), PolicyError::BadObservationSet { offset: set_at }),
        (
            record(b"\xffllegro", &SHA, b"full", b"", b""),
            PolicyError::Malformed { field: "task.hand", offset: TASK_AT + 1 },
        ),
        (
            record(b"allegro", &SHA, b"full\xff", b"", b""),
            PolicyError::Malformed { field: "task.observation_set", offset: set_at },
        ),
    ];
    for (task, expected) in cases {
        assert_eq!(inspect(&file_with(3, &task)), Err(expected), "{task:02x?}");
    }
    let ok = record(&longest, &SHA, b"full", &longest, &longest);
    assert_eq!(inspect(&file_with(3, &ok)).unwrap().unwrap().hand.len(), MAX_TASK_NAME_LEN);
    // A record cut short anywhere (meta_len still matching) reads on into the arrays or runs
    // out: an error, never a task.
    for n in 0..EXAMPLE_V3[TASK].len() {
        assert!(inspect(&file_with(3, &EXAMPLE_V3[TASK][..n])).is_err(), "record cut to {n} bytes");
    }
}

#[test]
fn errors_display() {
    assert_eq!(
        PolicyError::TaskName { field: "task.hand", len: 0 }.to_string(),
        "`task.hand` is empty: a task record names its hand"
    );
    assert_eq!(
        PolicyError::TaskName { field: "task.object", len: 70 }.to_string(),
        "`task.object` is 70 bytes, longer than 64 bytes"
    );
    assert!(PolicyError::BadObservationSet { offset: 7 }.to_string().contains("`proprio:K` (K 1 to 64)"));
}

#[test]
fn observation_sets_have_one_spelling() {
    for ok in ["full", "proprio", "proprio:1", "proprio:9", "proprio:10", "proprio:64"] {
        assert!(is_observation_set(ok), "{ok}");
    }
    for bad in [
        "",
        "Full",
        "full ",
        "proprio:",
        "proprio:0",
        "proprio:65",
        "proprio:01",
        "proprio:+4",
        "proprio:-1",
        "proprio:4 ",
        "proprio:100",
        "proprio:4:2",
        "proprio4",
        "vision",
    ] {
        assert!(!is_observation_set(bad), "{bad:?}");
    }
    assert_eq!(MAX_PROPRIO_HISTORY, 64);
    assert_eq!(check_task_name("task.object", "", false), Ok(()));
    assert_eq!(
        check_task_name("task.hand", "", true),
        Err(PolicyError::TaskName { field: "task.hand", len: 0 })
    );
}

/// xorshift64*: reproducible random records without a dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: u64) -> usize {
        (self.next() % n) as usize
    }

    fn name(&mut self) -> Vec<u8> {
        let len = if self.below(4) == 0 { self.below(100) } else { self.below(12) };
        (0..len).map(|_| b"abz_09:"[self.below(7)]).collect()
    }
}

#[test]
fn random_records_round_trip_exactly_when_they_keep_the_rules() {
    let mut rng = Rng(0x5eed_cafe_f00d_0001);
    let sets: [&[u8]; 8] =
        [b"full", b"proprio", b"proprio:1", b"proprio:64", b"proprio:65", b"proprio:007", b"", b"half"];
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..2000 {
        let (hand, object, orientation) = (rng.name(), rng.name(), rng.name());
        let mut sha = [0u8; 32];
        sha.iter_mut().for_each(|b| *b = rng.next() as u8);
        let set = sets[rng.below(sets.len() as u64)];
        let bytes = file_with(3, &record(&hand, &sha, set, &object, &orientation));
        let valid = (1..=MAX_TASK_NAME_LEN).contains(&hand.len())
            && object.len() <= MAX_TASK_NAME_LEN
            && orientation.len() <= MAX_TASK_NAME_LEN
            && is_observation_set(std::str::from_utf8(set).unwrap());
        match inspect(&bytes) {
            Ok(Some(t)) => {
                assert!(valid);
                accepted += 1;
                assert_eq!(
                    (t.hand.as_bytes(), t.hand_sha256, t.observation_set.as_bytes()),
                    (&hand[..], &sha, set)
                );
                assert_eq!((t.object.as_bytes(), t.orientation.as_bytes()), (&object[..], &orientation[..]));
                // The arrays after a record of any length are still aligned and used in place.
                let mut a = Aligned([0u8; 512]);
                a.0[..bytes.len()].copy_from_slice(&bytes);
                Policy::<'_, 2, 4>::load(&a.0[..bytes.len()], &mut []).unwrap();
            }
            Ok(None) => panic!("a record read as none"),
            Err(e) => {
                assert!(!valid, "{e}");
                assert!(
                    matches!(e, PolicyError::TaskName { .. } | PolicyError::BadObservationSet { .. }),
                    "{e}"
                );
                refused += 1;
            }
        }
    }
    assert!(accepted > 500 && refused > 500, "{accepted} accepted, {refused} refused");
}

#[test]
fn every_truncation_and_bit_flip_is_rejected() {
    for n in 0..EXAMPLE_V3.len() {
        let mut a = Aligned([0u8; 216]);
        a.0[..n].copy_from_slice(&EXAMPLE_V3[..n]);
        assert!(HandPolicy::load(&a.0[..n], &mut []).is_err(), "truncation to {n}");
    }
    for bit in 0..EXAMPLE_V3.len() * 8 {
        let mut b = Aligned(EXAMPLE_V3);
        b.0[bit / 8] ^= 1 << (bit % 8);
        assert!(HandPolicy::load(&b.0, &mut []).is_err(), "bit {bit}");
    }
}
