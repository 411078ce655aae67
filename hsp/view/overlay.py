"""Tracked meshes drawn over the colour frames: an MP4 per episode.

Each object's mesh, posed by the tracker, is projected with the recording's pinhole
intrinsics and filled translucently in its tracking status's colour (ok green, suspect
amber, lost red), with an outline; the ground-truth pose, when the recording has one, is
outlined thinly in white beside it.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from hsp.dataset.features import TrackStatus
from hsp.errors import HspError
from hsp.geometry import transform_points
from hsp.perception.pointcloud import project
from hsp.sim.render import Mesh

STATUS_BGR = {TrackStatus.OK: (80, 200, 60), TrackStatus.SUSPECT: (0, 180, 255), TrackStatus.LOST: (40, 40, 230)}
TRUTH_BGR = (255, 255, 255)


def _mask(mesh: Mesh, pose: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Silhouette ``(H, W)`` uint8 of the posed mesh (triangles in front of the camera)."""
    uv, z = project(transform_points(pose, mesh.vertices), K, T_world_cam)
    tri = mesh.triangles[np.all(z[mesh.triangles] > 0, axis=1)]
    out = np.zeros(shape, np.uint8)
    for polygon in np.round(uv[tri] * 4).astype(np.int32):  # one at a time: fillPoly cancels overlaps (even-odd)
        cv2.fillConvexPoly(out, polygon, 255, lineType=cv2.LINE_8, shift=2)
    return out


def draw_frame(rgb: np.ndarray, meshes: list[Mesh], poses: np.ndarray, status: np.ndarray, K: np.ndarray,
               T_world_cam: np.ndarray, truth: np.ndarray | None = None, alpha: float = 0.35) -> np.ndarray:
    """One overlay frame, BGR ``(H, W, 3)`` uint8, from an RGB frame and ``(n, 7)`` poses."""
    img = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    shape = img.shape[:2]
    fill = img.copy()
    outlines = []
    for mesh, pose, s in zip(meshes, poses, status):
        if not np.all(np.isfinite(pose)):
            continue
        m = _mask(mesh, pose, K, T_world_cam, shape)
        colour = STATUS_BGR[TrackStatus(int(s))]
        fill[m > 0] = colour
        outlines.append((m, colour, 2))
    img = cv2.addWeighted(fill, alpha, img, 1 - alpha, 0)
    if truth is not None:
        outlines += [(_mask(mesh, pose, K, T_world_cam, shape), TRUTH_BGR, 1) for mesh, pose in zip(meshes, truth)]
    for m, colour, width in outlines:
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(img, contours, -1, colour, width, lineType=cv2.LINE_AA)
    return img


def write_overlay(path: Path, rgb: np.ndarray, meshes: list[Mesh], poses: np.ndarray, status: np.ndarray,
                  K: np.ndarray, T_world_cam: np.ndarray, fps: float, truth: np.ndarray | None = None) -> Path:
    """An MP4 of ``rgb (T, H, W, 3)`` with the tracked ``poses (T, n, 7)`` drawn on it."""
    if len(rgb) != len(poses):
        raise HspError(f"{path}: {len(rgb)} colour frames but {len(poses)} pose frames")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial.mp4")
    H, W = rgb.shape[1:3]
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (W, H))
    if not writer.isOpened():
        raise HspError(f"{path}: OpenCV cannot write MP4 (mp4v) here")
    try:
        for t in range(len(rgb)):
            writer.write(draw_frame(rgb[t], meshes, poses[t], status[t], K, T_world_cam, None if truth is None else truth[t]))
    finally:
        writer.release()
    tmp.replace(path)
    return path
