"""One recording → 6D poses of every object in every frame: the first-frame scene estimate
(:mod:`hsp.perception.initialize`) starts the frame-to-frame tracker
(:mod:`hsp.perception.tracker`), which calls the same estimator again for objects it lost.

Only the colour, depth, intrinsics and camera pose of :class:`Recording` are used: the
recorded ground truth never reaches the tracker.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hsp.errors import HspError
from hsp.geometry.symmetry import z_folds
from hsp.perception.initialize import initialize
from hsp.perception.rest import CUBE_AXES, UPRIGHT, RestConfig, RestState
from hsp.perception.tracker import (FrameTracker, Support, SurfaceModel, TrackerConfig, evidence_at, follow,
                                    scene_points)
from hsp.recording.reader import Recording
from hsp.sim.render import load_mesh
from hsp.tasks.registry import Task


@dataclass
class TrackedEpisode:
    poses: np.ndarray
    """(T, n, 7) world poses in task order."""
    status: np.ndarray
    """(T, n) :class:`~hsp.dataset.features.TrackStatus` codes."""
    seconds: float
    """Time spent initialising and tracking (reading excluded)."""
    first_frame_seconds: float
    """Of which the first frame's scene estimate."""


def object_models(task: Task, cfg: TrackerConfig, seed: int) -> list[SurfaceModel]:
    """The task's surface models; a missing or unreadable mesh is an error naming it."""
    return [SurfaceModel(load_mesh(task.mesh(i)), cfg.model_points, seed + i, o.symmetry)
            for i, o in enumerate(task.spec.objects)]


def rest_state(task: Task, models: list[SurfaceModel], cfg: RestConfig = RestConfig()) -> RestState:
    """Which objects can rest and on which body axes: every face of a cube, the z axis of
    the others as the layout stands them; never the end-effector or what starts in the air.
    Objects the task mounts on a revolute joint (lug nuts) never tilt."""
    axes = [None if i == 0 or o.place.support == "air" else CUBE_AXES if o.symmetry == "cube" else UPRIGHT
            for i, o in enumerate(task.spec.objects)]
    fold = [z_folds(o.symmetry) for o in task.spec.objects]  # about the up axis
    periods = [2 * np.pi / f if f else 0.0 for f in fold]
    mounted = [o.place.joint == "revolute_z" for o in task.spec.objects]
    return RestState(axes, [m.surface for m in models], periods, cfg, mounted=mounted)


def first_frame_tracker(task: Task, rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                        models: list[SurfaceModel], cfg: TrackerConfig = TrackerConfig()) -> FrameTracker:
    """The scene estimate of a first frame (``rgb (H, W, 3)``, ``depth (H, W)`` m) and the
    stream tracker that starts from it, re-detecting lost objects with the same estimator;
    feed it every frame from this one on."""
    camera = T_world_cam[:3]
    pts, cols, _ = scene_points(rgb, depth, K, T_world_cam, cfg)
    first, found = initialize(task, pts, cols, models, camera, cfg, focal_px=K[0, 0],
                              support=lambda i, p: evidence_at(models[i], p, rgb, depth, K, T_world_cam, cfg).share)

    def redetect(p: np.ndarray, c: np.ndarray, idx: list[int], support: Support) -> tuple[np.ndarray, np.ndarray]:
        poses, ok = initialize(task, p, c, models, camera, cfg, only=idx, first_frame=False, support=support,
                               focal_px=K[0, 0])
        return poses[idx], ok[idx]

    return FrameTracker(K, T_world_cam, models, first, cfg, found, redetect, rest_state(task, models, cfg.rest))


def track_recording(task: Task, rec: Recording, models: list[SurfaceModel], cfg: TrackerConfig = TrackerConfig(),
                    progress: Callable[[], None] | None = None) -> TrackedEpisode:
    """Estimate the first frame's scene, then track every object through ``rec``."""
    if rec.T_world_cam is None:
        raise HspError(f"{rec.path}: no camera pose (no /tf_static chain from the table frame to "
                       f"{rec.frame_id!r}); the tracker needs it to place the table plane")
    start = time.perf_counter()
    tracker = first_frame_tracker(task, rec.rgb[0], rec.depth[0], rec.K, rec.T_world_cam, models, cfg)
    first_frame = time.perf_counter() - start
    poses, status = follow(tracker, rec.rgb, rec.depth, progress)
    return TrackedEpisode(poses, status, time.perf_counter() - start, first_frame)
