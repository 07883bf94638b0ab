//! N independent environments stepped across cores with rayon. Each world is stepped by
//! exactly the same code as [`Env::step`] and owns its own generator, so the results are
//! bit-identical to stepping the environments one by one (tested). rapier's `parallel`
//! feature is deliberately not used: it gave nothing for one small world and deadlocked
//! when a world was stepped inside a rayon loop (notes).

use rayon::prelude::*;

use crate::env::{Env, EnvConfig, ResetInfo, StepResult};
use crate::error::SimError;

/// A batch of environments.
#[derive(Debug)]
pub struct VecEnv {
    envs: Vec<Env>,
}

impl VecEnv {
    /// `n` environments with the same configuration.
    pub fn new(config: &EnvConfig, n: usize) -> Result<Self, SimError> {
        let envs = (0..n).map(|_| Env::new(config.clone())).collect::<Result<Vec<_>, _>>()?;
        Ok(Self { envs })
    }

    /// Number of environments.
    #[must_use]
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Whether the batch is empty.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// The environments (for privileged state).
    #[must_use]
    pub fn envs(&self) -> &[Env] {
        &self.envs
    }

    /// Resets every environment, `seeds[i]` for environment `i`.
    pub fn reset(&mut self, seeds: &[u64]) -> Result<Vec<(Vec<f32>, ResetInfo)>, SimError> {
        if seeds.len() != self.envs.len() {
            return Err(SimError::BatchLength { got: seeds.len(), expected: self.envs.len() });
        }
        self.envs.par_iter_mut().zip(seeds.par_iter()).map(|(env, seed)| env.reset(*seed)).collect()
    }

    /// Resets environment `index` alone.
    pub fn reset_one(&mut self, index: usize, seed: u64) -> Result<(Vec<f32>, ResetInfo), SimError> {
        let expected = self.envs.len();
        self.envs.get_mut(index).ok_or(SimError::BatchLength { got: index + 1, expected })?.reset(seed)
    }

    /// Joints per action row: the hand's (every env shares one config).
    #[must_use]
    pub fn action_dim(&self) -> usize {
        self.envs.first().map_or(0, |e| e.config().hand.num_joints())
    }

    /// Steps every environment; `actions` is row-major, one entry per joint per environment.
    /// The whole batch is validated before any world moves.
    pub fn step(&mut self, actions: &[f32]) -> Result<Vec<StepResult>, SimError> {
        let joints = self.action_dim();
        let expected = self.envs.len() * joints;
        if actions.len() != expected || joints == 0 {
            return Err(SimError::ActionLength { got: actions.len(), expected });
        }
        for (env, row) in self.envs.iter().zip(actions.chunks_exact(joints)) {
            env.check_action(row)?;
        }
        self.envs.par_iter_mut().zip(actions.par_chunks_exact(joints)).map(|(env, a)| env.step(a)).collect()
    }
}
