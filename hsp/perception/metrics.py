"""Pose-tracking errors against ground truth: translation, symmetry-aware rotation, ADD-S
and its area under the accuracy curve (0–10 cm, ×100, as se(3)-TrackNet's VOCap); how far the
tracker's own status can be trusted."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from hsp.geometry import transform_points
from hsp.geometry.symmetry import symmetry_rotations
from hsp.tasks.spec import Symmetry

AUC_MAX_M = 0.10
ACCURATE_MM = 10.0
ACCURATE_DEG = 5.0
"""A pose within 1 cm and 5° of the truth is accurate: what a frame marked ok must be."""


def rotation_error_deg(q_est: np.ndarray, q_gt: np.ndarray, symmetry: Symmetry) -> np.ndarray:
    """Smallest rotation angle (deg) between estimate and any symmetric equivalent of the
    truth; for ``z_continuous`` the angle between the two z axes. ``(..., 4)`` → ``(...)``."""
    R_est = Rotation.from_quat(np.asarray(q_est).reshape(-1, 4)).as_matrix()
    R_gt = Rotation.from_quat(np.asarray(q_gt).reshape(-1, 4)).as_matrix()
    if symmetry == "z_continuous":
        cos = np.clip(np.sum(R_est[:, :, 2] * R_gt[:, :, 2], axis=1), -1, 1)
        return np.degrees(np.arccos(cos)).reshape(np.shape(q_est)[:-1])
    S = symmetry_rotations(symmetry)
    rel = np.einsum("nji,njk->nik", R_gt, R_est)  # R_gt^T R_est
    traces = np.einsum("nik,mki->nm", rel, S)  # trace(rel · S_m)
    cos = np.clip((traces.max(axis=1) - 1) / 2, -1, 1)
    return np.degrees(np.arccos(cos)).reshape(np.shape(q_est)[:-1])


def add_s(points: np.ndarray, pose_est: np.ndarray, pose_gt: np.ndarray) -> np.ndarray:
    """ADD-S (m): mean distance from each model point under the estimate to the nearest
    model point under the truth; ``points (M, 3)``, poses ``(T, 7)`` → ``(T,)``."""
    out = np.empty(len(pose_est))
    for t, (pe, pg) in enumerate(zip(pose_est, pose_gt)):
        tree = cKDTree(transform_points(pg, points))
        out[t] = tree.query(transform_points(pe, points))[0].mean()
    return out


def auc(errors_m: np.ndarray, max_m: float = AUC_MAX_M) -> float:
    """Area under accuracy-vs-threshold on [0, max_m], ×100 (100 = every error is 0)."""
    e = np.sort(np.asarray(errors_m, float).ravel())
    if e.size == 0:
        return float("nan")
    thresholds = np.linspace(0, max_m, 1001)
    accuracy = np.searchsorted(e, thresholds, side="right") / e.size
    return float(np.trapezoid(accuracy, thresholds) / max_m * 100.0)


def match_identical(groups: list[list[int]], poses: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Object order ``(n,)`` that pairs each tracked object with the true one, within each
    group of identical objects (same mesh and label: four nuts), by least mean distance over
    the episode. Their names are interchangeable, so a tracker cannot be asked to tell them
    apart; it must only keep each one's identity through the episode."""
    order = np.arange(poses.shape[1])
    for g in groups:
        cost = np.linalg.norm(poses[:, g, None, :3] - truth[:, None, g, :3], axis=-1).mean(axis=0)  # (est, true)
        est, true = linear_sum_assignment(cost)
        order[np.asarray(g)[true]] = np.asarray(g)[est]
    return order


def episode_errors(symmetries: list[Symmetry], samples: list[np.ndarray], poses: np.ndarray, truth: np.ndarray) -> dict[str, np.ndarray]:
    """Per frame and object ``(T, n)``: translation error (mm), symmetry-aware rotation
    error (deg) and ADD-S (m) of tracked ``poses`` against ``truth`` (both ``(T, n, 7)``)."""
    te = np.linalg.norm(poses[..., :3] - truth[..., :3], axis=-1) * 1000.0
    re = np.stack([rotation_error_deg(poses[:, i, 3:], truth[:, i, 3:], s) for i, s in enumerate(symmetries)], axis=1)
    adds = np.stack([add_s(samples[i], poses[:, i], truth[:, i]) for i in range(len(symmetries))], axis=1)
    return {"translation_mm": te, "rotation_deg": re, "adds_m": adds}


def status_trust(translation_mm: np.ndarray, rotation_deg: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    """How far a tracker's status can be filtered on, from errors and ``ok`` flags of the
    same shape: the share of poses marked ok that are accurate (within ``ACCURATE_MM`` and
    ``ACCURATE_DEG``), and the share of inaccurate poses not marked ok (suspect or lost).
    NaN where there are no such poses."""
    accurate = (translation_mm <= ACCURATE_MM) & (rotation_deg <= ACCURATE_DEG)
    ok = np.asarray(ok, bool)
    precision = float(np.mean(accurate[ok])) if ok.any() else float("nan")
    flagged = float(np.mean(~ok[~accurate])) if (~accurate).any() else float("nan")
    return precision, flagged
