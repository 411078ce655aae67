"""Benchmark: closed-loop control steps per second in one process, with each observer.

The oracle (the demonstrator's plan) runs whole episodes of a task on the Kuka; per
observer, the median over episodes of steps per second (environment, policy and, with
``camera``, rendering and online tracking; the first frame's scene estimate included).
Run: ``python bench/eval_speed.py [--task stacking-1] [--episodes 3] [--observers sim camera]``.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from hsp.config import load_params, section
from hsp.evaluation.env import EnvConfig, HspEnv
from hsp.evaluation.observers import CameraObserver, SimObserver
from hsp.evaluation.oracle import Oracle
from hsp.evaluation.rollout import held_out_seeds, run_episode
from hsp.perception.tracker import TrackerConfig
from hsp.recording.record import camera_rig
from hsp.tasks.registry import load_task


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default="stacking-1")
    ap.add_argument("--episodes", type=int, default=3)
    ap.add_argument("--observers", nargs="+", default=["sim", "camera"])
    args = ap.parse_args()
    params = load_params(Path(__file__).resolve().parents[1] / "params.yaml")
    task = load_task(args.task)
    seeds = held_out_seeds(0, 1, args.episodes, 0)[0]
    for name in args.observers:
        observer = SimObserver() if name == "sim" else CameraObserver(task, camera_rig(params),
                                                                        section(params, "tracker", TrackerConfig))
        env = HspEnv(task, EnvConfig(max_steps=1500), observer=observer)
        rates, outcomes = [], []
        for seed in seeds:
            start = time.perf_counter()
            record = run_episode(env, Oracle(task, env.config.fps, env.reach_error), int(seed))
            rates.append(record["steps"] / (time.perf_counter() - start))
            outcomes.append(record["success"])
        env.close()
        print(f"{args.task} observer {name}: {statistics.median(rates):.1f} control steps/s per process "
              f"(median of {len(rates)} episodes, range {min(rates):.1f}–{max(rates):.1f}; {sum(outcomes)} succeeded)")


if __name__ == "__main__":
    main()
