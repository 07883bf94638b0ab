"""`Hand`: a hand read from its MJCF description (and the TOML beside it), with its
kinematics, as vge's simulator and controllers read it (the Rust crate vge-hand)."""

from __future__ import annotations

from os import PathLike, fspath

import numpy as np

from . import _vge


def _joint_angles(q, n: int) -> np.ndarray:
    """`q` as a C-contiguous float64 vector of `n` joint angles, or a ValueError naming what is
    wrong (the Rust side refuses NaN and infinity with the entry's index)."""
    try:
        a = np.asarray(q)
    except Exception as e:  # a ragged list, an object numpy cannot read
        raise ValueError(f"joint angles: cannot be read as an array ({e})") from None
    if a.dtype.kind not in "fiu":
        raise ValueError(f"joint angles have dtype {a.dtype}, expected real numbers")
    if a.shape != (n,):
        raise ValueError(f"joint angles have shape {a.shape}, expected ({n},)")
    return np.ascontiguousarray(a, dtype=np.float64)


class Hand:
    """A hand described by an MJCF file in vge's subset (`hands/vge15.xml`,
    `hands/allegro.xml`, or a user's), read with MuJoCo's semantics. The joint vector is
    MuJoCo's qpos order, finger-major; positions are in the MJCF world frame, in metres;
    angles in radians. Kinematics are float64.

    `Hand.load` raises `vge.HandError` (a ValueError) naming the file, line and element of
    anything outside the subset (tendons, equality constraints, ball or free joints, colliding
    meshes, unknown elements), and an OSError for a file it cannot read.
    """

    def __init__(self, core: "_vge.HandCore"):
        self._core = core

    @classmethod
    def load(cls, path: str | PathLike) -> "Hand":
        """Reads the MJCF file at `path` and the TOML beside it (same stem), if any."""
        return cls(_vge.HandCore.load(fspath(path)))

    @classmethod
    def named(cls, spec: str | PathLike) -> "Hand":
        """A hand by the name the `[env]` key `hand` takes: one that ships with vge
        (`vge.HANDS`: "vge15", "allegro"), or the path of an MJCF file (it has a `/` or ends
        in .xml)."""
        return cls(_vge.HandCore.named(fspath(spec)))

    @property
    def name(self) -> str:
        """`<mujoco model>`, else the file's stem."""
        return self._core.name

    @property
    def num_joints(self) -> int:
        return self._core.num_joints

    @property
    def num_fingers(self) -> int:
        return self._core.num_fingers

    @property
    def joint_names(self) -> list[str]:
        return self._core.joint_names

    @property
    def finger_names(self) -> list[str]:
        return self._core.finger_names

    @property
    def fingertip_names(self) -> list[str]:
        """The site or body that is each finger's fingertip."""
        return self._core.fingertip_names

    @property
    def finger_joints(self) -> list[tuple[int, int]]:
        """Each finger's joints as a (start, end) range of the joint vector."""
        return self._core.finger_joints

    @property
    def joint_limits(self) -> np.ndarray:
        """(num_joints, 2): lower and upper limit (rad); -inf, inf where unlimited."""
        return self._core.joint_limits()

    @property
    def body_names(self) -> list[str | None]:
        """MuJoCo's bodies in order, `world` first (None for an unnamed body)."""
        return self._core.body_names

    @property
    def description_sha256(self) -> str:
        """SHA-256 (hex) of the XML's bytes followed by the TOML's."""
        return self._core.description_sha256

    @property
    def start_grasp(self) -> np.ndarray | None:
        """The start grasp's joint angles (the keyframe the TOML names), if any."""
        q = self._core.start_grasp
        return None if q is None else np.asarray(q, dtype=np.float64)

    def fingertip_positions(self, q) -> np.ndarray:
        """(num_fingers, 3) fingertip positions (m) at joint angles `q`: a site's position, or
        a body's origin for a fingertip named by its body."""
        return self._core.fingertip_positions(_joint_angles(q, self.num_joints))

    def fingertip_jacobians(self, q) -> np.ndarray:
        """(num_fingers, 3, num_joints): d(fingertip position)/dq, zero in the columns of
        other fingers' joints (MuJoCo's mj_jacSite / mj_jacBody, translational part)."""
        return self._core.fingertip_jacobians(_joint_angles(q, self.num_joints))

    def body_poses(self, q) -> np.ndarray:
        """(num_bodies, 7) world poses at `q`: position (m) and quaternion w x y z (MuJoCo's
        xpos, xquat)."""
        return self._core.body_poses(_joint_angles(q, self.num_joints))

    def body_mass_properties(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each body's mass (kg), centre of mass (m, body frame) and inertia tensor about it
        (kg m^2, body axes), as MuJoCo compiles them."""
        return self._core.body_mass_properties()

    def __repr__(self) -> str:
        return f"vge.Hand({self.name!r}, {self.num_joints} joints, fingers {self.finger_names})"
