"""`Policy`: a vge policy file (`.vgep`) on vge's own runtime, the one `vge eval`, the bridge
and the firmware run."""

from __future__ import annotations

from os import PathLike
from typing import Any

import numpy as np

from . import _vge
from ._checks import float32_array


def _env_core(env):
    """The Rust core of a `HandEnv` or `VecHandEnv` (or a Gymnasium wrapper of one)."""
    core = getattr(getattr(env, "unwrapped", env), "_core", None)
    if not isinstance(core, (_vge.EnvCore, _vge.VecEnvCore)):
        raise TypeError(f"expected a vge.HandEnv or vge.VecHandEnv (or a wrapper of one), got {type(env).__name__}")
    return core


class Policy:
    """A loaded policy file: `policy(obs)` is the action for one observation (`obs_dim`,) or
    for a batch (n, `obs_dim`), float32.

    `Policy.load` runs every check of the runtime (framing, checksum, fields, dimensions,
    finite parameters); a file that fails one raises `vge.PolicyError` naming it. Given the
    env it will drive (`Policy.load(path, env=env)`, or `policy.check(env)` later), it also
    checks that the policy was trained for that env's hand (its name and description), takes
    the observation the env gives and names the env's joints as its actions, as `vge eval`
    checks a policy: a policy for another hand raises `vge.PolicyError` saying so.
    """

    def __init__(self, core: "_vge.PolicyCore"):
        self._core = core

    @classmethod
    def load(cls, path: str | PathLike, env=None) -> "Policy":
        """The policy file at `path`; checked against `env` (a `HandEnv` or `VecHandEnv`)
        when given."""
        policy = cls(_vge.PolicyCore.load(str(path)))
        if env is not None:
            policy.check(env)
        return policy

    def check(self, env) -> None:
        """Raises `vge.PolicyError` unless the policy drives `env` (a `HandEnv` or
        `VecHandEnv`, or a wrapper of one) as it is observed: same hand, same observation
        layout, actions named after its joints."""
        self._core.check_env(_env_core(env))

    @property
    def hand(self) -> str:
        """The hand the policy was trained for (a file without a task record: "vge15")."""
        return self._core.hand

    @property
    def observation_set(self) -> str:
        """What the policy observes: "full", "proprio" or "proprio:K" (a file without a task
        record: "full")."""
        return self._core.observation_set

    @property
    def obs_dim(self) -> int:
        return self._core.obs_dim

    @property
    def act_dim(self) -> int:
        return self._core.act_dim

    @property
    def metadata(self) -> dict[str, Any]:
        """What the file says besides its parameters: `obs_layout`, `action_names`,
        `control_hz`, `provenance` (vge version, config hash, seed, steps), `format_version`,
        `checksum`, `weight_type`, `num_layers`, `max_width`, `num_params`, `obs_clip`, and
        `task`: the task record (`hand`, `hand_sha256` in hex, `observation_set`, `object`,
        `orientation`; the last two empty when unspecified), or None for a file without one
        (a policy for vge15 with the full observation)."""
        return self._core.metadata()

    @property
    def control_hz(self) -> float:
        return self.metadata["control_hz"]

    def __call__(self, obs) -> np.ndarray:
        a = np.asarray(obs) if not isinstance(obs, np.ndarray) else obs
        if getattr(a, "ndim", None) == 2:
            return self._core.act_batch(float32_array(obs, (-1, self.obs_dim), "observations"))
        return self._core.act_one(float32_array(obs, (self.obs_dim,), "observation"))

    def __repr__(self) -> str:
        return f"vge.Policy({self._core.path!r})"
