//! The learner: an off-policy actor-critic behind the [`Learner`] trait, with its two
//! implementations, each read top to bottom in its own file:
//! - [`SoftActorCritic`] (`soft_actor_critic.rs`; Haarnoja et al. 2018, CleanRL's
//!   `sac_continuous_action`): twin critics with a Polyak-averaged target, a
//!   reparameterised actor, and an entropy coefficient α that is either fixed (0 allowed, as
//!   VGE uses) or tuned to a target entropy;
//! - [`Td3`] (`td3.rs`; Fujimoto et al. 2018, CleanRL's `td3_continuous_action`), the paper's
//!   second learner: the same twin critics, a deterministic actor (the mean head),
//!   target-policy smoothing and delayed actor updates.
//!
//! This module holds what both share ([`ActorCritic`]: the networks and optimisers, the
//! critic step, the BC weights, the target updates, checkpoints) and [`build`], which makes
//! the learner a [`LearnerConfig`] names.

use std::collections::HashMap;
use std::path::Path;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::nn;
use tch::{Device, Kind, Tensor};

use crate::nets::{GaussianActor, MatmulPrecision, NetSpec, TwinCritic};
use crate::optim::{Adam, flatten_storage};

mod obs_columns;
mod soft_actor_critic;
mod td3;
pub mod threads;

pub use obs_columns::ObsColumns;
pub use soft_actor_critic::SoftActorCritic;
pub use td3::Td3;
pub use threads::ThreadGovernor;

/// How the entropy coefficient α is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EntropyCoef {
    /// A constant α; 0 turns SAC into a deterministic-gradient learner with a stochastic actor.
    Fixed(f64),
    /// α tuned so the policy's entropy tracks this target (CleanRL: -act_dim).
    Auto { target_entropy: f64, initial: f64 },
}

/// Which off-policy algorithm the learner runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Algorithm {
    Sac,
    /// TD3's noises are fractions of the action scale (CleanRL: 0.1, 0.2, 0.5 and delay 2).
    Td3 {
        /// Std of the Gaussian noise added to the deterministic action when acting.
        explore_std: f64,
        /// Std of the target-policy smoothing noise, clipped to ±`target_noise_clip`.
        target_noise_std: f64,
        target_noise_clip: f64,
        /// The actor and the targets are updated once per this many critic updates.
        policy_delay: u64,
    },
}

impl Algorithm {
    /// TD3 with the `[td3]` section's defaults (CleanRL's), written once in the config.
    pub fn td3() -> Self {
        Self::td3_of(&vge_run::config::Td3Section::default())
    }

    /// TD3 with a config's `[td3]` section.
    pub fn td3_of(t: &vge_run::config::Td3Section) -> Self {
        Self::Td3 {
            explore_std: t.explore_std,
            target_noise_std: t.target_noise_std,
            target_noise_clip: t.target_noise_clip,
            policy_delay: t.policy_delay,
        }
    }
}

/// The learner's configuration (SAC or TD3, see [`Algorithm`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LearnerConfig {
    pub algorithm: Algorithm,
    /// The critics' networks (`obs_dim`: the env's full observation); the actor's are the
    /// same but for its input, `columns.actor_dim()`.
    pub net: NetSpec,
    /// Which columns of a stored observation row the critic and the actor see.
    pub columns: ObsColumns,
    pub action_scale: Vec<f32>,
    pub gamma: f64,
    /// Polyak factor of the target critic: target ← τ·critic + (1-τ)·target.
    pub tau: f64,
    pub actor_lr: f64,
    pub critic_lr: f64,
    pub entropy: EntropyCoef,
    /// Layer normalisation in the critics' hidden layers (see [`TwinCritic`]).
    pub critic_layer_norm: bool,
    /// SAC: floor of the policy's pre-tanh σ (unit action range); 0 keeps CleanRL's
    /// `exp(LOG_STD_MIN)`. See [`crate::nets::GaussianActor::with_min_std`].
    pub min_policy_std: f64,
    /// Updates that step only the critics (and their targets) before the actor learns.
    pub actor_hold_updates: u64,
    /// The hidden layers' matmuls inside updates (acting and export are always f32).
    pub matmul: MatmulPrecision,
}

