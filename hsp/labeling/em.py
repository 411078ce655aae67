"""EM refinement of the pseudo-labels (Algorithm 1, last line).

E-step: Viterbi labels every episode. M-step: the policies are trained on those labels.
The next E-step scores with the trained networks instead of the hand-set priors. This
repeats until no label changes, or for at most ``em_iterations`` rounds.

Training is the training stage's job. Here it is a callable, ``fit``, that takes the
current labels and returns a :data:`ScoreModel`: for one episode, a
:class:`~hsp.labeling.viterbi.Scores` of log-probabilities (π_h over pairs, π_m over
way-points, π_l of the observed motion), with pairs in the order of
:func:`~hsp.labeling.priors.pairs_of`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from hsp.errors import HspError
from hsp.labeling.label import EpisodeLabels, label_episode, prepared_poses
from hsp.labeling.priors import PriorConfig, pairs_of
from hsp.labeling.viterbi import Scores

if TYPE_CHECKING:
    from hsp.tasks.registry import Task

log = logging.getLogger(__name__)

ScoreModel = Callable[[np.ndarray, np.ndarray, EpisodeLabels], Scores]
"""(world poses (H, n, 7), status (H, n), the episode's labels of the last round) → its
log-scores; the labels give the networks their history (the previous pairs and way-points)."""
Fit = Callable[[list[EpisodeLabels]], ScoreModel]
"""Labels of every episode → the networks trained on them, as a score model."""


class Refinement(Protocol):
    """EM as the label stage runs it: labels of a task's episodes (world poses, status)
    and the fraction of frames relabelled in each round."""

    def run(self, task: "Task", poses: list[np.ndarray], status: list[np.ndarray],
            cfg: PriorConfig) -> tuple[list[EpisodeLabels], list[float]]: ...


@dataclass
class EmResult:
    labels: list[EpisodeLabels]
    changed: list[float]
    """Fraction of frames whose (tool, target, way-point) changed, per EM round."""


def changed_fraction(old: list[EpisodeLabels], new: list[EpisodeLabels]) -> float:
    diff = sum(int(np.sum((a.tool != b.tool) | (a.target != b.target) | (a.waypoint_index != b.waypoint_index)))
               for a, b in zip(old, new))
    return diff / max(sum(len(a.tool) for a in old), 1)


def em_label(episodes: list[tuple[np.ndarray, np.ndarray]], cfg: PriorConfig, fit: Fit, iterations: int,
             symmetries: list[str] | None = None) -> EmResult:
    """Labels of ``episodes`` (world poses, status): Viterbi over the priors, then up to
    ``iterations`` rounds of fit → Viterbi over the fitted model, stopping when nothing changes.
    With the objects' ``symmetries``, poses are prepared first as for
    :func:`~hsp.labeling.label.label_episode` (the model sees them so)."""
    if iterations < 0:
        raise HspError(f"em_iterations must be ≥ 0, got {iterations}")
    if symmetries is not None:
        episodes = [(prepared_poses(w, symmetries, cfg), s) for w, s in episodes]
    labels = [label_episode(w, s, cfg) for w, s in episodes]
    changed: list[float] = []
    for round_ in range(iterations):
        model = fit(labels)
        new = []
        for (w, s), last in zip(episodes, labels):
            scores = model(w, s, last)
            if (scores.H, scores.P) != (len(w), len(pairs_of(w.shape[1]))):
                raise HspError(f"EM round {round_ + 1}: the model scored {scores.H} frames × {scores.P} pairs for an "
                               f"episode of {len(w)} frames and {w.shape[1]} objects")
            new.append(label_episode(w, s, cfg, scores))
        changed.append(changed_fraction(labels, new))
        labels = new
        log.info("EM round %d: %.2f %% of frames relabelled", round_ + 1, 100 * changed[-1])
        if changed[-1] == 0.0:
            break
    return EmResult(labels, changed)
