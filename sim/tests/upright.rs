//! The upright task's bound ([`EnvConfig::upright_within_rad`]) on the real rapier world: the
//! object's tilt is read every step, and the bound ends the episode as a drop on the first
//! step past it and changes nothing before.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use vge_sim::{Env, EnvConfig, StepResult};

/// The steps of one episode (seed 3) under random actions (their own seeded generator), to
/// its end or 400 steps.
fn episode(upright_within_rad: Option<f32>) -> Vec<StepResult> {
    let config = EnvConfig { upright_within_rad, ..EnvConfig::default() };
    let max_action_rad = config.max_action_rad;
    let mut env = Env::new(config).expect("config");
    env.reset(3).expect("reset");
    let joints = env.config().hand.num_joints();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut steps = Vec::new();
    for _ in 0..400 {
        let action: Vec<f32> =
            (0..joints).map(|_| rng.random_range(-max_action_rad..=max_action_rad)).collect();
        let r = env.step(&action).expect("step");
        let ended = r.terminated || r.truncated;
        steps.push(r);
        if ended {
            break;
        }
    }
    steps
}

#[test]
fn the_tilt_bound_ends_the_episode_as_a_drop_on_its_first_step_past_it() {
    let free = episode(None);
    assert!(free.iter().all(|r| !r.info.tipped_over), "no bound, no tipping over");
    assert!(free[0].info.object_tilt_rad < 0.02, "upright after the grasp: {}", free[0].info.object_tilt_rad);
    // The most the object tipped before it fell (if it did): the random hand tips it.
    let held = free.iter().take_while(|r| !r.info.dropped);
    let most_rad = held.map(|r| r.info.object_tilt_rad).fold(0.0, f32::max);
    assert!(most_rad > 0.1, "random actions tip the cube: at most {most_rad} rad");

    let bound_rad = most_rad / 2.0;
    let first_past =
        free.iter().position(|r| r.info.object_tilt_rad > bound_rad).expect("a step past the bound");
    let bounded = episode(Some(bound_rad));
    assert_eq!(bounded.len(), first_past + 1, "ended on the first step past {bound_rad} rad");
    assert_eq!(bounded[..first_past], free[..first_past], "the same steps before it, bit for bit");
    let last = &bounded[first_past];
    assert!(
        last.terminated && !last.truncated && last.info.dropped && last.info.tipped_over,
        "{:?}",
        last.info
    );
    assert_eq!(last.info.object_tilt_rad, free[first_past].info.object_tilt_rad);
    assert_eq!(
        (last.obs.as_slice(), last.reward),
        (free[first_past].obs.as_slice(), free[first_past].reward)
    );
}

#[test]
fn a_tilt_bound_outside_zero_to_pi_is_refused() {
    for bad in [0.0, -0.2, 3.2, f32::NAN] {
        let config = EnvConfig { upright_within_rad: Some(bad), ..EnvConfig::default() };
        let err = Env::new(config).expect_err("refused");
        assert!(err.to_string().contains("upright bound"), "{bad}: {err}");
    }
}
