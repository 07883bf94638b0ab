//! The metadata a hand policy file carries: the hand's observation and action layouts, its
//! action scaling and control rate. Whatever made the actor (vge's trainer, an ONNX import),
//! the file describes the hand it drives the same way.

use vge_export::{ObsNorm, ObsSlice, PolicyMeta, Provenance};
use vge_sim::EnvConfig;
use vge_sim::kinematics::JOINT_NAMES;
use vge_sim::observation::{OBS_DIM, OBS_LAYOUT};

fn slice(name: &str, range: std::ops::Range<usize>) -> ObsSlice {
    // The observation is 65 floats: the casts are exact.
    ObsSlice::new(name, range.start as u32..range.end as u32)
}

/// Metadata of a hand policy trained on `env`: named observation slices (as
/// `vge_sim::observation` lays them out), `finger.joint` action names, actions scaled to the
/// env's largest joint-target change per step, and the env's control rate.
pub fn hand_policy_meta(env: &EnvConfig, provenance: Provenance) -> PolicyMeta {
    let action_names = env
        .hand
        .fingers
        .iter()
        .flat_map(|f| JOINT_NAMES.iter().map(move |j| format!("{}.{j}", f.name)))
        .collect::<Vec<_>>();
    let act_dim = action_names.len();
    PolicyMeta {
        obs_layout: OBS_LAYOUT.iter().map(|(name, range)| slice(name, range.clone())).collect(),
        action_names,
        obs_norm: ObsNorm::identity(OBS_DIM),
        action_scale: vec![env.max_action_rad; act_dim],
        action_offset: vec![0.0; act_dim],
        control_hz: env.control_hz,
        provenance,
        task: None,
    }
}
