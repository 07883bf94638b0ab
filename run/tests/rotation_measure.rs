//! The success test measures turning, not a tipped object's Euler yaw: the stored policy that
//! plain RL learned under the Euler-yaw reward (docs/results/euler-yaw-reward/rl-exploit: it
//! tips the cube to 90° and wiggles it, once scored 166 rad in 30 s) turns nothing, while the
//! stored FGE gait on the same episodes turns the cube by full turns.

use std::path::{Path, PathBuf};

use vge_run::eval::{
    SUCCESS_TEST_EPISODE_S, SUCCESS_TEST_GRASP_NOISE_RAD, eval_policy_file, success_test_env,
};
use vge_sim::EnvConfig;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures")
}

#[test]
fn a_tipped_and_wiggled_cube_is_not_a_turn_and_a_gait_is() {
    let env = success_test_env(&EnvConfig::default(), SUCCESS_TEST_EPISODE_S, SUCCESS_TEST_GRASP_NOISE_RAD);
    let episodes = 4;
    let exploit =
        eval_policy_file(&fixtures().join("policies/euler-yaw-rl-exploit-400k.vgep"), &env, episodes, 0)
            .expect("the exploit policy runs");
    for e in &exploit.per_episode {
        assert!(e.rotation_rad.abs() < 2.0, "the exploit 'turned' the cube: {e:?}");
    }
    assert_eq!(exploit.success_rate, 0.0);
    let gait = eval_policy_file(&fixtures().join("runs/euler-yaw-fge-seed-0/policy.vgep"), &env, episodes, 0)
        .expect("the gait policy runs");
    assert!(
        gait.per_episode.iter().any(|e| e.success() && e.rotation_rad > 10.0),
        "the stored gait no longer turns the cube: {:?}",
        gait.per_episode
    );
}
