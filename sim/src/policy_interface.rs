//! What a policy file must declare to drive a hand: observations in the layout of its
//! observation set for that hand, and one action per joint named after the hand's joints, in
//! order. Sizes alone are not enough: the same shape with other slices or joints in another
//! order would run and move the wrong fingers. Every place that runs a policy file on a hand
//! (the success test, scoring, the bridge, Python) checks this before it loads the weights.

use vge_hand::Hand;
use vge_runtime::policy::PolicyInfo;

use crate::observation::ObservationLayout;

/// Checks a policy file's description ([`vge_runtime::policy::inspect`]) against `hand` and
/// the observation `layout` it will be given: sizes, observation slices and action names; the
/// error names what differs.
pub fn check_policy_interface(
    info: &PolicyInfo<'_>,
    hand: &Hand,
    layout: &ObservationLayout,
) -> Result<(), String> {
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
    crate::action::check_action_names(hand, info.action_names.iter())
        .map_err(|e| format!("other actions: {e}"))
}
