"""Closed-loop evaluation: episodes of a method on held-out layouts, in parallel processes.

Test layouts come from seeds that no recording used: episode ``e`` of run ``r`` draws
its seed from ``SeedSequence([seed, EVAL_STREAM, r, e])`` (recordings use
``SeedSequence([seed, e])``), and any seed that a recording of the task did use is skipped.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.progress import Progress

from hsp.baselines import check_method, load_agent
from hsp.errors import HspError
from hsp.evaluation.env import EnvConfig, HspEnv, world_poses
from hsp.evaluation.observers import CameraObserver, Observer, SimObserver
from hsp.evaluation.stats import summarise
from hsp.fileio import atomic_path, write_json
from hsp.methods import HIERARCHY, METHODS
from hsp.parallel import ScaleOut, worker_pool
from hsp.perception.tracker import TrackerConfig
from hsp.recording.record import episode_seed
from hsp.recording.writer import CameraRig
from hsp.tasks.registry import Task, load_task

log = logging.getLogger(__name__)

OBSERVERS = ("sim", "camera")
EVAL_STREAM = 1
"""Third entropy word of the evaluation seeds, apart from the recordings' two-word ones."""


@dataclass(frozen=True)
class EvalConfig:
    episodes: int = 50
    """Episodes per run."""
    runs: int = 5
    """Runs, each on its own held-out layouts; ``success_rate_std`` is across them."""
    seed: int = 0
    """Stage seed (``params.yaml: seed``)."""
    workers: int = 2
    """Episodes in parallel processes."""
    videos: int = 1
    """Episodes of each run recorded as MP4."""
    recorded_episodes: int = 0
    """Recordings of the task made from ``seed``; their seeds are never test layouts."""
    env: EnvConfig = field(default_factory=EnvConfig)
    rig: CameraRig | None = None
    """The recordings' camera and depth model, for ``--observer camera``."""
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    """The tracker's settings, for ``--observer camera`` (``params.yaml: tracker``)."""
    scale: ScaleOut = field(default_factory=ScaleOut)
    """Where the workers run (``params.yaml: parallel``)."""

    def __post_init__(self) -> None:
        for key in ("episodes", "runs", "workers"):
            if getattr(self, key) < 1:
                raise HspError(f"eval.{key} = {getattr(self, key)}: must be at least 1")


def held_out_seeds(seed: int, runs: int, episodes: int, recorded_episodes: int) -> np.ndarray:
    """Layout seeds ``(runs, episodes)`` disjoint from the recordings' and from each other."""
    used = {episode_seed(seed, e) for e in range(recorded_episodes)}
    out = np.zeros((runs, episodes), np.int64)
    for r in range(runs):
        e = k = 0
        while e < episodes:
            s = int(np.random.SeedSequence([seed, EVAL_STREAM, r, k]).generate_state(1)[0])
            k += 1
            if s not in used:
                out[r, e], e = s, e + 1
                used.add(s)
    return out


def load_runner(task: Task, method: str, model_dir: Path | None, reach_error=None):
    """The runner of a trained hierarchy; a one-line error for a missing, damaged or foreign model."""
    from hsp.evaluation.proposed import HierarchyRunner
    from hsp.policy.train import load

    if model_dir is None or not Path(model_dir).exists():
        raise HspError(f"{model_dir}: model directory not found (run `hsp train {task.name} --method {method}`)")
    return HierarchyRunner(load(model_dir), task, str(model_dir), reach_error)


def make_agent(task: Task, method: str, model_dir: Path | None, env: HspEnv):
    """The policy object of a method: ``reset(poses, seed)``, ``act(poses) -> action``."""
    if method == "oracle":
        from hsp.evaluation.oracle import Oracle

        return Oracle(task, env.config.fps, env.reach_error)
    if method in HIERARCHY:
        return load_runner(task, method, model_dir, env.reach_error)
    return load_agent(task, method, model_dir, env.config.fps)