impl LearnerConfig {
    /// The learner of a run config: its hand's sizes (observation, action, the actor's
    /// observation set), the `[sac]` section's sizes and rates, `algorithm`, and `[td3]` for
    /// TD3. Refused when the config's hand does not load.
    pub fn for_hand(config: &vge_run::config::Config) -> Result<Self, vge_sim::SimError> {
        use vge_run::config::{AlgorithmName, Alpha, AlphaName};
        let env = config.env_config(0)?;
        let set =
            config.env.observation_set().map_err(|e| vge_sim::SimError::InvalidConfig(e.to_string()))?;
        let columns = ObsColumns::of(&env, set);
        let act = env.hand.num_joints() as i64;
        let sac = &config.sac;
        let entropy = match sac.alpha {
            Alpha::Fixed(a) => EntropyCoef::Fixed(a),
            Alpha::Named(AlphaName::Auto) => EntropyCoef::Auto {
                target_entropy: sac.target_entropy.unwrap_or(-(act as f64)),
                initial: sac.initial_alpha,
            },
        };
        let algorithm = match config.algorithm {
            AlgorithmName::Sac => Algorithm::Sac,
            AlgorithmName::Td3 => Algorithm::td3_of(&config.td3),
        };
        Ok(Self {
            algorithm,
            net: NetSpec { obs_dim: columns.critic_dim, act_dim: act, hidden: sac.hidden.clone() },
            columns,
            action_scale: vec![config.env.max_action_rad; act as usize],
            gamma: sac.gamma,
            tau: sac.tau,
            actor_lr: sac.actor_lr,
            critic_lr: sac.critic_lr,
            entropy,
            critic_layer_norm: sac.critic_layer_norm,
            min_policy_std: sac.min_policy_std,
            actor_hold_updates: sac.actor_hold_updates,
            matmul: sac.matmul,
        })
    }

    /// The actor's networks: the critics' sizes with the actor's observation as input.
    #[must_use]
    pub fn actor_net(&self) -> NetSpec {
        NetSpec { obs_dim: self.columns.actor_dim(), ..self.net.clone() }
    }
}

/// The value-weighted behaviour-cloning term of a batch (the paper's Eq. for L_BC):
/// `L_BC = -beta * mean_batch(mask * max(Q(s,a), 0) * log pi(a|s))`, with `a` the
/// controller's action at `s` ([`Self::action`]) and Q = min of the twins, detached (a
/// weight, not a path for gradients). Negative values weigh 0: a weighted likelihood with a
/// negative weight has no maximum (the paper's reward is mostly positive; this one charges
/// drops and backward turns).
///
/// Sign: the paper writes `sum beta log pi(a|s) Q(s,a)` and the step `theta <- theta -
/// grad L_BC`; taken literally that *lowers* the likelihood of high-value controller actions,
/// the opposite of cloning them. Cloning (raising log pi of valuable actions) needs the
/// minus sign, as in advantage/value-weighted regression; that is what is minimised here.
/// The sum is normalised by the batch size, so beta does not depend on it.
#[derive(Debug)]
pub struct BcTerm {
    pub beta: f64,
    /// `[batch, 1]`: 1 on the rows that are cloned (those with a controller action).
    pub mask: Tensor,
    /// `[batch, act_dim]`: the controller's action at each row's state (any value where the
    /// mask is 0).
    pub action: Tensor,
}

/// Controller actions at the action bound are cloned as this fraction of it: the tanh
/// policy reaches ±1 only at infinite pre-squash values, and the log-density of a point that
/// close to the bound (atanh(1 - 1e-6) = 7.3, tens of σ away) swamps the gradient.
pub const BC_TARGET_MAX_UNIT: f64 = 0.995;

/// One minibatch of transitions; rewards and `done` are `[batch, 1]`. `obs` and `next_obs`
/// are what the critics see, `actor_obs` and `next_actor_obs` what the actor sees (the same
/// tensors unless the actor observes less: [`ObsColumns`]).
#[derive(Debug)]
pub struct Batch {
    pub obs: Tensor,
    pub actor_obs: Tensor,
    pub action: Tensor,
    pub reward: Tensor,
    pub next_obs: Tensor,
    pub next_actor_obs: Tensor,
    /// 1 where the episode terminated (no bootstrap), 0 otherwise (including truncation).
    pub done: Tensor,
    /// The BC term, when the method uses it.
    pub bc: Option<BcTerm>,
}

