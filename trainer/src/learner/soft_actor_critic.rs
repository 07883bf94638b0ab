//! Soft Actor-Critic (Haarnoja et al. 2018; CleanRL's `sac_continuous_action`): it acts by
//! sampling its policy; an update steps the critics towards the soft target, the
//! reparameterised actor (plus the value-weighted BC term), and α when it is tuned.

use std::collections::HashMap;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Device, Kind, Tensor};

use super::{
    ActorCritic, Batch, EntropyCoef, Learner, LearnerConfig, UpdateStats, bc_target, mix_seed,
    standard_normal,
};
use crate::optim::Adam;

/// SAC: the shared networks and, when α is tuned, log α with its optimiser and target
/// entropy.
#[derive(Debug)]
pub struct SoftActorCritic {
    core: ActorCritic,
    log_alpha: Option<(Tensor, Adam, f64)>,
    alpha: f64,
}

impl SoftActorCritic {
    /// The learner of `config` (its `entropy` sets α); parameters drawn from `seed` when
    /// given ([`super::build_seeded`]), else from libtorch's generator.
    pub fn new(config: LearnerConfig, device: Device, seed: Option<u64>) -> Result<Self, tch::TchError> {
        let entropy = config.entropy;
        let mut core = ActorCritic::new(config, device)?;
        let (log_alpha, alpha) = match entropy {
            EntropyCoef::Fixed(alpha) => (None, alpha),
            EntropyCoef::Auto { target_entropy, initial } => {
                let log_alpha =
                    Tensor::from_slice(&[initial.ln() as f32]).to_device(device).set_requires_grad(true);
                let opt = Adam::new(vec![log_alpha.shallow_clone()], core.config.critic_lr);
                (Some((log_alpha, opt, target_entropy)), initial)
            }
        };
        if let Some(seed) = seed {
            core.seed_parameters(seed)?;
        }
        Ok(Self { core, log_alpha, alpha })
    }
}

impl Learner for SoftActorCritic {
    fn core(&self) -> &ActorCritic {
        &self.core
    }

    fn core_mut(&mut self) -> &mut ActorCritic {
        &mut self.core
    }

    fn alpha(&self) -> f64 {
        self.alpha
    }

    fn actor_mean_log_std(&self, obs: &Tensor) -> Option<f64> {
        let (_, log_std) = tch::no_grad(|| self.core.actor.distribution(obs));
        Some(log_std.mean(Kind::Float).double_value(&[]))
    }

    /// A sample of the policy, with `eps` as its noise.
    fn behaviour_action(&self, obs: &Tensor, eps: &Tensor) -> Tensor {
        tch::no_grad(|| self.core.actor.sample_with(obs, Some(eps)).action)
    }

    /// One gradient step of the critics, the actor (plus the BC term when the batch has one)
    /// and α, then the target update.
    fn update_step(&mut self, batch: &Batch) -> UpdateStats {
        let rows = batch.obs.size()[0];
        let act = self.core.config.net.act_dim;
        let (eps_next, eps_pi) = match self.core.seed {
            Some(seed) => {
                let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, self.core.updates, 0x5ac) as u64);
                (Some(standard_normal(&mut rng, rows, act)), Some(standard_normal(&mut rng, rows, act)))
            }
            None => (None, None),
        };
        self.core.updates += 1;
        let alpha = self.alpha;
        let bc_weight = if self.core.actor_learns() { self.core.bc_weight(batch) } else { None };

        // log π is needed for a non-zero or tuned α only.
        let with_log_prob = alpha != 0.0 || self.log_alpha.is_some();
        let q_next: Tensor = tch::no_grad(|| {
            let next = self.core.actor.sample_opt(&batch.next_actor_obs, eps_next.as_ref(), with_log_prob);
            let q_next = self.core.target.min_q(&batch.next_obs, &next.action);
            match next.log_prob.filter(|_| alpha != 0.0) {
                Some(log_prob) => q_next - alpha * log_prob,
                None => q_next,
            }
        });
        let (critic_loss, q) = self.core.critic_step(batch, &q_next);

        // Held (`actor_hold_updates`), only the critics learn.
        let (rl_value, bc_value) = if self.core.actor_learns() {
            // The actor's loss needs gradients through the critic's input, not its weights.
            self.core.critic_vs.freeze();
            let (pi, bc_loss) = match (&batch.bc, &bc_weight) {
                (Some(bc), Some(weight)) => {
                    let (pi, log_prob_data) = self.core.actor.sample_and_log_prob_of(
                        &batch.actor_obs,
                        &bc_target(bc, self.core.actor.action_scale()),
                        eps_pi.as_ref(),
                        with_log_prob,
                    );
                    let bc_loss = (weight * log_prob_data).mean(Kind::Float) * -bc.beta;
                    (pi, Some(bc_loss))
                }
                _ => (self.core.actor.sample_opt(&batch.actor_obs, eps_pi.as_ref(), with_log_prob), None),
            };
            let q_pi = self.core.critic.min_q(&batch.obs, &pi.action);
            let rl_loss = match &pi.log_prob {
                Some(log_prob) if alpha != 0.0 => (alpha * log_prob - &q_pi).mean(Kind::Float),
                _ => -q_pi.mean(Kind::Float),
            };
            let actor_loss = match &bc_loss {
                Some(bc) => &rl_loss + bc,
                None => rl_loss.shallow_clone(),
            };
            self.core.actor_opt.backward_step(&actor_loss);
            self.core.critic_vs.unfreeze();

            if let (Some((log_alpha, opt, target_entropy)), Some(log_prob)) =
                (&mut self.log_alpha, &pi.log_prob)
            {
                let log_prob = log_prob.detach();
                let alpha_loss = (-log_alpha.exp() * (log_prob + *target_entropy)).mean(Kind::Float);
                opt.backward_step(&alpha_loss);
                self.alpha = log_alpha.exp().double_value(&[0]);
            }
            (rl_loss.double_value(&[]), bc_loss.map_or(0.0, |t| t.double_value(&[])))
        } else {
            (self.core.last_actor_loss, 0.0)
        };

        self.core.soft_update_target();
        UpdateStats {
            critic_loss: critic_loss.double_value(&[]),
            actor_loss: rl_value,
            bc_loss: bc_value,
            alpha,
            mean_q: q.mean(Kind::Float).double_value(&[]),
        }
    }

    fn own_state(&self) -> Vec<(String, Tensor)> {
        match &self.log_alpha {
            Some((log_alpha, opt, _)) => {
                let mut named = vec![("log_alpha".to_owned(), log_alpha.detach())];
                named.extend(opt.state("alpha_opt"));
                named
            }
            None => Vec::new(),
        }
    }

    fn restore_own_state(&mut self, named: &HashMap<String, Tensor>) -> Result<(), tch::TchError> {
        if let Some((log_alpha, opt, _)) = &mut self.log_alpha {
            crate::saved_state::restore_into(log_alpha, named, "log_alpha")?;
            opt.restore("alpha_opt", named)?;
            self.alpha = log_alpha.exp().f_double_value(&[0])?;
        }
        Ok(())
    }
}
