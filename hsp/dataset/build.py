"""The ``parse`` stage: recordings → 6D pose trajectories → LeRobot dataset.

Poses come from the tracker (:mod:`hsp.perception.episode`) or, for the ablation that
separates perception error from learning error, from the recordings' ground truth
(``--poses-from ground-truth``).
"""

from __future__ import annotations

import logging
import multiprocessing
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.progress import Progress

from hsp.dataset.features import TrackStatus
from hsp.dataset.writer import EpisodePoses, write_dataset
from hsp.errors import HspError
from hsp.parallel import one_omp_thread, pin_to_one_core
from hsp.perception.episode import object_models, track_recording
from hsp.perception.metrics import auc, episode_errors, match_identical
from hsp.perception.tracker import TrackerConfig
from hsp.recording.ground_truth import GroundTruth, matching_ground_truth, read_ground_truth
from hsp.recording.reader import ReadOptions, find_recordings, read_recording
from hsp.tasks.registry import Task, load_task

log = logging.getLogger(__name__)
POSE_SOURCES = ("tracker", "ground-truth")


def _ground_truth_episodes(task: Task, recordings: list[Path], first: GroundTruth, fps: int) -> Iterator[EpisodePoses]:
    for k, path in enumerate(recordings):
        gt = first if k == 0 else read_ground_truth(path)
        if gt.objects != task.names:
            raise HspError(f"{path}: objects {gt.objects} do not match task {task.name!r} {task.names}")
        if int(gt.metadata.get("fps", fps)) != fps:
            raise HspError(f"{path}: recorded at {gt.metadata['fps']} fps, the other recordings at {fps}")
        yield EpisodePoses(str(path), gt.poses, np.full(gt.poses.shape[:2], TrackStatus.OK, np.int64))


@dataclass(frozen=True)
class TrackJob:
    task: str
    pipeline_dir: Path
    path: Path
    options: ReadOptions
    cfg: TrackerConfig
    seed: int


@dataclass
class TrackOutcome:
    episode: EpisodePoses
    frames: int
    seconds: float
    errors: dict[str, np.ndarray] | None
    """Per-frame errors against the recorded truth (``None`` without ground truth)."""


def identical_groups(task: Task) -> list[list[int]]:
    """Indices of objects that share mesh and label, in groups of two or more."""
    groups: dict[tuple[str, str], list[int]] = {}
    for i, o in enumerate(task.objects):
        groups.setdefault((o.mesh, o.label), []).append(i)
    return [g for g in groups.values() if len(g) > 1]


def _track_one(job: TrackJob) -> TrackOutcome:
    """Track one recording; then, separately, score it against its ground truth if any."""
    task = load_task(job.task, job.pipeline_dir)
    rec = read_recording(job.path, job.options)
    models = object_models(task, job.cfg, job.seed)
    tracked = track_recording(task, rec, models, job.cfg)
    frames = len(rec.rgb)
    del rec
    errors = None
    gt = matching_ground_truth(job.path, task.names, frames)
    if gt is not None:
        samples = [np.asarray(m.cloud.points)[::3] for m in models]
        order = match_identical(identical_groups(task), tracked.poses, gt.poses)
        errors = episode_errors([o.symmetry for o in task.objects], samples, tracked.poses[:, order], gt.poses)
    return TrackOutcome(EpisodePoses(str(job.path), tracked.poses, tracked.status), frames, tracked.seconds, errors)


def _tracked_episodes(jobs: list[TrackJob], workers: int, outcomes: list[TrackOutcome]) -> Iterator[EpisodePoses]:
    """Episodes in order, tracked in ``workers`` processes, each on a core of its own. One
    worker is a process too: Open3D's parallel reductions round differently from run to run
    on more than one thread, and the dataset must not depend on the run or on how many
    processes made it."""
    with Progress() as progress, one_omp_thread():
        bar = progress.add_task(f"track {jobs[0].task}", total=len(jobs))
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=pin_to_one_core, initargs=(ctx.Value("i", 0),))
        try:
            for outcome in pool.map(_track_one, jobs):
                outcomes.append(outcome)
                progress.advance(bar)
                yield outcome.episode
        finally:
            pool.shutdown(cancel_futures=True)


