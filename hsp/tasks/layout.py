"""Random initial layouts (paper, Fig. 1: objects are placed at random at the start of
every demonstration and every test episode)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.errors import HspError
from hsp.geometry import compose
from hsp.geometry.mesh import obj_vertices
from hsp.tasks.registry import Task

ROBOT_BASE_RADIUS = 0.15
"""Keep-out disc around the robot base at the world origin (m)."""


def mesh_extent(path: Path) -> tuple[float, float]:
    """(footprint radius in xy, height of the lowest point below the frame) of an OBJ."""
    verts = obj_vertices(path)
    return float(np.max(np.linalg.norm(verts[:, :2], axis=1))), float(-verts[:, 2].min())


def _yaw_pose(xyz: np.ndarray, yaw: float) -> np.ndarray:
    return np.concatenate([xyz, Rotation.from_euler("z", yaw).as_quat()])


def sample_layout(task: Task, rng: np.random.Generator, max_tries: int = 500) -> np.ndarray:
    """World poses ``(n, 7)`` of all objects at the start of an episode.

    Table objects are drawn uniformly in their x, y, yaw ranges and rested on the table,
    rejecting footprints (mesh radius + ``min_clearance``) that overlap each other or the
    robot base; objects placed ``on`` another one follow it; the end-effector starts at
    a drawn x, y, z, yaw pointing down.
    """
    for _ in range(max_tries):
        poses = _try_layout(task, rng, tries_per_object=50)
        if poses is not None:
            return poses
    raise HspError(f"{task.path}: no overlap-free layout in {max_tries} attempts; widen place.x/y or lower min_clearance")


def _try_layout(task: Task, rng: np.random.Generator, tries_per_object: int) -> np.ndarray | None:
    poses = np.zeros((len(task.objects), 7))
    discs: list[tuple[np.ndarray, float]] = [(np.zeros(2), ROBOT_BASE_RADIUS)]
    for i, obj in enumerate(task.objects):
        pl = obj.place
        if i == 0:
            xyz = np.array([rng.uniform(*pl.x), rng.uniform(*pl.y), rng.uniform(*pl.z)])
            poses[0] = _yaw_pose(xyz, rng.uniform(*pl.yaw))
            continue
        if pl.support != "table":
            parent = poses[task.index(pl.support)]
            poses[i] = compose(parent, _yaw_pose(np.asarray(pl.xyz), rng.uniform(*pl.yaw)))
            continue
        radius, rest = mesh_extent(task.mesh(i))
        pattern = getattr(task.spec.success, "pattern", None)
        if pattern and obj.name == getattr(task.spec.success, "base", None):
            radius += max(np.linalg.norm(np.asarray(v)[:2]) for v in pattern.values())  # room for the pattern
        for _ in range(tries_per_object):
            xy = np.array([rng.uniform(*pl.x), rng.uniform(*pl.y)])
            if all(np.linalg.norm(xy - c) >= radius + r + task.spec.min_clearance for c, r in discs):
                break
        else:
            return None
        discs.append((xy, radius))
        poses[i] = _yaw_pose(np.array([xy[0], xy[1], rest]), rng.uniform(*pl.yaw))
    return poses