/// The BC term's controller actions, pulled inside `±BC_TARGET_MAX_UNIT` of the bound.
fn bc_target(bc: &BcTerm, scale: &Tensor) -> Tensor {
    (&bc.action / scale).clamp(-BC_TARGET_MAX_UNIT, BC_TARGET_MAX_UNIT) * scale
}

impl Batch {
    /// A batch without a BC term.
    pub fn new(obs: Tensor, action: Tensor, reward: Tensor, next_obs: Tensor, done: Tensor) -> Self {
        let (actor_obs, next_actor_obs) = (obs.shallow_clone(), next_obs.shallow_clone());
        Self { obs, actor_obs, action, reward, next_obs, next_actor_obs, done, bc: None }
    }

    /// This batch of stored rows split as `columns` says (the actor's and the critics' parts
    /// of `obs` and `next_obs`; the rest shared).
    #[must_use]
    pub fn split(&self, columns: &ObsColumns) -> Self {
        Self {
            obs: columns.critic_of(&self.obs),
            actor_obs: columns.actor_of(&self.obs),
            action: self.action.shallow_clone(),
            reward: self.reward.shallow_clone(),
            next_obs: columns.critic_of(&self.next_obs),
            next_actor_obs: columns.actor_of(&self.next_obs),
            done: self.done.shallow_clone(),
            bc: self.bc.as_ref().map(|bc| BcTerm {
                beta: bc.beta,
                mask: bc.mask.shallow_clone(),
                action: bc.action.shallow_clone(),
            }),
        }
    }
}

/// Losses and diagnostics of one update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpdateStats {
    pub critic_loss: f64,
    pub actor_loss: f64,
    /// The BC part of the actor loss (0 without a BC term).
    pub bc_loss: f64,
    pub alpha: f64,
    pub mean_q: f64,
}

// The files of a checkpoint that [`Learner::save`] writes (checkpoint.rs lists them in its manifest).
pub const ACTOR_FILE: &str = "actor.ot";
pub const CRITIC_FILE: &str = "critic.ot";
pub const TARGET_FILE: &str = "target.ot";
/// TD3 only.
pub const TARGET_ACTOR_FILE: &str = "target_actor.ot";
pub const OPTIM_FILE: &str = "optim.ot";

/// What both learners share: the actor, the twin critics and their target, the optimisers,
/// the update counter and the seed of the updates' noise.
#[derive(Debug)]
pub struct ActorCritic {
    pub config: LearnerConfig,
    pub actor_vs: nn::VarStore,
    pub actor: GaussianActor,
    critic_vs: nn::VarStore,
    critic: TwinCritic,
    target_vs: nn::VarStore,
    target: TwinCritic,
    /// The target critics' parameters, one buffer laid out as the critic optimiser's.
    target_flat: Tensor,
    actor_opt: Adam,
    critic_opt: Adam,
    /// The last actor loss, reported on updates that skip the actor.
    last_actor_loss: f64,
    /// Updates done; with a seed ([`Learner::set_seed`]), update `k` draws its noise from a
    /// generator seeded by (seed, k), so a run is reproducible and resumable without any RNG
    /// state of libtorch's, and independent of other threads using libtorch.
    updates: u64,
    seed: Option<u64>,
}

/// A `[rows, cols]` tensor of standard normal draws from `rng` (Box-Muller), so that
/// sampling does not depend on libtorch's process-wide generator.
pub fn standard_normal(rng: &mut ChaCha8Rng, rows: i64, cols: i64) -> Tensor {
    let n = (rows * cols).max(0) as usize;
    let mut v = Vec::with_capacity(n + 1);
    while v.len() < n {
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        v.push((r * c) as f32);
        v.push((r * s) as f32);
    }
    v.truncate(n);
    Tensor::from_slice(&v).view([rows, cols])
}

/// A 64-bit mix (SplitMix64's finaliser) of a seed and a counter, for per-update seeds.
pub fn mix_seed(seed: u64, counter: u64, salt: u64) -> i64 {
    let mut z = seed ^ salt.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ counter.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 1) as i64
}

