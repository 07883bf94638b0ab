"""vge from Python: the simulated hand as a Gymnasium environment (`HandEnv`, and
`VecHandEnv` stepping many in Rust), vge's controllers as experts (`vge.controllers`),
policy files on vge's runtime (`Policy`), and hand descriptions with their kinematics
(`Hand`).

Importing `vge` registers one Gymnasium id per object: `gymnasium.make("vge/FingerGait-Cube-v0")`.
"""

from __future__ import annotations

import gymnasium as gym

from . import _vge, controllers
from ._vge import HANDS, OBJECTS, HandError, PolicyError
from .env import HandEnv
from .hand import Hand
from .policy import Policy
from .vector import VecHandEnv

__version__ = _vge.VERSION

#: The `[env]` keys of a vge config that `HandEnv` and `VecHandEnv` accept by name.
ENV_KEYS = tuple(_vge.ENV_KEYS)

#: The hands that ship with vge, by the name the `[env]` key `hand` takes ("vge15", the
#: default, and "allegro"); the key also takes the path of an MJCF file.
HANDS = tuple(HANDS)

# The sizes of one hand are an env's now (`env.obs_dim`, `env.act_dim`, `env.obs_layout`,
# `env.joint_names`, `env.finger_names`); these module constants were vge15's.
_REMOVED = {
    "OBS_DIM": "env.obs_dim",
    "NUM_JOINTS": "env.act_dim (or env.hand.num_joints)",
    "NUM_FINGERS": "env.hand.num_fingers",
    "OBS_LAYOUT": "env.obs_layout",
}


def __getattr__(name: str):
    if name in _REMOVED:
        raise AttributeError(
            f"vge.{name} was the size of one hand (vge15); each env has its own: use {_REMOVED[name]}"
        )
    raise AttributeError(f"module 'vge' has no attribute {name!r}")


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
    "HANDS",
    "OBJECTS",
]
