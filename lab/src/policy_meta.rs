//! The metadata a hand policy file carries: the hand's observation and action layouts, its
//! action scaling and control rate. Whatever made the actor (vge's trainer, an ONNX import),
//! the file describes the hand it drives the same way.

use vge_export::{ObsNorm, ObsSlice, PolicyMeta, Provenance};
use vge_sim::EnvConfig;
use vge_sim::observation::ObservationLayout;

fn slice(name: &str, range: std::ops::Range<usize>) -> ObsSlice {
    // An observation is a few hundred floats at most: the casts are exact.
    ObsSlice::new(name, range.start as u32..range.end as u32)
}

/// Metadata of a hand policy trained on `env` that observes `layout`: its named observation
/// slices, the hand's joint names as action names, actions scaled to the env's largest
/// joint-target change per step, and the env's control rate.
pub fn hand_policy_meta(env: &EnvConfig, layout: &ObservationLayout, provenance: Provenance) -> PolicyMeta {
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
        task: None,
    }
}
