"""Shared fixtures: the repository's task files, loaded once."""

from __future__ import annotations

from pathlib import Path

import pytest

from hsp.tasks.registry import Task, load_task

REPO = Path(__file__).resolve().parents[1]
PIPELINE = REPO / "pipeline"
TASKS = ["painting", "stacking-1", "stacking-2", "tire-removal"]


@pytest.fixture(scope="session")
def tasks() -> dict[str, Task]:
    return {name: load_task(name, PIPELINE) for name in TASKS}
