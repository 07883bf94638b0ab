//! A tiny continuous task for testing SAC end to end: a 1-D point driven to a target.
//!
//! State: position `x` and target `g`, both drawn uniformly from [-1, 1] at reset.
//! Observation `[x, g - x]`; action `a` in [-1, 1] moves the point by `0.2 a` (velocity
//! control); reward `-|g - x|` after the move; episodes are truncated after 20 steps (never
//! terminal). Doing nothing scores about -13.3 per episode; the optimum is about -1.1.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tch::{Device, Tensor};

use crate::learner::{self, Algorithm, EntropyCoef, LearnerConfig, standard_normal};
use crate::nets::NetSpec;
use crate::replay::{ReplayBuffer, Source};

pub const EPISODE_STEPS: usize = 20;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointMass {
    pub x: f32,
    pub goal: f32,
    pub t: usize,
}

impl PointMass {
    pub fn reset(rng: &mut ChaCha8Rng) -> Self {
        Self { x: rng.random_range(-1.0..=1.0), goal: rng.random_range(-1.0..=1.0), t: 0 }
    }

    pub fn obs(&self) -> [f32; 2] {
        [self.x, self.goal - self.x]
    }

    /// `(reward, truncated)`.
    pub fn step(&mut self, a: f32) -> (f32, bool) {
        self.x = (self.x + 0.2 * a.clamp(-1.0, 1.0)).clamp(-1.5, 1.5);
        self.t += 1;
        (-(self.goal - self.x).abs(), self.t >= EPISODE_STEPS)
    }
}

/// Outcome of [`train_point_mass`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToyResult {
    /// Mean return of the deterministic actor over 20 evaluation episodes.
    pub eval_return: f64,
    /// The same for the zero action.
    pub zero_return: f64,
    pub updates: u64,
}

/// Mean return over 20 seeded episodes of `policy`.
fn evaluate(policy: &mut dyn FnMut(&[f32; 2]) -> f32, seed: u64) -> f64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut total = 0.0;
    for _ in 0..20 {
        let mut env = PointMass::reset(&mut rng);
        loop {
            let a = policy(&env.obs());
            let (r, done) = env.step(a);
            total += f64::from(r);
            if done {
                break;
            }
        }
    }
    total / 20.0
}

/// Trains SAC (64x64 networks, batch 64, UTD 1, 500 random warm-up steps) for `env_steps`
/// steps on the point mass, seeded, and evaluates the deterministic actor.
pub fn train_point_mass(
    algorithm: Algorithm,
    entropy: EntropyCoef,
    seed: u64,
    env_steps: usize,
) -> Result<ToyResult, tch::TchError> {
    let config = LearnerConfig {
        algorithm,
        net: NetSpec { obs_dim: 2, act_dim: 1, hidden: vec![64, 64] },
        columns: crate::learner::ObsColumns::whole(2),
        action_scale: vec![1.0],
        gamma: 0.9,
        tau: 0.01,
        actor_lr: 1e-3,
        critic_lr: 1e-3,
        entropy,
        critic_layer_norm: true,
        min_policy_std: 0.0,
        actor_hold_updates: 0,
        matmul: crate::nets::MatmulPrecision::F32,
    };
    // 64-wide layers gain nothing from a second intra-op thread, and a spinning pool thread
    // fighting another process (or test) for the core slows this loop several-fold.
    tch::set_num_threads(1);
    let mut learner = learner::build_seeded(config, Device::Cpu, seed)?;
    let mut replay =
        ReplayBuffer::new(env_steps.max(1), 2, 1).map_err(|e| tch::TchError::Convert(e.to_string()))?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut env = PointMass::reset(&mut rng);
    let warmup = 500;
    for step in 0..env_steps {
        let obs = env.obs();
        let a = if step < warmup {
            rng.random_range(-1.0f32..=1.0)
        } else {
            let t = Tensor::from_slice(&obs).view([1, 2]);
            let eps = standard_normal(&mut rng, 1, 1);
            learner.behaviour_action(&t, &eps).double_value(&[0, 0]) as f32
        };
        let (r, done) = env.step(a);
        replay
            .push(&obs, &[a], r, &env.obs(), false, Source::Learner, None)
            .map_err(|e| tch::TchError::Convert(e.to_string()))?;
        if done {
            env = PointMass::reset(&mut rng);
        }
        if step >= warmup {
            let batch =
                replay.sample(64, &mut rng, None).map_err(|e| tch::TchError::Convert(e.to_string()))?;
            learner.update(&batch);
        }
    }
    let eval_return = evaluate(
        &mut |o| {
            let t = Tensor::from_slice(o).view([1, 2]);
            tch::no_grad(|| learner.actor().deterministic(&t)).double_value(&[0, 0]) as f32
        },
        seed ^ 0xe7a1,
    );
    let zero_return = evaluate(&mut |_| 0.0, seed ^ 0xe7a1);
    Ok(ToyResult { eval_return, zero_return, updates: learner.updates() })
}
