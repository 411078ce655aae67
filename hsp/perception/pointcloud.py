"""Depth images to world-frame points with colours."""

from __future__ import annotations

import numpy as np

from hsp.geometry import inverse, pose_to_matrix, transform_points


def camera_points(depth: np.ndarray, K: np.ndarray, stride: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Valid pixels of ``depth (H, W)`` m, every ``stride``-th row and column, as camera-frame
    points ``(N, 3)``, with their rows and columns ``(N,)``."""
    d = depth[::stride, ::stride]
    v, u = np.nonzero(d > 0)
    z = d[v, u].astype(np.float64)
    u, v = u * stride, v * stride
    return np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1), v, u


def backproject(depth: np.ndarray, rgb: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, stride: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Valid pixels of ``depth (H, W)`` m, every ``stride``-th row and column, as world
    points ``(N, 3)`` and their colours ``(N, 3)`` in [0, 1]."""
    pc, v, u = camera_points(depth, K, stride)
    M = pose_to_matrix(T_world_cam)
    return pc @ M[:3, :3].T + M[:3, 3], rgb[v, u].astype(np.float64) / 255.0


def project(points_world: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``(N, 2)`` (u right, v down; pixel centres at integers) of world
    points ``(N, 3)`` and their depth along the optical axis ``(N,)``."""
    pc = transform_points(inverse(T_world_cam), points_world)
    z = pc[:, 2]
    uv = (pc[:, :2] / np.maximum(z, 1e-9)[:, None]) * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    return uv, z


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """Brightness-free colour ``(…, 3)``: r, g, b over their sum (shading cancels)."""
    return rgb / np.maximum(rgb.sum(axis=-1, keepdims=True), 1e-6)


SHADE_RANGE = (0.3, 1.2)
"""Brightness of a lit surface relative to its albedo, darkest to brightest face: shading
changes brightness, not chromaticity, but within bounds (black is never lit to steel)."""


def colour_match(rgb: np.ndarray, albedo: np.ndarray, tol: float, shade: tuple[float, float] = SHADE_RANGE) -> np.ndarray:
    """Whether pixel colours could show surfaces of the given albedo (broadcast, ``(…, 3)``
    → ``(…)``): chromaticity within ``tol``, brightness within ``shade`` times the albedo's."""
    near = np.linalg.norm(chromaticity(rgb) - chromaticity(albedo), axis=-1) <= tol
    ratio = rgb.sum(axis=-1) / np.maximum(albedo.sum(axis=-1), 1e-6)
    return near & (ratio >= shade[0]) & (ratio <= shade[1])


def palette_mask(rgb: np.ndarray, palette: np.ndarray, tol: float, shade: tuple[float, float] = SHADE_RANGE) -> np.ndarray:
    """Which colours ``(N, 3)`` could show one of the palette colours ``(K, 3)``, ``(N,)``."""
    return np.any(colour_match(rgb[:, None, :], palette[None], tol, shade), axis=1)
