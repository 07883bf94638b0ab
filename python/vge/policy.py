"""`Policy`: a vge policy file (`.vgep`) on vge's own runtime, the one `vge eval`, the bridge
and the firmware run."""

from __future__ import annotations

from os import PathLike
from typing import Any

import numpy as np

from . import _vge
from ._checks import float32_array


class Policy:
    """A loaded policy file: `policy(obs)` is the action for one observation (`obs_dim`,) or
    for a batch (n, `obs_dim`), float32.

    `Policy.load` runs every check of the runtime (framing, checksum, fields, dimensions,
    finite parameters); a file that fails one raises `vge.PolicyError` naming it.
    """

    def __init__(self, core: "_vge.PolicyCore"):
        self._core = core

    @classmethod
    def load(cls, path: str | PathLike) -> "Policy":
        return cls(_vge.PolicyCore.load(str(path)))

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
        `checksum`, `weight_type`, `num_layers`, `max_width`, `num_params`, `obs_clip`."""
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
