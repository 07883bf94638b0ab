"""The shipped gait (policies/cube.vgep), driven from Python."""

import numpy as np

import vge


def test_shipped_gait_turns_the_cube_a_full_turn_in_30_s_without_a_drop(repo):
    policy = vge.Policy.load(repo / "policies/cube.vgep")
    meta = policy.metadata
    assert [name for name, *_ in meta["obs_layout"]] == [name for name, *_ in vge.OBS_LAYOUT]
    assert meta["obs_dim"] == 65 and meta["act_dim"] == 15 and len(meta["action_names"]) == 15
    hz = policy.control_hz
    env = vge.HandEnv("cube", control_hz=hz, episode_length=round(30 * hz), grasp_pose_noise_rad=0.02)
    obs, _ = env.reset(seed=0)
    rotation_rad, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        rotation_rad += info["object_rotation_z_rad"]
        steps += 1
        if terminated or truncated:
            break
    assert not terminated, f"dropped after {steps} steps"
    assert steps == round(30 * hz)
    assert rotation_rad >= 2 * np.pi, rotation_rad
