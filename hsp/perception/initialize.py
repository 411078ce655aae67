"""First-frame pose estimates (the scene-level estimate that starts tracking).

Each object is looked for among the points that match its colour palette, grouped into
clusters (DBSCAN). From each of the largest clusters, pose hypotheses are refined by the
tracker's ICP: objects standing on the table keep their resting attitude (the layout is
physically consistent: upright, at the height where the model touches z = 0; objects on
other objects upright too) and try a grid of yaw angles; the end-effector is assumed to point down and tries the same grid.
The hypothesis wins that puts the most scene points on the model's surface where the
model has their colour, less the nearby points of its colours that it leaves unexplained; identical objects (same
palette) take distinct clusters.

Hypotheses are screened first, on every k-th point (``SCREEN_POINTS``) with ICP's widest
gate alone; the ``REFINED`` best are fitted again on all points through every gate and
scored there. An end-effector in the air has 432 hypotheses: screening them cost 3–5 s a
tire-removal episode with the full fit, 1–2 s so.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from hsp.geometry import compose, pose_from_matrix, pose_to_matrix
from hsp.geometry.symmetry import z_folds
from hsp.perception.pointcloud import SHADE_RANGE, colour_match, palette_mask
from hsp.perception.tracker import Support, SurfaceModel, TrackerConfig, _icp, colour_agreement, min_points
from hsp.tasks.layout import mesh_extent
from hsp.tasks.registry import Task

YAW_STEPS = 16
CLUSTER_EPS_M = 0.012
MAX_CLUSTERS = 3
MIN_DISTINCTIVE_AREA = 0.2
SCREEN_POINTS = 150
"""Scene points per hypothesis (every k-th) when all hypotheses are screened."""
REFINED = 4
"""Best screened hypotheses of each object refined and scored again on all their points."""
AIR_SHIFTS = [np.array(v) for v in ([0, 0, -0.04], [0, 0, -0.02], [0, 0, 0], [0, 0, 0.02], [0, 0, 0.04],
                                    [0.02, 0, 0], [-0.02, 0, 0], [0, 0.02, 0], [0, -0.02, 0])]
"""Where an object in the air may sit relative to its visible part's centre (m)."""
AWAY_STEPS = (0.0, 0.25, 0.5, 0.75)
"""Radii from its visible part's centre, away from the camera, that a resting object is tried at."""


