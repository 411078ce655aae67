"""Benchmark: RGB-D reader throughput (frames/s) on a recorded 640×480 episode.

Target (issue 3): ≥ 100 frames/s. Run: ``python bench/read_throughput.py [--repeats 5]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from hsp.recording.reader import read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from hsp.tasks.registry import load_task


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--task", default="stacking-1")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "rec"
        record(load_task(args.task), RecordConfig(episodes=1, seed=0, workers=1, rig=CameraRig(CameraConfig(), DepthNoiseConfig())), out)
        path = out / "episode_000000.mcap"
        rates = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            rec = read_recording(path)
            rates.append(len(rec.rgb) / (time.perf_counter() - start))
        size = path.stat().st_size / len(rec.rgb) / 1e3
    print(f"{args.task}: {len(rec.rgb)} frames, {size:.0f} kB/frame on disk; "
          f"read median {statistics.median(rates):.0f} frames/s (min {min(rates):.0f}, max {max(rates):.0f})")


if __name__ == "__main__":
    main()