def run_episode(env: HspEnv, agent, seed: int, video: Path | None = None) -> dict:
    """One episode from the layout of ``seed``; its record (success, steps, sub-goals, why it ended)."""
    obs, info = env.reset(seed=seed)
    agent.reset(world_poses(obs), seed)
    frames = [env.render()] if video else []
    terminated = truncated = False
    while not (terminated or truncated):
        obs, _, terminated, truncated, info = env.step(agent.act(world_poses(obs)))
        if video:
            frames.append(env.render())
    if video:
        write_video(video, frames, env.config.fps)
    return {"seed": int(seed), "success": bool(info["is_success"]), "steps": int(info["steps"]),
            "progress": info["progress"], "ended": "success" if terminated else "step limit"}


def write_video(path: Path, frames: list[np.ndarray], fps: int) -> None:
    import cv2

    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    for f in frames:
        writer.write(cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    writer.release()


def make_observer(task: Task, observer: str, cfg: EvalConfig) -> Observer:
    if observer == "sim":
        return SimObserver()
    if observer == "camera":
        if cfg.rig is None:
            raise HspError("--observer camera needs the recordings' camera (params.yaml: camera, depth_noise)")
        return CameraObserver(task, cfg.rig, cfg.tracker, cfg.seed)
    raise HspError(f"unknown observer {observer!r}; valid observers: {', '.join(OBSERVERS)}")


def _job(args: tuple) -> dict:
    task_name, pipeline_dir, method, observer, model_dir, cfg, run, episode, seed, video = args
    import torch

    torch.set_num_threads(1)
    task = load_task(task_name, pipeline_dir)
    env = HspEnv(task, cfg.env, "rgb_array" if video else None, make_observer(task, observer, cfg))
    try:
        record = run_episode(env, make_agent(task, method, model_dir, env), seed, video)
    finally:
        env.close()
    return {"run": run, "episode": episode, **record}


def evaluate(task: Task, method: str, observer: str, model_dir: Path | None, cfg: EvalConfig,
             out_dir: Path) -> dict[str, float | int | str]:
    """Run ``cfg.runs × cfg.episodes`` episodes; write ``eval.json``, ``episodes.jsonl`` and
    ``videos/`` into ``out_dir`` (suffixed ``_camera`` for that observer), all or nothing."""
    if method not in METHODS:
        check_method(method, ("oracle", *HIERARCHY))
    make_observer(task, observer, cfg)  # bad input fails here, before any episode
    if method in HIERARCHY:
        load_runner(task, method, model_dir)
    elif method != "oracle":
        load_agent(task, method, model_dir, cfg.env.fps)
    suffix = "" if observer == "sim" else f"_{observer}"
    seeds = held_out_seeds(cfg.seed, cfg.runs, cfg.episodes, cfg.recorded_episodes)
    out_dir = Path(out_dir)
    start = time.perf_counter()
    with atomic_path(out_dir / f"videos{suffix}") as videos:
        videos.mkdir(parents=True)
        jobs = [(task.name, task.objects_dir.parent, method, observer, model_dir, cfg, r, e, int(seeds[r, e]),
                 videos / f"run{r}_episode{e:03d}.mp4" if e < cfg.videos else None)
                for r in range(cfg.runs) for e in range(cfg.episodes)]
        log.info("eval %s: %s, observer %s, %d runs × %d episodes, %d workers", task.name, method, observer, cfg.runs,
                 cfg.episodes, cfg.workers)
        records = []
        with Progress() as progress, worker_pool(cfg.workers, cfg.scale) as pool:
            bar = progress.add_task(f"eval {task.name} {method}", total=len(jobs))
            for rec in pool.map(_job, jobs):
                records.append(rec)
                progress.advance(bar)
        seconds = time.perf_counter() - start
        with atomic_path(out_dir / f"episodes{suffix}.jsonl") as tmp:
            tmp.write_text("".join(json.dumps(r, sort_keys=True) + "\n" for r in records))
    report = summarise(records) | {"seconds": seconds, "steps_per_second": sum(r["steps"] for r in records) / seconds}
    write_json(out_dir / f"eval{suffix}.json", report)
    log.info("eval %s %s: success %.3f over %d episodes; wrote %s in %.1f s", task.name, method, report["success_rate"],
             len(records), out_dir, seconds)
    return report

