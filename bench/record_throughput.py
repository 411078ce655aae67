"""Benchmark: demonstrations recorded per second (ground truth only), per task.

Prints the median over repeats of frames/s for one process, and the 2-process speed-up.
Run: ``python bench/record_throughput.py [--episodes 6] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from hsp.recording.record import RecordConfig, record
from hsp.tasks.registry import list_tasks, load_task


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"{'task':14s} {'frames/s 1 proc':>16s} {'frames/s 2 proc':>16s} {'ratio':>6s}")
    for name in list_tasks():
        task = load_task(name)
        rates = {}
        for workers in (1, 2):
            runs = []
            for r in range(args.repeats):
                with tempfile.TemporaryDirectory() as tmp:
                    start = time.perf_counter()
                    rep = record(task, RecordConfig(episodes=args.episodes, seed=r, workers=workers), Path(tmp) / "rec")
                    runs.append(rep["frames"] / (time.perf_counter() - start))
            rates[workers] = statistics.median(runs)
        print(f"{name:14s} {rates[1]:16.0f} {rates[2]:16.0f} {rates[2] / rates[1]:6.2f}")


if __name__ == "__main__":
    main()
