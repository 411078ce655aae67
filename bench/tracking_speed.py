"""Benchmark: the tracker's frame rate at 640×480, with and without the first-frame estimate.

For each task, the first ``--frames`` frames of two recordings are tracked (reading and
decoding excluded): one at a time in one process, then both at once in two processes, as
``hsp parse`` runs them (one process per core, pinned to it). Prints the median over
``--repeats`` of frames/s for one process and the combined rate of two, with and without
the first-frame estimate (a fixed cost per episode, which weighs on 150 frames). Issue 4's
target: ≥ 30 frames/s with six objects (tire-removal) on this 2-core machine; the paper's
GPU tracker: 90.
Run: ``python bench/tracking_speed.py [--recordings data/recordings] [--frames 150] [--repeats 3] [--tasks …]``;
``--frames 0`` tracks whole episodes (the first-frame estimate then weighs as in ``hsp parse``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # before Open3D is imported, here and in the workers

import argparse  # noqa: E402
import multiprocessing  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from hsp.parallel import pin_to_one_core  # noqa: E402
from hsp.perception.episode import object_models, track_recording  # noqa: E402
from hsp.perception.tracker import TrackerConfig  # noqa: E402
from hsp.recording.reader import read_recording  # noqa: E402
from hsp.tasks.registry import list_tasks, load_task  # noqa: E402


def _rates(job: tuple[str, Path, int]) -> tuple[float, float]:
    """Frames/s with the first-frame estimate counted, and of the frame-to-frame tracking alone."""
    name, path, frames = job
    task, cfg = load_task(name), TrackerConfig()
    rec = read_recording(path)
    if frames > 0:
        rec.rgb, rec.depth = rec.rgb[:frames], rec.depth[:frames]
    tracked = track_recording(task, rec, object_models(task, cfg, 0), cfg)
    return len(rec.rgb) / tracked.seconds, (len(rec.rgb) - 1) / (tracked.seconds - tracked.first_frame_seconds)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--recordings", type=Path, default=Path("data/recordings"))
    ap.add_argument("--frames", type=int, default=150, help="first frames of each episode; 0: whole episodes")
    ap.add_argument("--tasks", nargs="*", default=None, help="default: every task")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"frames/s, median of {args.repeats}; in brackets, frame-to-frame tracking alone (first-frame estimate excluded)")
    print(f"{'task':14s} {'objects':>7s} {'1 process':>18s} {'2 processes':>18s}")
    ctx = multiprocessing.get_context("spawn")
    one_pool, pool = (ProcessPoolExecutor(k, mp_context=ctx, initializer=pin_to_one_core, initargs=(ctx.Value("i", 0),))
                      for k in (1, 2))
    for name in args.tasks or list_tasks():
        paths = sorted((args.recordings / name).glob("*.mcap"))[:2]
        if len(paths) < 2:
            print(f"{name:14s} needs two recordings under {args.recordings / name}")
            continue
        jobs = [(name, p, args.frames) for p in paths]
        one = [one_pool.submit(_rates, jobs[0]).result() for _ in range(args.repeats)]
        two = [np.sum(list(pool.map(_rates, jobs)), axis=0) for _ in range(args.repeats)]
        (a, b), (c, d) = np.median(one, axis=0), np.median(two, axis=0)
        print(f"{name:14s} {len(load_task(name).objects):7d} {a:8.1f} ({b:5.1f}) {c:11.1f} ({d:5.1f})", flush=True)
    one_pool.shutdown()
    pool.shutdown()


if __name__ == "__main__":
    main()
