"""`VecHandEnv`: N hands stepped in Rust, side by side on rayon's threads."""

from __future__ import annotations

from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv

from . import _vge
from ._checks import float32_array
from .env import env_keys, episode_seed, warn_training_only
from ._hand_sizes import HandSizes
from .hand import Hand

# Per-env info arrays (each with its "_key" mask, all True: every env reports every key).
_INFO_KEYS = (
    "tip_contacts",
    "contact_forces_n",
    "external_force_n",
    "object_rotation_z_rad",
    "object_height_m",
    "object_tilt_rad",
    "dropped",
    "tipped_over",
    "step",
    "autoreset",
)


class VecHandEnv(HandSizes, VectorEnv):
    """`num_envs` `HandEnv`s as one Gymnasium `VectorEnv`, stepped in Rust into numpy arrays
    allocated once, with Gymnasium 1.x's next-step autoreset (`metadata["autoreset_mode"]`):
    an env whose episode ended on step t returns that step's final observation, and on step
    t+1 is reset instead of stepped (its action ignored; reward 0, not terminated, not
    truncated) and returns the new episode's first observation.

    Env `i` behaves as a `HandEnv` would: `reset(seed=s)` gives it seed `s + i` (a list gives
    each its own), and an episode begun without a seed (an autoreset, or `reset()`) draws its
    seed from env `i`'s own generator, as `HandEnv.reset()` does. So the batch reproduces
    Gymnasium's `SyncVectorEnv` over `HandEnv`s to the bit (tested), only faster.

    `object` applies to every env; without it env `i` gets `objects[i % len(objects)]`, as in
    training. Every env has the one hand the keys name (`hand`), and the widths of the arrays
    are its: observations `(num_envs, obs_dim)`, actions `(num_envs, act_dim)`, per-fingertip
    infos `(num_envs, fingers)`; with `observation="proprio:K"`, `infos["full_obs"]` holds
    each env's full observation. `copy=False` returns the internal arrays themselves (overwritten by the next
    call) instead of copies.
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        object: str | None = None,
        *,
        copy: bool = True,
        _config_path: str | None = None,
        **env: Any,
    ):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        self._core = _vge.VecEnvCore(int(num_envs), env_keys(object, env), _config_path)
        warn_training_only(self._core.training_only_keys)
        self.num_envs = int(num_envs)
        self.copy = copy
        self._buffers = self._core.buffers()
        # The full observation too, when the envs observe less (what a critic may see).
        self._info_keys = _INFO_KEYS + (("full_obs",) if "full_obs" in self._buffers else ())
        bounds = np.asarray(self._core.max_action_rad, dtype=np.float32)
        if not np.all(bounds == bounds[0]):
            raise ValueError(f"the envs have different action bounds {bounds}")
        bound = bounds[0]
        self._hand = Hand(self._core.hand)
        self.single_action_space = gym.spaces.Box(-bound, bound, shape=(self.act_dim,), dtype=np.float32)
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(self.obs_dim,), dtype=np.float32)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, self.num_envs)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self._env_rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._zero_seeds = np.zeros(self.num_envs, dtype=np.uint64)

    @classmethod
    def from_config(cls, path: str, num_envs: int, **overrides: Any) -> "VecHandEnv":
        """`num_envs` envs of the `[env]` section of the vge config at `path` (env `i` with
        object `objects[i % len]`), with `overrides` replacing its keys."""
        return cls(num_envs, _config_path=str(path), **overrides)

    @property
    def objects(self) -> list[str]:
        return self._core.objects

    def _draw_seed(self, i: int) -> int:
        if self._env_rngs[i] is None:
            self._env_rngs[i], _ = seeding.np_random()
        return episode_seed(self._env_rngs[i])

    def _results(self):
        b = self._buffers
        infos: dict[str, Any] = {}
        mask = np.ones(self.num_envs, dtype=np.bool_)
        for key in self._info_keys:
            infos[key] = b[key].copy() if self.copy else b[key]
            infos["_" + key] = mask
        obs = b["obs"].copy() if self.copy else b["obs"]
        return obs, infos

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed if isinstance(seed, int) else None)
        if options:
            raise ValueError(f"VecHandEnv.reset takes no options, got {sorted(options)}")
        if seed is None:
            seed = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seed = [int(seed) + i for i in range(self.num_envs)]
        if len(seed) != self.num_envs:
            raise ValueError(f"{len(seed)} seeds for {self.num_envs} envs")
        seeds = np.empty(self.num_envs, dtype=np.uint64)
        for i, s in enumerate(seed):
            if s is None:
                seeds[i] = self._draw_seed(i)
            else:
                if not (0 <= int(s) < 2**64):
                    raise ValueError(f"seed {s} (env {i}) is not in 0..2**64")
                self._env_rngs[i], _ = seeding.np_random(int(s))
                seeds[i] = int(s)
        self._core.reset(seeds)
        return self._results()

    def step(self, actions):
        actions = float32_array(actions, (self.num_envs, self.act_dim), "actions")
        pending = self._core.pending_resets()
        seeds = self._zero_seeds
        if any(pending):
            seeds = self._zero_seeds.copy()
            for i, p in enumerate(pending):
                if p:
                    seeds[i] = self._draw_seed(i)
        self._core.step(actions, seeds)
        b = self._buffers
        obs, infos = self._results()
        if self.copy:
            return obs, b["rewards"].copy(), b["terminations"].copy(), b["truncations"].copy(), infos
        return obs, b["rewards"], b["terminations"], b["truncations"], infos

    def close_extras(self, **kwargs: Any) -> None:
        pass
