//! How a stored observation row splits between the critic and the actor (an asymmetric
//! actor-critic): the critic sees the env's full observation, the first `critic_dim` columns;
//! the actor sees the columns its observation set names. For the full set that is the whole
//! row; for `proprio:K` it is the joint angles and targets at the row's front and the K past
//! steps of them stored after the full observation. The controllers and the critic are used
//! in training only, so they may see what the real hand cannot measure; the actor may not.

use tch::Tensor;
use vge_sim::{EnvConfig, ObservationSet};

/// The columns of a stored row each network sees.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObsColumns {
    /// The critic's: columns `0..critic_dim`.
    pub critic_dim: i64,
    /// The actor's: `(start, len)` runs, in order.
    pub actor: Vec<(i64, i64)>,
}

impl ObsColumns {
    /// Actor and critic see the same `dim` columns.
    #[must_use]
    pub fn whole(dim: i64) -> Self {
        Self { critic_dim: dim, actor: vec![(0, dim)] }
    }

    /// The rows of `env` for an actor observing `set`.
    #[must_use]
    pub fn of(env: &EnvConfig, set: ObservationSet) -> Self {
        let critic_dim = env.observation_layout().dim() as i64;
        match set {
            ObservationSet::Full => Self::whole(critic_dim),
            ObservationSet::Proprio { history } => {
                let joints = env.hand.num_joints() as i64;
                let mut actor = vec![(0, 2 * joints)];
                if history > 0 {
                    actor.push((critic_dim, 2 * joints * history as i64));
                }
                Self { critic_dim, actor }
            }
        }
    }

    /// The actor's observation length.
    #[must_use]
    pub fn actor_dim(&self) -> i64 {
        self.actor.iter().map(|(_, len)| len).sum()
    }

    /// A stored row's length.
    #[must_use]
    pub fn row_dim(&self) -> i64 {
        self.actor.iter().map(|(start, len)| start + len).fold(self.critic_dim, i64::max)
    }

    /// Whether actor and critic see the whole row (no copy is made then).
    #[must_use]
    pub fn is_whole(&self) -> bool {
        self.row_dim() == self.critic_dim && self.actor == [(0, self.critic_dim)]
    }

    /// The critic's part of `rows` (`[batch, row_dim]`).
    pub fn critic_of(&self, rows: &Tensor) -> Tensor {
        if self.row_dim() == self.critic_dim {
            rows.shallow_clone()
        } else {
            rows.narrow(1, 0, self.critic_dim)
        }
    }

    /// The actor's part of `rows` (`[batch, row_dim]`).
    pub fn actor_of(&self, rows: &Tensor) -> Tensor {
        if self.is_whole() {
            return rows.shallow_clone();
        }
        let parts: Vec<Tensor> = self.actor.iter().map(|&(start, len)| rows.narrow(1, start, len)).collect();
        Tensor::cat(&parts, 1)
    }

    /// The stored row of one step: the critic's (full) observation, then the actor's entries
    /// that it does not hold (the runs past `critic_dim`, in order).
    #[must_use]
    pub fn row(&self, full: &[f32], actor_obs: &[f32]) -> Vec<f32> {
        let mut row = Vec::with_capacity(self.row_dim() as usize);
        row.extend_from_slice(full);
        let mut offset = 0usize;
        for &(start, len) in &self.actor {
            let len = len as usize;
            if start >= self.critic_dim {
                row.extend(actor_obs.iter().skip(offset).take(len));
            }
            offset += len;
        }
        row
    }

    /// The actor's entries of one row's values (the same selection on a plain slice).
    #[must_use]
    pub fn actor_values(&self, row: &[f32]) -> Vec<f32> {
        self.actor
            .iter()
            .flat_map(|&(start, len)| row.iter().skip(start as usize).take(len as usize).copied())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_allegro_proprio_actor_sees_joints_targets_and_their_past_and_the_critic_the_full_observation() {
        let env = EnvConfig::for_hand(vge_sim::hands::load("allegro").expect("allegro")).expect("env");
        let full = ObsColumns::of(&env, ObservationSet::Full);
        assert!(full.is_whole());
        assert_eq!((full.critic_dim, full.actor_dim(), full.row_dim()), (60, 60, 60));
        let proprio = ObsColumns::of(&env, ObservationSet::Proprio { history: 2 });
        assert_eq!((proprio.critic_dim, proprio.actor_dim(), proprio.row_dim()), (60, 32 + 64, 60 + 64));
        let row: Vec<f32> = (0..proprio.row_dim()).map(|v| v as f32).collect();
        let actor = proprio.actor_values(&row);
        assert_eq!(actor.len(), 96);
        assert_eq!((actor[31], actor[32], actor[95]), (31.0, 60.0, 123.0));
        let rows = Tensor::from_slice(&row).view([1, proprio.row_dim()]);
        let from_tensor = Vec::<f32>::try_from(proprio.actor_of(&rows).view(-1)).expect("values");
        assert_eq!(from_tensor, actor);
        assert_eq!(proprio.critic_of(&rows).size(), [1, 60]);
        // A step's row puts the actor's past after the full observation, and reads back.
        let full_obs: Vec<f32> = (0..60).map(|v| v as f32).collect();
        let actor_obs: Vec<f32> = (0..96).map(|v| 1000.0 + v as f32).collect();
        let stored = proprio.row(&full_obs, &actor_obs);
        assert_eq!(stored.len(), 124);
        assert_eq!(proprio.actor_values(&stored)[32..], actor_obs[32..]);
        assert_eq!(full.row(&full_obs, &full_obs), full_obs);
    }
}
