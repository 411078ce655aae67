"""Benchmark: `hsp record` throughput (frames/s), ground truth only and with the RGB-D
camera at 640×480 (render + depth noise + MCAP), with 1 and 2 processes.

Target (issue 3): ≥ 15 frames/s with the camera on this 2-core machine.
Run: ``python bench/record_throughput.py [--episodes 4] [--repeats 3] [--tasks stacking-1]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from hsp.tasks.registry import list_tasks, load_task


def rate(task_name: str, episodes: int, repeats: int, workers: int, camera: bool) -> float:
    task = load_task(task_name)
    rig = CameraRig(CameraConfig(), DepthNoiseConfig()) if camera else None
    runs = []
    for r in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            rep = record(task, RecordConfig(episodes=episodes, seed=r, workers=workers, rig=rig), Path(tmp) / "rec")
            runs.append(rep["frames"] / (time.perf_counter() - start))
    return statistics.median(runs)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tasks", nargs="*", default=None)
    args = ap.parse_args()
    print(f"median of {args.repeats} runs of {args.episodes} episodes; frames/s")
    print(f"{'task':14s} {'no camera, 2 proc':>18s} {'camera, 1 proc':>15s} {'camera, 2 proc':>15s} {'2/1':>5s}")
    for name in args.tasks or list_tasks():
        gt = rate(name, args.episodes, args.repeats, 2, camera=False)
        one = rate(name, args.episodes, args.repeats, 1, camera=True)
        two = rate(name, args.episodes, args.repeats, 2, camera=True)
        print(f"{name:14s} {gt:18.0f} {one:15.1f} {two:15.1f} {two / one:5.2f}", flush=True)


if __name__ == "__main__":
    main()