impl ActorCritic {
    /// The actor, the critics and the target critics (a copy of the critics), with their
    /// optimisers. Parameters come from libtorch's generator; [`Self::seed_parameters`]
    /// redraws them from a seed.
    fn new(config: LearnerConfig, device: Device) -> Result<Self, tch::TchError> {
        let actor_vs = nn::VarStore::new(device);
        let actor = GaussianActor::new(&actor_vs.root(), &config.actor_net(), &config.action_scale)
            .with_min_std(config.min_policy_std);
        let critic_vs = nn::VarStore::new(device);
        let critic =
            TwinCritic::new(&critic_vs.root(), &config.net, &config.action_scale, config.critic_layer_norm);
        let mut target_vs = nn::VarStore::new(device);
        let target =
            TwinCritic::new(&target_vs.root(), &config.net, &config.action_scale, config.critic_layer_norm);
        target_vs.copy(&critic_vs)?;
        target_vs.freeze();
        let target_flat = flatten_storage(&target.parameters().collect::<Vec<_>>());
        let actor_opt = Adam::new(sorted_trainables(&actor_vs), config.actor_lr);
        let critic_opt = Adam::new(critic.parameters().collect(), config.critic_lr);
        Ok(Self {
            config,
            actor_vs,
            actor,
            critic_vs,
            critic,
            target_vs,
            target,
            target_flat,
            actor_opt,
            critic_opt,
            last_actor_loss: 0.0,
            updates: 0,
            seed: None,
        })
    }

