"""Benchmark: training π_h, π_m, π_l — time per iteration and peak memory.

Synthetic episodes (random-walk poses, labels from the priors), so it runs without the
pipeline's data. Gradient steps only (no held-out episodes, so no free-running checkpoints).
Run: ``python bench/train_speed.py [--episodes 32] [--frames 400] [--objects 6] [--iterations 200] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time

import numpy as np
import torch

from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig
from hsp.policy.features import episode_steps
from hsp.policy.train import TrainConfig, train

from label_speed import random_walk


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=32)
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--objects", type=int, default=6)
    ap.add_argument("--iterations", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    n = args.objects
    classes = np.arange(n)
    steps = []
    for e in range(args.episodes):
        world = random_walk(args.frames, n, e)
        lab = label_episode(world, np.zeros((args.frames, n), int), PriorConfig())
        steps.append(episode_steps(world, np.ones((args.frames, n), bool), lab.tool, lab.target, lab.waypoint_index,
                                   classes, n, equivalent=lab.equivalent))
    cfg = TrainConfig(iterations=args.iterations, checkpoint_every=args.iterations)
    train(steps, [str(i) for i in range(n)], classes, n, TrainConfig(iterations=2), seed=0)  # warm-up: torch's lazy imports
    times = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        train(steps, [str(i) for i in range(n)], classes, n, cfg, seed=0)
        times.append((time.perf_counter() - start) / args.iterations)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{args.episodes} episodes × {args.frames} frames, {n} objects, {torch.get_num_threads()} threads: "
          f"median {1000 * statistics.median(times):.1f} ms per iteration (min {1000 * min(times):.1f}, "
          f"max {1000 * max(times):.1f}); 20,000 iterations ≈ {20000 * statistics.median(times) / 60:.1f} min; "
          f"peak RSS {peak:.0f} MiB")


if __name__ == "__main__":
    main()
