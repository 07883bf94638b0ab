//! Small policy files for the tests: a random two-layer MLP for a hand and an observation set,
//! with the observation slices and action names that set has on that hand and the task record
//! that names both, written with vge_export (no training, no libtorch). Its actions are small (tanh scaled to 0.02 rad), so
//! a run with it stays in the grasp's neighbourhood.

use std::path::{Path, PathBuf};

use vge_export::{LayerRecord, ObsSlice, PolicyFile, PolicyTask, Provenance};
use vge_hand::Hand;
use vge_runtime::format::ACT_TANH;
use vge_sim::observation::{ObservationLayout, ObservationSet};

/// Hidden units of the test policies.
const HIDDEN: usize = 16;

/// Uniform in [-scale, scale) from a 64-bit LCG: deterministic, no dependency.
fn weights(n: usize, seed: &mut u64, scale: f32) -> Vec<f32> {
    (0..n)
        .map(|_| {
            *seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let unit = (*seed >> 40) as f32 / (1u64 << 24) as f32;
            (2.0 * unit - 1.0) * scale
        })
        .collect()
}

/// The bytes of a random policy for `hand` observing `set`.
pub fn policy_bytes(hand: &Hand, set: ObservationSet, seed: u64) -> Vec<u8> {
    let layout = ObservationLayout::new(set, hand.num_joints(), hand.num_fingers());
    let (obs_dim, act_dim) = (layout.dim(), hand.num_joints());
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let layer = |in_dim: usize, out_dim: usize, state: &mut u64| LayerRecord {
        in_dim: in_dim as u32,
        out_dim: out_dim as u32,
        activation: ACT_TANH,
        weights: weights(in_dim * out_dim, state, 0.3),
        bias: weights(out_dim, state, 0.1),
    };
    let layers = vec![layer(obs_dim, HIDDEN, &mut state), layer(HIDDEN, act_dim, &mut state)];
    let file = PolicyFile {
        provenance: Provenance {
            vge_version: "test".to_owned(),
            config_hash: format!("test-{}-{}", hand.name(), set.name()),
            seed,
            steps: 0,
        },
        control_hz: 20.0,
        obs_dim: obs_dim as u32,
        act_dim: act_dim as u32,
        obs_layout: layout
            .slices()
            .iter()
            .map(|(name, r)| ObsSlice::new(*name, r.start as u32..r.end as u32))
            .collect(),
        obs_mean: vec![0.0; obs_dim],
        obs_std: vec![1.0; obs_dim],
        obs_clip: Some(5.0),
        layers,
        action_names: vge_sim::action::action_names(hand),
        action_scale: vec![0.02; act_dim],
        action_offset: vec![0.0; act_dim],
        task: Some(PolicyTask {
            hand: hand.name().to_owned(),
            hand_sha256: hand.description_sha256(),
            observation_set: set.name(),
            object: "cube".to_owned(),
            orientation: String::new(),
        }),
    };
    file.to_bytes().expect("a valid policy file")
}

/// Writes a random policy for `hand` observing `set` into `dir`; its path.
pub fn write_policy(dir: &Path, hand: &Hand, set: ObservationSet, seed: u64) -> PathBuf {
    std::fs::create_dir_all(dir).expect("the policy directory");
    let path = dir.join(format!("{}-{}-{seed}.vgep", hand.name(), set.name().replace(':', "-")));
    std::fs::write(&path, policy_bytes(hand, set, seed)).expect("writes the policy file");
    path
}
