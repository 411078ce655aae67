"""The ``train`` stage (pose dataset + pseudo-labels → trained π_h, π_m, π_l) and the EM
model that ``hsp label --policy`` scores with."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hsp.dataset.features import TrackStatus
from hsp.dataset.reader import episode_recordings, load_episodes
from hsp.errors import HspError
from hsp.labeling.em import Fit, ScoreModel, em_label
from hsp.geometry import relative
from hsp.geometry.symmetry import z_folds
from hsp.labeling.label import EpisodeLabels, canonical_poses, prepared_poses
from hsp.labeling.priors import PriorConfig
from hsp.labeling.stage import read_labels
from hsp.policy.features import Steps, episode_steps
from hsp.policy.scores import PolicyScores
from hsp.policy.train import Policy, TrainConfig, save, split, train
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)


def semantic_classes(task: Task) -> tuple[np.ndarray, int]:
    """Each object's semantic label as an index ``(n,)``, and how many labels there are
    (the four lug nuts share one)."""
    names = sorted({o.label for o in task.objects})
    return np.array([names.index(o.label) for o in task.objects]), len(names)


def symmetry_folds(task: Task) -> np.ndarray:
    """Per object, its turns about z per revolution that leave it unchanged (0: any)."""
    return np.array([z_folds(o.symmetry) for o in task.objects])


def annotation_labels(task: Task, recordings: list[Path], poses: list[np.ndarray]) -> list[EpisodeLabels]:
    """The demonstrator's own annotation as labels of the dataset's episodes (the
    ``supervised`` upper bound): its tool and target, mapped onto the tracker's object
    identities (identical objects are matched by distance, as the label metrics do), and
    way-point frame k at the end of each annotated way-point's segment, where the tool has
    arrived (w_t = p_k[o+, o*], as the pseudo-labels define it)."""
    from hsp.dataset.build import identical_groups
    from hsp.perception.metrics import match_identical
    from hsp.recording.ground_truth import read_ground_truth

    groups, out = identical_groups(task), []
    for path, p in zip(recordings, poses, strict=True):
        gt = read_ground_truth(path)
        if len(gt.tool) != len(p) or gt.objects != task.names:
            raise HspError(f"{path}: annotation of {len(gt.tool)} frames of {gt.objects}, the dataset episode has {len(p)} "
                           f"frames of {task.names}")
        tracked = match_identical(groups, p, gt.poses)  # true object index → the tracker's
        ends = np.flatnonzero(np.diff(gt.waypoint_index) != 0)
        last = np.concatenate([ends, [len(p) - 1]])
        k = last[np.searchsorted(last, np.arange(len(p)))]
        tool, target = tracked[gt.tool], tracked[gt.target]
        canon = canonical_poses(p, [o.symmetry for o in task.objects])
        w = relative(canon[k, tool], canon[k, target])
        out.append(EpisodeLabels(tool, target, k, w, np.arange(p.shape[1]) == target[:, None]))
    return out


def labelled_steps(task: Task, world: list[np.ndarray], status: list[np.ndarray], labels: list[EpisodeLabels],
                   cfg: TrainConfig) -> list[Steps]:
    """Network inputs and targets of every episode (canonical poses, as the labels are;
    decided where the tool rests, :func:`~hsp.policy.features.decisions`); frames
    where the labelled tool or target is lost do not count in the losses."""
    classes, n_classes = semantic_classes(task)
    n = len(task.objects)
    out = []
    for w, st, lab in zip(world, status, labels):
        bad = (lab.target == 0) | (lab.target == lab.tool) | (lab.tool < 0) | (lab.tool >= n) | (lab.target >= n)
        if bad.any():
            raise HspError(f"labels name a (tool, target) pair that cannot be: {lab.tool[bad][0]}, {lab.target[bad][0]}")
        out.append(episode_steps(w, st != TrackStatus.LOST, lab.tool, lab.target, lab.waypoint_index, classes, n_classes,
                                 cfg.still_m, cfg.settle_frames))
    return out


def train_task(task: Task, dataset_dir: Path, out_dir: Path, cfg: TrainConfig, seed: int, labels_file: Path | None = None,
               recordings_dir: Path | None = None) -> dict[str, float | int]:
    """Train on the pseudo-labels of ``labels_file`` or, for the supervised upper bound, on
    the demonstrator's annotation in ``recordings_dir`` (exactly one of the two)."""
    if (labels_file is None) == (recordings_dir is None):
        raise HspError("train: give either a labels file or the recordings with the annotation")
    start = time.perf_counter()
    poses, status, _ = load_episodes(dataset_dir, task.name, task.names)
    world = [canonical_poses(p, [o.symmetry for o in task.objects]) for p in poses]
    if labels_file is not None:
        labels = read_labels(labels_file, [len(p) for p in poses], len(task.objects))
    else:
        labels = annotation_labels(task, episode_recordings(dataset_dir, recordings_dir), poses)  # type: ignore
    source = labels_file or recordings_dir
    steps = labelled_steps(task, world, status, labels, cfg)
    classes, n_classes = semantic_classes(task)
    fit_on, held = split(len(steps), cfg.validation_every)
    log.info("train %s: %d episodes (%d frames) from %s and %s, %d more held out to validate", task.name, len(fit_on),
             sum(len(steps[i]) for i in fit_on), dataset_dir, source, len(held))
    policy, figures = train([steps[i] for i in fit_on], task.names, classes, n_classes, cfg, seed,
                            [steps[i] for i in held], symmetry_folds(task))
    save(policy, cfg, out_dir)
    report: dict[str, float | int] = {"iterations": cfg.iterations, **figures, "episodes": len(fit_on),
                                      "frames": int(sum(len(steps[i]) for i in fit_on)), "validation_episodes": len(held)}
    report["seconds"] = time.perf_counter() - start
    log.info("wrote %s in %.1f s", out_dir, report["seconds"])
    return report


