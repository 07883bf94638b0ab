"""HandEnv as Gymnasium sees it: its own checker, the registered ids, seeding, info."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import vge

# Advice check_env gives any env whose observations are unbounded or whose actions are not
# in [-1, 1] (Gymnasium's MuJoCo envs get it too): the hand's actions are radians.
ADVICE = ("infinity", "symmetric and normalized")


def test_check_env_passes_with_no_other_warning():
    # Through gymnasium.make, so that the env has a spec (check_env then also makes and closes
    # new ones from it).
    env = gym.make("vge/FingerGait-Cube-v0", episode_length=20).unwrapped
    assert isinstance(env, vge.HandEnv)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    others = [str(w.message) for w in caught if not any(a in str(w.message) for a in ADVICE)]
    assert others == []


@pytest.mark.parametrize("object", vge.OBJECTS)
def test_every_object_has_a_registered_id(object):
    env = gym.make(vge.env_id(object))
    assert env.unwrapped.object == object
    obs, info = env.reset(seed=1)
    assert obs.shape == (65,) and obs.dtype == np.float32
    assert info["num_tip_contacts"] >= 3
    env.close()
    assert vge.env_id("hexagonal-prism") == "vge/FingerGait-HexagonalPrism-v0"


def test_gymnasium_make_cube_and_step_info():
    env = gym.make("vge/FingerGait-Cube-v0", episode_length=3)
    env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(np.zeros(15, np.float32))
    assert isinstance(reward, float) and not terminated and not truncated
    assert info["tip_contacts"].shape == (5,) and info["tip_contacts"].dtype == np.bool_
    assert info["contact_forces_n"].shape == (5,)
    assert (info["contact_forces_n"] > 0).sum() == info["num_tip_contacts"]
    assert info["external_force_n"].tolist() == [0.0, 0.0, 0.0]
    assert info["dropped"] is False and info["step"] == 1
    for _ in range(2):
        *_, truncated, info = env.step(np.zeros(15, np.float32))
    assert truncated and info["step"] == 3


def test_seeding_follows_gymnasium():
    env = vge.HandEnv(grasp_pose_noise_rad=0.05)
    a, _ = env.reset(seed=5)
    b, _ = env.reset()  # drawn from the generator seeded by 5
    c, _ = env.reset(seed=5)
    d, _ = env.reset()
    assert np.array_equal(a, c) and np.array_equal(b, d)
    assert not np.array_equal(a, b)
    assert env.episode_seed != 5


def test_keys_by_name_and_from_config(repo):
    env = vge.HandEnv("sphere", episode_length=7, control_hz=30.0, max_action_rad=0.02)
    assert (env.object, env.episode_length, env.control_hz) == ("sphere", 7, 30.0)
    assert env.action_space.high.tolist() == [np.float32(0.02)] * 15
    cfg = vge.HandEnv.from_config(repo / "configs/cube-fg-vge.toml", episode_length=9)
    assert (cfg.object, cfg.episode_length) == ("cube", 9)
    assert "pose_noise_rad: 0.02" in cfg._core.config_debug()
    multi = vge.HandEnv.from_config(repo / "configs/multi-object-fg-vge.toml", index=1)
    assert multi.object != "cube"


def test_config_files_are_read_over_their_base_chain_as_the_lab_reads_them(repo, tmp_path):
    # configs/variants/side-on.toml is cube-base.toml plus one [env] key.
    side_on = vge.HandEnv.from_config(repo / "configs/variants/side-on.toml")
    assert "SideOn" in side_on._core.config_debug()
    assert "SideOn" not in vge.HandEnv.from_config(repo / "configs/cube-base.toml")._core.config_debug()
    # A loop is refused naming the file, with the lab's message (one reader, config-file/).
    (tmp_path / "a.toml").write_text('base = "b.toml"\n')
    (tmp_path / "b.toml").write_text('base = "a.toml"\n')
    with pytest.raises(ValueError, match=r"b\.toml.*already built on"):
        vge.HandEnv.from_config(tmp_path / "a.toml")


def test_bad_keys_name_the_key(repo):
    with pytest.raises(ValueError, match="control_hzz"):
        vge.HandEnv(control_hzz=20.0)
    with pytest.raises(ValueError, match="episode_length"):
        vge.HandEnv(episode_length="long")
    with pytest.raises(ValueError, match="control rate"):
        vge.HandEnv(control_hz=-5.0)
    with pytest.raises(ValueError, match="unknown variant `cubee`"):
        vge.HandEnv("cubee")
    with pytest.raises(FileNotFoundError, match="nope.toml"):
        vge.HandEnv.from_config(repo / "configs/nope.toml")
    # The lab's checks of the section: a ramp needs a force to ramp to.
    with pytest.raises(ValueError, match="env.perturb_ramp_steps"):
        vge.HandEnv(perturb_ramp_steps=1000)
    with pytest.warns(UserWarning, match="perturb_ramp_steps"):
        vge.HandEnv(perturb_ramp_steps=1000, perturb_force_std_n=0.5)


def test_env_keys_are_the_trainers(repo):
    """Every key of the [env] section (sim/src/env_keys.rs, which the lab's configs read) is
    in ENV_KEYS, in declaration order."""
    import re

    src = (repo / "sim/src/env_keys.rs").read_text()
    body = src[src.index("pub struct EnvSection {") :]
    body = body[: body.index("\n}\n")]
    trainer_keys = re.findall(r"^\s*pub (\w+):", body, flags=re.M)
    assert trainer_keys == list(vge.ENV_KEYS)