    /// Redraws every network parameter from a generator seeded by `seed` (PyTorch's
    /// `nn.Linear` bounds, U(±1/√fan_in)), copies the critics into their target, and seeds
    /// the updates' noise: the networks are then a function of `seed`.
    fn seed_parameters(&mut self, seed: u64) -> Result<(), tch::TchError> {
        let device = self.actor_vs.device();
        let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 0, 0x1417) as u64);
        for vs in [&self.actor_vs, &self.critic_vs] {
            // Trainable parameters only: the normalisers' statistics keep their identity start.
            let mut named: Vec<(String, Tensor)> =
                vs.variables().into_iter().filter(|(_, t)| t.requires_grad()).collect();
            named.sort_by(|a, b| a.0.cmp(&b.0));
            let fan_in = |name: &str| -> Option<i64> {
                // actor.X.weight [out, in]; critic.wI [2, in, out]. Biases use their weight's.
                let weight = if let Some(base) = name.strip_suffix(".bias") {
                    format!("{base}.weight")
                } else if let Some(i) = name.strip_prefix("critic.b") {
                    format!("critic.w{i}")
                } else {
                    name.to_owned()
                };
                let t = &named.iter().find(|(n, _)| *n == weight)?.1;
                Some(t.size()[1])
            };
            for (name, t) in &named {
                let bound = 1.0 / (fan_in(name).unwrap_or(1) as f64).sqrt();
                let n = t.numel();
                let values: Vec<f32> = (0..n).map(|_| rng.random_range(-bound..bound) as f32).collect();
                let src = Tensor::from_slice(&values).view(t.size().as_slice()).to_device(device);
                let mut t = t.shallow_clone();
                tch::no_grad(|| t.f_copy_(&src))?;
            }
        }
        self.target_vs.copy(&self.critic_vs)?;
        self.seed = Some(seed);
        Ok(())
    }

    /// Whether the current update (counted) steps the actor: not while it is held
    /// ([`LearnerConfig::actor_hold_updates`]).
    fn actor_learns(&self) -> bool {
        self.updates > self.config.actor_hold_updates
    }

    /// Q-values min(Q₁, Q₂) of given actions, without gradients.
    fn q_of(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        tch::no_grad(|| self.critic.min_q(obs, action))
    }

    fn set_matmul_precision(&mut self, precision: MatmulPrecision) {
        self.actor.set_matmul_precision(precision);
        self.critic.set_matmul_precision(precision);
        self.target.set_matmul_precision(precision);
    }

    /// `(obs - mean) / std` in the actor (its statistics) and in the critics and the target
    /// critics (theirs).
    fn set_obs_normalisation(&mut self, actor: (&Tensor, &Tensor), critic: (&Tensor, &Tensor)) {
        self.actor.obs_norm.set(actor.0, actor.1);
        self.critic.obs_norm.set(critic.0, critic.1);
        self.target.obs_norm.set(critic.0, critic.1);
    }

    /// One gradient step of both critics towards `r + γ (1 − done) q_next`; returns the
    /// loss and the twins' Q-values of the batch before the step (`[2, batch, 1]`, detached).
    fn critic_step(&mut self, batch: &Batch, q_next: &Tensor) -> (Tensor, Tensor) {
        let not_done: Tensor = 1.0 - &batch.done;
        let y = &batch.reward + not_done * self.config.gamma * q_next;
        let q = self.critic.q_values(&batch.obs, &batch.action);
        // Sum over the twins of each one's mean squared error, as two separate critics would.
        let critic_loss = (&q - y.unsqueeze(0)).square().mean(Kind::Float) * TwinCritic::TWINS as f64;
        self.critic_opt.backward_step(&critic_loss);
        (critic_loss, q.detach())
    }

    /// The BC term's weights `mask · max(min Q(s, a_controller), 0)` from the critics before
    /// this update's step (None without an active BC term). A weighted likelihood needs
    /// weights >= 0: with a negative one, cloning turns into pushing the policy away from the
    /// controller's action, and SAC's log-likelihood has no lower bound, so its mean runs off
    /// and tanh pins every joint at the bound whatever the actor observes. TD3's squared error
    /// is bounded by the tanh, but a negative weight still drives its actions to the bound.
    fn bc_weight(&self, batch: &Batch) -> Option<Tensor> {
        batch
            .bc
            .as_ref()
            .filter(|bc| bc.beta > 0.0)
            .map(|bc| self.q_of(&batch.obs, &bc.action).clamp_min(0.0) * &bc.mask)
    }

    /// target ← target + τ (online − target), in place: one lerp over the critics' flat
    /// buffers.
    fn soft_update_target(&mut self) {
        let tau = self.config.tau;
        tch::no_grad(|| {
            let _ = self.target_flat.lerp_(self.critic_opt.flat(), tau);
        });
    }

    /// The var stores a checkpoint holds, with their file names, in writing order.
    fn stores(&self) -> Vec<(&'static str, &nn::VarStore)> {
        vec![(ACTOR_FILE, &self.actor_vs), (CRITIC_FILE, &self.critic_vs), (TARGET_FILE, &self.target_vs)]
    }

    fn load_stores(&mut self, dir: &Path) -> Result<(), tch::TchError> {
        self.actor_vs.load(dir.join(ACTOR_FILE))?;
        self.critic_vs.load(dir.join(CRITIC_FILE))?;
        self.target_vs.load(dir.join(TARGET_FILE))
    }

    /// The optimisers' state, the update counter and the last actor loss, by name.
    fn state(&self) -> Vec<(String, Tensor)> {
        let mut named = self.actor_opt.state("actor_opt");
        named.extend(self.critic_opt.state("critic_opt"));
        named.push(("updates".to_owned(), Tensor::from_slice(&[self.updates as i64])));
        named.push(("last_actor_loss".to_owned(), Tensor::from_slice(&[self.last_actor_loss])));
        named
    }

    fn restore_state(&mut self, named: &HashMap<String, Tensor>) -> Result<(), tch::TchError> {
        self.actor_opt.restore("actor_opt", named)?;
        self.critic_opt.restore("critic_opt", named)?;
        let updates = crate::saved_state::saved_i64(named, "updates")?;
        self.updates = u64::try_from(updates)
            .map_err(|_| tch::TchError::FileFormat(format!("the checkpoint's updates is {updates}")))?;
        // Absent in checkpoints from before TD3; only a logged number depends on it.
        self.last_actor_loss = if named.contains_key("last_actor_loss") {
            crate::saved_state::saved_f64(named, "last_actor_loss")?
        } else {
            0.0
        };
        Ok(())
    }
}

/// An off-policy learner: how it explores, how it updates from a batch, and what its
/// checkpoint holds. [`SoftActorCritic`] and [`Td3`] implement it; the rest is shared
/// ([`ActorCritic`]).
pub trait Learner: Send + std::fmt::Debug {
    /// The shared networks and optimisers.
    fn core(&self) -> &ActorCritic;
    fn core_mut(&mut self) -> &mut ActorCritic;

