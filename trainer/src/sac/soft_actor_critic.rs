//! SAC's update (Haarnoja et al. 2018; CleanRL's `sac_continuous_action`): the critics
//! towards the soft target, the reparameterised actor (plus the value-weighted BC term), and
//! α when it is tuned; on the shared critic step ([`Sac::critic_step`]).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tch::{Kind, Tensor};

use super::{Batch, Sac, UpdateStats, bc_target, mix_seed, standard_normal};

impl Sac {
    /// SAC: one gradient step of the critics, the actor (plus the BC term when the batch has
    /// one) and α, then the target update.
    pub(super) fn update_sac(&mut self, batch: &Batch) -> UpdateStats {
        let rows = batch.obs.size()[0];
        let act = self.config.net.act_dim;
        let (eps_next, eps_pi) = match self.seed {
            Some(seed) => {
                let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, self.updates, 0x5ac) as u64);
                (Some(standard_normal(&mut rng, rows, act)), Some(standard_normal(&mut rng, rows, act)))
            }
            None => (None, None),
        };
        self.updates += 1;
        let alpha = self.alpha;
        let bc_weight = if self.actor_learns() { self.bc_weight(batch) } else { None };

        // log π is needed for a non-zero or tuned α only.
        let with_log_prob = alpha != 0.0 || self.log_alpha.is_some();
        let q_next: Tensor = tch::no_grad(|| {
            let next = self.actor.sample_opt(&batch.next_obs, eps_next.as_ref(), with_log_prob);
            let q_next = self.target.min_q(&batch.next_obs, &next.action);
            match next.log_prob.filter(|_| alpha != 0.0) {
                Some(log_prob) => q_next - alpha * log_prob,
                None => q_next,
            }
        });
        let (critic_loss, q) = self.critic_step(batch, &q_next);

        // Held (`actor_hold_updates`), only the critics learn.
        let (rl_value, bc_value) = if self.actor_learns() {
            // The actor's loss needs gradients through the critic's input, not its weights.
            self.critic_vs.freeze();
            let (pi, bc_loss) = match (&batch.bc, &bc_weight) {
                (Some(bc), Some(weight)) => {
                    let (pi, log_prob_data) = self.actor.sample_and_log_prob_of(
                        &batch.obs,
                        &bc_target(bc, self.actor.action_scale()),
                        eps_pi.as_ref(),
                        with_log_prob,
                    );
                    let bc_loss = (weight * log_prob_data).mean(Kind::Float) * -bc.beta;
                    (pi, Some(bc_loss))
                }
                _ => (self.actor.sample_opt(&batch.obs, eps_pi.as_ref(), with_log_prob), None),
            };
            let q_pi = self.critic.min_q(&batch.obs, &pi.action);
            let rl_loss = match &pi.log_prob {
                Some(log_prob) if alpha != 0.0 => (alpha * log_prob - &q_pi).mean(Kind::Float),
                _ => -q_pi.mean(Kind::Float),
            };
            let actor_loss = match &bc_loss {
                Some(bc) => &rl_loss + bc,
                None => rl_loss.shallow_clone(),
            };
            self.actor_opt.backward_step(&actor_loss);
            self.critic_vs.unfreeze();

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
            (self.last_actor_loss, 0.0)
        };

        self.soft_update_target();
        UpdateStats {
            critic_loss: critic_loss.double_value(&[]),
            actor_loss: rl_value,
            bc_loss: bc_value,
            alpha,
            mean_q: q.mean(Kind::Float).double_value(&[]),
        }
    }
}
