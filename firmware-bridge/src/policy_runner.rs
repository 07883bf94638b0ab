//! An exported policy file on vge-runtime, as the loops' policy: checked against the hand it
//! will drive before its weights are loaded, and fed the observation it was trained on.
//!
//! Every path that runs a policy file (`run` over CAN or against the simulator, vge15 or the
//! Allegro, and `bench`) reads it through [`check_policy`]: the file must be for this hand
//! ([`check_task_record`]), its observation set must be one the hand can give over this link
//! (a hand without fingertip sensing runs `proprio` policies only), and its sizes, observation
//! slices and action names must be the hand's ([`vge_sim::check_policy_interface`]).

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

/// The slices of an observation that need fingertip sensing (`vge_sim::observation`'s full set).
const CONTACT_SLICES: [&str; 3] = ["contact_position_m", "contact_normal", "contact_force_n"];

/// Whether the policy file is for `hand`: the one place the bridge compares the hand a policy
/// was trained for with the hand it drives. The file's task record names the hand and the
/// hash of its description (a file without one is for vge's own hand,
/// [`vge_runtime::policy::UNRECORDED_HAND`]); both must be this hand's, and the policy's
/// actions must be the hand's joints in its order.
pub fn check_task_record(info: &PolicyInfo<'_>, hand: &Hand) -> Result<(), String> {
    let refuse = |why: String| format!("not a policy for the hand {}: {why}", hand.name());
    let (name, sha256) = match &info.task {
        Some(task) => (task.hand, Some(task.hand_sha256)),
        None => (vge_runtime::policy::UNRECORDED_HAND, None),
    };
    if name != hand.name() {
        let unrecorded = if info.task.is_none() { " (a file without a task record is its)" } else { "" };
        return Err(refuse(format!("it was trained for the hand {name}{unrecorded}")));
    }
    if let Some(sha256) = sha256
        && *sha256 != hand.description_sha256()
    {
        let hex = |b: &[u8; 32]| b.iter().map(|x| format!("{x:02x}")).collect::<String>();
        return Err(refuse(format!(
            "it was trained on another description of it (sha256 {}, this one's {}): its joints, gains \
             or geometry may differ",
            hex(sha256),
            hex(&hand.description_sha256())
        )));
    }
    vge_sim::action::check_action_names(hand, info.action_names.iter()).map_err(refuse)
}

/// The observation set a policy file observes: its task record's, else read from its slices:
/// `full` where it has a fingertip contact slice, else `proprio` with as many past steps as
/// its `q_rad_past` slice holds (0 without one). A record or layout that is neither is left
/// for [`vge_sim::check_policy_interface`] to refuse, naming the difference.
#[must_use]
pub fn observation_set_of(info: &PolicyInfo<'_>, num_joints: usize) -> ObservationSet {
    if let Some(set) = info.task.as_ref().and_then(|t| ObservationSet::parse(t.observation_set).ok()) {
        return set;
    }
    if info.obs_layout.iter().any(|s| CONTACT_SLICES.contains(&s.name)) {
        return ObservationSet::Full;
    }
    let history = info
        .obs_layout
        .get("q_rad_past")
        .map_or(0, |s| s.end.saturating_sub(s.start).div_ceil(num_joints.max(1)));
    ObservationSet::Proprio { history }
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
    check_task_record(info, hand)?;
    let set = observation_set_of(info, hand.num_joints());
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
