//! The policy's action: [`crate::NUM_JOINTS`] changes of the joint position targets (rad)
//! per control step, finger-major like the joint vector, each clipped to a largest step.
//! Physics-free, so that the env and the bridge (whose CAN-only build has no simulator)
//! clip with the same default.

/// Default largest joint-target change per control step (rad): the env's
/// `EnvConfig::max_action_rad` and the bridge's `--max-delta-rad`.
pub const DEFAULT_MAX_ACTION_RAD: f32 = 0.05;

/// The action's entries by name, finger-major as the joint vector: `thumb.roll`,
/// `thumb.flex_prox`, `thumb.flex_dist`, `index.roll`, ... (the names a hand policy file
/// carries).
pub fn action_names() -> impl Iterator<Item = String> {
    use crate::kinematics::{FINGER_NAMES, JOINT_NAMES};
    FINGER_NAMES.iter().flat_map(|f| JOINT_NAMES.iter().map(move |j| format!("{f}.{j}")))
}

/// Checks a policy's action names against the hand's joints, in order: a file whose outputs
/// drive other joints, or these joints in another order, would move the wrong fingers, so
/// it is refused with both lists.
pub fn check_action_names<'a>(names: impl IntoIterator<Item = &'a str>) -> Result<(), String> {
    let got: Vec<&str> = names.into_iter().collect();
    let want: Vec<String> = action_names().collect();
    if got.len() == want.len() && got.iter().zip(&want).all(|(g, w)| g == w) {
        return Ok(());
    }
    Err(format!("the policy's actions are [{}], the hand's joints [{}]", got.join(", "), want.join(", ")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hands_own_names_pass_and_a_swap_or_a_missing_joint_is_refused() {
        let names: Vec<String> = action_names().collect();
        assert_eq!(names.len(), crate::NUM_JOINTS);
        assert_eq!((names[0].as_str(), names[14].as_str()), ("thumb.roll", "little.flex_dist"));
        assert_eq!(check_action_names(names.iter().map(String::as_str)), Ok(()));
        let mut swapped = names.clone();
        swapped.swap(1, 2);
        let err = check_action_names(swapped.iter().map(String::as_str)).expect_err("swapped");
        assert!(err.contains("[thumb.roll, thumb.flex_dist, thumb.flex_prox"), "{err}");
        assert!(check_action_names(names[..14].iter().map(String::as_str)).is_err());
    }
}
