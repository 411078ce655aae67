"""What one frame says of an object's pose: its camera-facing surface samples rendered at the
pose and compared, pixel by pixel, with the depth and colour images.

A sample whose pixel reads its depth (within a margin) and its colour supports the pose; one
whose pixel reads deeper contradicts it (the camera sees past where the object would be), as
does one at its depth in another colour; one whose pixel reads nearer, or nothing, is hidden
and says nothing. ICP only asks whether the points it was given lie on the model; a pose slid
along a half-visible object, or onto another object's points, fits them and is contradicted here.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hsp.perception.pointcloud import colour_match, project


def surface_pixels(surface: np.ndarray, normals: np.ndarray, pose_matrix: np.ndarray, K: np.ndarray,
                   T_world_cam: np.ndarray, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Camera-facing samples (object frame ``(M, 3)``, with normals) at ``pose_matrix (4, 4)``
    that project into an image of ``shape``: their indices, rows, columns and depths ``(k,)``."""
    pts = surface @ pose_matrix[:3, :3].T + pose_matrix[:3, 3]
    nrm = normals @ pose_matrix[:3, :3].T
    facing = np.flatnonzero(np.sum(nrm * (T_world_cam[:3] - pts), axis=1) > 0)
    uv, z = project(pts[facing], K, T_world_cam)
    u, v = np.round(uv).astype(int).T
    inside = (z > 0) & (u >= 0) & (v >= 0) & (u < shape[1]) & (v < shape[0])
    return facing[inside], v[inside], u[inside], z[inside]


class Evidence(NamedTuple):
    share: float
    """Share of the seen samples that support the pose (0 when none is seen)."""
    seen: int
    """Samples whose pixel supports or contradicts the pose."""
    seen_through: float
    """:func:`seen_through`'s share, from the same projection."""


def evidence(surface: np.ndarray, normals: np.ndarray, albedo: np.ndarray, pose_matrix: np.ndarray, rgb: np.ndarray,
             depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, colour_tolerance: float,
             margin_m: float = 0.01) -> Evidence:
    """What the frame says of the pose, from one projection of the object's camera-facing
    surface samples (``albedo (M, 3)`` their colours): :func:`explained` and :func:`seen_through`."""
    idx, v, u, z = surface_pixels(surface, normals, pose_matrix, K, T_world_cam, depth.shape)
    d = depth[v, u]
    at = (d > 0) & (np.abs(d - z) < margin_m)
    past = d > z + margin_m
    seen = int(np.count_nonzero(at | past))
    through = _past_share(d, z, margin_m)
    if seen == 0:
        return Evidence(0.0, 0, through)
    support = colour_match(rgb[v[at], u[at]] / 255.0, albedo[idx[at]], colour_tolerance)
    return Evidence(float(np.count_nonzero(support)) / seen, seen, through)


def explained(surface: np.ndarray, normals: np.ndarray, albedo: np.ndarray, pose_matrix: np.ndarray, rgb: np.ndarray,
              depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, colour_tolerance: float,
              margin_m: float = 0.01) -> tuple[float, int]:
    """Share of the object's seen surface samples (``albedo (M, 3)`` their colours) that support
    the pose, among those that support or contradict it, and how many were seen; (0, 0) when
    none is seen (hidden, or outside the image)."""
    share, seen, _ = evidence(surface, normals, albedo, pose_matrix, rgb, depth, K, T_world_cam, colour_tolerance,
                              margin_m)
    return share, seen


def _past_share(d: np.ndarray, z: np.ndarray, margin_m: float) -> float:
    """Share of the pixels with a reading ``d`` that read at least ``margin_m`` deeper than ``z``; 1 when none reads."""
    reads = d > 0
    if not reads.any():
        return 1.0
    return float(np.mean(d[reads] > z[reads] + margin_m))


def seen_through(surface: np.ndarray, normals: np.ndarray, pose_matrix: np.ndarray, depth: np.ndarray, K: np.ndarray,
                 T_world_cam: np.ndarray, margin_m: float = 0.01) -> float:
    """Share of the object's camera-facing surface samples (object frame ``(M, 3)``, with
    normals) at pose ``pose_matrix (4, 4)`` whose pixel reads at least ``margin_m`` deeper:
    the camera sees past where the object would be. 1 when none project into the image
    with a reading."""
    _, v, u, z = surface_pixels(surface, normals, pose_matrix, K, T_world_cam, depth.shape)
    return _past_share(depth[v, u], z, margin_m)
