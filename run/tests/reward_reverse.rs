//! The reward cannot be earned by a back-and-forth. VGE seed 1 on the paper's reward
//! (docs/results/paper-reward/cube-fg-vge-seeds/seed-1) learned to turn the cube forward on
//! three fingertips and back on two, where the paper's reward pays nothing either way. Its
//! policy, on the same episode, must collect far more than its net turn under the paper's
//! reward and no more than it under the default one.

use std::path::{Path, PathBuf};

use vge_run::eval::{
    SUCCESS_TEST_EPISODE_S, SUCCESS_TEST_GRASP_NOISE_RAD, eval_policy_file, success_test_env,
};
use vge_sim::EnvConfig;

fn exploit_policy() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/fixtures/policies/paper-reward-exploit.vgep")
}

/// Rotation paid by an episode's rewards (rad): the reward is a rate, paid per control step.
fn paid_rad(episode_return: f64, env: &EnvConfig) -> f64 {
    episode_return / f64::from(env.control_hz)
}

#[test]
fn a_back_and_forth_pays_under_the_papers_reward_and_not_under_the_default() {
    let charged =
        success_test_env(&EnvConfig::default(), SUCCESS_TEST_EPISODE_S, SUCCESS_TEST_GRASP_NOISE_RAD);
    assert!(charged.charge_reverse_rotation, "the default charges backward turns");
    let paper = EnvConfig { charge_reverse_rotation: false, ..charged.clone() };
    let episodes = 2;
    let under_paper = eval_policy_file(&exploit_policy(), &paper, episodes, 0).expect("the policy runs");
    let under_default = eval_policy_file(&exploit_policy(), &charged, episodes, 0).expect("the policy runs");
    for (p, d) in under_paper.per_episode.iter().zip(&under_default.per_episode) {
        // Same episode: the reward does not change the physics.
        assert_eq!(p.rotation_rad, d.rotation_rad);
        assert!(
            paid_rad(p.episode_return, &paper) > p.rotation_rad + 3.0,
            "the paper's reward no longer pays this back-and-forth: {p:?}"
        );
        assert!(
            paid_rad(d.episode_return, &charged) <= d.rotation_rad + 0.05,
            "the default reward paid more than the net turn: {d:?}"
        );
    }
}
