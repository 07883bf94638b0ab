"""vge from Python: the simulated hand as a Gymnasium environment (`HandEnv`, and
`VecHandEnv` stepping many in Rust), vge's controllers as experts (`vge.controllers`),
policy files on vge's runtime (`Policy`), and hand descriptions with their kinematics
(`Hand`).

Importing `vge` registers one Gymnasium id per object: `gymnasium.make("vge/FingerGait-Cube-v0")`.
"""

from __future__ import annotations

import gymnasium as gym

from . import _vge, controllers
from ._vge import NUM_FINGERS, NUM_JOINTS, OBJECTS, OBS_DIM, OBS_LAYOUT, HandError, PolicyError
from .env import HandEnv
from .hand import Hand
from .policy import Policy
from .vector import VecHandEnv

__version__ = _vge.VERSION

#: The `[env]` keys of a vge config that `HandEnv` and `VecHandEnv` accept by name.
ENV_KEYS = tuple(_vge.ENV_KEYS)


def env_id(object: str) -> str:
    """The Gymnasium id of the hand turning `object`: "cube" -> "vge/FingerGait-Cube-v0"."""
    return "vge/FingerGait-" + "".join(part.capitalize() for part in object.split("-")) + "-v0"


for _object in OBJECTS:
    if env_id(_object) not in gym.registry:
        gym.register(id=env_id(_object), entry_point="vge.env:HandEnv", kwargs={"object": _object})

__all__ = [
    "HandEnv",
    "VecHandEnv",
    "Hand",
    "HandError",
    "Policy",
    "PolicyError",
    "controllers",
    "env_id",
    "ENV_KEYS",
    "OBJECTS",
    "OBS_DIM",
    "OBS_LAYOUT",
    "NUM_JOINTS",
    "NUM_FINGERS",
]