    /// The learner's exploratory actions for `obs` given standard-normal noise `eps`
    /// (`[rows, act_dim]`).
    fn behaviour_action(&self, obs: &Tensor, eps: &Tensor) -> Tensor;

    /// One update from `batch`, its matmuls at the configured precision.
    fn update_step(&mut self, batch: &Batch) -> UpdateStats;

    /// The entropy coefficient α (0 for a learner without one).
    fn alpha(&self) -> f64;

    /// Sets the matmul precision of the networks beyond the shared ones.
    fn set_own_matmul_precision(&mut self, _precision: MatmulPrecision) {}
    /// The actor's log-std averaged over `obs` (a batch) and the action's dimensions: how
    /// widely a stochastic actor still explores. `None` for a deterministic actor (TD3).
    fn actor_mean_log_std(&self, _obs: &Tensor) -> Option<f64> {
        None
    }

    /// Sets the observation normalisation of the networks beyond the shared ones (actors: the
    /// actor's statistics).
    fn set_own_obs_normalisation(&mut self, _actor_mean: &Tensor, _actor_std: &Tensor) {}

    /// The var stores beyond the shared ones that a checkpoint holds, with their file names.
    fn own_stores(&self) -> Vec<(&'static str, &nn::VarStore)> {
        Vec::new()
    }

    /// Loads [`Self::own_stores`] from `dir`.
    fn load_own_stores(&mut self, _dir: &Path) -> Result<(), tch::TchError> {
        Ok(())
    }

    /// The learner's own optimiser state (beyond the shared optimisers'), by name.
    fn own_state(&self) -> Vec<(String, Tensor)> {
        Vec::new()
    }

    /// Restores [`Self::own_state`].
    fn restore_own_state(&mut self, _named: &HashMap<String, Tensor>) -> Result<(), tch::TchError> {
        Ok(())
    }

    fn config(&self) -> &LearnerConfig {
        &self.core().config
    }

    fn actor(&self) -> &GaussianActor {
        &self.core().actor
    }

    fn actor_vs(&self) -> &nn::VarStore {
        &self.core().actor_vs
    }

    /// Updates done so far.
    fn updates(&self) -> u64 {
        self.core().updates
    }

    /// Makes every later update draw its noise from a generator seeded by
    /// `(seed, update index)` instead of libtorch's global one.
    fn set_seed(&mut self, seed: u64) {
        self.core_mut().seed = Some(seed);
    }

    /// Q-values min(Q₁, Q₂) of given actions, without gradients (for behaviour-policy choice).
    fn q_of(&self, obs: &Tensor, action: &Tensor) -> Tensor {
        self.core().q_of(obs, action)
    }

    /// One update of the learner's algorithm. Only the update's matmuls take the configured
    /// precision: acting and evaluation compute in f32, as the deployed runtime does.
    fn update(&mut self, batch: &Batch) -> UpdateStats {
        let precision = self.config().matmul;
        self.core_mut().set_matmul_precision(precision);
        self.set_own_matmul_precision(precision);
        let split;
        let batch = if self.config().columns.is_whole() {
            batch
        } else {
            split = batch.split(&self.config().columns);
            &split
        };
        let stats = self.update_step(batch);
        self.core_mut().set_matmul_precision(MatmulPrecision::F32);
        self.set_own_matmul_precision(MatmulPrecision::F32);
        stats
    }

    /// Sets the observation normalisation of every network to `(obs - mean) / std`, from the
    /// statistics of stored rows (each slice has `columns.row_dim()` entries; `std` entries
    /// must be > 0): the critics take theirs, the actor its columns'.
    fn set_obs_normalisation(&mut self, mean: &[f32], std: &[f32]) {
        let columns = self.config().columns.clone();
        let dim = columns.row_dim() as usize;
        assert!(mean.len() == dim && std.len() == dim, "normalisation of {dim} observations");
        assert!(std.iter().all(|&s| s > 0.0 && s.is_finite()), "std must be positive and finite");
        let device = self.actor_vs().device();
        let tensor = |v: &[f32]| Tensor::from_slice(v).to_device(device);
        let critic_dim = columns.critic_dim as usize;
        let (cm, cs) = (tensor(&mean[..critic_dim]), tensor(&std[..critic_dim]));
        let (am, a_s) = (tensor(&columns.actor_values(mean)), tensor(&columns.actor_values(std)));
        self.core_mut().set_obs_normalisation((&am, &a_s), (&cm, &cs));
        self.set_own_obs_normalisation(&am, &a_s);
    }

