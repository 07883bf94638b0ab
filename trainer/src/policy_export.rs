//! What a trained hand actor becomes on disk: the policy file's metadata for the hand's
//! observation and action layouts, and the export of an actor's variables.

use tch::nn::VarStore;
use vge_export::{ActorSpec, ExportError, ObsNorm, ObsSlice, PolicyMeta, Provenance, export_policy};
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
    }
}

/// Policy-file bytes of the actor in `actor_vs` (variables `actor.*`, as `nets::GaussianActor`
/// names them) for the hand of `env`.
pub fn export_hand_actor(
    actor_vs: &VarStore,
    hidden: &[usize],
    env: &EnvConfig,
    provenance: Provenance,
) -> Result<Vec<u8>, ExportError> {
    let spec = ActorSpec { obs_dim: OBS_DIM, hidden: hidden.to_vec(), act_dim: vge_sim::NUM_JOINTS };
    let mut meta = hand_policy_meta(env, provenance);
    // The actor's normaliser (`nets::ObsNormaliser`), when it has one, goes into the file so
    // the runtime normalises and clips exactly as the actor did in training.
    let vars = actor_vs.variables();
    if let (Some(mean), Some(std)) = (vars.get("actor.obs_mean"), vars.get("actor.obs_std")) {
        let to_vec = |t: &tch::Tensor| Vec::<f32>::try_from(t.to_kind(tch::Kind::Float).view(-1));
        match (to_vec(mean), to_vec(std)) {
            (Ok(mean), Ok(std)) if mean.len() == OBS_DIM && std.len() == OBS_DIM => {
                meta.obs_norm = ObsNorm { mean, std, clip: Some(crate::nets::OBS_CLIP as f32) };
            }
            _ => {
                return Err(ExportError::MissingVariable {
                    name: "actor.obs_mean/obs_std of the observation size".to_owned(),
                });
            }
        }
    }
    export_policy(actor_vs, "actor", &spec, meta)
}
