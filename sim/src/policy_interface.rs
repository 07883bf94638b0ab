//! What a policy file must declare to drive this hand: [`OBS_DIM`] observations in vge's
//! layout and [`NUM_JOINTS`] actions named after the hand's joints, in order. Sizes alone are
//! not enough: the same 65 -> 15 shape with other slices or joints in another order would
//! run and move the wrong fingers. Every place that runs a policy file on the hand (the
//! success test, scoring, the bridge) checks this before it loads the weights.

use vge_runtime::policy::PolicyInfo;

use crate::NUM_JOINTS;
use crate::observation::OBS_DIM;

/// Checks a policy file's description ([`vge_runtime::policy::inspect`]): its sizes,
/// observation slices and action names against the hand's; the error names what differs.
pub fn check_policy_interface(info: &PolicyInfo<'_>) -> Result<(), String> {
    let (obs_dim, act_dim) = (info.obs_dim, info.act_dim);
    if obs_dim != OBS_DIM || act_dim != NUM_JOINTS {
        return Err(format!(
            "the policy maps {obs_dim} observations to {act_dim} actions, the hand needs {OBS_DIM} -> {NUM_JOINTS}"
        ));
    }
    crate::observation::check_layout(info.obs_layout.iter().map(|s| (s.name, s.start, s.end)))
        .map_err(|e| format!("another observation layout: {e}"))?;
    crate::action::check_action_names(info.action_names.iter()).map_err(|e| format!("other actions: {e}"))
}
