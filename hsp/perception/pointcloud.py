"""Depth images to world-frame points with colours."""

from __future__ import annotations

import numpy as np

from hsp.geometry import pose_to_matrix


def backproject(depth: np.ndarray, rgb: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, stride: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Valid pixels of ``depth (H, W)`` m, every ``stride``-th row and column, as world
    points ``(N, 3)`` and their colours ``(N, 3)`` in [0, 1]."""
    d = depth[::stride, ::stride]
    v, u = np.nonzero(d > 0)
    z = d[v, u].astype(np.float64)
    u, v = u * stride, v * stride
    pc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    M = pose_to_matrix(T_world_cam)
    return pc @ M[:3, :3].T + M[:3, 3], rgb[v, u].astype(np.float64) / 255.0


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """Brightness-free colour ``(…, 3)``: r, g, b over their sum (shading cancels)."""
    return rgb / np.maximum(rgb.sum(axis=-1, keepdims=True), 1e-6)


SHADE_RANGE = (0.3, 1.2)
"""Brightness of a lit surface relative to its albedo, darkest to brightest face: shading
changes brightness, not chromaticity, but within bounds (black is never lit to steel)."""


def palette_mask(rgb: np.ndarray, palette: np.ndarray, tol: float, shade: tuple[float, float] = SHADE_RANGE) -> np.ndarray:
    """Which colours ``(N, 3)`` could show a palette colour ``(K, 3)`` (albedo, same units)
    under some shading: chromaticity within ``tol`` and brightness within ``shade`` times
    the palette colour's, ``(N,)`` bool."""
    near = np.linalg.norm(chromaticity(rgb)[:, None, :] - chromaticity(palette)[None], axis=-1) <= tol
    ratio = rgb.sum(axis=-1)[:, None] / np.maximum(palette.sum(axis=-1)[None], 1e-6)
    return np.any(near & (ratio >= shade[0]) & (ratio <= shade[1]), axis=1)
