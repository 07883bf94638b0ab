"""`HandEnv`: the simulated hand and an object as a Gymnasium environment."""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np

from . import _vge
from ._checks import float32_array
from ._hand_sizes import HandSizes
from .hand import Hand


def env_keys(object: str | None, keys: dict[str, Any]) -> dict[str, Any]:
    """The `[env]` keys with `object` (one object) in place of `objects`."""
    keys = dict(keys)
    if object is not None:
        if keys.get("objects") is not None:
            raise ValueError("give either object= or objects=, not both")
        keys["objects"] = [object]
    return keys


def warn_training_only(keys: list[str]) -> None:
    if keys:
        warnings.warn(
            f"env keys {', '.join(keys)} are training curricula of `vge train` (levels ramped "
            "over a run's env steps); this env runs at the full levels",
            stacklevel=3,
        )


def episode_seed(rng: np.random.Generator) -> int:
    """The seed of an episode begun without one, drawn from the env's Gymnasium generator."""
    return int(rng.integers(0, 2**63, dtype=np.int64))


class HandEnv(HandSizes, gym.Env):
    """A hand turning an object about the vertical, as vge trains it. The hand is the `[env]`
    key `hand`: `"vge15"` (vge's own 15-joint, 5-finger hand, the default), `"allegro"`
    (16 joints, 4 fingers), or the path of an MJCF file; its sizes are the env's
    (`obs_dim`, `act_dim`, `joint_names`, `finger_names`, `hand`).

    - Observation: `obs_dim` float32 in the layout `obs_layout`. With `observation="full"`
      (the default): joint angles, joint targets, per fingertip contact point, normal and
      normal force (zeros out of contact): 65 for vge15, 60 for the Allegro. With
      `observation="proprio:K"`: joint angles and targets now and at the last K control
      steps (what a hand without fingertip sensing measures), `2 * joints * (1 + K)`; then
      `info["full_obs"]` carries the full observation (what a critic may see, in
      `full_obs_layout`).
    - Action: `act_dim` float32 joint-target changes (rad), one per joint in `joint_names`'
      order, each within +-`max_action_rad`.
    - Reward: the object's rotation rate about z (rad/s), clipped to +-`max_reward_rad_per_s`,
      while enough fingertips touch it; a backward turn is charged whatever the contacts
      (`charge_reverse_rotation`, on by default), and `drop_penalty` (0 by default) on a drop.
    - terminated: the object dropped (or tipped past `upright_within_rad`, when set); truncated:
      the episode's time limit.
    - info: `tip_contacts`, `num_tip_contacts`, `contact_forces_n` (per fingertip, N),
      `external_force_n` (the push on the object, N), `object_rotation_z_rad` (this
      step's), `object_angvel_z_rad_per_s`, `object_height_m`, `object_tilt_rad` (how far
      the object has tipped since the grasp), `dropped`, `tipped_over`, `step`, and
      `full_obs` when the env observes less than the full observation.

    `object` is one of `vge.OBJECTS`; any key of a vge config's `[env]` section is accepted by
    name (`HandEnv(episode_length=600, noise_q_std_rad=0.01)`,
    `HandEnv(hand="allegro", observation="proprio:3")`), or use `from_config`.

    `reset(seed=s)` starts the episode the Rust `vge_sim::Env` starts from seed `s`; a reset
    without a seed draws the episode's seed from the env's generator (`np_random`).
    """

    metadata = {"render_modes": []}

    def __init__(self, object: str | None = None, *, _config_path: str | None = None, _index: int = 0, **env: Any):
        self._core = _vge.EnvCore(env_keys(object, env), _index, _config_path)
        warn_training_only(self._core.training_only_keys)
        self._hand = Hand(self._core.hand)
        bound = np.float32(self._core.max_action_rad)
        self.action_space = gym.spaces.Box(-bound, bound, shape=(self.act_dim,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(self.obs_dim,), dtype=np.float32)

    @classmethod
    def from_config(cls, path: str, index: int = 0, **overrides: Any) -> "HandEnv":
        """The env of the `[env]` section of the vge config at `path` (env `index` of its
        vector: object `objects[index % len]`), with `overrides` replacing its keys."""
        return cls(_config_path=str(path), _index=index, **overrides)

    @property
    def object(self) -> str:
        return self._core.object

    @property
    def control_hz(self) -> float:
        return self._core.control_hz

    @property
    def episode_length(self) -> int:
        """Control steps per episode (the time limit)."""
        return self._core.episode_length

    @property
    def episode_seed(self) -> int | None:
        """The seed of the current episode."""
        return self._core.episode_seed

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if options:
            raise ValueError(f"HandEnv.reset takes no options, got {sorted(options)}")
        if seed is None:
            seed = episode_seed(self.np_random)
        elif not (0 <= int(seed) < 2**64):
            raise ValueError(f"seed {seed} is not in 0..2**64")
        return self._core.reset(int(seed))

    def step(self, action):
        return self._core.step(float32_array(action, (self.act_dim,), "action"))

    def privileged_state(self) -> dict[str, Any]:
        """The noise-free state (object pose and velocities, joint angles and targets,
        contacts), what the controllers read."""
        return self._core.privileged()

    def close(self):
        pass
