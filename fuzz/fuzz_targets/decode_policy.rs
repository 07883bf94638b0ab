//! Fuzzes the `no_std` policy decoder: `scripts/fuzz.sh [SECONDS]` (coverage-guided, no
//! cargo-fuzz needed) or `RUSTC_BOOTSTRAP=1 cargo fuzz run decode_policy` (from the repository
//! root; seeds in `fuzz/seeds/`).
//!
//! An input starting with the magic is decoded as a whole file. Any other input is taken as a
//! format version (its first byte modulo 3: 1 is version 1, 2 is 2, 0 is 3) and a payload,
//! framed with a valid header and CRC-32 first, so that mutations get past the checksum into
//! the postcard decoder, the aligned array layout (versions 2 and 3), version 3's task record
//! and the field validation. Every file is loaded from a 16-byte aligned copy (versions 2 and
//! 3 read their arrays in place) and from a copy one byte off (which they must refuse with a
//! typed error, never a panic). Whatever loads is run on an observation taken from the input.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vge_runtime::format::{MAGIC, crc32, header};
use vge_runtime::{AlignedBytes, Policy};

fn exercise(file: &[u8], storage: &mut [f32]) {
    let mut shifted = vec![0u8; file.len() + 1];
    shifted[1..].copy_from_slice(file);
    let shifted = AlignedBytes::new(&shifted);
    let _ = Policy::<4, 64>::load(&shifted[1..], storage);
    let aligned = AlignedBytes::new(file);
    let file = aligned.as_bytes();
    let info = vge_runtime::policy::inspect(file);
    let loaded = Policy::<4, 64>::load(file, storage);
    if let (Ok(info), Ok(policy)) = (info, loaded) {
        assert_eq!(policy.obs_dim(), info.obs_dim);
        let _ = info.obs_layout.iter().count();
        let _ = info.action_names.iter().count();
        if let Some(task) = info.task {
            assert!(!task.hand.is_empty() && vge_runtime::policy::is_observation_set(task.observation_set));
            let _ = (task.hand_sha256.len(), task.object.len(), task.orientation.len());
        }
        let mut obs = [0.0f32; 64];
        for (o, c) in obs.iter_mut().zip(file.chunks_exact(4).rev()) {
            *o = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
        let mut action = [0.0f32; 64];
        let n_obs = info.obs_dim.min(64);
        let n_act = info.act_dim.min(64);
        let _ = policy.forward(&obs[..n_obs], &mut action[..n_act]);
        let _ = policy.forward(&[0.0; 64][..n_obs], &mut action[..n_act]);
    }
}

fuzz_target!(|data: &[u8]| {
    let mut storage = vec![0.0f32; 8192];
    if data.starts_with(&MAGIC) {
        exercise(data, &mut storage);
    } else if let Some((&version, payload)) = data.split_first()
        && let Ok(len) = u32::try_from(payload.len())
    {
        let version = match version % 3 {
            1 => 1,
            2 => 2,
            _ => 3,
        };
        let mut file = Vec::with_capacity(payload.len() + 20);
        file.extend_from_slice(&header(version, len));
        file.extend_from_slice(payload);
        let crc = crc32(&file);
        file.extend_from_slice(&crc.to_le_bytes());
        exercise(&file, &mut storage);
    }
});
