//! The policy's action: [`crate::NUM_JOINTS`] changes of the joint position targets (rad)
//! per control step, finger-major like the joint vector, each clipped to a largest step.
//! Physics-free, so that the env and the bridge (whose CAN-only build has no simulator)
//! clip with the same default.

/// Default largest joint-target change per control step (rad): the env's
/// `EnvConfig::max_action_rad` and the bridge's `--max-delta-rad`.
pub const DEFAULT_MAX_ACTION_RAD: f32 = 0.05;
