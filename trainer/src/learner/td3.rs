//! TD3 (Fujimoto et al. 2018; CleanRL's `td3_continuous_action`), the paper's second
//! learner: it acts with its deterministic action plus Gaussian noise; an update steps the
//! critics towards a smoothed target-policy value, and every `policy_delay` updates the
//! deterministic actor (plus the BC term) and both targets.

use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Device, Kind, Tensor, nn};

use super::{
    ActorCritic, Algorithm, Batch, Learner, LearnerConfig, TARGET_ACTOR_FILE, UpdateStats, bc_target,
    mix_seed, standard_normal,
};
use crate::nets::{GaussianActor, MatmulPrecision};
use crate::optim::flatten_storage;

/// TD3's target actor: a frozen copy of the actor whose trainable tensors live in one flat
/// buffer laid out as the actor optimiser's (both in name order), for a one-op Polyak update.
#[derive(Debug)]
struct TargetActor {
    vs: nn::VarStore,
    actor: GaussianActor,
    flat: Tensor,
}

impl TargetActor {
    fn new(online: &nn::VarStore, config: &LearnerConfig) -> Result<Self, tch::TchError> {
        let mut vs = nn::VarStore::new(online.device());
        let actor = GaussianActor::new(&vs.root(), &config.actor_net(), &config.action_scale);
        vs.copy(online)?;
        let online_vars = online.variables();
        let mut named: Vec<(String, Tensor)> = vs
            .variables()
            .into_iter()
            .filter(|(name, _)| online_vars.get(name).is_some_and(Tensor::requires_grad))
            .collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        let flat = flatten_storage(&named.into_iter().map(|(_, t)| t).collect::<Vec<_>>());
        vs.freeze();
        Ok(Self { vs, actor, flat })
    }
}

/// TD3: the shared networks, the target actor, and the algorithm's noises and delay.
#[derive(Debug)]
pub struct Td3 {
    core: ActorCritic,
    target_actor: TargetActor,
    /// Std of the Gaussian noise added to the deterministic action when acting.
    explore_std: f64,
    /// Std of the target-policy smoothing noise, clipped to ±`noise_clip`.
    noise_std: f64,
    noise_clip: f64,
    /// The actor and the targets are updated once per this many critic updates.
    policy_delay: u64,
}

impl Td3 {
    /// The learner of `config` (its `algorithm` gives the noises and the delay; `entropy`
    /// does not apply); parameters drawn from `seed` when given ([`super::build_seeded`]),
    /// else from libtorch's generator.
    pub fn new(config: LearnerConfig, device: Device, seed: Option<u64>) -> Result<Self, tch::TchError> {
        let Algorithm::Td3 { explore_std, target_noise_std, target_noise_clip, policy_delay } =
            config.algorithm
        else {
            return Err(tch::TchError::Kind(format!("a TD3 learner built from {:?}", config.algorithm)));
        };
        let mut core = ActorCritic::new(config, device)?;
        let mut target_actor = TargetActor::new(&core.actor_vs, &core.config)?;
        if let Some(seed) = seed {
            core.seed_parameters(seed)?;
            target_actor.vs.copy(&core.actor_vs)?;
        }
        Ok(Self {
            core,
            target_actor,
            explore_std,
            noise_std: target_noise_std,
            noise_clip: target_noise_clip,
            policy_delay,
        })
    }
}

impl Learner for Td3 {
    fn core(&self) -> &ActorCritic {
        &self.core
    }

    fn core_mut(&mut self) -> &mut ActorCritic {
        &mut self.core
    }

    fn alpha(&self) -> f64 {
        0.0
    }

    /// The deterministic action plus `explore_std`-scaled `eps`, clipped to the action range.
    fn behaviour_action(&self, obs: &Tensor, eps: &Tensor) -> Tensor {
        tch::no_grad(|| {
            let scale = self.core.actor.action_scale();
            let unit = self.core.actor.deterministic(obs) / scale + eps * self.explore_std;
            unit.clamp(-1.0, 1.0) * scale
        })
    }

    fn set_own_matmul_precision(&mut self, precision: MatmulPrecision) {
        self.target_actor.actor.set_matmul_precision(precision);
    }

