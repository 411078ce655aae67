"""Worker processes for Open3D work (tracking): one thread each, on a core of its own.

Kept free of heavy imports: a spawned worker runs :func:`pin_to_one_core` before it
unpickles its first task, and so before Open3D starts its thread pool.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


def pin_to_one_core(counter: Any) -> None:
    """Pool initializer: the n-th worker runs on the n-th allowed core only. Open3D's ICP
    reduces with TBB, which ignores ``OMP_NUM_THREADS``; on one core it uses one thread and
    gives the same bits every run (measured: 7 of 16 matrix entries differ between runs
    otherwise)."""
    cores = sorted(os.sched_getaffinity(0))
    with counter.get_lock():
        n = counter.value
        counter.value += 1
    os.sched_setaffinity(0, {cores[n % len(cores)]})


@contextmanager
def one_omp_thread() -> Iterator[None]:
    """``OMP_NUM_THREADS=1`` while the pool lives: workers are spawned on demand and read it
    before they import Open3D (two OpenMP threads per worker on two cores spin and slow down)."""
    saved = os.environ.get("OMP_NUM_THREADS")
    os.environ["OMP_NUM_THREADS"] = "1"
    try:
        yield
    finally:
        if saved is None:
            del os.environ["OMP_NUM_THREADS"]
        else:
            os.environ["OMP_NUM_THREADS"] = saved


class _Collect(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def captured_warnings() -> Iterator[list[str]]:
    """Warnings of hsp's loggers collected into a list instead of printed: a worker process
    hands them back with its result, and the main process logs them once, with their level
    (a spawned worker's own logging prints them bare)."""
    logger = logging.getLogger("hsp")
    handler, propagate = _Collect(), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield handler.messages
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate
