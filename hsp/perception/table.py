"""The table frame of a recording: z = 0 on the table top, z up, which the tracker needs.

A recording made by ``hsp record`` carries it on ``/tf_static``; one from the RealSense
driver carries only the camera's own frames (``camera_link`` → ``camera_color_frame`` →
``camera_color_optical_frame``), whose root is no table. So the table plane is always fitted
in the depth of the first frames (their per-pixel median, so that one bad frame or a hand
passing does not decide it; Open3D's RANSAC plane segmentation, refined by least squares on
its inliers), and the frame used is, in this order:

1. the camera pose the user gives (``--camera-pose``);
2. the root of ``/tf_static`` when the fitted plane lies at its z = 0, facing up;
3. a frame on the fitted plane: origin where the optical axis meets it, x along the image's
   x axis, z toward the camera. Heading and origin on the table are arbitrary, which
   changes no object-to-object pose.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from hsp.errors import HspError
from hsp.geometry import inverse, pose_from_matrix, pose_to_matrix
from hsp.perception.pointcloud import camera_points


GROUND_TRUTH_FRAME = "ground truth"
"""The frame of poses taken from a recording's ground truth (``hsp parse --poses-from ground-truth``)."""


def in_recorded_world(how: str) -> bool:
    """Whether poses in a table frame found ``how`` are in the recording's own world, that of
    its ground truth: a fitted or given frame is not, so it is not scored against it."""
    return how.startswith("tf_static") or how == GROUND_TRUTH_FRAME


@dataclass(frozen=True)
class TableConfig:
    inlier_m: float = 0.005
    """RANSAC's inlier distance to the plane."""
    min_inliers: float = 0.3
    """The plane must hold at least this share of the frame's depth readings."""
    agree_m: float = 0.02
    """``/tf_static``'s root is the table frame if the fitted plane lies within this of its z = 0 ..."""
    agree_deg: float = 3.0
    """... and its normal within this of its z axis."""
    stride: int = 2
    """Every ``stride``-th pixel row and column."""
    iterations: int = 500
    """RANSAC iterations."""
    frames: int = 5
    """The plane is fitted in the per-pixel median depth of the recording's first frames."""


@dataclass(frozen=True)
class TablePlane:
    normal: np.ndarray
    """(3,) unit normal in the camera frame, toward the camera."""
    distance_m: float
    """The camera's height above the plane: points p on it satisfy normal · p + distance_m = 0."""
    inliers: float
    """Share of the depth readings on the plane."""


def median_depth(depth: np.ndarray) -> np.ndarray:
    """Per-pixel median ``(H, W)`` of the readings in ``depth (N, H, W)`` m (0 = none), 0 where none."""
    readings = np.where(depth > 0, depth, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # pixels with no reading in any frame
        return np.nan_to_num(np.nanmedian(readings, axis=0), nan=0.0).astype(np.float32)


def fit_table(depth: np.ndarray, K: np.ndarray, cfg: TableConfig = TableConfig(), seed: int = 0,
              source: str = "depth") -> TablePlane:
    """The dominant plane in ``depth``, the first frames ``(N, H, W)`` m (or one, ``(H, W)``);
    a one-line error naming ``source`` if there is none."""
    import open3d as o3d

    depth = median_depth(depth[: cfg.frames]) if depth.ndim == 3 else depth
    pts = camera_points(depth, K, cfg.stride)[0]
    if len(pts) < 100:
        raise HspError(f"{source}: {len(pts)} depth readings in the first frames; too few to find the table")
    o3d.utility.random.seed(seed)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    _, idx = cloud.segment_plane(cfg.inlier_m, 3, cfg.iterations)
    share = len(idx) / len(pts)
    if share < cfg.min_inliers:
        raise HspError(f"{source}: no table in the first frames (the largest plane holds {share:.0%} of the depth, "
                       f"parse.table.min_inliers is {cfg.min_inliers:.0%}); give the camera pose with --camera-pose")
    on = pts[idx]
    centre = on.mean(axis=0)
    normal = np.linalg.svd(on - centre, full_matrices=False)[2][2]  # least squares on the inliers
    distance = -float(normal @ centre)
    if distance < 0:
        normal, distance = -normal, -distance
    return TablePlane(normal, distance, share)


def frame_on_plane(plane: TablePlane) -> np.ndarray:
    """``T_table_cam (7,)`` for a table frame on ``plane`` (see the module docstring)."""
    n, d = plane.normal, plane.distance_m
    origin = np.array([0.0, 0.0, -d / n[2]]) if n[2] < -0.1 else -d * n  # the optical axis meets the plane
    x = np.array([1.0, 0.0, 0.0]) - n[0] * n
    if np.linalg.norm(x) < 0.1:
        x = np.array([0.0, 1.0, 0.0]) - n[1] * n
    x /= np.linalg.norm(x)
    M = np.eye(4)
    M[:3, :3] = np.stack([x, np.cross(n, x), n], axis=1)  # the table's axes in the camera frame
    M[:3, 3] = origin
    return inverse(pose_from_matrix(M))


def plane_offset(plane: TablePlane, T_world_cam: np.ndarray) -> tuple[float, float]:
    """Height (m) of the fitted plane above z = 0 of ``T_world_cam``'s world, and its tilt (degrees)."""
    M = pose_to_matrix(T_world_cam)
    normal_w = M[:3, :3] @ plane.normal
    height = float((M[:3, :3] @ (-plane.distance_m * plane.normal) + M[:3, 3])[2])
    return height, float(np.degrees(np.arccos(np.clip(normal_w[2], -1.0, 1.0))))


def table_frame(depth: np.ndarray, K: np.ndarray, T_tf: np.ndarray | None, tf_root: str, given: np.ndarray | None,
                cfg: TableConfig = TableConfig(), seed: int = 0, source: str = "depth") -> tuple[np.ndarray, str]:
    """``T_world_cam (7,)`` from the first frames ``depth (N, H, W)`` and how it was found (module docstring)."""
    if given is not None:
        return np.asarray(given, float), "given"
    plane = fit_table(depth, K, cfg, seed, source)
    if T_tf is not None:
        height, tilt = plane_offset(plane, T_tf)
        if abs(height) <= cfg.agree_m and tilt <= cfg.agree_deg:
            return T_tf, f"tf_static {tf_root}"
    return frame_on_plane(plane), "fitted"
