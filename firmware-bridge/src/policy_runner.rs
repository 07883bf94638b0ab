//! An exported policy file on vge-runtime, as the control loop's policy.

use thiserror::Error;
use vge_runtime::{HandPolicy, PolicyError, policy};
use vge_sim::NUM_JOINTS;
use vge_sim::observation::OBS_DIM;

use crate::control_loop::PolicyRunner;

#[derive(Debug, Error)]
pub enum LoadError {
    #[error("invalid policy file")]
    Invalid(#[from] PolicyError),
    /// Other sizes, observation slices or joints than the hand's
    /// ([`vge_sim::check_policy_interface`]).
    #[error("{0}")]
    OtherHand(String),
}

/// Weight storage for a policy file: the runtime decodes weights into caller memory.
pub fn storage_for(bytes: &[u8]) -> Result<Vec<f32>, LoadError> {
    let info = policy::inspect(bytes)?;
    // Same size is not same meaning: the slices must be the ones the bridge fills, the
    // actions the joints it commands, in its order.
    vge_sim::check_policy_interface(&info).map_err(LoadError::OtherHand)?;
    Ok(vec![0.0; info.storage_len])
}

/// A loaded hand policy (65 observations -> 15 joint-target changes).
#[derive(Debug)]
pub struct RuntimePolicy<'a> {
    pub policy: HandPolicy<'a>,
}

impl<'a> RuntimePolicy<'a> {
    /// Loads `bytes` into `storage` (from [`storage_for`]).
    pub fn load(bytes: &'a [u8], storage: &'a mut [f32]) -> Result<Self, LoadError> {
        Ok(Self { policy: HandPolicy::load(bytes, storage)? })
    }

    pub fn control_hz(&self) -> f32 {
        self.policy.info().control_hz
    }
}

impl PolicyRunner for RuntimePolicy<'_> {
    type Error = PolicyError;

    fn act(&mut self, obs: &[f32; OBS_DIM]) -> Result<[f32; NUM_JOINTS], PolicyError> {
        let mut action = [0.0; NUM_JOINTS];
        self.policy.forward(obs, &mut action)?;
        Ok(action)
    }
}
