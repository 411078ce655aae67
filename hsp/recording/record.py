"""The ``record`` stage: run the demonstrator on N random layouts, one MCAP per episode."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import Progress

from hsp.config import section
from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.parallel import ScaleOut, worker_pool
from hsp.recording.writer import CameraRig, write_episode
from hsp.sim.camera import CameraConfig
from hsp.sim.demonstration import demonstrate
from hsp.sim.depth_noise import DepthNoiseConfig
from hsp.tasks.registry import Task, load_task

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RecordConfig:
    episodes: int
    """Number of demonstrations (paper: 70 painting, 40 for the other tasks)."""
    seed: int
    """Stage seed; episode e uses the seed derived from (seed, e)."""
    fps: int = 15
    """Frame rate of the recording (must divide the 240 Hz physics rate)."""
    workers: int = 2
    """Processes recording episodes in parallel."""
    rig: CameraRig | None = None
    """Camera and depth-sensor model; ``None`` records the ground-truth topics only."""
    scale: ScaleOut = field(default_factory=ScaleOut)
    """Where the workers run (``params.yaml: parallel``)."""

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise HspError(f"record.episodes = {self.episodes}: must be at least 1")
        if self.fps < 1 or 240 % self.fps:
            raise HspError(f"record.fps = {self.fps}: must divide 240")
        if self.workers < 1:
            raise HspError(f"record.workers = {self.workers}: must be at least 1")


def camera_rig(params: dict[str, Any]) -> CameraRig:
    """Camera and depth-sensor model from the ``camera`` and ``depth_noise`` params sections."""
    return CameraRig(section(params, "camera", CameraConfig), section(params, "depth_noise", DepthNoiseConfig))


def episode_seed(seed: int, episode: int) -> int:
    """Independent per-episode seed derived from the stage seed."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def episode_path(out_dir: Path, episode: int) -> Path:
    return out_dir / f"episode_{episode:06d}.mcap"


def _record_one(args: tuple[str, Path, int, int, int, Path, CameraRig | None]) -> tuple[int, bool, int]:
    task_name, pipeline_dir, seed, episode, fps, out_dir, rig = args
    task = load_task(task_name, pipeline_dir)
    demo = demonstrate(task, episode_seed(seed, episode), fps)
    write_episode(episode_path(out_dir, episode), task, demo, episode, rig)
    return episode, demo.success, demo.frames


def record(task: Task, cfg: RecordConfig, out_dir: Path, force: bool = False) -> dict[str, float | int]:
    """Record ``cfg.episodes`` demonstrations into ``out_dir``; returns the flat report."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not force:
        raise HspError(f"{out_dir}: output directory exists; pass --force to replace it")
    with atomic_path(out_dir) as tmp:
        tmp.mkdir(parents=True)
        jobs = [(task.name, task.objects_dir.parent, cfg.seed, e, cfg.fps, tmp, cfg.rig) for e in range(cfg.episodes)]
        start = time.perf_counter()
        results = []
        with Progress() as progress:
            bar = progress.add_task(f"record {task.name}", total=len(jobs))
            if cfg.workers == 1 and cfg.scale.backend == "processes":
                for job in jobs:
                    results.append(_record_one(job))
                    progress.advance(bar)
            else:
                with worker_pool(cfg.workers, cfg.scale) as pool:
                    for r in pool.map(_record_one, jobs):
                        results.append(r)
                        progress.advance(bar)
        seconds = time.perf_counter() - start
    frames = sum(f for _, _, f in results)
    failed = [e for e, ok, _ in results if not ok]
    log.info("wrote %d episodes (%d frames) to %s in %.1f s; demonstrator failed on %s", len(results), frames, out_dir, seconds, failed or "none")
    return {
        "episodes": len(results),
        "demonstrator_success_rate": 1.0 - len(failed) / len(results),
        "demonstrator_failures": len(failed),
        "frames": frames,
        "frames_per_second": frames / seconds,
        "seconds": seconds,
    }
