"""VecHandEnv against Gymnasium's own SyncVectorEnv over HandEnvs: the reference
implementation of next-step autoreset."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import vge

N = 3
# Short episodes (truncation) and, for env 1, a hand that opens until the cube drops
# (termination), so that both ends and their autoresets occur.
KEYS = {"episode_length": 12, "grasp_pose_noise_rad": 0.02}


def actions_for(step, rng):
    a = rng.uniform(-0.01, 0.01, size=(N, 15)).astype(np.float32)
    a[1] = -0.05  # open every joint: the cube falls
    return a


def test_autoreset_matches_gymnasiums_sync_vector_env():
    ours = vge.VecHandEnv(N, **KEYS)
    theirs = gym.vector.SyncVectorEnv([lambda: vge.HandEnv(**KEYS) for _ in range(N)])
    assert ours.metadata["autoreset_mode"] == theirs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    a_obs, _ = ours.reset(seed=21)
    b_obs, _ = theirs.reset(seed=21)
    assert np.array_equal(a_obs, b_obs)
    rng = np.random.default_rng(0)
    ended = {"terminated": 0, "truncated": 0}
    for step in range(40):
        actions = actions_for(step, rng)
        a = ours.step(actions)
        b = theirs.step(actions)
        for x, y in zip(a[:4], b[:4]):
            assert x.dtype == y.dtype and np.array_equal(x, y), f"step {step}"
        ended["terminated"] += int(a[2].sum())
        ended["truncated"] += int(a[3].sum())
    assert ended["terminated"] >= 1 and ended["truncated"] >= 4, ended
    # Unseeded resets draw from each env's generator, as HandEnv's do.
    assert np.array_equal(ours.reset()[0], theirs.reset()[0])


def test_next_step_semantics():
    env = vge.VecHandEnv(2, episode_length=2)
    obs0, _ = env.reset(seed=0)
    zero = np.zeros((2, 15), np.float32)
    env.step(zero)
    final_obs, rewards, terminated, truncated, info = env.step(zero)
    assert truncated.tolist() == [True, True] and not info["autoreset"].any()
    obs, rewards, terminated, truncated, info = env.step(np.full((2, 15), 0.05, np.float32))
    # The step after an end resets: the action is ignored, reward 0, no end, a first observation.
    assert info["autoreset"].tolist() == [True, True]
    assert rewards.tolist() == [0.0, 0.0] and not terminated.any() and not truncated.any()
    assert info["step"].tolist() == [0, 0]
    single = vge.HandEnv(episode_length=2)
    single.reset(seed=0)
    for _ in range(2):
        single.step(np.zeros(15, np.float32))
    first, _ = single.reset()  # the seed HandEnv draws after reset(seed=0)
    assert np.array_equal(obs[0], first)
    assert not np.array_equal(obs[0], final_obs[0])


def test_copies_unless_asked_not_to():
    env = vge.VecHandEnv(2, copy=False)
    obs, _ = env.reset(seed=0)
    obs2, *_ = env.step(np.zeros((2, 15), np.float32))
    assert obs2 is obs  # the internal array, overwritten in place
    env = vge.VecHandEnv(2)
    obs, _ = env.reset(seed=0)
    obs2, *_ = env.step(np.zeros((2, 15), np.float32))
    assert obs2 is not obs and not np.array_equal(obs, obs2)


def test_objects_cycle_as_in_training(repo):
    env = vge.VecHandEnv.from_config(repo / "configs/multi-object-fg-vge.toml", 6)
    objects = env.objects
    assert objects[0] == objects[5] and len(set(objects)) == 5


@pytest.mark.parametrize(
    "actions,match",
    [
        (np.zeros((2, 14), np.float32), r"shape \(2, 14\), expected \(3, 15\)"),
        (np.zeros((3, 15), np.complex64), "dtype complex64"),
        (np.where(np.eye(3, 15) > 0, np.nan, 0.0), r"entry \(0, 0\) is not finite"),
    ],
)
def test_bad_actions_raise_value_error(actions, match):
    env = vge.VecHandEnv(3)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(actions)


def test_tilt_and_tipping_over_match_hand_env():
    """With the upright task's bound, each env's tilt and its tipping over read as a HandEnv's
    do, and tipping over ends the episode as a drop."""
    keys = {"episode_length": 200, "upright_within_rad": 0.05}
    ours = vge.VecHandEnv(N, **keys)
    singles = [vge.HandEnv(**keys) for _ in range(N)]
    ours.reset(seed=3)
    for i, env in enumerate(singles):
        env.reset(seed=3 + i)
    rng = np.random.default_rng(5)
    for step in range(200):
        actions = rng.uniform(-0.05, 0.05, size=(N, 15)).astype(np.float32)
        _, _, terminated, _, info = ours.step(actions)
        for i, env in enumerate(singles):
            _, _, t, _, single = env.step(actions[i])
            assert info["object_tilt_rad"][i] == single["object_tilt_rad"], f"step {step}"
            assert info["tipped_over"][i] == single["tipped_over"] and terminated[i] == t
        if terminated.any():
            break
    assert terminated.any(), "random actions tip a cube past 0.05 rad"
    ended = np.flatnonzero(terminated)
    assert info["tipped_over"][ended].all() and info["dropped"][ended].all()
    assert (info["object_tilt_rad"][ended] > 0.05).all()
