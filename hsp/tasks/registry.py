"""Loading task files: ``pipeline/tasks/<name>.yaml`` → a validated :class:`Task`."""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml
from pydantic import ValidationError

from hsp.errors import HspError
from hsp.tasks.spec import ObjectSpec, TaskSpec


def default_pipeline_dir() -> Path:
    """``$HSP_PIPELINE_DIR``, else ``./pipeline`` if present, else the repository's own."""
    if env := os.environ.get("HSP_PIPELINE_DIR"):
        return Path(env)
    local = Path.cwd() / "pipeline"
    return local if (local / "tasks").is_dir() else Path(__file__).resolve().parents[2] / "pipeline"


@dataclass(frozen=True)
class Task:
    """A validated task with resolved model files; objects ordered as in its YAML."""

    spec: TaskSpec
    path: Path
    objects_dir: Path

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def objects(self) -> list[ObjectSpec]:
        return self.spec.objects

    @cached_property
    def names(self) -> list[str]:
        return [o.name for o in self.spec.objects]

    @cached_property
    def labels(self) -> list[str]:
        return [o.label for o in self.spec.objects]

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise HspError(f"{self.path}: no object named {name!r} (objects: {', '.join(self.names)})") from None

    def keypoint(self, name: str, point: str) -> np.ndarray:
        """Named point of an object in its own frame, ``(3,)``."""
        obj = self.objects[self.index(name)]
        if point not in obj.keypoints:
            raise HspError(f"{self.path}: object {name!r} has no keypoint {point!r} (has: {sorted(obj.keypoints)})")
        return np.asarray(obj.keypoints[point], dtype=float)

    def urdf(self, i: int) -> Path:
        return self.objects_dir / self.objects[i].model

    def mesh(self, i: int) -> Path:
        return self.objects_dir / self.objects[i].mesh


def list_tasks(pipeline_dir: Path | None = None) -> list[str]:
    tasks_dir = (pipeline_dir or default_pipeline_dir()) / "tasks"
    return sorted(p.stem for p in tasks_dir.glob("*.yaml"))


def _format_validation(path: Path, err: ValidationError) -> str:
    first = err.errors()[0]
    where = ".".join(str(p) for p in first["loc"]) or "(top level)"
    more = f" (and {err.error_count() - 1} more)" if err.error_count() > 1 else ""
    return f"{path}: {where}: {first['msg']}{more}"


def load_task(name: str, pipeline_dir: Path | None = None) -> Task:
    """Read and validate a task; raises :class:`HspError` naming the file and field."""
    pipeline_dir = pipeline_dir or default_pipeline_dir()
    path = pipeline_dir / "tasks" / f"{name}.yaml"
    if not path.is_file():
        known = list_tasks(pipeline_dir)
        raise HspError(f"unknown task {name!r}; valid tasks: {', '.join(known) or '(none found in ' + str(path.parent) + ')'}")
    try:
        raw = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise HspError(f"{path}: invalid YAML: {str(e).splitlines()[0]}") from None
    if not isinstance(raw, dict):
        raise HspError(f"{path}: expected a mapping at the top level, got {type(raw).__name__}")
    try:
        spec = TaskSpec.model_validate(raw)
    except ValidationError as e:
        raise HspError(_format_validation(path, e)) from None
    if spec.name != name:
        raise HspError(f"{path}: name: {spec.name!r} does not match the file name {name!r}")
    task = Task(spec=spec, path=path, objects_dir=pipeline_dir / "objects")
    for i, obj in enumerate(spec.objects):
        for f in (task.urdf(i), task.mesh(i)):
            if not f.is_file():
                raise HspError(f"{path}: objects.{i} ({obj.name}): model file {f} is missing")
    return task
