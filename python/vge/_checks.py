"""Input checks shared by the env, the vector env and the policy: every array that crosses
into Rust is checked here first, so a caller gets a ValueError that names the problem."""

from __future__ import annotations

import numpy as np


def float32_array(value, shape: tuple, what: str) -> np.ndarray:
    """`value` as a C-contiguous float32 array of `shape` (-1 matches any length), or a
    ValueError naming what is wrong: its dtype (not a real number), its shape, or a NaN or
    infinity (with its index)."""
    try:
        a = np.asarray(value)
    except Exception as e:  # a ragged list, an object numpy cannot read
        raise ValueError(f"{what}: cannot be read as an array ({e})") from None
    if a.dtype.kind not in "fiu":
        raise ValueError(
            f"{what} has dtype {a.dtype}, expected real numbers (float32, float64 or integers)"
        )
    if a.ndim != len(shape) or any(s != -1 and s != n for s, n in zip(shape, a.shape)):
        want = "(" + ", ".join("n" if s == -1 else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{what} has shape {a.shape}, expected {want}")
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is reported below
        a = np.ascontiguousarray(a, dtype=np.float32)
    bad = ~np.isfinite(a)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        where = index[0] if len(index) == 1 else index
        original = np.asarray(value)[index]
        raise ValueError(f"{what} entry {where} is not finite ({original}) as float32")
    return a
