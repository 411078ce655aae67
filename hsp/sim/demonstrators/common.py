"""Small pose builders shared by the demonstrator plans."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import compose, inverse, yaw_of


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