def _clusters(points: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the DBSCAN clusters of ``points``, largest first."""
    if len(points) < 10:
        return []
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    labels = np.asarray(pcd.cluster_dbscan(eps=CLUSTER_EPS_M, min_points=8))
    groups = [np.flatnonzero(labels == k) for k in range(labels.max() + 1)] if labels.size else []
    return sorted(groups, key=len, reverse=True)


def _yaw_grid(symmetry: str) -> np.ndarray:
    """Yaw hypotheses: ``YAW_STEPS`` per turn, over one period of the object's symmetry about z."""
    period = z_folds(symmetry)
    if not period:
        return np.zeros(1)
    steps = max(1, -(-YAW_STEPS // period))
    return np.arange(steps) * 2 * np.pi / (period * steps)


def _centre_of_colour(points: np.ndarray, start: np.ndarray, radius: float, steps: int = 3) -> np.ndarray:
    """Mean-shift of ``start`` over the object's colour ``points`` within ``radius``: the
    centre of the whole visible object when DBSCAN cut it in two (a bucket's rim and inside)."""
    centre = start
    for _ in range(steps):
        near = points[np.linalg.norm(points - centre, axis=1) < radius]
        if len(near) == 0:
            break
        centre = near.mean(axis=0)
    return centre


def _upright(pose: np.ndarray) -> np.ndarray:
    """``pose`` with its roll and pitch removed (yaw kept): an object resting on its support
    at the start stands upright, though a few noisy points may tilt its fit."""
    x = Rotation.from_quat(pose[3:]).apply([1.0, 0.0, 0.0])
    return np.concatenate([pose[:3], Rotation.from_euler("z", np.arctan2(x[1], x[0])).as_quat()])


def _extent(points: np.ndarray) -> float:
    """Largest side of the axis-aligned box around ``points``."""
    return float(np.max(points.max(axis=0) - points.min(axis=0)))


def distinctive_palettes(task: Task, models: list[SurfaceModel], tol: float) -> list[np.ndarray]:
    """Each object's colours that no differently labelled object of the task has (the
    brush's brown, not its grey ferrule, which the canvas shares); all its colours if those
    cover less than ``MIN_DISTINCTIVE_AREA`` of its surface (a nut's small paint mark)."""
    out = []
    lo, hi = SHADE_RANGE  # two colours are alike if some shading of each gives the same pixel
    for i, model in enumerate(models):
        others = [m.palette for j, m in enumerate(models) if task.labels[j] != task.labels[i]]
        other = np.concatenate(others) if others else np.zeros((0, 3))
        shared = palette_mask(model.palette, other, tol, (lo / hi, hi / lo)) if other.size else np.zeros(len(model.palette), bool)
        own = model.palette[~shared]
        area = model.face_area[palette_mask(model.face_rgb, own, tol, (0.99, 1.01))].sum() if len(own) else 0.0
        out.append(own if area >= MIN_DISTINCTIVE_AREA * model.face_area.sum() else model.palette)
    return out


def _anchor(face_centres: np.ndarray, face_rgb: np.ndarray, palette: np.ndarray, tol: float) -> np.ndarray:
    """Centre, in the object frame, of the model's faces in the distinctive colours: the
    point a cluster of those colours is centred on (the palm, not the fingertips)."""
    sel = palette_mask(face_rgb, palette, tol)
    return face_centres[sel].mean(axis=0) if sel.any() else face_centres.mean(axis=0)


def _near(pts: np.ndarray, coloured: np.ndarray, centre: np.ndarray, reach: float) -> np.ndarray:
    """The ``coloured`` indices (scene points in the model's colours) within ``reach`` of ``centre``."""
    return coloured[np.linalg.norm(pts[coloured] - centre, axis=1) < reach]


def _hypothesis(model: SurfaceModel, guess: np.ndarray, pts: np.ndarray, cols: np.ndarray, near: np.ndarray,
                camera: np.ndarray, coarse: TrackerConfig, cfg: TrackerConfig) -> tuple[float, np.ndarray]:
    """ICP from ``guess`` on the ``near`` points; the score of the fitted pose (points on the
    surface where the model has their colour, less those left unexplained) and the pose."""
    M = pose_to_matrix(guess)[:3, :3]
    local = (pts[near] - guess[:3]) @ M
    corr, _, _ = _icp(model, local, coarse, (camera - guess[:3]) @ M)
    agree = colour_agreement(model, local @ corr[:3, :3].T + corr[:3, 3], cols[near], cfg)
    return float(2 * agree - len(near)), compose(guess, pose_from_matrix(np.linalg.inv(corr)))


def _away(seen: np.ndarray, camera: np.ndarray, radius: float) -> list[np.ndarray]:
    """Where an object resting on the table may sit relative to its visible part's centre
    ``seen (3,)``: there, or up to ``AWAY_STEPS`` radii further from the camera, level. The
    camera sees the near half of an object, so the near half's centre lies between the
    camera and the object's (half a radius, from a low view of a wheel)."""
    away = np.array([seen[0] - camera[0], seen[1] - camera[1], 0.0])
    away /= max(np.linalg.norm(away), 1e-9)
    return [f * radius * away for f in AWAY_STEPS]


def _guesses(seen: np.ndarray, anchor: np.ndarray, yaws: np.ndarray, shifts: list[np.ndarray],
             rest_height: float | None) -> list[np.ndarray]:
    """Poses ``(7,)`` that put the model's ``anchor`` on the ``seen`` centre at each yaw,
    shifted by each of ``shifts``; at ``rest_height`` when the object rests on the table."""
    out = []
    for yaw, shift in ((y, d) for y in yaws for d in shifts):
        R = Rotation.from_euler("z", yaw)
        centre = seen - R.apply(anchor) + shift
        if rest_height is not None:
            centre[2] = rest_height
        out.append(np.concatenate([centre, R.as_quat()]))
    return out


def _screen(model: SurfaceModel, guesses: list[np.ndarray], pts: np.ndarray, cols: np.ndarray, coloured: np.ndarray,
            reach: float, camera: np.ndarray, screen: TrackerConfig, cfg: TrackerConfig) -> list[tuple[float, np.ndarray]]:
    """Score and fitted pose of each guess with enough points near it, on every k-th point
    (one k for all the guesses, so that their scores compare)."""
    out, stride = [], None
    for guess in guesses:
        near = _near(pts, coloured, guess[:3], reach)
        if len(near) < cfg.min_points:
            continue
        stride = stride or max(1, len(near) // SCREEN_POINTS)
        score, fitted = _hypothesis(model, guess, pts, cols, near[::stride], camera, screen, cfg)
        out.append((score * stride, fitted))
    return out


def initialize(task: Task, pts: np.ndarray, cols: np.ndarray, models: list[SurfaceModel], camera: np.ndarray,
               cfg: TrackerConfig = TrackerConfig(), only: list[int] | None = None,
               first_frame: bool = True, support: Support | None = None,
               focal_px: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World poses ``(n, 7)`` and whether each was found ``(n,)``, for every object or the
    ``only`` ones; ``camera (3,)`` is the camera's world position (for back-face culling).
    In the first frame, objects placed on the table rest there upright; later (re-detection)
    any object may be anywhere, upright or pointing down. With the camera's ``focal_px``, a
    small or far object needs fewer points (:func:`~hsp.perception.tracker.min_points`).

    With the frame's ``support``, each estimate checks itself the other way round: the score
    counts the scene points the model explains, the support the share of the model's seen
    surface that the frame explains. A hypothesis wins on their product (a canvas slid 8 mm
    along itself keeps every point on its surface, but its far edge hangs over the table:
    support 0.97 against 1.0), and is found only if supported by ``cfg.min_explained``."""
    n = len(models)
    poses = np.tile([0, 0, 0, 0, 0, 0, 1.0], (n, 1))
    found = np.zeros(n, bool)
    taken: dict[bytes, set[int]] = {}
    screenings: dict[tuple, list] = {}
    palettes = distinctive_palettes(task, models, cfg.colour_tolerance)

    def need(model: SurfaceModel, at: np.ndarray) -> int:
        """The fewest points that support ``model`` at ``at (3,)``."""
        if focal_px is None:
            return cfg.min_points
        return min_points(model, float(np.linalg.norm(at - camera)), focal_px, cfg)
    for i, (obj, model) in enumerate(zip(task.objects, models)):
        if only is not None and i not in only:
            continue
        key = palettes[i].tobytes()
        used = taken.setdefault(key, set())
        rest_height = mesh_extent(task.mesh(i))[1] if first_frame and i > 0 and obj.place.support == "table" else None
        wide = max(0.03, model.radius / 3)  # a wheel's visible part is centred centimetres off its own centre
        coarse = TrackerConfig(gates_m=(wide, 0.015, 0.006), tukey_m=max(cfg.tukey_m, wide if wide > 0.03 else 0.0))
        coloured = np.flatnonzero(model.colour_mask(cols, cfg.colour_tolerance))
        reach = model.radius + cfg.crop_margin_m
        same = (key, task.mesh(i), obj.symmetry, rest_height)  # identical objects share one screening
        if same not in screenings:
            mask = np.flatnonzero(palette_mask(cols, palettes[i], cfg.colour_tolerance))
            anchor = _anchor(model.face_centres, model.face_rgb, palettes[i], cfg.colour_tolerance)
            groups = _clusters(pts[mask])
            fits = [g for g, idx in enumerate(groups) if _extent(pts[mask[idx]]) <= 2 * reach]
            twins = sum(p.tobytes() == key for p in palettes) - 1
            yaws = _yaw_grid(obj.symmetry)
            screen = TrackerConfig(gates_m=coarse.gates_m[:1], tukey_m=coarse.tukey_m)
            screenings[same] = []
            for g in (fits or list(range(len(groups))))[: MAX_CLUSTERS + twins]:
                seen = _centre_of_colour(pts[mask], pts[mask[groups[g]]].mean(axis=0), 1.5 * model.radius)
                shifts = AIR_SHIFTS if rest_height is None else _away(seen, camera, model.radius)
                guesses = _guesses(seen, anchor, yaws, shifts, rest_height)
                screenings[same] += [(score, fitted, g) for score, fitted in
                                     _screen(model, guesses, pts, cols, coloured, reach, camera, screen,
                                             replace(cfg, min_points=need(model, seen)))]
        screened = [h for h in screenings[same] if h[2] not in used]
        best = (-np.inf, None, -1)
        for _, guess, g in sorted(screened, key=lambda h: -h[0])[:REFINED]:
            near = _near(pts, coloured, guess[:3], reach)
            fewest = need(model, guess[:3])
            if len(near) >= fewest:
                score, fitted = _hypothesis(model, guess, pts, cols, near, camera, coarse, cfg)
                share = 1.0 if support is None else support(i, _upright(fitted) if rest_height is not None else fitted)
                # the agreement net of what is left unexplained, and the frame's support
                if score >= fewest and share >= cfg.min_explained and score * share > best[0]:
                    best = (score * share, fitted, g)
        if best[1] is not None:
            resting = first_frame and i > 0 and obj.place.support != "air"
            poses[i], found[i] = _upright(best[1]) if resting else best[1], True
            used.add(best[2])
    return poses, found
