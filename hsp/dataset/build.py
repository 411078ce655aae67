"""The ``parse`` stage: recordings → 6D pose trajectories → LeRobot dataset.

Poses come from the tracker (:mod:`hsp.perception.episode`) or, for the ablation that
separates perception error from learning error, from the recordings' ground truth
(``--poses-from ground-truth``).
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import Progress

from hsp.dataset.features import TrackStatus
from hsp.dataset.writer import EpisodePoses, write_dataset
from hsp.errors import HspError
from hsp.parallel import ScaleOut, captured_warnings, worker_pool
from hsp.perception.episode import object_models, track_recording
from hsp.perception.metrics import auc, episode_errors, match_identical, status_trust
from hsp.perception.table import GROUND_TRUTH_FRAME, TableConfig, in_recorded_world, table_frame
from hsp.perception.tracker import TrackerConfig
from hsp.recording.ground_truth import GroundTruth, matching_ground_truth, read_ground_truth
from hsp.recording.reader import ReadOptions, find_recordings, read_recording, recording_name
from hsp.tasks.registry import Task, load_task

log = logging.getLogger(__name__)
POSE_SOURCES = ("tracker", "ground-truth")
RATE_TOLERANCE = 0.05
"""A recording whose measured frame rate is further than this fraction from the dataset's is refused."""


def _ground_truth_episodes(task: Task, recordings: list[Path], root: Path, first: GroundTruth,
                           fps: int) -> Iterator[EpisodePoses]:
    for k, path in enumerate(recordings):
        gt = first if k == 0 else read_ground_truth(path)
        if gt.objects != task.names:
            raise HspError(f"{path}: objects {gt.objects} do not match task {task.name!r} {task.names}")
        if int(gt.metadata.get("fps", fps)) != fps:
            raise HspError(f"{path}: recorded at {gt.metadata['fps']} fps, the other recordings at {fps}")
        yield EpisodePoses(recording_name(path, root), gt.poses, np.full(gt.poses.shape[:2], TrackStatus.OK, np.int64),
                           {"table_frame": GROUND_TRUTH_FRAME})


@dataclass(frozen=True)
class TrackJob:
    task: str
    pipeline_dir: Path
    path: Path
    name: str
    """The recording's name in the dataset (:func:`recording_name`)."""
    options: ReadOptions
    cfg: TrackerConfig
    seed: int
    table: TableConfig = TableConfig()
    check: RecordingCheck | None = None
    """What :func:`check_recording` found (tracking jobs only): the table frame to track in."""


@dataclass
class RecordingCheck:
    """What :func:`check_recording` found in one recording: ``error`` if it cannot be parsed."""

    path: Path
    error: str = ""
    frames: int = 0
    fps: float = 0.0
    """Measured from the colour frames' ``header.stamp`` (median period)."""
    dropped: int = 0
    """Frames missing between the stamps."""
    T_world_cam: np.ndarray | None = None
    table_frame: str = ""
    """How the table frame was found: "given", "tf_static ROOT" or "fitted"."""
    skipped_chunks: int = 0
    """Corrupt MCAP chunks and undecodable messages left out."""
    truncated: bool = False
    warnings: list[str] = field(default_factory=list)
    intrinsics: tuple[float, ...] = ()
    """(fx, fy, cx, cy) as read (or given) ..."""
    topics: dict[str, str] = field(default_factory=dict)
    """... and the topics: what reading the recording again the same way takes (``hsp view``)."""

    def episode_info(self) -> dict:
        """What the dataset keeps of this check for its episode (:data:`~hsp.dataset.features.EPISODE_SOURCES`)."""
        return {"table_frame": self.table_frame, "T_world_cam": [float(v) for v in self.T_world_cam],
                "fps": self.fps, "dropped_frames": self.dropped, "intrinsics": list(self.intrinsics),
                "topics": self.topics}


def frame_rate(stamps_ns: np.ndarray) -> tuple[float, int]:
    """Frame rate (Hz) from the median period of ``stamps_ns``, and the frames missing between them."""
    period = float(np.median(np.diff(stamps_ns)))
    return 1e9 / period, int(np.sum(np.maximum(np.round(np.diff(stamps_ns) / period) - 1, 0)))


def check_recording(job: TrackJob) -> RecordingCheck:
    """Read one recording whole and find its table frame and frame rate, before any tracking."""
    with captured_warnings() as warnings:
        try:
            rec = read_recording(job.path, job.options)
            if len(rec.stamps_ns) < 2:
                raise HspError(f"{job.path}: {len(rec.stamps_ns)} usable frame(s); an episode needs at least 2")
            fps, dropped = frame_rate(rec.stamps_ns)
            T, how = table_frame(rec.depth, rec.K, rec.T_world_cam, rec.tf_root, job.options.camera_pose, job.table,
                                 job.seed, str(job.path))
        except HspError as e:
            return RecordingCheck(job.path, error=str(e), warnings=warnings)
        except Exception as e:  # noqa: BLE001 - whatever else a damaged file raises is a fault of that file
            error = f"{job.path}: cannot be read ({type(e).__name__}: {e})".splitlines()[0]
            return RecordingCheck(job.path, error=error, warnings=warnings)
    K = rec.K
    return RecordingCheck(job.path, "", len(rec.stamps_ns), fps, dropped, T, how,
                          rec.report.skipped_chunks + rec.report.skipped_messages, rec.report.truncated, warnings,
                          (K[0, 0], K[1, 1], K[0, 2], K[1, 2]), rec.topics)


