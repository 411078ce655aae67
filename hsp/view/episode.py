"""``hsp view``: the overlay video, the label timeline and the Rerun recording of one episode."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from hsp.dataset.reader import episode_recordings, episode_sources, load_episodes, read_options
from hsp.errors import HspError
from hsp.perception.table import in_recorded_world
from hsp.recording.ground_truth import matching_ground_truth
from hsp.recording.reader import read_recording
from hsp.sim.render import load_mesh
from hsp.tasks.registry import Task
from hsp.view.overlay import write_overlay
from hsp.view.rerun_log import write_rrd
from hsp.view.timeline import write_timeline

log = logging.getLogger(__name__)


def _labels(labels_file: Path | None, episode: int, frames: int) -> dict[str, np.ndarray] | None:
    if labels_file is None or not Path(labels_file).is_file():
        return None
    import pandas as pd

    df = pd.read_parquet(labels_file)
    rows = df[df["episode_index"] == episode].sort_values("frame_index")
    if len(rows) != frames:
        raise HspError(f"{labels_file}: episode {episode} has {len(rows)} labelled frames, the dataset {frames}")
    return {k: rows[k].to_numpy() for k in ("tool", "target", "waypoint_index")}


def view_episode(task: Task, episode: int, recordings_dir: Path, dataset_dir: Path, labels_file: Path | None,
                 out_dir: Path, rrd_every: int = 1) -> dict[str, Path]:
    """Write ``episode_N.mp4``, ``episode_N_timeline.png`` and ``episode_N.rrd`` into ``out_dir``."""
    start = time.perf_counter()
    if rrd_every < 1:
        raise HspError(f"--rrd-every {rrd_every}: must be at least 1")
    poses, status, meta = load_episodes(dataset_dir, task.name, task.names)
    if not 0 <= episode < len(poses):
        raise HspError(f"{dataset_dir}: no episode {episode} (the dataset has 0–{len(poses) - 1})")
    source, (path,) = episode_sources(dataset_dir)[episode], episode_recordings(dataset_dir, recordings_dir, [episode])
    rec = read_recording(path, read_options(source))
    P, S = poses[episode], status[episode]
    if len(rec.rgb) != len(P):
        raise HspError(f"{path}: {len(rec.rgb)} frames, dataset episode {episode} has {len(P)}")
    T_world_cam = source.get("T_world_cam") or rec.T_world_cam  # the table frame parse tracked in
    if T_world_cam is None:
        raise HspError(f"{path}: no camera pose in /tf_static; cannot project the poses")
    T_world_cam = np.asarray(T_world_cam, float)
    gt = matching_ground_truth(path, task.names, len(P)) if in_recorded_world(source["table_frame"]) else None
    truth = None if gt is None else gt.poses
    labels = _labels(labels_file, episode, len(P))
    meshes = [load_mesh(task.mesh(i)) for i in range(len(task.objects))]
    out_dir = Path(out_dir)
    stem = f"episode_{episode:06d}"
    fps = float(meta["fps"])
    out = {"video": write_overlay(out_dir / f"{stem}.mp4", rec.rgb, meshes, P, S, rec.K, T_world_cam, fps, truth)}
    if labels is not None:
        true_labels = None if truth is None else {"tool": gt.tool, "target": gt.target, "waypoint_index": gt.waypoint_index}
        out["timeline"] = write_timeline(out_dir / f"{stem}_timeline.png", task.names, labels, S, true_labels, fps,
                                         f"{task.name}, episode {episode}: pseudo-labels above the demonstrator's annotation")
    else:
        log.warning("no labels for %s (run `hsp label %s` first): timeline skipped", stem, task.name)
    out["rerun"] = write_rrd(out_dir / f"{stem}.rrd", task.names, meshes, P, rec.rgb, rec.depth, rec.K, T_world_cam,
                             labels, truth, rrd_every)
    log.info("view %s episode %d: read %s, %s; wrote %s in %.1f s", task.name, episode, path, dataset_dir,
             ", ".join(str(p) for p in out.values()), time.perf_counter() - start)
    return out
