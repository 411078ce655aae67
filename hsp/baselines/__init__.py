"""Baselines trained on the same pose datasets and scored by the same ``hsp eval`` harness
as the hierarchy (issue 20). One module per method; this is their common face:
:func:`train_baseline` (the ``train`` stage) and :func:`load_agent` (for ``hsp eval``)."""

from __future__ import annotations

import importlib
import logging
import time
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from hsp.errors import HspError
from hsp.methods import BASELINES
from hsp.tasks.registry import Task

if TYPE_CHECKING:
    from hsp.evaluation.env import EnvConfig

log = logging.getLogger(__name__)

def check_method(method: str, others: tuple[str, ...] = ()) -> None:
    """A one-line error for a name that is no method (``others``: the caller's own methods,
    listed in the message)."""
    if method not in BASELINES:
        raise HspError(f"unknown method {method!r}; valid methods: {', '.join((*others, *BASELINES))}")


_PARTS = {  # method: its module, configuration (params.yaml: baselines.METHOD) and closed-loop agent
    "bc": ("bc", "BaselineConfig", "BCAgent"),
    "bc-rnn": ("bc", "BaselineConfig", "BCAgent"),
    "taco": ("taco", "BaselineConfig", "TacoAgent"),
    "gail": ("gail", "GailConfig", "GailAgent"),
    "act": ("lerobot_policies", "LeRobotPolicyConfig", "LeRobotAgent"),
    "diffusion": ("lerobot_policies", "LeRobotPolicyConfig", "LeRobotAgent"),
}


def _module(method: str):
    check_method(method)
    return importlib.import_module(f"hsp.baselines.{_PARTS[method][0]}")


def config_class(method: str) -> type:
    """The configuration dataclass of ``method`` (its section ``baselines.METHOD`` of params.yaml)."""
    return getattr(_module(method), _PARTS[method][1])


def train_baseline(task: Task, method: str, dataset_dir: Path, out_dir: Path, cfg, seed: int,
                   recordings_dir: Path | None = None, env: EnvConfig | None = None) -> dict:
    """Train ``method`` on the pose dataset (taco: with the sketches of the annotation in
    ``recordings_dir``; gail: interacting with the task's environment configured by ``env``)
    and save it to ``out_dir``; the stage's report."""
    from hsp.baselines.observations import load_demonstrations
    from hsp.baselines.taco import annotated_sketches

    module = _module(method)
    start = time.perf_counter()
    demos, poses = load_demonstrations(task, dataset_dir, cfg.moving_m, cfg.grasp_m)
    log.info("train %s %s: read %d episodes (%d frames) from %s", task.name, method, len(demos),
             sum(len(o) for o in demos.obs), dataset_dir)
    if method == "taco":
        sketches = annotated_sketches(task, poses, dataset_dir, recordings_dir)
        model, report = module.train(demos, sketches, task.names, cfg, seed, str(recordings_dir))
    elif method == "gail":
        from hsp.evaluation.env import EnvConfig, HspEnv

        if env is not None and env.fps != demos.fps:
            raise HspError(f"{dataset_dir}: recorded at {demos.fps} fps, the environment runs at {env.fps} (record.fps)")
        model, report = module.train(demos, task, partial(HspEnv, task, env or EnvConfig(fps=demos.fps)), cfg, seed)
    else:
        model, report = module.train(demos, task.names, method, cfg, seed)
    module.save(model, cfg, out_dir)
    return {"method": method, "config": asdict(cfg), **report, "seconds": time.perf_counter() - start}


def load_agent(task: Task, method: str, model_dir: Path | None, fps: int):
    """The closed-loop agent of a trained baseline: ``reset(poses, seed)``, ``act(poses)``."""
    module = _module(method)
    if model_dir is None or not Path(model_dir).exists():
        raise HspError(f"{model_dir}: model directory not found (run `hsp train {task.name} --method {method}`)")
    model = module.load(model_dir, method)
    if model.fps != fps:
        raise HspError(f"{model_dir}: trained on {model.fps} fps demonstrations, the environment runs at {fps}")
    return getattr(module, _PARTS[method][2])(model, task, str(model_dir))
