"""The ``label`` stage: a pose dataset → pseudo-labels parquet (+ metrics against the
demonstrator's annotation when the recordings are given)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import pandas as pd
from rich.progress import track

from hsp.dataset.build import identical_groups
from hsp.dataset.reader import episode_recordings, load_episodes
from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.geometry import compose, relative
from hsp.labeling.em import Refinement
from hsp.labeling.label import EpisodeLabels, canonical_poses, label_episode
from hsp.labeling.metrics import label_metrics
from hsp.labeling.priors import PriorConfig
from hsp.perception.metrics import match_identical
from hsp.recording.ground_truth import GroundTruth, read_ground_truth
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)
WAYPOINT_COLUMNS = ["waypoint_x", "waypoint_y", "waypoint_z", "waypoint_qx", "waypoint_qy", "waypoint_qz", "waypoint_qw"]
LABEL_COLUMNS = ["episode_index", "frame_index", "tool", "target", "waypoint_index", *WAYPOINT_COLUMNS, "equivalent"]


def labels_frame(labels: list[EpisodeLabels]) -> pd.DataFrame:
    """One row per frame: episode_index, frame_index, tool, target, waypoint_index, w (7)
    and the target's equivalence set as a bit mask over object indices (``equivalent``)."""
    parts = []
    for e, lab in enumerate(labels):
        H, n = lab.equivalent.shape
        df = pd.DataFrame({"episode_index": np.full(H, e), "frame_index": np.arange(H), "tool": lab.tool,
                           "target": lab.target, "waypoint_index": lab.waypoint_index})
        df[WAYPOINT_COLUMNS] = lab.waypoint
        df["equivalent"] = lab.equivalent.astype(np.int64) @ (np.int64(1) << np.arange(n, dtype=np.int64))
        parts.append(df)
    return pd.concat(parts, ignore_index=True)


def read_labels(path: Path, lengths: list[int], n_objects: int) -> list[EpisodeLabels]:
    """Per-episode labels from ``hsp label``'s parquet, checked against the dataset's
    episodes (their lengths) and its ``n_objects``."""
    path = Path(path)
    if not path.is_file():
        raise HspError(f"{path}: labels file not found (run `hsp label`)")
    df = pd.read_parquet(path)
    missing = [c for c in LABEL_COLUMNS if c not in df.columns]
    if missing:
        raise HspError(f"{path}: not an hsp labels file of this version (missing columns {missing}; run `hsp label`)")
    groups = dict(list(df.sort_values(["episode_index", "frame_index"]).groupby("episode_index")))
    if sorted(groups) != list(range(len(lengths))):
        raise HspError(f"{path}: labels for episodes {sorted(groups)[:5]}…, the dataset has {len(lengths)} episodes")
    out = []
    for e, H in enumerate(lengths):
        g = groups[e]
        if len(g) != H:
            raise HspError(f"{path}: episode {e} has {len(g)} labelled frames, the dataset {H}")
        bits = g["equivalent"].to_numpy()
        if np.any(bits >> n_objects):
            raise HspError(f"{path}: episode {e} names objects beyond the dataset's {n_objects}")
        equivalent = (bits[:, None] >> np.arange(n_objects)) & 1 == 1
        out.append(EpisodeLabels(g["tool"].to_numpy(), g["target"].to_numpy(), g["waypoint_index"].to_numpy(),
                                 g[WAYPOINT_COLUMNS].to_numpy(), equivalent))
    return out


def canonical_waypoints(gt: GroundTruth, symmetries: list[str]) -> np.ndarray:
    """The annotation's way-points ``(H, 7)``, given in the target's frame at the way-point
    frame, re-expressed in that target's canonical frame (as the labels are)."""
    H = len(gt.tool)
    k = np.clip(gt.waypoint_index, 0, H - 1)
    target = gt.poses[k, gt.target]  # (H, 7) raw target frames
    canonical = canonical_poses(gt.poses, symmetries)[k, gt.target]
    return compose(relative(target, canonical), gt.waypoint)


def label_dataset(task: Task, dataset_dir: Path, out_file: Path, cfg: PriorConfig,
                  recordings_dir: Path | None = None, em: Refinement | None = None) -> dict[str, float | int]:
    """Labels every episode of ``dataset_dir`` (Viterbi over the priors; with ``em``, then
    EM rounds over the trained policy) into ``out_file``; the report scores them against the
    recordings' annotation when ``recordings_dir`` is given."""
    start = time.perf_counter()
    poses, status, _ = load_episodes(dataset_dir, task.name, task.names)
    recs = None if recordings_dir is None else episode_recordings(dataset_dir, recordings_dir)
    symmetries = [o.symmetry for o in task.objects]
    report: dict[str, float | int] = {"episodes": len(poses), "frames": int(sum(len(p) for p in poses))}
    if em is None:
        labels = [label_episode(p, s, cfg, symmetries=symmetries)
                  for p, s in track(list(zip(poses, status)), description=f"label {task.name}")]
    else:
        labels, changed = em.run(task, poses, status, cfg)
        report |= {"em_rounds": len(changed), "em_changed_fraction_last": changed[-1] if changed else 0.0}
    with atomic_path(Path(out_file)) as tmp:
        labels_frame(labels).to_parquet(tmp, index=False)
    if recs is not None:
        truth, pred = [], []
        groups = identical_groups(task)
        for path, p, lab in zip(recs, poses, labels):
            gt = read_ground_truth(path)
            if len(gt.tool) != len(p):
                raise HspError(f"{path}: {len(gt.tool)} frames, the dataset episode has {len(p)}")
            truth.append({"tool": gt.tool, "target": gt.target, "waypoint": canonical_waypoints(gt, symmetries)})
            true_index = np.argsort(match_identical(groups, p, gt.poses))  # the tracker's nut 1 may be the truth's nut 3
            equivalent = np.zeros_like(lab.equivalent)
            equivalent[:, true_index] = lab.equivalent
            pred.append({"tool": true_index[lab.tool], "target": true_index[lab.target], "waypoint": lab.waypoint,
                         "equivalent": equivalent})
        report.update(label_metrics(pred, truth))
    report["seconds"] = time.perf_counter() - start
    log.info("labelled %d episodes from %s into %s in %.1f s", len(labels), dataset_dir, out_file, report["seconds"])
    return report
