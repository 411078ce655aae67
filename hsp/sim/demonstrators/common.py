"""Small pose builders shared by the demonstrator plans."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import compose, inverse, yaw_of

REACH_TOLERANCE_M = 0.001
"""A pose counts as reachable by the arm when its IK solution lands this close (m)."""


def pose(xyz: np.ndarray, rot: Rotation) -> np.ndarray:
    return np.concatenate([np.asarray(xyz, float), rot.as_quat()])


def in_frame(T_world_frame: np.ndarray, T_world_x: np.ndarray) -> np.ndarray:
    """``T_frame_x``: a world pose re-expressed in another object's frame."""
    return compose(inverse(T_world_frame), T_world_x)


def nearest_yaw(candidates: np.ndarray, current_yaw: float) -> float:
    """The candidate yaw (rad) closest to ``current_yaw`` on the circle."""
    diff = np.angle(np.exp(1j * (np.asarray(candidates) - current_yaw)))
    return float(np.asarray(candidates)[np.argmin(np.abs(diff))])


def hand_yaw(T_world_hand: np.ndarray) -> float:
    return float(yaw_of(T_world_hand[3:]))


def reachable_yaw(preferred: float, poses_at: Callable[[float], list[np.ndarray]],
                  reach_error: Callable[[list[np.ndarray]], float] | None, candidates: int = 16) -> float:
    """The yaw (rad) nearest ``preferred`` at which the arm reaches, one after the other,
    the world poses of object 0 that ``poses_at(yaw)`` lists; where none is reached within
    ``REACH_TOLERANCE_M``, the one it comes closest to. ``preferred`` itself for the
    floating hand, which reaches every pose."""
    if reach_error is None:
        return preferred
    offsets = np.arange(candidates) * 2 * np.pi / candidates
    yaws = preferred + offsets[np.argsort(np.abs(np.angle(np.exp(1j * offsets))), kind="stable")]
    errors = []
    for yaw in yaws:
        errors.append(reach_error(poses_at(float(yaw))))
        if errors[-1] <= REACH_TOLERANCE_M:
            return float(yaw)
    return float(yaws[int(np.argmin(errors))])
