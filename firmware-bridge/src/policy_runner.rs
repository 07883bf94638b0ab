//! An exported policy file on vge-runtime, as the loops' policy: checked against the hand it
//! will drive before its weights are loaded, and fed the observation it was trained on.
//!
//! Every path that runs a policy file (`run` over CAN or against the simulator, vge15 or the
//! Allegro, and `bench`) reads it through [`check_policy`], with the checks `vge eval` makes:
//! the file must be for this hand and this description of it
//! (`vge_sim::policy_interface::check_task`), its observation set (read from its slices,
//! `vge_sim::ObservationSet::of_layout`) must be one the hand can give over this link (a hand
//! without fingertip sensing runs `proprio` policies only), and its sizes, observation slices
//! and action names must be the hand's ([`vge_sim::check_policy_interface`]).

use thiserror::Error;
use vge_hand::Hand;
use vge_runtime::policy::PolicyInfo;
use vge_runtime::{HandPolicy, PolicyError, policy};
use vge_sim::observation::{
    FingertipReading, ObservationLayout, ObservationSet, ProprioHistory, build_observation,
};

/// What turns an observation into a change of the joint targets (rad, in the hand's joint
/// order, one per joint).
pub trait PolicyRunner {
    type Error: std::error::Error + Send + Sync + 'static;
    /// Writes the action for `obs` into `action` (as long as the hand has joints).
    fn act(&mut self, obs: &[f32], action: &mut [f32]) -> Result<(), Self::Error>;
}

#[derive(Debug, Error)]
pub enum LoadError {
    #[error("invalid policy file")]
    Invalid(#[from] PolicyError),
    /// Not this hand's policy, an observation this link cannot give, or other sizes, slices
    /// or joints than the hand's.
    #[error("{0}")]
    OtherHand(String),
}

/// What a checked policy is fed: its observation set and that set's layout on the hand.
#[derive(Debug, Clone, PartialEq)]
pub struct PolicyFeed {
    pub set: ObservationSet,
    pub layout: ObservationLayout,
}

/// Checks a policy file's description against `hand`, reached over a link with fingertip
/// sensing or without (`tip_sensing`), before any weight is loaded: the observation the bridge
/// will feed it, or why it cannot drive this hand.
pub fn check_policy(info: &PolicyInfo<'_>, hand: &Hand, tip_sensing: bool) -> Result<PolicyFeed, String> {
    // The hand first: its name says more than a layout that does not fit it.
    vge_sim::policy_interface::check_task(info, hand)?;
    let slices: Vec<(&str, usize, usize)> =
        info.obs_layout.iter().map(|s| (s.name, s.start, s.end)).collect();
    let set = ObservationSet::of_layout(&slices, hand.num_joints(), hand.num_fingers())?;
    let layout = ObservationLayout::new(set, hand.num_joints(), hand.num_fingers());
    if layout.needs_tip_sensing() && !tip_sensing {
        return Err(format!(
            "the policy observes fingertip contacts (observation set `{}`), and the hand {} has no \
             fingertip sensors here: it runs only policies trained with the `proprio` observation set \
             (joint angles and targets, now and at past control steps)",
            set.name(),
            hand.name()
        ));
    }
    vge_sim::check_policy_interface(info, hand, &layout)?;
    Ok(PolicyFeed { set, layout })
}

/// Reads `bytes`' description and checks it for `hand` ([`check_policy`]); the observation it
/// is to be fed and zeroed weight storage for [`RuntimePolicy::load`].
pub fn storage_for(
    bytes: &[u8],
    hand: &Hand,
    tip_sensing: bool,
) -> Result<(PolicyFeed, Vec<f32>), LoadError> {
    let info = policy::inspect(bytes)?;
    // Same size is not same meaning: the slices must be the ones the bridge fills, the
    // actions the joints it commands, in its order.
    let feed = check_policy(&info, hand, tip_sensing).map_err(LoadError::OtherHand)?;
    Ok((feed, vec![0.0; info.storage_len]))
}

/// A loaded hand policy.
#[derive(Debug)]
pub struct RuntimePolicy<'a> {
    pub policy: HandPolicy<'a>,
}

impl<'a> RuntimePolicy<'a> {
    /// Loads `bytes` into `storage` (from [`storage_for`], which checked it for the hand).
    pub fn load(bytes: &'a [u8], storage: &'a mut [f32]) -> Result<Self, LoadError> {
        Ok(Self { policy: HandPolicy::load(bytes, storage)? })
    }

    pub fn control_hz(&self) -> f32 {
        self.policy.info().control_hz
    }
}

impl PolicyRunner for RuntimePolicy<'_> {
    type Error = PolicyError;

    fn act(&mut self, obs: &[f32], action: &mut [f32]) -> Result<(), PolicyError> {
        self.policy.forward(obs, action)
    }
}

/// Builds a policy's observation from raw readings, as the simulator does: the full set from
/// joint angles, targets and fingertip contacts, or the proprioceptive one from joint angles
/// and targets now and at the last control steps ([`ProprioHistory`]).
#[derive(Debug, Clone)]
pub struct Observer {
    set: ObservationSet,
    history: ProprioHistory,
    started: bool,
}

impl Observer {
    pub fn new(set: ObservationSet) -> Self {
        let past = match set {
            ObservationSet::Full => 0,
            ObservationSet::Proprio { history } => history,
        };
        Self { set, history: ProprioHistory::new(past), started: false }
    }

    pub fn set(&self) -> ObservationSet {
        self.set
    }

    /// The observation of one control step; the first after [`Self::new`] or
    /// [`Self::restart`] starts the history (the past is the present repeated).
    pub fn observe(
        &mut self,
        q_rad: &[f32],
        q_target_rad: &[f32],
        contacts: &[Option<FingertipReading>],
    ) -> Vec<f32> {
        match self.set {
            ObservationSet::Full => build_observation(q_rad, q_target_rad, contacts),
            ObservationSet::Proprio { .. } if !self.started => {
                self.started = true;
                self.history.start(q_rad, q_target_rad)
            }
            ObservationSet::Proprio { .. } => self.history.step(q_rad, q_target_rad),
        }
    }

    /// Forgets the past: the next observation starts a new episode.
    pub fn restart(&mut self) {
        self.started = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_proprio_observer_starts_from_the_present_and_then_remembers() {
        let mut o = Observer::new(ObservationSet::Proprio { history: 1 });
        assert_eq!(o.observe(&[1.0], &[2.0], &[]), [1.0, 2.0, 1.0, 2.0]);
        assert_eq!(o.observe(&[3.0], &[4.0], &[]), [3.0, 4.0, 1.0, 2.0]);
        assert_eq!(o.observe(&[5.0], &[6.0], &[]), [5.0, 6.0, 3.0, 4.0]);
        o.restart();
        assert_eq!(o.observe(&[7.0], &[8.0], &[]), [7.0, 8.0, 7.0, 8.0]);
        let mut full = Observer::new(ObservationSet::Full);
        let obs = full.observe(&[0.1, 0.2], &[0.3, 0.4], &[None]);
        assert_eq!(obs.len(), 2 * 2 + 7);
    }
}
