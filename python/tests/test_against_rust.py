"""The Python package against Rust that never passed through Python: the reference binary
(python/reference) steps `vge_sim::Env` and runs the policy runtime the way `vge eval` does,
and the `vge` command line rolls out the controllers and evaluates the shipped policy."""

import json

import numpy as np
import pytest

import vge
from conftest import run_json


def trace_in_python(object, keys, seed, actions):
    env = vge.HandEnv(object, **keys)
    obs, _ = env.reset(seed=seed)
    observations, rewards, terminated, truncated = [obs], [], [], []
    for a in actions:
        obs, r, te, tr, _ = env.step(a)
        observations.append(obs)
        rewards.append(r)
        terminated.append(te)
        truncated.append(tr)
        if te or tr:
            break
    return np.array(observations), np.array(rewards), terminated, truncated


@pytest.mark.parametrize(
    "object,keys",
    [
        ("cube", {}),
        # Every random draw of the env: grasp pose, sensor noise, pushes, mass and friction,
        # and an action latency.
        (
            "dodecahedron",
            {
                "grasp_pose_noise_rad": 0.03,
                "randomize_fingers": True,
                "noise_q_std_rad": 0.01,
                "noise_normal_std_frac": 0.1,
                "noise_position_std_m": 0.002,
                "perturb_force_std_n": 1.0,
                "perturb_change_probability": 0.2,
                "mass_scale": [0.8, 1.2],
                "friction_scale": [0.9, 1.1],
                "action_latency_steps": 1,
                "episode_length": 30,
            },
        ),
    ],
)
def test_observations_and_rewards_are_bit_identical_to_the_rust_env(reference, object, keys):
    rng = np.random.default_rng(3)
    actions = rng.uniform(-0.05, 0.05, size=(30, 15)).astype(np.float32)
    request = {"object": object, "env": keys, "seed": 11, "actions": actions.tolist()}
    want = run_json([reference, "env-trace"], stdin=json.dumps(request))
    obs, rewards, terminated, truncated = trace_in_python(object, keys, 11, actions)
    assert obs.view(np.uint32).tolist() == want["obs_bits"]
    assert rewards.astype(np.float32).view(np.uint32).tolist() == want["reward_bits"]
    assert (terminated, truncated) == (want["terminated"], want["truncated"])
    assert len(rewards) >= 20 and np.abs(rewards).sum() > 0, "the actions moved the object"


def test_policy_actions_equal_vge_evals_runtime_on_1000_observations(reference, repo, tmp_path):
    policy = vge.Policy.load(repo / "policies/cube.vgep")
    # Observations the policy meets: its own rollout, and the same observations disturbed.
    env = vge.HandEnv(episode_length=500)
    obs, _ = env.reset(seed=2)
    rows = [obs]
    for _ in range(499):
        obs, *_ = env.step(policy(obs))
        rows.append(obs)
    rows = np.array(rows)
    noisy = rows + np.random.default_rng(0).normal(0, 0.01, rows.shape).astype(np.float32)
    observations = np.concatenate([rows, noisy]).astype(np.float32)
    assert observations.shape == (1000, 65)
    observations.tofile(tmp_path / "obs.f32")
    out = tmp_path / "actions.f32"
    run = __import__("subprocess").run(
        [str(reference), "policy-actions", str(repo / "policies/cube.vgep"), str(tmp_path / "obs.f32"), str(out)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    want = np.fromfile(out, dtype="<f4").reshape(1000, 15)
    batch = policy(observations)
    one_by_one = np.array([policy(o) for o in observations])
    assert batch.dtype == np.float32 and batch.shape == (1000, 15)
    assert np.array_equal(batch.view(np.uint32), want.view(np.uint32))
    assert np.array_equal(one_by_one.view(np.uint32), want.view(np.uint32))


def rollout_controller(env, controller, seed):
    env.reset(seed=seed)
    ret, rot, steps, dropped = 0.0, 0.0, 0, False
    while True:
        a = controller.act(env)
        _, r, te, tr, info = env.step(a if a is not None else np.zeros(15, np.float32))
        ret += r
        rot += info["object_rotation_z_rad"]
        steps += 1
        if te or tr:
            return ret, rot, steps, te


# The success test's env, as `vge controller --config` runs a config: its [env] without the
# training disturbances, with the episode length and grasp noise of the command line.
SUCCESS_TEST_KEYS = {
    "grasp_pose_noise_rad": 0.02,
    "noise_q_std_rad": 0.0,
    "noise_normal_std_frac": 0.0,
    "noise_position_std_m": 0.0,
    "perturb_force_std_n": 0.0,
    "perturb_force_magnitude_n": 0.0,
    "perturb_change_probability": 0.0,
    "mass_scale": [1.0, 1.0],
    "friction_scale": [1.0, 1.0],
    "action_latency_steps": 0,
    "drop_penalty": 0.0,
    "terminate_below_contacts": 0,
    "perturb_ramp_steps": 0,
    "perturb_ramp_start": 0,
    "noise_ramp_steps": 0,
}


@pytest.mark.parametrize(
    "kind,config",
    [
        ("cs", None),
        ("igm", "configs/cube-fg-vge.toml"),
        ("fg", "configs/variants/heavy-cube.toml"),
    ],
)
def test_controllers_and_config_keys_reproduce_vge_controller(vge_cli, repo, kind, config):
    """`vge controller` rolls a controller out in Rust (with --config, the config's [env]
    mapped by the trainer's code); the Python loop drives the package's controller in an env
    from the package's mapping: the returns and rotations agree to the bit."""
    args = [vge_cli, "controller", "--kind", kind, "--episodes", "1", "--seed", "4", "--episode-s", "6", "--json"]
    if config is None:
        want = run_json(args)
        env = vge.HandEnv(episode_length=round(6 * 20.0), grasp_pose_noise_rad=0.02)
    else:
        want = run_json(args + ["--config", repo / config])
        hz = vge.HandEnv.from_config(repo / config).control_hz
        env = vge.HandEnv.from_config(repo / config, episode_length=round(6 * hz), **SUCCESS_TEST_KEYS)
    controller = {"igm": vge.controllers.IGM, "cs": vge.controllers.CS, "fg": vge.controllers.FG}[kind](env)
    ret, rot, steps, dropped = rollout_controller(env, controller, 4)
    assert np.float32(ret) == np.float32(want["mean_return"])
    assert np.float32(rot) == np.float32(want["mean_rotation_rad"])
    assert (steps, int(dropped)) == (want["mean_steps"], want["drops"])
    assert abs(rot) > 0, "the controller moved the object"


def test_shipped_gait_reproduces_vge_eval(vge_cli, repo):
    want = run_json([vge_cli, "eval", "--policy", repo / "policies/cube.vgep", "--episodes", "1", "--json"])
    (episode,) = want["per_episode"]
    policy = vge.Policy.load(repo / "policies/cube.vgep")
    hz = policy.control_hz
    env = vge.HandEnv("cube", control_hz=hz, episode_length=round(30 * hz), grasp_pose_noise_rad=0.02)
    obs, _ = env.reset(seed=0)
    ret, rot = 0.0, 0.0
    while True:
        obs, r, te, tr, info = env.step(policy(obs))
        ret += r
        rot += info["object_rotation_z_rad"]
        if te or tr:
            break
    assert (ret, rot, te) == (episode["episode_return"], episode["rotation_rad"], episode["terminated"])