    /// The files [`Self::save`] writes into a checkpoint folder, in the order it writes them.
    fn checkpoint_files(&self) -> Vec<&'static str> {
        let mut files: Vec<&'static str> = self.core().stores().into_iter().map(|(name, _)| name).collect();
        files.extend(self.own_stores().into_iter().map(|(name, _)| name));
        files.push(OPTIM_FILE);
        files
    }

    /// Saves networks, optimiser states and the update counter under `dir`
    /// ([`Self::checkpoint_files`]: `actor.ot`, `critic.ot`, `target.ot`, `target_actor.ot`
    /// for TD3, `optim.ot`), as [`Self::save_to_memory`] serialises them.
    fn save(&self, dir: &Path) -> Result<(), tch::TchError> {
        for (name, bytes) in self.save_to_memory()? {
            std::fs::write(dir.join(name), bytes)?;
        }
        Ok(())
    }

    /// What [`Self::save`] writes, serialised in memory: (file name, bytes) in
    /// [`Self::checkpoint_files`] order. libtorch then writes no file itself: writing one,
    /// it aborts the process on a full disk (a C++ exception through the FFI) instead of
    /// returning the OS's error.
    fn save_to_memory(&self) -> Result<Vec<(&'static str, Vec<u8>)>, tch::TchError> {
        let mut files = Vec::new();
        for (name, vs) in self.core().stores().into_iter().chain(self.own_stores()) {
            let mut bytes = Vec::new();
            vs.save_to_stream(&mut bytes)?;
            files.push((name, bytes));
        }
        let mut named = self.core().state();
        named.extend(self.own_state());
        let mut bytes = Vec::new();
        Tensor::save_multi_to_stream(&named, &mut bytes)?;
        files.push((OPTIM_FILE, bytes));
        Ok(files)
    }

    /// Restores the networks [`Self::save`] wrote (actor, critics, targets, with the
    /// observation normalisers they hold), leaving the optimiser state and the update
    /// counter as they are: a run that starts from another run's networks.
    fn load_networks(&mut self, dir: &Path) -> Result<(), tch::TchError> {
        self.core_mut().load_stores(dir)?;
        self.load_own_stores(dir)
    }

    /// Restores what [`Self::save`] wrote (same configuration).
    fn load(&mut self, dir: &Path) -> Result<(), tch::TchError> {
        self.load_networks(dir)?;
        let named: HashMap<String, Tensor> = Tensor::load_multi(dir.join(OPTIM_FILE))?.into_iter().collect();
        self.core_mut().restore_state(&named)?;
        self.restore_own_state(&named)
    }
}

/// The learner `config.algorithm` names, its parameters from libtorch's generator.
pub fn build(config: LearnerConfig, device: Device) -> Result<Box<dyn Learner>, tch::TchError> {
    build_with(config, device, None)
}

/// [`build`] with every network parameter drawn from a generator seeded by `seed`, not from
/// libtorch's global generator, and the updates' noise seeded too
/// ([`Learner::set_seed`]): the whole learner is a function of `seed`.
pub fn build_seeded(
    config: LearnerConfig,
    device: Device,
    seed: u64,
) -> Result<Box<dyn Learner>, tch::TchError> {
    build_with(config, device, Some(seed))
}

fn build_with(
    config: LearnerConfig,
    device: Device,
    seed: Option<u64>,
) -> Result<Box<dyn Learner>, tch::TchError> {
    Ok(match config.algorithm {
        Algorithm::Sac => Box::new(SoftActorCritic::new(config, device, seed)?),
        Algorithm::Td3 { .. } => Box::new(Td3::new(config, device, seed)?),
    })
}

/// A var store's trainable variables in name order (HashMap order is not stable, and the
/// optimiser state is saved by position).
fn sorted_trainables(vs: &nn::VarStore) -> Vec<Tensor> {
    let mut named: Vec<(String, Tensor)> = vs.variables().into_iter().collect();
    named.sort_by(|a, b| a.0.cmp(&b.0));
    named.into_iter().filter(|(_, t)| t.requires_grad()).map(|(_, t)| t).collect()
}