def tracking_report(task: Task, outcomes: list[TrackOutcome], workers: int, wall_seconds: float) -> dict[str, float | int | str]:
    """``reports/TASK/tracking.json``: errors over all frames and objects (lost ones included),
    per object too, and the tracking rate."""
    frames = sum(o.frames for o in outcomes)
    status = np.concatenate([o.episode.status for o in outcomes])
    report: dict[str, float | int | str] = {
        "episodes": len(outcomes),
        "frames": frames,
        "objects": len(task.objects),
        "lost_fraction": float(np.mean(status == TrackStatus.LOST)),
        "suspect_fraction": float(np.mean(status == TrackStatus.SUSPECT)),
        "frames_per_second": frames / wall_seconds,
        "frames_per_second_per_process": frames / sum(o.seconds for o in outcomes),
        "workers": workers,
    }
    scored = [o.errors for o in outcomes if o.errors is not None]
    report["episodes_with_ground_truth"] = len(scored)
    if scored:
        err = {k: np.concatenate([e[k] for e in scored]) for k in scored[0]}
        report.update({
            "translation_error_mm_median": float(np.median(err["translation_mm"])),
            "translation_error_mm_p95": float(np.percentile(err["translation_mm"], 95)),
            "rotation_error_deg_median": float(np.median(err["rotation_deg"])),
            "rotation_error_deg_p95": float(np.percentile(err["rotation_deg"], 95)),
            "adds_auc": auc(err["adds_m"]),
        })
        for i, name in enumerate(task.names):
            report[f"objects.{name}.translation_error_mm_median"] = float(np.median(err["translation_mm"][:, i]))
            report[f"objects.{name}.translation_error_mm_p95"] = float(np.percentile(err["translation_mm"][:, i], 95))
            report[f"objects.{name}.rotation_error_deg_median"] = float(np.median(err["rotation_deg"][:, i]))
            report[f"objects.{name}.lost_fraction"] = float(np.mean(status[:, i] == TrackStatus.LOST))
    return report


def parse(task: Task, recordings_dir: Path, out_dir: Path, poses_from: str = "tracker", workers: int = 1,
          options: ReadOptions = ReadOptions(), cfg: TrackerConfig = TrackerConfig(),
          seed: int = 0) -> tuple[dict[str, float | int | str], dict[str, float | int | str] | None]:
    """Build the dataset of ``task`` from every recording in ``recordings_dir``; returns the
    parse report and, for tracked poses, the tracking report."""
    if poses_from not in POSE_SOURCES:
        raise HspError(f"--poses-from {poses_from!r}: choose one of {', '.join(POSE_SOURCES)}")
    recordings = find_recordings(recordings_dir)
    start = time.perf_counter()
    tracking = None
    if poses_from == "ground-truth":
        first = read_ground_truth(recordings[0])
        fps = int(first.metadata.get("fps", 0)) or int(round(1e9 / np.median(np.diff(first.stamps_ns))))
        counts = write_dataset(task, _ground_truth_episodes(task, recordings, first, fps), out_dir, fps)
    else:
        object_models(task, cfg, seed)  # a missing mesh fails here, before any work
        stamps = read_recording(recordings[0], options).stamps_ns
        if len(stamps) < 2:
            raise HspError(f"{recordings[0]}: {len(stamps)} usable frame(s); an episode needs at least 2")
        fps = int(round(1e9 / np.median(np.diff(stamps))))
        jobs = [TrackJob(task.name, task.objects_dir.parent, p, options, cfg, seed) for p in recordings]
        outcomes: list[TrackOutcome] = []
        counts = write_dataset(task, _tracked_episodes(jobs, workers, outcomes), out_dir, fps)
        tracking = tracking_report(task, outcomes, workers, time.perf_counter() - start)
    seconds = time.perf_counter() - start
    log.info("parsed %d recordings (%d frames) from %s into %s in %.1f s", counts["episodes"], counts["frames"],
             recordings_dir, out_dir, seconds)
    return {**counts, "poses_from": poses_from, "fps": fps, "seconds": seconds}, tracking
