"""Writing pose trajectories as one LeRobot dataset, atomically.

``LeRobotDataset.create`` → ``add_frame`` per frame → ``save_episode`` per recording →
``finalize()`` exactly once, in a temporary root that is checked by re-opening it offline
and then renamed into place; a failure leaves no dataset behind.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hsp.dataset.features import ACTION, ENV_STATE, EPISODE_SOURCES, STATE, STATUS, TrackStatus, features
from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.geometry import rotvec_delta
from hsp.tasks.registry import Task

os.environ.setdefault("HF_HUB_OFFLINE", "1")  # a missing local file must fail, not go to the Hub


@dataclass
class EpisodePoses:
    """World poses of one episode: ``poses (T, n, 7)`` in task order, ``status (T, n)``."""

    source: str
    """The recording's name within the recordings folder (:func:`hsp.recording.reader.recording_name`)."""
    poses: np.ndarray
    status: np.ndarray
    info: dict = field(default_factory=dict)
    """JSON-ready: the table frame the poses are in (``table_frame``, ``T_world_cam``) and how
    the recording was read (:meth:`hsp.dataset.build.RecordingCheck.episode_info`)."""


def actions(ee: np.ndarray, status: np.ndarray) -> np.ndarray:
    """a_t = e_{t+1} − e_t (world translation + rotation vector), ``(T, 6)``; the last
    frame and any step touching a lost end-effector pose get zeros."""
    a = np.zeros((len(ee), 6))
    if len(ee) > 1:
        a[:-1] = rotvec_delta(ee[:-1], ee[1:])
        bad = (status[:-1] == TrackStatus.LOST) | (status[1:] == TrackStatus.LOST)
        a[:-1][bad] = 0.0
    return a


def repo_id(task: Task) -> str:
    return f"hsp/{task.name}"


def _add_episode(ds, task: Task, ep: EpisodePoses) -> int:
    """Append one episode to LeRobot's writer ``ds``; its frame count."""
    T, n = len(ep.poses), len(task.objects)
    if ep.poses.shape != (T, n, 7) or ep.status.shape != (T, n):
        raise HspError(f"{ep.source}: poses {ep.poses.shape} / status {ep.status.shape} "
                       f"do not match {n} objects of {task.name!r}")
    if T < 2:
        raise HspError(f"{ep.source}: {T} frame(s); an episode needs at least 2")
    if not np.all(np.isfinite(ep.poses[ep.status != TrackStatus.LOST])):
        raise HspError(f"{ep.source}: NaN or infinite poses in frames not marked lost")
    a = actions(ep.poses[:, 0], ep.status[:, 0]).astype(np.float32)
    state = ep.poses[:, 0].astype(np.float32)
    env = ep.poses[:, 1:].reshape(T, -1).astype(np.float32)
    status = ep.status.astype(np.int64)
    for t in range(T):
        ds.add_frame({STATE: state[t], ENV_STATE: env[t], ACTION: a[t], STATUS: status[t], "task": task.name})
    ds.save_episode()
    return T


def write_dataset(task: Task, episodes: Iterable[EpisodePoses], out_dir: Path, fps: int) -> dict[str, int]:
    """Write all episodes to ``out_dir`` (replaced only on success, nothing left otherwise); returns counts."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out_dir = Path(out_dir).resolve()
    with atomic_path(out_dir) as tmp:
        ds = LeRobotDataset.create(repo_id(task), fps=fps, features=features(task), root=tmp, use_videos=False,
                                   robot_type="hsp")
        try:
            lengths, infos = [], []
            for ep in episodes:
                lengths.append(_add_episode(ds, task, ep))
                infos.append({"episode_index": len(infos), "source": ep.source, **ep.info})
            if not lengths:
                raise HspError("no episodes to write")
        except BaseException:
            with contextlib.suppress(Exception):  # LeRobot flushes its episode metadata when collected, which
                ds.finalize()                      # would re-create tmp/meta after the clean-up: flush it now
            raise
        ds.finalize()
        (tmp / EPISODE_SOURCES).write_text("".join(json.dumps(i) + "\n" for i in infos))
        check = LeRobotDataset(repo_id(task), root=tmp)
        if len(check) != sum(lengths) or check.num_episodes != len(lengths):
            raise HspError(f"{tmp}: wrote {len(lengths)} episodes / {sum(lengths)} frames "
                           f"but read back {check.num_episodes} / {len(check)}")
    return {"episodes": len(lengths), "frames": sum(lengths)}