@dataclass
class TrackOutcome:
    episode: EpisodePoses
    frames: int
    seconds: float
    errors: dict[str, np.ndarray] | None
    """Per-frame errors against the recorded truth and ``ok``, the frames the tracker marked
    ok, all ``(T, n)`` in the truth's object order (``None`` without ground truth)."""


def identical_groups(task: Task) -> list[list[int]]:
    """Indices of objects that share mesh and label, in groups of two or more."""
    groups: dict[tuple[str, str], list[int]] = {}
    for i, o in enumerate(task.objects):
        groups.setdefault((o.mesh, o.label), []).append(i)
    return [g for g in groups.values() if len(g) > 1]


def _track_one(job: TrackJob) -> TrackOutcome:
    """Track one recording from its checked table frame; then, separately, score it against
    its ground truth if any."""
    task = load_task(job.task, job.pipeline_dir)
    with captured_warnings():  # the reader's, already reported by the check
        rec = replace(read_recording(job.path, job.options), T_world_cam=job.check.T_world_cam)
    models = object_models(task, job.cfg, job.seed)
    tracked = track_recording(task, rec, models, job.cfg)
    frames = len(rec.rgb)
    del rec
    errors = None
    gt = matching_ground_truth(job.path, task.names, frames) if in_recorded_world(job.check.table_frame) else None
    if gt is not None:
        samples = [np.asarray(m.cloud.points)[::3] for m in models]
        order = match_identical(identical_groups(task), tracked.poses, gt.poses)
        errors = episode_errors([o.symmetry for o in task.objects], samples, tracked.poses[:, order], gt.poses)
        errors["ok"] = tracked.status[:, order] == TrackStatus.OK
    episode = EpisodePoses(job.name, tracked.poses, tracked.status, job.check.episode_info())
    return TrackOutcome(episode, frames, tracked.seconds, errors)


def check_recordings(task: Task, jobs: list[TrackJob], pool: Any) -> list[RecordingCheck]:
    """:func:`check_recording` of every job, in order, with progress; warnings logged once, with their level."""
    checks = []
    with Progress() as progress:
        bar = progress.add_task(f"check {task.name}", total=len(jobs))
        for check in pool.map(check_recording, jobs):
            for w in check.warnings:
                log.warning(w)
            checks.append(check)
            progress.advance(bar)
    return checks


def _tracked_episodes(jobs: list[TrackJob], pool: Any,
                      outcomes: list[TrackOutcome]) -> Iterator[EpisodePoses]:
    """Episodes in order, tracked in the pool's processes."""
    with Progress() as progress:
        bar = progress.add_task(f"track {jobs[0].task}", total=len(jobs))
        for outcome in pool.map(_track_one, jobs):
            outcomes.append(outcome)
            progress.advance(bar)
            yield outcome.episode


def tracking_report(task: Task, outcomes: list[TrackOutcome], workers: int, wall_seconds: float) -> dict[str, float | int | str]:
    """``reports/TASK/tracking.json``: errors over all frames and objects (lost ones included),
    per object too, how far the status can be trusted (:func:`status_trust`: ``ok_accurate``,
    ``inaccurate_flagged``), and the tracking rate."""
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
        report["ok_accurate"], report["inaccurate_flagged"] = status_trust(err["translation_mm"], err["rotation_deg"], err["ok"])
        for i, name in enumerate(task.names):
            report[f"objects.{name}.translation_error_mm_median"] = float(np.median(err["translation_mm"][:, i]))
            report[f"objects.{name}.translation_error_mm_p95"] = float(np.percentile(err["translation_mm"][:, i], 95))
            report[f"objects.{name}.rotation_error_deg_median"] = float(np.median(err["rotation_deg"][:, i]))
            report[f"objects.{name}.lost_fraction"] = float(np.mean(status[:, i] == TrackStatus.LOST))
            report[f"objects.{name}.ok_accurate"], report[f"objects.{name}.inaccurate_flagged"] = status_trust(
                err["translation_mm"][:, i], err["rotation_deg"][:, i], err["ok"][:, i])
    return report


def _near(fps: float, rate: int, tolerance: float) -> bool:
    return rate > 0 and abs(fps - rate) <= tolerance * rate


