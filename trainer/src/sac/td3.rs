//! TD3's update (Fujimoto et al. 2018; CleanRL's `td3_continuous_action`), the paper's
//! second learner: the critics towards a smoothed target-policy value, and every
//! `policy_delay` updates the deterministic actor (plus the BC term) and both targets; on
//! the shared critic step ([`Sac::critic_step`]).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor, nn};

use super::{Batch, Sac, SacConfig, UpdateStats, bc_target, mix_seed, standard_normal};
use crate::nets::GaussianActor;
use crate::optim::flatten_storage;

/// TD3's target actor: a frozen copy of the actor whose trainable tensors live in one flat
/// buffer laid out as the actor optimiser's (both in name order), for a one-op Polyak update.
#[derive(Debug)]
pub(super) struct TargetActor {
    pub(super) vs: nn::VarStore,
    pub(super) actor: GaussianActor,
    pub(super) flat: Tensor,
}

impl TargetActor {
    pub(super) fn new(online: &nn::VarStore, config: &SacConfig) -> Result<Self, tch::TchError> {
        let mut vs = nn::VarStore::new(online.device());
        let actor = GaussianActor::new(&vs.root(), &config.net, &config.action_scale);
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

impl Sac {
    /// TD3: one critic step towards `r + γ min Q'(s', clip(μ'(s') + clip(ε))`; every
    /// `policy_delay` updates an actor step on `-Q₁(s, μ(s))` (plus the BC term) and the
    /// Polyak update of both targets.
    ///
    /// BC for a deterministic actor: with a Gaussian of fixed σ around μ(s), `-log π(a|s)`
    /// is `‖a − μ(s)‖² / 2σ²` up to a constant, so the value-weighted term becomes
    /// `beta · mean(mask · Q(s,a) · ‖(a − μ(s)) / scale‖²)` (σ absorbed into beta).
    pub(super) fn update_td3(
        &mut self,
        batch: &Batch,
        noise_std: f64,
        noise_clip: f64,
        policy_delay: u64,
    ) -> UpdateStats {
        let rows = batch.obs.size()[0];
        let act = self.config.net.act_dim;
        let eps = match self.seed {
            Some(seed) => {
                let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, self.updates, 0x7d3) as u64);
                standard_normal(&mut rng, rows, act)
            }
            None => Tensor::randn([rows, act], (Kind::Float, batch.obs.device())),
        };
        self.updates += 1;
        let delayed_step = self.updates.is_multiple_of(policy_delay.max(1));
        // While the actor is held the targets still follow the critics (and, unchanged, the actor).
        let actor_step = delayed_step && self.actor_learns();
        // The BC weights come from the critics before this update's critic step, and only
        // an update with an actor step reads them.
        let bc_weight = if actor_step { self.bc_weight(batch) } else { None };
        let scale = self.actor.action_scale().shallow_clone();
        let target_actor = match &self.target_actor {
            Some(target) => &target.actor,
            None => unreachable!("TD3 learners are built with a target actor"),
        };

        let q_next: Tensor = tch::no_grad(|| {
            let noise = (eps * noise_std).clamp(-noise_clip, noise_clip);
            let next =
                (target_actor.deterministic(&batch.next_obs) / &scale + noise).clamp(-1.0, 1.0) * &scale;
            self.target.min_q(&batch.next_obs, &next)
        });
        let (critic_loss, q) = self.critic_step(batch, &q_next);

        let mut bc_value = 0.0;
        if actor_step {
            self.critic_vs.freeze();
            let mu = self.actor.deterministic(&batch.obs);
            let rl_loss = -self.critic.q1(&batch.obs, &mu).mean(Kind::Float);
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
            self.actor_opt.backward_step(&actor_loss);
            self.critic_vs.unfreeze();
            self.last_actor_loss = rl_loss.double_value(&[]);
        }
        if delayed_step {
            self.soft_update_target();
        }
        UpdateStats {
            critic_loss: critic_loss.double_value(&[]),
            actor_loss: self.last_actor_loss,
            bc_loss: bc_value,
            alpha: 0.0,
            mean_q: q.mean(Kind::Float).double_value(&[]),
        }
    }
}
