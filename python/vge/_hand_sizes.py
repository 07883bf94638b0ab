"""The hand-decided sizes and names that `HandEnv` and `VecHandEnv` both expose (per env)."""

from __future__ import annotations

from .hand import Hand


class HandSizes:
    """Properties read from the Rust core (`self._core`) and the env's `Hand` (`self._hand`)."""

    _core: object
    _hand: Hand

    @property
    def hand(self) -> Hand:
        """The hand the env simulates (its names, limits and kinematics)."""
        return self._hand

    @property
    def obs_dim(self) -> int:
        """Entries of one env's observation (the observation set's, on this hand)."""
        return self._core.obs_dim

    @property
    def act_dim(self) -> int:
        """Entries of one env's action: one per joint."""
        return self._core.act_dim

    @property
    def obs_layout(self) -> list[tuple[str, int, int]]:
        """The observation's named slices, `(name, start, end)` in order."""
        return self._core.obs_layout

    @property
    def full_obs_layout(self) -> list[tuple[str, int, int]]:
        """The full observation's slices (`info["full_obs"]` when the env observes less)."""
        return self._core.full_obs_layout

    @property
    def observation(self) -> str:
        """The observation set: `full`, `proprio` or `proprio:K`."""
        return self._core.observation

    @property
    def joint_names(self) -> list[str]:
        """The joints, in the order of an action's entries."""
        return self._hand.joint_names

    @property
    def finger_names(self) -> list[str]:
        """The fingers, in the order of the per-fingertip info entries."""
        return self._hand.finger_names
