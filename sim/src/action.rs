//! The policy's action: one change of each joint's position target (rad) per control step, in
//! the hand's joint order, each clipped to a largest step. Physics-free, so that the env and
//! the bridge (whose CAN-only build has no simulator) clip with the same default.

use vge_hand::Hand;

/// Default largest joint-target change per control step (rad): the env's
/// `EnvConfig::max_action_rad` and the bridge's `--max-delta-rad`.
pub const DEFAULT_MAX_ACTION_RAD: f32 = 0.05;

/// The action's entries by name: the hand's joint names in its joint order (vge15:
/// `thumb.roll`, `thumb.flex_prox`, ...; the names a hand policy file carries).
#[must_use]
pub fn action_names(hand: &Hand) -> Vec<String> {
    hand.joints().iter().map(|j| j.name.clone()).collect()
}

/// Checks a policy's action names against the hand's joints, in order: a file whose outputs
/// drive other joints, or these joints in another order, would move the wrong fingers, so
/// it is refused with both lists.
pub fn check_action_names<'a>(hand: &Hand, names: impl IntoIterator<Item = &'a str>) -> Result<(), String> {
    let got: Vec<&str> = names.into_iter().collect();
    let want = action_names(hand);
    if got.len() == want.len() && got.iter().zip(&want).all(|(g, w)| g == w) {
        return Ok(());
    }
    Err(format!(
        "the policy's actions are [{}], the hand {}'s joints [{}]",
        got.join(", "),
        hand.name(),
        want.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hands_own_names_pass_and_a_swap_or_a_missing_joint_is_refused() {
        let hand = crate::hands::vge15().expect("vge15");
        let names = action_names(&hand);
        assert_eq!(names.len(), hand.num_joints());
        assert_eq!((names[0].as_str(), names[14].as_str()), ("thumb.roll", "little.flex_dist"));
        assert_eq!(check_action_names(&hand, names.iter().map(String::as_str)), Ok(()));
        let mut swapped = names.clone();
        swapped.swap(1, 2);
        let err = check_action_names(&hand, swapped.iter().map(String::as_str)).expect_err("swapped");
        assert!(err.contains("[thumb.roll, thumb.flex_dist, thumb.flex_prox"), "{err}");
        assert!(check_action_names(&hand, names[..14].iter().map(String::as_str)).is_err());
        let allegro = crate::hands::load("allegro").expect("allegro");
        let err = check_action_names(&allegro, names.iter().map(String::as_str)).expect_err("another hand");
        assert!(err.contains("allegro") && err.contains("ffj0"), "{err}");
    }
}