def dataset_rate(checks: list[RecordingCheck], tolerance: float) -> int:
    """The dataset's frame rate: the most common among the recordings' rates that are whole
    numbers (within ``tolerance``, a fraction), as LeRobot stores a whole number of frames per
    second; the recordings further than that from it are marked bad."""
    rates = [round(c.fps) for c in checks if _near(c.fps, round(c.fps), tolerance)]
    if not rates:
        raise HspError(f"{checks[0].path}: recorded at {checks[0].fps:.2f} fps; a LeRobot dataset needs a whole number "
                       "of frames per second (record at 6, 15, 30 or 60 fps)")
    fps = max(set(rates), key=lambda r: (rates.count(r), r))
    near = [c for c in checks if _near(c.fps, fps, tolerance)]
    for c in checks:
        if c not in near:
            c.error = (f"{c.path}: recorded at {c.fps:.2f} fps, {len(near)} other recording(s) at {fps} fps; "
                       "one dataset has one frame rate (record them alike, or parse them apart)")
    return fps


def parse(task: Task, recordings_dir: Path, out_dir: Path, poses_from: str = "tracker", workers: int = 1,
          options: ReadOptions = ReadOptions(), cfg: TrackerConfig = TrackerConfig(),
          seed: int = 0, table: TableConfig = TableConfig(), skip_bad: bool = False, scale: ScaleOut = ScaleOut(),
          ) -> tuple[dict[str, float | int | str | list[str]], dict[str, float | int | str] | None]:
    """Build the dataset of ``task`` from every recording ``recordings_dir`` names; returns
    the parse report and, for tracked poses, the tracking report. Every recording is read
    and checked before any is tracked; a bad one is an error, or with ``skip_bad`` left out
    and listed in the report. Recordings are tracked in ``workers`` processes, one core and
    one thread each (:func:`~hsp.parallel.worker_pool`): even one worker is a process, since
    Open3D's reductions round differently on more threads and the dataset must not depend on
    the run or on how many processes made it."""
    if poses_from not in POSE_SOURCES:
        raise HspError(f"--poses-from {poses_from!r}: choose one of {', '.join(POSE_SOURCES)}")
    recordings = find_recordings(recordings_dir)
    start = time.perf_counter()
    tracking, extra = None, {}
    if poses_from == "ground-truth":
        first = read_ground_truth(recordings[0])
        fps = int(first.metadata.get("fps", 0)) or round(frame_rate(first.stamps_ns)[0])
        counts = write_dataset(task, _ground_truth_episodes(task, recordings, recordings_dir, first, fps), out_dir, fps)
    else:
        counts, fps, extra, tracking = _parse_tracked(task, recordings, recordings_dir, out_dir, workers, options, cfg,
                                                      seed, table, skip_bad, start, scale)
    seconds = time.perf_counter() - start
    log.info("parsed %d recordings (%d frames) from %s into %s in %.1f s", counts["episodes"], counts["frames"],
             recordings_dir, out_dir, seconds)
    return {**counts, "poses_from": poses_from, "fps": fps, "seconds": seconds, **extra}, tracking


def _parse_tracked(task: Task, recordings: list[Path], root: Path, out_dir: Path, workers: int, options: ReadOptions,
                   cfg: TrackerConfig, seed: int, table: TableConfig, skip_bad: bool, start: float, scale: ScaleOut):
    """Check every recording, then track the good ones into the dataset: counts, frame rate,
    the check's part of the parse report and the tracking report."""
    object_models(task, cfg, seed)  # a missing mesh fails here, before any work
    jobs = [TrackJob(task.name, task.objects_dir.parent, p, recording_name(p, root), options, cfg, seed, table)
            for p in recordings]
    with worker_pool(workers, scale, pinned=True) as pool:
        checks = check_recordings(task, jobs, pool)
        readable = [c for c in checks if not c.error]
        fps = dataset_rate(readable, RATE_TOLERANCE) if readable else 0  # marks recordings at another rate bad
        bad = [c for c in checks if c.error]
        if bad and (not skip_bad or len(bad) == len(checks)):
            more = f" ({len(bad) - 1} more bad recording(s); --skip-bad parses the rest)" if len(bad) > 1 else ""
            raise HspError(bad[0].error + more)
        for c in bad:
            log.warning("skipped: %s", c.error)
        good = [c for c in checks if not c.error]
        log.info("checked %d recordings: %d good at %d fps (%d frames dropped), %d skipped; table frames: %s",
                 len(checks), len(good), fps, sum(c.dropped for c in good), len(bad),
                 dict(Counter(c.table_frame for c in good)))
        jobs = [replace(j, check=c) for j, c in zip(jobs, checks) if not c.error]
        outcomes: list[TrackOutcome] = []
        counts = write_dataset(task, _tracked_episodes(jobs, pool, outcomes), out_dir, fps)
    tracking = tracking_report(task, outcomes, workers, time.perf_counter() - start)
    extra = {"dropped_frames": sum(c.dropped for c in good), "skipped_chunks": sum(c.skipped_chunks for c in good),
             "truncated_recordings": sum(c.truncated for c in good), "warnings": sum(len(c.warnings) for c in checks),
             "skipped": [c.error for c in bad]}
    extra |= {f"table_frame.{how}": n for how, n in Counter(c.table_frame.split()[0] for c in good).items()}
    return counts, fps, extra, tracking
