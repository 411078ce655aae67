"""The ``parse`` stage: recordings → 6D pose trajectories → LeRobot dataset.

Poses come from the tracker (``hsp.perception``, not built yet) or, for the ablation that
separates perception error from learning error, from the recordings' ground truth
(``--poses-from ground-truth``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from hsp.dataset.features import TrackStatus
from hsp.dataset.writer import EpisodePoses, write_dataset
from hsp.errors import HspError
from hsp.recording.ground_truth import GroundTruth, read_ground_truth
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)
POSE_SOURCES = ("tracker", "ground-truth")


def list_recordings(recordings_dir: Path) -> list[Path]:
    """Episode files (``*.mcap``) or rosbag2 directories under ``recordings_dir``, sorted."""
    d = Path(recordings_dir)
    if not d.is_dir():
        raise HspError(f"{d}: recordings directory not found")
    found = sorted(list(d.glob("*.mcap")) + [p for p in d.iterdir() if (p / "metadata.yaml").is_file()])
    if not found:
        raise HspError(f"{d}: no .mcap recordings or rosbag2 directories")
    return found


def _ground_truth_episodes(task: Task, recordings: list[Path], first: GroundTruth, fps: int) -> Iterator[EpisodePoses]:
    for k, path in enumerate(recordings):
        gt = first if k == 0 else read_ground_truth(path)
        if gt.objects != task.names:
            raise HspError(f"{path}: objects {gt.objects} do not match task {task.name!r} {task.names}")
        if int(gt.metadata.get("fps", fps)) != fps:
            raise HspError(f"{path}: recorded at {gt.metadata['fps']} fps, the other recordings at {fps}")
        yield EpisodePoses(str(path), gt.poses, np.full(gt.poses.shape[:2], TrackStatus.OK, np.int64))


def parse(task: Task, recordings_dir: Path, out_dir: Path, poses_from: str = "tracker") -> dict[str, float | int | str]:
    """Build the dataset of ``task`` from every recording in ``recordings_dir``."""
    if poses_from not in POSE_SOURCES:
        raise HspError(f"--poses-from {poses_from!r}: choose one of {', '.join(POSE_SOURCES)}")
    if poses_from == "tracker":
        raise HspError("pose tracking is not available yet (issue 4); use --poses-from ground-truth for the ablation")
    recordings = list_recordings(recordings_dir)
    first = read_ground_truth(recordings[0])
    fps = int(first.metadata.get("fps", 0)) or int(round(1e9 / np.median(np.diff(first.stamps_ns))))
    start = time.perf_counter()
    counts = write_dataset(task, _ground_truth_episodes(task, recordings, first, fps), out_dir, fps)
    seconds = time.perf_counter() - start
    log.info("parsed %d recordings (%d frames) from %s into %s in %.1f s", counts["episodes"], counts["frames"],
             recordings_dir, out_dir, seconds)
    return {**counts, "poses_from": poses_from, "fps": fps, "seconds": seconds}
