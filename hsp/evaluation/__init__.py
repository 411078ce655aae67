"""Closed-loop execution on the simulated Kuka: one gymnasium environment per task
(``gymnasium.make("hsp/Painting-v0")`` once this package is imported), the policy
runners and the evaluation that scores them with the paper's success criteria."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym

from hsp.tasks.registry import list_tasks


def env_id(task_name: str) -> str:
    """Gymnasium id of a task's environment: ``tire-removal`` → ``hsp/TireRemoval-v0``."""
    return "hsp/" + "".join(part.capitalize() for part in task_name.split("-")) + "-v0"


def make_env(task: str, pipeline_dir: Path | None = None, render_mode: str | None = None, **config):
    """The environment of a task by name; ``config`` are :class:`~hsp.evaluation.env.EnvConfig` fields."""
    from hsp.evaluation.env import EnvConfig, HspEnv
    from hsp.tasks.registry import load_task

    return HspEnv(load_task(task, pipeline_dir), EnvConfig(**config), render_mode)


def register_envs(pipeline_dir: Path | None = None) -> list[str]:
    """Register ``hsp/<Task>-v0`` for every task file; returns the ids."""
    ids = []
    for name in list_tasks(pipeline_dir):
        ids.append(env_id(name))
        if ids[-1] not in gym.registry:
            gym.register(ids[-1], entry_point="hsp.evaluation:make_env",
                         kwargs={"task": name, "pipeline_dir": pipeline_dir})
    return ids


register_envs()
