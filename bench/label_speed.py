"""Benchmark: labelling one long episode (priors + Viterbi) — time and peak memory.

Target (issue 5): 1,800 frames with 6 objects in ≤ 2 s, under 2 GiB.
Run: ``python bench/label_speed.py [--frames 1800] [--objects 6] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig


def random_walk(H: int, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xyz = 0.5 + np.cumsum(rng.normal(0, 0.003, (H, n, 3)), axis=0)
    rot = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.01, (H * n, 3)), axis=0)).as_quat().reshape(H, n, 4)
    return np.concatenate([xyz, rot], -1)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=1800)
    ap.add_argument("--objects", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    world = random_walk(args.frames, args.objects, 0)
    status = np.zeros(world.shape[:2], int)
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        label_episode(world, status, PriorConfig())
        times.append(time.perf_counter() - start)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{args.frames} frames, {args.objects} objects: median {statistics.median(times):.2f} s "
          f"(min {min(times):.2f}, max {max(times):.2f}); peak RSS {peak:.0f} MiB")


if __name__ == "__main__":
    main()
