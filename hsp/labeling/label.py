"""Labelling one episode: priors (or trained networks) → Viterbi → tool, target, w per frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter

from hsp.dataset.features import TrackStatus
from hsp.errors import HspError
from hsp.geometry import relative
from hsp.geometry.symmetry import canonical_orientations
from hsp.labeling.equivalence import equivalent_targets
from hsp.labeling.priors import PriorConfig, PriorScores, continuous_quaternions, pairs_of
from hsp.labeling.ties import resolve_target_ties
from hsp.labeling.viterbi import Scores, Transition, viterbi


@dataclass
class EpisodeLabels:
    tool: np.ndarray
    """o+ per frame ``(H,)``."""
    target: np.ndarray
    """o* per frame ``(H,)``."""
    waypoint_index: np.ndarray
    """k per frame ``(H,)``: the frame whose relative pose is the way-point."""
    waypoint: np.ndarray
    """w = p_k[o+, o*] per frame ``(H, 7)``, in the target's frame."""
    equivalent: np.ndarray
    """Per frame, the objects the target cannot be told apart from ``(H, n)`` bool, o*
    included (:mod:`~hsp.labeling.equivalence`); only o* where the labels are exact."""


def canonical_poses(world: np.ndarray, symmetries: list[str]) -> np.ndarray:
    """World poses ``(H, n, 7)`` with each symmetric object's orientation made canonical
    (:func:`~hsp.geometry.symmetry.canonical_orientations`): way-points in a bucket's or a
    wheel's frame then mean the same whatever heading the tracker gave it."""
    out = world.copy()
    for i, symmetry in enumerate(symmetries):
        out[:, i, 3:] = canonical_orientations(world[:, i, 3:], symmetry)
    return out


def median_headings(world: np.ndarray, window: int) -> np.ndarray:
    """World poses ``(H, n, 7)`` with every object's orientation but the end-effector's
    replaced by its running median over ``window`` frames (quaternion components, their
    signs made continuous first, then renormalised). A tracker's heading glitch of a few
    frames swings the tool's position in that object's frame by lever arm × angle, which
    π_l charges as motion (a nut's 21° for five frames, the wrench 30 cm away: 77 nats in
    one frame); a median keeps sustained turns. The end-effector's orientation is the
    commanded motion itself and is kept."""
    if window <= 1 or world.shape[1] < 2:
        return world
    q = median_filter(continuous_quaternions(world[:, 1:, 3:]), size=(window, 1, 1), mode="nearest")
    out = world.copy()
    out[:, 1:, 3:] = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out


def prepared_poses(world: np.ndarray, symmetries: list[str], cfg: PriorConfig) -> np.ndarray:
    """Tracked world poses ``(H, n, 7)`` as labelling reads them: headings median-filtered
    (:func:`median_headings`), then symmetric objects' orientations made canonical."""
    return canonical_poses(median_headings(world, cfg.heading_median_frames), symmetries)


def label_episode(world: np.ndarray, status: np.ndarray, cfg: PriorConfig, scores: Scores | None = None,
                  symmetries: list[str] | None = None) -> EpisodeLabels:
    """Pseudo-labels of one episode of world poses ``(H, n, 7)`` with status ``(H, n)``.
    With the objects' ``symmetries``, the poses are tracked ones and are prepared first
    (:func:`prepared_poses`; way-points are then in canonical frames); without, they are
    used as given.

    ``scores`` replaces the priors (EM with trained networks); it must use the pair order
    of :func:`~hsp.labeling.priors.pairs_of`. Over the priors, the tie rules of
    :mod:`~hsp.labeling.ties` then choose among targets rigid with each other; over
    ``scores`` nothing overrules Viterbi. The targets rigid with the labelled one over its
    sub-task come with it as its equivalence set (:mod:`~hsp.labeling.equivalence`).
    """
    H, n = world.shape[:2]
    if H < 2:
        raise HspError(f"an episode of {H} frame(s) cannot be labelled; at least 2 are needed")
    if n < 2:
        raise HspError(f"{n} object(s): labelling needs the end-effector and at least one other object")
    ok = status != TrackStatus.LOST
    if symmetries is not None:
        world = prepared_poses(world, symmetries, cfg)
    path = viterbi(scores or PriorScores(world, ok, cfg), Transition(cfg.gamma, cfg.beta))
    tool, target = pairs_of(n)[path.pair].T
    if scores is None:
        target = resolve_target_ties(world, ok, tool, target, path.k, cfg.rigid_m, cfg.rigid_deg)
    return EpisodeLabels(tool, target, path.k, relative(world[path.k, tool], world[path.k, target]),
                         equivalent_targets(world, ok, tool, target, cfg.rigid_m, cfg.rigid_deg))
