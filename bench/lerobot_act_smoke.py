"""Check: LeRobot's own `lerobot-train` runs a few steps of a small state-only ACT on an hsp
pose dataset (issue 4's contract with LeRobot). Prints the steps done and the seconds.

Run: ``python bench/lerobot_act_smoke.py [--task stacking-1] [--steps 5]``; records two
ground-truth episodes, parses them with ``--poses-from ground-truth``, then trains.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hsp.dataset.build import parse
from hsp.recording.record import RecordConfig, record
from hsp.tasks.registry import load_task


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default="stacking-1")
    ap.add_argument("--steps", type=int, default=5)
    args = ap.parse_args()
    task = load_task(args.task)
    with tempfile.TemporaryDirectory() as tmp:
        rec, ds, out = Path(tmp) / "rec", Path(tmp) / "ds", Path(tmp) / "train"
        record(task, RecordConfig(episodes=2, seed=0, workers=1), rec)
        parse(task, rec, ds, poses_from="ground-truth")
        cmd = [
            str(Path(sys.executable).with_name("lerobot-train")), f"--dataset.repo_id=hsp/{task.name}", f"--dataset.root={ds}",
            "--policy.type=act", "--policy.device=cpu", "--policy.push_to_hub=false", f"--output_dir={out}",
            f"--steps={args.steps}", "--batch_size=8", "--num_workers=0", "--wandb.enable=false",
            "--policy.dim_model=64", "--policy.dim_feedforward=256", "--policy.n_encoder_layers=1",
            "--policy.chunk_size=10", "--policy.n_action_steps=10", "--save_checkpoint=false", "--log_freq=1",
        ]
        start = time.perf_counter()
        env = {**os.environ, "HF_HUB_OFFLINE": "1"}
        result = subprocess.run(cmd, env=env, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        log = result.stdout + result.stderr
        steps = [line for line in log.splitlines() if "step:" in line]
        print(f"lerobot-train exit {result.returncode}, {len(steps)} logged steps, {seconds:.0f} s")
        if result.returncode != 0 or not steps:
            print(log[-3000:])
            sys.exit(1)
        print(steps[-1].strip())


if __name__ == "__main__":
    main()
