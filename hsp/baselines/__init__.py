"""Baselines trained on the same pose datasets and scored by the same ``hsp eval`` harness
as the hierarchy (issue 20). One module per method; this is their common face:
:func:`train_baseline` (the ``train`` stage) and :func:`load_agent` (for ``hsp eval``)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

from hsp.errors import HspError
from hsp.tasks.registry import Task

log = logging.getLogger(__name__)

METHODS = ("bc", "bc-rnn")
"""Baselines built so far."""
PLANNED = ("gail", "taco", "act", "diffusion")
"""Baselines of issue 20 not built yet: asking for one is a clear error."""


def check_method(method: str) -> None:
    if method in PLANNED:
        raise HspError(f"baseline {method!r} is not built yet (issue 20); built: {', '.join(METHODS)}")
    if method not in METHODS:
        raise HspError(f"unknown baseline {method!r}; built: {', '.join(METHODS)}")


def train_baseline(task: Task, method: str, dataset_dir: Path, out_dir: Path, cfg, seed: int) -> dict:
    """Train ``method`` on the pose dataset and save it to ``out_dir``; the stage's report."""
    from hsp.baselines import bc
    from hsp.baselines.observations import load_demonstrations

    check_method(method)
    start = time.perf_counter()
    demos = load_demonstrations(task, dataset_dir, cfg.moving_m)
    log.info("train %s %s: read %d episodes (%d frames) from %s", task.name, method, len(demos),
             sum(len(o) for o in demos.obs), dataset_dir)
    model, report = bc.train(demos, task.names, method, cfg, seed)
    bc.save(model, cfg, out_dir)
    return {"method": method, "iterations": cfg.iterations, **report, "seconds": time.perf_counter() - start}


def config_class(method: str) -> type:
    """The configuration dataclass of ``method`` (its section ``baselines.METHOD`` of params.yaml)."""
    from hsp.baselines.bc import BCConfig

    check_method(method)
    return BCConfig


def load_agent(task: Task, method: str, model_dir: Path, fps: int):
    """The closed-loop agent of a trained baseline: ``reset(poses, seed)``, ``act(poses)``."""
    from hsp.baselines import bc

    check_method(method)
    if not Path(model_dir).exists():
        raise HspError(f"{model_dir}: model directory not found (run `hsp train {task.name} --method {method}`)")
    model = bc.load(model_dir)
    if model.method != method:
        raise HspError(f"{model_dir}: a {model.method} model, not {method}")
    if model.fps != fps:
        raise HspError(f"{model_dir}: trained on {model.fps} fps demonstrations, the environment runs at {fps}")
    return bc.BCAgent(model, task, str(model_dir))