def score_model(policy: Policy, cfg: PriorConfig) -> ScoreModel:
    """Viterbi scores of an episode from ``policy``: what one EM round labels with."""
    return lambda world, status, last: PolicyScores(world, status != TrackStatus.LOST, policy, last, cfg)


def em_fit(task: Task, policy: Policy, cfg: PriorConfig, train_cfg: TrainConfig, seed: int,
           world: list[np.ndarray], status: list[np.ndarray]) -> Fit:
    """The M-step of EM: the given (already trained) policy first, then π_h, π_m, π_l
    trained anew on each round's labels."""
    given = [policy]

    def fit(labels: list[EpisodeLabels]) -> ScoreModel:
        if given:
            return score_model(given.pop(), cfg)
        classes, n_classes = semantic_classes(task)
        retrained, _ = train(labelled_steps(task, world, status, labels, train_cfg), task.names, classes, n_classes,
                             train_cfg, seed, folds=symmetry_folds(task))
        return score_model(retrained, cfg)

    return fit


@dataclass(frozen=True)
class PolicyRefinement:
    """EM over a trained policy (:class:`~hsp.labeling.em.Refinement`): Viterbi over the
    priors, then over ``policy``'s networks (read from ``source``), then over networks
    retrained on each new set of labels, for at most ``iterations`` rounds or until no
    label changes."""

    policy: Policy
    source: Path
    train: TrainConfig
    iterations: int
    seed: int

    def run(self, task: Task, poses: list[np.ndarray], status: list[np.ndarray],
            cfg: PriorConfig) -> tuple[list[EpisodeLabels], list[float]]:
        if self.policy.objects != task.names:
            raise HspError(f"{self.source}: a policy for objects {self.policy.objects}, not those of task {task.name!r} {task.names}")
        world = [prepared_poses(p, [o.symmetry for o in task.objects], cfg) for p in poses]
        fit = em_fit(task, self.policy, cfg, self.train, self.seed, world, status)
        result = em_label(list(zip(world, status)), cfg, fit, self.iterations)
        return result.labels, result.changed
