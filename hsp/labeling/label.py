"""Labelling one episode: priors (or trained networks) → Viterbi → tool, target, w per frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hsp.dataset.features import TrackStatus
from hsp.errors import HspError
from hsp.labeling.priors import PriorConfig, PriorScores
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


def label_episode(world: np.ndarray, status: np.ndarray, cfg: PriorConfig, scores: Scores | None = None) -> EpisodeLabels:
    """Pseudo-labels of one episode of world poses ``(H, n, 7)`` with status ``(H, n)``.

    ``scores`` replaces the priors (EM with trained networks); it must use the pair order
    of :func:`~hsp.labeling.priors.pairs_of`.
    """
    H, n = world.shape[:2]
    if H < 2:
        raise HspError(f"an episode of {H} frame(s) cannot be labelled; at least 2 are needed")
    if n < 2:
        raise HspError(f"{n} object(s): labelling needs the end-effector and at least one other object")
    ok = status != TrackStatus.LOST
    prior = PriorScores(world, ok, cfg)
    path = viterbi(scores or prior, Transition(cfg.gamma, cfg.beta))
    pair = prior.pairs[path.pair]
    return EpisodeLabels(pair[:, 0], pair[:, 1], path.k, prior.rel[path.k, path.pair])
