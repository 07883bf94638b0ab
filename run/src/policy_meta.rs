//! The metadata a hand policy file carries: the hand's observation and action layouts, its
//! action scaling and control rate. Whatever made the actor (vge's trainer, an ONNX import),
//! the file describes the hand it drives the same way.

use vge_export::{ObsNorm, ObsSlice, PolicyMeta, PolicyTask, Provenance};
use vge_sim::EnvConfig;
use vge_sim::observation::{ObservationLayout, ObservationSet};

fn slice(name: &str, range: std::ops::Range<usize>) -> ObsSlice {
    // An observation is a few hundred floats at most: the casts are exact.
    ObsSlice::new(name, range.start as u32..range.end as u32)
}

/// Metadata of a hand policy trained on `env` that observes `set`: its named observation
/// slices, the hand's joint names as action names, actions scaled to the env's largest
/// joint-target change per step, the env's control rate, and its task (the hand by name and
/// description hash, the observation set, the object and the hand's orientation).
pub fn hand_policy_meta(env: &EnvConfig, set: ObservationSet, provenance: Provenance) -> PolicyMeta {
    let layout = ObservationLayout::new(set, env.hand.num_joints(), env.hand.num_fingers());
    let task = PolicyTask {
        hand: env.hand.name().to_owned(),
        hand_sha256: env.hand.description_sha256(),
        observation_set: set.name(),
        object: env.object.shape.name().to_owned(),
        orientation: env.physics.hand_orientation.name().to_owned(),
    };
    let action_names = vge_sim::action::action_names(&env.hand);
    let act_dim = action_names.len();
    PolicyMeta {
        obs_layout: layout.slices().iter().map(|(name, range)| slice(name, range.clone())).collect(),
        action_names,
        obs_norm: ObsNorm::identity(layout.dim()),
        action_scale: vec![env.max_action_rad; act_dim],
        action_offset: vec![0.0; act_dim],
        control_hz: env.control_hz,
        provenance,
        task: Some(task),
    }
}
