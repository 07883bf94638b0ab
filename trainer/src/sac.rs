//! Soft Actor-Critic's update step (Haarnoja et al. 2018; CleanRL's `sac_continuous_action`
//! layout): twin critics with a Polyak-averaged target, a reparameterised actor, and an
//! entropy coefficient α that is either fixed (0 allowed, as VGE uses) or tuned to a target
//! entropy.

use tch::nn::{self, OptimizerConfig};
use tch::{Device, Kind, Tensor};

use crate::nets::{GaussianActor, NetSpec, TwinCritic};

/// How the entropy coefficient α is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EntropyCoef {
    /// A constant α; 0 turns SAC into a deterministic-gradient learner with a stochastic actor.
    Fixed(f64),
    /// α tuned so the policy's entropy tracks this target (CleanRL: -act_dim).
    Auto { target_entropy: f64, initial: f64 },
}

#[derive(Debug, Clone, PartialEq)]
pub struct SacConfig {
    pub net: NetSpec,
    pub action_scale: Vec<f32>,
    pub gamma: f64,
    /// Polyak factor of the target critic: target ← τ·critic + (1-τ)·target.
    pub tau: f64,
    pub actor_lr: f64,
    pub critic_lr: f64,
    pub entropy: EntropyCoef,
}

impl SacConfig {
    /// The paper's sizes for the hand: obs 65, action 15, 256x256 networks.
    pub fn hand_default(max_delta_rad: f32) -> Self {
        Self {
            net: NetSpec { obs_dim: 65, act_dim: 15, hidden: vec![256, 256] },
            action_scale: vec![max_delta_rad; 15],
            gamma: 0.99,
            tau: 0.005,
            actor_lr: 3e-4,
            critic_lr: 1e-3,
            entropy: EntropyCoef::Auto { target_entropy: -15.0, initial: 0.1 },
        }
    }
}

/// One minibatch of transitions; rewards and `done` are `[batch, 1]`.
#[derive(Debug)]
pub struct Batch {
    pub obs: Tensor,
    pub action: Tensor,
    pub reward: Tensor,
    pub next_obs: Tensor,
    /// 1 where the episode terminated (no bootstrap), 0 otherwise (including truncation).
    pub done: Tensor,
}

/// Losses and diagnostics of one update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpdateStats {
    pub critic_loss: f64,
    pub actor_loss: f64,
    pub alpha: f64,
    pub mean_q: f64,
}

#[derive(Debug)]
pub struct Sac {
    pub config: SacConfig,
    pub actor_vs: nn::VarStore,
    pub actor: GaussianActor,
    critic_vs: nn::VarStore,
    critic: TwinCritic,
    /// Kept alive for the target's variables; updated through `target`'s tensors.
    _target_vs: nn::VarStore,
    target: TwinCritic,
    actor_opt: nn::Optimizer,
    critic_opt: nn::Optimizer,
    log_alpha: Option<(Tensor, nn::Optimizer, f64)>,
    alpha: f64,
}

impl Sac {
    pub fn new(config: SacConfig, device: Device) -> Result<Self, tch::TchError> {
        let actor_vs = nn::VarStore::new(device);
        let actor = GaussianActor::new(&actor_vs.root(), &config.net, &config.action_scale);
        let critic_vs = nn::VarStore::new(device);
        let critic = TwinCritic::new(&critic_vs.root(), &config.net);
        let mut target_vs = nn::VarStore::new(device);
        let target = TwinCritic::new(&target_vs.root(), &config.net);
        target_vs.copy(&critic_vs)?;
        target_vs.freeze();
        let actor_opt = nn::Adam::default().build(&actor_vs, config.actor_lr)?;
        let critic_opt = nn::Adam::default().build(&critic_vs, config.critic_lr)?;
        let (log_alpha, alpha) = match config.entropy {
            EntropyCoef::Fixed(alpha) => (None, alpha),
            EntropyCoef::Auto { target_entropy, initial } => {
                let alpha_vs = nn::VarStore::new(device);
                let log_alpha = alpha_vs.root().var("log_alpha", &[1], nn::Init::Const(initial.ln()));
                let opt = nn::Adam::default().build(&alpha_vs, config.critic_lr)?;
                (Some((log_alpha, opt, target_entropy)), initial)
            }
        };
        Ok(Self {
            config,
            actor_vs,
            actor,
            critic_vs,
            critic,
            _target_vs: target_vs,
            target,
            actor_opt,
            critic_opt,
            log_alpha,
            alpha,
        })
    }

    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// Q-values min(Q₁, Q₂) of given actions, without gradients (for behaviour-policy choice).
    pub fn q_of(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        tch::no_grad(|| self.critic.min_q(obs, action))
    }

    /// One gradient step of the critics, the actor and α, then the target update.
    pub fn update(&mut self, batch: &Batch) -> UpdateStats {
        let gamma = self.config.gamma;
        let alpha = self.alpha;

        let y: Tensor = tch::no_grad(|| {
            let next = self.actor.sample(&batch.next_obs);
            let q_next = self.target.min_q(&batch.next_obs, &next.action) - alpha * next.log_prob;
            let not_done: Tensor = 1.0 - &batch.done;
            &batch.reward + not_done * gamma * q_next
        });
        let q = self.critic.q_values(&batch.obs, &batch.action);
        // Sum over the twins of each one's mean squared error, as two separate critics would.
        let critic_loss = (&q - y.unsqueeze(0)).square().mean(Kind::Float) * TwinCritic::TWINS as f64;
        self.critic_opt.backward_step(&critic_loss);

        // The actor's loss needs gradients through the critic's input, not its weights.
        self.critic_vs.freeze();
        let pi = self.actor.sample(&batch.obs);
        let q_pi = self.critic.min_q(&batch.obs, &pi.action);
        let actor_loss = (alpha * &pi.log_prob - &q_pi).mean(Kind::Float);
        self.actor_opt.backward_step(&actor_loss);
        self.critic_vs.unfreeze();

        if let Some((log_alpha, opt, target_entropy)) = &mut self.log_alpha {
            let log_prob = pi.log_prob.detach();
            let alpha_loss = (-log_alpha.exp() * (log_prob + *target_entropy)).mean(Kind::Float);
            opt.backward_step(&alpha_loss);
            self.alpha = log_alpha.exp().double_value(&[0]);
        }

        self.soft_update_target();
        UpdateStats {
            critic_loss: critic_loss.double_value(&[]),
            actor_loss: actor_loss.double_value(&[]),
            alpha,
            mean_q: q.mean(Kind::Float).double_value(&[]),
        }
    }

    /// target ← target + τ (critic − target), in place, one lerp per parameter tensor.
    fn soft_update_target(&mut self) {
        let tau = self.config.tau;
        tch::no_grad(|| {
            for (mut t, s) in self.target.parameters().zip(self.critic.parameters()) {
                let _ = t.lerp_(&s, tau);
            }
        });
    }
}
