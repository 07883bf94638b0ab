"""vge's sub-skill controllers as experts for a Python learner: in-grasp manipulation (`IGM`),
contact switching (`CS`) and finger-gaiting (`FG` = IGM + CS), the controllers that steer
vge's exploration.

A controller reads the env's noise-free state (object pose, contacts), as in training:

    env = vge.HandEnv()
    fg = vge.controllers.FG(env)
    obs, info = env.reset(seed=0)
    action = fg.act(env)           # float32 (env.act_dim,), or None when it has no action this step

A controller works on any hand (`vge.HandEnv(hand="allegro")` too): it is built for one env
(its hand and control period) and keeps episode state
(CS's switching trajectory). When the env has begun a new episode since its last action, it
resets itself with a generator seeded from the episode's seed, as `vge controller` does, so a
loop stepping `fg.act(env)` (zeros when None) reproduces that command's episodes exactly.
"""

from __future__ import annotations

import numpy as np

from . import _vge


def _core_of(env):
    core = getattr(getattr(env, "unwrapped", env), "_core", None)
    if not isinstance(core, _vge.EnvCore):
        raise TypeError(f"expected a vge.HandEnv (or a wrapper of one), got {type(env).__name__}")
    return core


class _Controller:
    _kind = ""

    def __init__(self, env, horizon_steps: int | None = None):
        self._core = _vge.ControllerCore(self._kind, _core_of(env), horizon_steps)

    def act(self, env) -> np.ndarray | None:
        """The controller's action for `env`'s current state, or None (see `last_error`).
        Raises ValueError for an env other than the one it was built for."""
        return self._core.act(_core_of(env))

    __call__ = act

    @property
    def last_error(self) -> str | None:
        """Why the last `act` returned None."""
        return self._core.last_error

    def __repr__(self) -> str:
        return f"vge.controllers.{type(self).__name__}()"


class IGM(_Controller):
    """In-grasp manipulation: turns the object with the fingertips in contact (a contact-force
    QP keeps the grasp)."""

    _kind = "igm"


class CS(_Controller):
    """Contact switching: one finger at a time leaves the object and lands elsewhere
    (`horizon_steps` per switch, default 50)."""

    _kind = "cs"


class FG(_Controller):
    """Finger-gaiting: IGM and CS on the same step (`horizon_steps` per switch, default 50)."""

    _kind = "fg"


__all__ = ["IGM", "CS", "FG"]