    fn set_own_obs_normalisation(&mut self, mean: &Tensor, std: &Tensor) {
        self.target_actor.actor.obs_norm.set(mean, std);
    }

    fn own_stores(&self) -> Vec<(&'static str, &nn::VarStore)> {
        vec![(TARGET_ACTOR_FILE, &self.target_actor.vs)]
    }

    fn load_own_stores(&mut self, dir: &Path) -> Result<(), tch::TchError> {
        self.target_actor.vs.load(dir.join(TARGET_ACTOR_FILE))
    }

    /// TD3: one critic step towards `r + γ min Q'(s', clip(μ'(s') + clip(ε))`; every
    /// `policy_delay` updates an actor step on `-Q₁(s, μ(s))` (plus the BC term) and the
    /// Polyak update of both targets.
    ///
    /// BC for a deterministic actor: with a Gaussian of fixed σ around μ(s), `-log π(a|s)`
    /// is `‖a − μ(s)‖² / 2σ²` up to a constant, so the value-weighted term becomes
    /// `beta · mean(mask · Q(s,a) · ‖(a − μ(s)) / scale‖²)` (σ absorbed into beta).
    fn update_step(&mut self, batch: &Batch) -> UpdateStats {
        let (noise_std, noise_clip, policy_delay) = (self.noise_std, self.noise_clip, self.policy_delay);
        let rows = batch.obs.size()[0];
        let act = self.core.config.net.act_dim;
        let eps = match self.core.seed {
            Some(seed) => {
                let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, self.core.updates, 0x7d3) as u64);
                standard_normal(&mut rng, rows, act)
            }
            None => Tensor::randn([rows, act], (Kind::Float, batch.obs.device())),
        };
        self.core.updates += 1;
        let delayed_step = self.core.updates.is_multiple_of(policy_delay.max(1));
        // While the actor is held the targets still follow the critics (and, unchanged, the actor).
        let actor_step = delayed_step && self.core.actor_learns();
        // The BC weights come from the critics before this update's critic step, and only
        // an update with an actor step reads them.
        let bc_weight = if actor_step { self.core.bc_weight(batch) } else { None };
        let scale = self.core.actor.action_scale().shallow_clone();
        let target_actor = &self.target_actor.actor;

        let q_next: Tensor = tch::no_grad(|| {
            let noise = (eps * noise_std).clamp(-noise_clip, noise_clip);
            let next = (target_actor.deterministic(&batch.next_actor_obs) / &scale + noise).clamp(-1.0, 1.0)
                * &scale;
            self.core.target.min_q(&batch.next_obs, &next)
        });
        let (critic_loss, q) = self.core.critic_step(batch, &q_next);

        let mut bc_value = 0.0;
        if actor_step {
            self.core.critic_vs.freeze();
            let mu = self.core.actor.deterministic(&batch.actor_obs);
            let rl_loss = -self.core.critic.q1(&batch.obs, &mu).mean(Kind::Float);
            let actor_loss = match (&batch.bc, &bc_weight) {
                (Some(bc), Some(weight)) => {
                    let sq = ((bc_target(bc, &scale) - &mu) / &scale).square().sum_dim_intlist(
                        -1,
                        true,
                        Kind::Float,
                    );
                    let bc_loss = (weight * sq).mean(Kind::Float) * bc.beta;
                    bc_value = bc_loss.double_value(&[]);
                    &rl_loss + bc_loss
                }
                _ => rl_loss.shallow_clone(),
            };
            self.core.actor_opt.backward_step(&actor_loss);
            self.core.critic_vs.unfreeze();
            self.core.last_actor_loss = rl_loss.double_value(&[]);
        }
        if delayed_step {
            self.core.soft_update_target();
            let tau = self.core.config.tau;
            tch::no_grad(|| {
                let _ = self.target_actor.flat.lerp_(self.core.actor_opt.flat(), tau);
            });
        }
        UpdateStats {
            critic_loss: critic_loss.double_value(&[]),
            actor_loss: self.core.last_actor_loss,
            bc_loss: bc_value,
            alpha: 0.0,
            mean_q: q.mean(Kind::Float).double_value(&[]),
        }
    }
}
