"""Reading pose trajectories back from a LeRobot dataset written by :mod:`hsp.dataset.writer`."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from hsp.dataset.features import ENV_STATE, EPISODE_SOURCES, STATE, STATUS
from hsp.errors import HspError

os.environ.setdefault("HF_HUB_OFFLINE", "1")


def load_episodes(dataset_dir: Path, task_name: str,
                  objects: list[str] | None = None) -> tuple[list[np.ndarray], list[np.ndarray], dict]:
    """Per episode: world poses ``(T, n, 7)`` and status ``(T, n)``; plus the feature metadata.
    With ``objects`` (the task's object names), a dataset of other objects is an error.

    Columns are read straight from the Arrow table (fast), split at the episode
    boundaries that LeRobot's metadata records.
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    dataset_dir = Path(dataset_dir).resolve()
    if not (dataset_dir / "meta" / "info.json").is_file():
        raise HspError(f"{dataset_dir}: not a LeRobot dataset (no meta/info.json)")
    ds = LeRobotDataset(f"hsp/{task_name}", root=dataset_dir)
    feats = ds.meta.features
    if ENV_STATE not in feats or STATUS not in feats:
        raise HspError(f"{dataset_dir}: not a pose dataset of this hsp version (features: {sorted(feats)}; "
                       "re-run `hsp parse`)")
    names = [feats[STATE].get("object")] + list(feats[ENV_STATE].get("objects", []))
    if objects is not None and names != objects:
        raise HspError(f"{dataset_dir}: dataset objects {names} are not those of task {task_name!r} {objects}")
    table = ds.hf_dataset.data
    state = np.stack(table.column(STATE).to_numpy(zero_copy_only=False))
    env = np.stack(table.column(ENV_STATE).to_numpy(zero_copy_only=False))
    status = np.stack(table.column(STATUS).to_numpy(zero_copy_only=False))
    poses = np.concatenate([state[:, None, :], env.reshape(len(env), -1, 7)], axis=1).astype(np.float64)
    starts = ds.meta.episodes["dataset_from_index"]
    ends = ds.meta.episodes["dataset_to_index"]
    return ([poses[s:e] for s, e in zip(starts, ends)], [status[s:e] for s, e in zip(starts, ends)],
            {"objects": names, "tasks": sorted(set(ds.meta.tasks.index)), "fps": ds.fps})


def episode_sources(dataset_dir: Path) -> list[dict]:
    """Per episode, as ``hsp parse`` wrote it: ``source`` (the recording's name), ``table_frame``
    and, for tracked poses, ``T_world_cam`` (7), ``intrinsics``, ``topics``, ``fps`` and
    ``dropped_frames``."""
    path = Path(dataset_dir) / EPISODE_SOURCES
    if not path.is_file():
        raise HspError(f"{dataset_dir}: no {EPISODE_SOURCES} (written by an older hsp); re-run `hsp parse`")
    try:
        sources = [json.loads(line) for line in path.read_text().splitlines()]
        episodes = json.loads((Path(dataset_dir) / "meta" / "info.json").read_text())["total_episodes"]
    except (json.JSONDecodeError, KeyError, OSError) as e:
        raise HspError(f"{path}: cannot be read ({e})") from None
    if [s.get("episode_index") for s in sources] != list(range(episodes)):
        raise HspError(f"{path}: {len(sources)} episode sources for the dataset's {episodes} episodes "
                       "(edited since `hsp parse`?); re-run `hsp parse`")
    return sources


def episode_recordings(dataset_dir: Path, recordings: Path, episodes: list[int] | None = None) -> list[Path]:
    """The recording in ``recordings`` (a folder, a bag or a file, as ``hsp parse`` was given
    it) that each episode of ``dataset_dir`` (or of ``episodes``) was parsed from, matched by
    name: recordings that ``--skip-bad`` left out do not shift the others."""
    from hsp.recording.reader import find_recordings, recording_name

    found = {recording_name(p, recordings): p for p in find_recordings(recordings)}
    sources = episode_sources(dataset_dir)
    out = []
    for info in sources if episodes is None else [sources[e] for e in episodes]:
        if info["source"] not in found:
            raise HspError(f"{recordings}: no recording {info['source']!r}, which episode {info['episode_index']} of "
                           f"{dataset_dir} was parsed from ({len(found)} found)")
        out.append(found[info["source"]])
    return out


def read_options(source: dict):
    """:class:`~hsp.recording.reader.ReadOptions` that read an episode's recording again as
    ``hsp parse`` read it: its topics and intrinsics (an entry of :func:`episode_sources`)."""
    from hsp.recording.reader import ReadOptions

    topics = source.get("topics", {})
    intrinsics = tuple(source["intrinsics"]) if source.get("intrinsics") else None
    return ReadOptions(topics.get("color"), topics.get("depth"), topics.get("info") or None, intrinsics)
