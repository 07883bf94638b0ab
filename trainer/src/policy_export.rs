//! What a trained hand actor becomes on disk: the export of an actor's variables, with the
//! hand's metadata ([`hand_policy_meta`]).

use tch::nn::VarStore;
use vge_export::{ActorSpec, ExportError, ObsNorm, Provenance};
use vge_export_tch::export_policy;
use vge_run::config::Config;
pub use vge_run::policy_meta::hand_policy_meta;
use vge_sim::EnvConfig;
use vge_sim::observation::{ObservationLayout, ObservationSet};

use crate::learner::Learner;
use crate::train::TrainError;

/// The actor of `learner` encoded as a policy file (hand metadata, provenance with the config
/// hash, seed and steps).
pub fn export_actor(config: &Config, learner: &dyn Learner, steps: u64) -> Result<Vec<u8>, TrainError> {
    let hidden: Vec<usize> = config.sac.hidden.iter().map(|&h| h as usize).collect();
    let provenance = Provenance {
        vge_version: env!("CARGO_PKG_VERSION").to_owned(),
        config_hash: config.hash_hex(),
        seed: config.seed,
        steps,
    };
    let env = config.env_config(0)?;
    let set = config.env.observation_set().map_err(|e| vge_sim::SimError::InvalidConfig(e.to_string()))?;
    Ok(export_hand_actor(learner.actor_vs(), &hidden, &env, set, provenance)?)
}

/// Policy-file bytes of the actor in `actor_vs` (variables `actor.*`, as `nets::GaussianActor`
/// names them) for the hand of `env`, observing `set`.
pub fn export_hand_actor(
    actor_vs: &VarStore,
    hidden: &[usize],
    env: &EnvConfig,
    set: ObservationSet,
    provenance: Provenance,
) -> Result<Vec<u8>, ExportError> {
    let obs_dim = ObservationLayout::new(set, env.hand.num_joints(), env.hand.num_fingers()).dim();
    let spec = ActorSpec { obs_dim, hidden: hidden.to_vec(), act_dim: env.hand.num_joints() };
    let mut meta = hand_policy_meta(env, set, provenance);
    // The actor's normaliser (`nets::ObsNormaliser`), when it has one, goes into the file so
    // the runtime normalises and clips exactly as the actor did in training.
    let vars = actor_vs.variables();
    if let (Some(mean), Some(std)) = (vars.get("actor.obs_mean"), vars.get("actor.obs_std")) {
        let to_vec = |t: &tch::Tensor| Vec::<f32>::try_from(t.to_kind(tch::Kind::Float).view(-1));
        match (to_vec(mean), to_vec(std)) {
            (Ok(mean), Ok(std)) if mean.len() == obs_dim && std.len() == obs_dim => {
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
