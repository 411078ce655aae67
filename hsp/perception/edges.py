"""Heading and position of an object at rest from the image edges of its model's creases.

Depth alone hardly tells a small nut's heading: on 50 points of a hex nut, the point-to-
plane cost changes by 2 % over ±6°, and its minimum sits 2–5° off even at the true
position. The colour image shows what depth blurs: where two faces meet, the shading jumps.
Projected into the image, the model's creases (edges between faces at an angle) lie on
the strongest intensity gradients across them only at the right pose (the idea of
model-based edge tracking, as in RAPiD). For an object standing on its support, a search
over its heading about the vertical and its horizontal position maximises the mean
gradient across its visible creases. Only the mesh is used, never its appearance.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import pose_from_matrix, pose_to_matrix
from hsp.perception.pointcloud import project
from hsp.sim.render import Mesh


@dataclass(frozen=True)
class EdgeConfig:
    samples: int = 8
    """Points sampled along each crease."""
    max_turn_deg: float = 30.0
    """Widest heading search, each way (a nut's whole 60° period)."""
    turn_step_deg: float = 2.0
    """Coarse heading step; then a fine search at a quarter of it."""
    shift_m: float = 0.003
    """Widest horizontal search, each way (ICP's position is rarely further off; wider
    searches find the edges of neighbours)."""
    shift_step_m: float = 0.001
    """Coarse horizontal step; then a fine search at a quarter of it."""
    fine_rounds: int = 2
    """Fine searches after the coarse one, heading and position in turn."""


@dataclass(frozen=True)
class Creases:
    """Crease edges of a mesh: end points ``(E, 2, 3)`` and the normals of the two faces
    that meet there ``(E, 2, 3)``, in the object frame."""

    ends: np.ndarray
    normals: np.ndarray


def crease_edges(mesh: Mesh, min_deg: float = 20.0) -> Creases:
    """Edges shared by two faces whose normals differ by more than ``min_deg`` (a hex nut's
    18 and its paint mark's 12; not the diagonals of flat quads); vertices
    duplicated per face (an OBJ with face colours) are merged by position."""
    key = np.round(mesh.vertices / 1e-6).astype(np.int64)
    _, vid = np.unique(key, axis=0, return_inverse=True)
    vid = vid.ravel()
    tri = vid[mesh.triangles]
    v = mesh.vertices[mesh.triangles]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area = np.linalg.norm(n, axis=1)
    ok = area > 1e-12
    tri, n = tri[ok], n[ok] / area[ok, None]
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    face = np.tile(np.arange(len(tri)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, face = edges[order], face[order]
    pair = np.flatnonzero(np.all(edges[1:] == edges[:-1], axis=1))  # an edge and its twin
    na, nb = n[face[pair]], n[face[pair + 1]]
    sharp = np.sum(na * nb, axis=1) < np.cos(np.radians(min_deg))
    position = np.zeros((vid.max() + 1, 3))
    position[vid] = mesh.vertices
    return Creases(position[edges[pair[sharp]]], np.stack([na[sharp], nb[sharp]], axis=1))


def image_gradient(rgb: np.ndarray) -> np.ndarray:
    """Sobel gradient of the grey image, ``(H, W, 2)`` float32 (x then y)."""
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
    return np.dstack([cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)])


def edge_scores(gradient: np.ndarray, creases: Creases, poses: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                samples: int = 8) -> np.ndarray:
    """Mean image gradient across the visible creases (one of the two faces faces the
    camera) of the object at each world pose ``(P, 4, 4)`` → ``(P,)``."""
    Rt, t = poses[:, :3, :3].transpose(0, 2, 1), poses[:, None, :3, 3]
    a, b = creases.ends[:, 0] @ Rt + t, creases.ends[:, 1] @ Rt + t  # (P, E, 3)
    facing = (creases.normals.reshape(-1, 3) @ Rt).reshape(len(poses), -1, 2, 3)  # (P, E, 2, 3)
    visible = np.any(np.sum(facing * (T_world_cam[:3] - (a + b) / 2)[:, :, None], axis=-1) > 0, axis=2)  # (P, E)
    s = np.linspace(0.1, 0.9, samples)
    pts = a[:, :, None] + s[:, None] * (b - a)[:, :, None]  # (P, E, S, 3)
    uv = project(pts.reshape(-1, 3), K, T_world_cam)[0].reshape(*pts.shape[:3], 2)
    d = uv[:, :, -1] - uv[:, :, 0]
    across = np.stack([-d[..., 1], d[..., 0]], axis=-1) / (np.linalg.norm(d, axis=-1, keepdims=True) + 1e-6)
    grid = uv.reshape(len(poses), -1, 2).astype(np.float32)  # rows and columns stay below OpenCV's 32767
    g = cv2.remap(gradient, grid[..., 0], grid[..., 1], cv2.INTER_LINEAR, borderValue=0.0).reshape(uv.shape)
    g = np.abs(np.sum(g * across[:, :, None], axis=-1)).mean(axis=2)  # (P, E)
    return np.sum(g * visible, axis=1) / np.maximum(visible.sum(axis=1), 1)


def _turned(M: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Pose ``M (4, 4)`` turned about the world vertical through its origin, ``(A, 4, 4)``."""
    out = np.repeat(M[None], len(angles), axis=0)
    out[:, :3, :3] = Rotation.from_euler("z", angles[:, None]).as_matrix() @ M[:3, :3]
    return out


def _shifted(M: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Pose ``M (4, 4)`` moved horizontally by each of ``offsets (A, 2)``, ``(A, 4, 4)``."""
    out = np.repeat(M[None], len(offsets), axis=0)
    out[:, :2, 3] += offsets
    return out


def _grid(half: float, step: float) -> np.ndarray:
    k = int(round(half / step))
    return np.arange(-k, k + 1) * step


def refine_on_edges(gradient: np.ndarray, creases: Creases, pose: np.ndarray, period: float, K: np.ndarray,
                    T_world_cam: np.ndarray, cfg: EdgeConfig = EdgeConfig()) -> np.ndarray:
    """World pose ``(7,)`` of an object standing on its support: ``pose`` turned about the
    vertical (within half the symmetry ``period`` (rad), at most ``cfg.max_turn_deg``) and
    moved horizontally (within ``cfg.shift_m``) to lie on the strongest image edges.
    A coarse grid over heading and position jointly (they trade off: a shifted nut fits
    better turned), then finer ones."""
    M = pose_to_matrix(pose)
    turn = np.radians(cfg.turn_step_deg)
    searches = [(min(np.radians(cfg.max_turn_deg), period / 2), turn, cfg.shift_m, cfg.shift_step_m)]
    searches += [(turn, turn / 4, cfg.shift_step_m, cfg.shift_step_m / 4)] * cfg.fine_rounds
    for turn_half, turn_step, shift_half, shift_step in searches:  # joint over heading and position
        g = _grid(shift_half, shift_step)
        offsets = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
        candidates = np.concatenate([_shifted(T, offsets) for T in _turned(M, _grid(turn_half, turn_step))])
        scores = edge_scores(gradient, creases, candidates, K, T_world_cam, cfg.samples)
        here = len(candidates) // 2  # both grids are odd and centred: the pose as it is
        best = int(np.argmax(scores))
        M = candidates[best if scores[best] > scores[here] else here]  # no edge evidence: stay
    return pose_from_matrix(M)
