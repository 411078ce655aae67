"""Benchmark: the frame-to-frame tracker on recorded episodes, started from the true
first-frame poses (tracking alone, without the initialiser), against the ground truth.

Prints per task: frames/s (one process) and, over all objects and frames, the median and
95th percentile translation error, the median symmetry-aware rotation error, the ADD-S
AUC (0–10 cm) and the lost fraction. Issue 4's targets: ≤ 2 mm, ≤ 5 mm, ≤ 2°, ≥ 95, ≤ 1 %.
Run: ``python bench/tracking_from_truth.py [--recordings data/recordings] [--episodes 1] [--frames 300]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from hsp.perception.metrics import add_s, auc, rotation_error_deg
from hsp.perception.tracker import SurfaceModel, TrackerConfig, track
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.reader import read_recording
from hsp.sim.render import load_mesh
from hsp.tasks.registry import list_tasks, load_task


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--recordings", type=Path, default=Path("data/recordings"))
    ap.add_argument("--episodes", type=int, default=1)
    ap.add_argument("--frames", type=int, default=300)
    args = ap.parse_args()
    print(f"{'task':14s} {'fps':>5s} {'t med mm':>9s} {'t p95 mm':>9s} {'r med deg':>10s} {'ADD-S AUC':>10s} {'lost':>6s}")
    for name in list_tasks():
        task = load_task(name)
        meshes = [load_mesh(task.mesh(i)) for i in range(len(task.objects))]
        models = [SurfaceModel(m, TrackerConfig().model_points, i) for i, m in enumerate(meshes)]
        samples = [np.asarray(SurfaceModel(m, 500).cloud.points) for m in meshes]
        te, re, adds, lost, frames, seconds = [], [], [], [], 0, 0.0
        for path in sorted((args.recordings / name).glob("*.mcap"))[: args.episodes]:
            rec, gt = read_recording(path), read_ground_truth(path)
            n = min(args.frames, len(rec.rgb))
            start = time.perf_counter()
            poses, status = track(rec.rgb[:n], rec.depth[:n], rec.K, rec.T_world_cam, models, gt.poses[0], TrackerConfig())
            seconds += time.perf_counter() - start
            frames += n
            G = gt.poses[:n]
            for i, obj in enumerate(task.objects):
                te.append(np.linalg.norm(poses[:, i, :3] - G[:, i, :3], axis=1) * 1000)
                re.append(rotation_error_deg(poses[:, i, 3:], G[:, i, 3:], obj.symmetry))
                adds.append(add_s(samples[i], poses[:, i], G[:, i]))
                lost.append(status[:, i] == 2)
        if frames == 0:
            print(f"{name:14s} no recordings under {args.recordings / name}")
            continue
        te_all, re_all = np.concatenate(te), np.concatenate(re)
        print(f"{name:14s} {frames / seconds:5.1f} {np.median(te_all):9.2f} {np.percentile(te_all, 95):9.2f} "
              f"{np.median(re_all):10.2f} {auc(np.concatenate(adds)):10.1f} {np.mean(np.concatenate(lost)):6.3f}", flush=True)


if __name__ == "__main__":
    main()
