"""The shipped gait (policies/cube.vgep), driven from Python."""

import numpy as np

import vge


def test_shipped_gait_turns_the_cube_a_full_turn_in_30_s_without_a_drop(repo):
    hz = vge.Policy.load(repo / "policies/cube.vgep").control_hz
    env = vge.HandEnv("cube", control_hz=hz, episode_length=round(30 * hz), grasp_pose_noise_rad=0.02)
    # Checked against the env it drives: vge15's hand, its full observation, its joints.
    policy = vge.Policy.load(repo / "policies/cube.vgep", env=env)
    meta = policy.metadata
    assert [tuple(s) for s in meta["obs_layout"]] == [tuple(s) for s in env.obs_layout]
    assert meta["obs_dim"] == env.obs_dim == 65 and meta["act_dim"] == env.act_dim == 15
    assert meta["action_names"] == env.joint_names
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
