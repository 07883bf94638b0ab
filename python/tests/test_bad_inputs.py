"""Bad input raises ValueError naming the problem (never a panic across the boundary); a
damaged policy file raises vge.PolicyError naming the check it failed."""

import shutil

import gymnasium as gym
import numpy as np
import pytest

import vge


@pytest.fixture
def env():
    e = vge.HandEnv()
    e.reset(seed=0)
    return e


@pytest.mark.parametrize(
    "action,match",
    [
        (np.zeros(14, np.float32), r"action has shape \(14,\), expected \(15,\)"),
        (np.zeros((1, 15), np.float32), r"action has shape \(1, 15\), expected \(15,\)"),
        (np.zeros(15, np.complex128), "action has dtype complex128"),
        (np.array(["a"] * 15), "action has dtype <U1"),
        (np.array([None] * 15), "action has dtype object"),
        (np.array([0.0] * 14 + [np.nan]), r"action entry 14 is not finite \(nan\)"),
        (np.array([np.inf] + [0.0] * 14), r"action entry 0 is not finite \(inf\)"),
        (np.array([1e300] + [0.0] * 14), r"action entry 0 is not finite \(1e\+300\) as float32"),
        ([[0.0, 1.0], [2.0]], "cannot be read as an array"),
    ],
)
def test_bad_actions(env, action, match):
    with pytest.raises(ValueError, match=match):
        env.step(action)


def test_the_rust_side_checks_too(env):
    # Past the Python checks, straight into the extension: the Rust message arrives intact.
    with pytest.raises(ValueError, match="action entry 3 is not finite"):
        env._core.step(np.array([0, 0, 0, np.nan] + [0] * 11, np.float32))
    with pytest.raises(ValueError, match="action has 14 entries, expected 15"):
        env._core.step(np.zeros(14, np.float32))
    with pytest.raises(TypeError):
        env._core.step(np.zeros(15, np.float64))
    # Every other entry of 30: 15 entries, not contiguous; said so, not "15 expected 15".
    with pytest.raises(ValueError, match="action: .*contiguous"):
        env._core.step(np.zeros(30, np.float32)[::2])


def test_a_controller_refuses_an_env_it_was_not_built_for(env):
    other = vge.HandEnv()
    other.reset(seed=1)
    fg = vge.controllers.FG(env)
    assert fg.act(env) is not None, fg.last_error
    # Its episode state is keyed on `env`'s episode count, which means nothing for `other`:
    # refused, by the extension itself (so the private class cannot mix them either).
    with pytest.raises(ValueError, match="this fg controller was built for another env"):
        fg.act(other)
    with pytest.raises(ValueError, match="this fg controller was built for another env"):
        fg._core.act(other._core)
    # A wrapper of the same env is the same env.
    assert fg.act(gym.wrappers.TimeLimit(env, 10)) is not None, fg.last_error


def test_step_before_reset_is_a_runtime_error():
    with pytest.raises(RuntimeError, match="step called before reset"):
        vge.HandEnv().step(np.zeros(15, np.float32))


def test_python_lists_and_float64_are_actions(env):
    env.step([0.0] * 15)
    env.step(np.zeros(15))


def test_bad_observations(repo):
    policy = vge.Policy.load(repo / "policies/cube.vgep")
    with pytest.raises(ValueError, match=r"observation has shape \(64,\)"):
        policy(np.zeros(64, np.float32))
    with pytest.raises(ValueError, match=r"observation entry 7 is not finite"):
        policy(np.where(np.arange(65) == 7, np.nan, 0.0))
    with pytest.raises(ValueError, match=r"observations entry \(1, 2\) is not finite"):
        policy(np.where(np.arange(130).reshape(2, 65) == 67, np.inf, 0.0))
    with pytest.raises(ValueError, match="observation has 64 values, expected 65"):
        policy._core.act_one(np.zeros(64, np.float32))


def damaged(tmp_path, repo, change):
    data = bytearray((repo / "policies/cube.vgep").read_bytes())
    data = change(data)
    path = tmp_path / "damaged.vgep"
    path.write_bytes(bytes(data))
    return path


def flip(offset):
    def change(data):
        data[offset] ^= 0x40
        return data

    return change


@pytest.mark.parametrize(
    "change,match",
    [
        (flip(1000), "checksum mismatch: stored 0x[0-9a-f]{8}, computed 0x[0-9a-f]{8}"),
        (flip(0), r"not a vge policy file \(bad magic\)"),
        (lambda d: d[: len(d) // 2], "truncated or trailing data"),
        (lambda d: d[:10], "shorter than the"),
    ],
)
def test_damaged_policy_files_name_the_check(tmp_path, repo, change, match):
    path = damaged(tmp_path, repo, change)
    with pytest.raises(vge.PolicyError, match=match) as e:
        vge.Policy.load(path)
    assert str(path) in str(e.value)
    assert isinstance(e.value, ValueError)


def test_missing_policy_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.vgep"):
        vge.Policy.load(tmp_path / "nothing.vgep")


def test_a_vector_of_envs_no_machine_holds_is_refused_before_any_is_made():
    # 10**8 envs would take hundreds of TB: refused with the estimate, as `vge train` refuses
    # its num_envs, instead of allocating until the process is killed.
    with pytest.raises(ValueError, match=r"VecHandEnv\(100000000\) would hold about .* more than the 1.10 TB"):
        vge.VecHandEnv(10**8)


def test_a_config_base_that_is_a_device_is_refused_unread_naming_it(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text('base = "/dev/zero"\n')
    with pytest.raises(OSError, match="/dev/zero.*not a regular file"):
        vge.HandEnv.from_config(str(config))
