//! What a policy file must declare to drive a hand: observations in the layout of its
//! observation set for that hand, and one action per joint named after the hand's joints, in
//! order. Sizes alone are not enough: the same shape with other slices or joints in another
//! order would run and move the wrong fingers. Every place that runs a policy file on a hand
//! (the success test, scoring, the bridge, Python) checks this before it loads the weights.

use vge_hand::Hand;
use vge_runtime::policy::PolicyInfo;

use crate::observation::{ObservationLayout, ObservationSet};

/// Checks a policy file's description ([`vge_runtime::policy::inspect`]) against `hand` and
/// the observation `layout` it will be given: sizes, observation slices and action names; the
/// error names what differs.
pub fn check_policy_interface(
    info: &PolicyInfo<'_>,
    hand: &Hand,
    layout: &ObservationLayout,
) -> Result<(), String> {
    check_task(info, hand)?;
    let (obs_dim, act_dim) = (info.obs_dim, info.act_dim);
    let (want_obs, want_act) = (layout.dim(), hand.num_joints());
    if obs_dim != want_obs || act_dim != want_act {
        return Err(format!(
            "the policy maps {obs_dim} observations to {act_dim} actions, the hand {} needs {want_obs} -> {want_act}",
            hand.name()
        ));
    }
    layout
        .check(info.obs_layout.iter().map(|s| (s.name, s.start, s.end)))
        .map_err(|e| format!("another observation layout: {e}"))?;
    // A recorded observation set must be the one its slices spell: a file whose record and
    // layout disagree was written by something else than vge's export.
    if let Some(task) = &info.task {
        let recorded = ObservationSet::parse(task.observation_set)?;
        if ObservationLayout::new(recorded, hand.num_joints(), hand.num_fingers()) != *layout {
            return Err(format!(
                "the policy records the observation set {}, but its inputs are another set's",
                task.observation_set
            ));
        }
    }
    crate::action::check_action_names(hand, info.action_names.iter())
        .map_err(|e| format!("other actions: {e}"))
}

/// The policy's recorded hand against `hand`: a file from before hands were recorded is
/// vge's own hand ([`vge_runtime::policy::UNRECORDED_HAND`]); one of another hand, or of
/// another version of this hand's description, is refused.
pub fn check_task(info: &PolicyInfo<'_>, hand: &Hand) -> Result<(), String> {
    let (name, sha) = match &info.task {
        Some(task) => (task.hand, Some(task.hand_sha256)),
        None => (vge_runtime::policy::UNRECORDED_HAND, None),
    };
    if name != hand.name() {
        return Err(format!("the policy drives the hand {name}, not {}", hand.name()));
    }
    if let Some(sha) = sha
        && *sha != hand.description_sha256()
    {
        let hex = |b: &[u8; 32]| b.iter().map(|x| format!("{x:02x}")).collect::<String>();
        return Err(format!(
            "the policy was trained on another description of the hand {name} (sha256 {}, this one's {}): \
             its joints, gains or geometry may differ",
            hex(sha),
            hex(&hand.description_sha256())
        ));
    }
    Ok(())
}
