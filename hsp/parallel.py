"""The parallel map over episodes (record, parse, eval): local processes or a Ray cluster.

:func:`worker_pool` gives every stage the same face, an ordered ``map(fn, items)``, over
``concurrent.futures`` processes on this machine or Ray's ``multiprocessing.Pool`` (local,
or a cluster at ``parallel.address``). Pinned pools (Open3D's tracking) run one thread per
worker on a core of its own. Kept free of heavy imports: a spawned worker runs
:func:`pin_to_one_core` before it unpickles its first task, and so before Open3D starts
its thread pool. A local worker ends with the process that started it
(:func:`end_with_parent`), so a stage killed mid-run leaves no worker behind.
"""

from __future__ import annotations

import ctypes
import logging
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from typing import Any

from hsp.errors import HspError

BACKENDS = ("processes", "ray")


@dataclass(frozen=True)
class ScaleOut:
    """Where the parallel map over episodes runs (``params.yaml: parallel``); the results do
    not depend on it."""

    backend: str = "processes"
    """``processes`` on this machine, or ``ray``: Ray's multiprocessing pool."""
    address: str | None = None
    """Ray cluster to join (``auto``: the one this machine belongs to, ``ray://head:10001``);
    none: Ray starts on this machine. Every node needs hsp installed and the data directories
    at the same paths (a shared file system)."""

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise HspError(f"parallel.backend = {self.backend!r}: choose one of {', '.join(BACKENDS)}")


PR_SET_PDEATHSIG = 1
"""Linux's ``prctl`` option: the signal a process gets when the thread that started it ends."""


def end_with_parent(parent: int) -> None:
    """Pool initializer: Linux sends this worker SIGTERM when its parent ``parent`` (pid) ends,
    however it ends (a stage killed with SIGTERM left its worker tracking for another 57 min).
    The signal follows the thread that started the worker, so ``map`` is called from one that
    outlives the pool (hsp's stages call it from their main thread). Elsewhere than Linux, nothing."""
    if sys.platform != "linux":
        return
    ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != parent:  # the parent ended before the request was made
        os._exit(1)


def _start_worker(parent: int, counter: Any | None) -> None:
    """Pool initializer of local workers: :func:`end_with_parent`, then, in a pinned pool,
    :func:`pin_to_one_core`."""
    end_with_parent(parent)
    if counter is not None:
        pin_to_one_core(counter)


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


def pin_to_a_core() -> None:
    """Ray pool initializer: one core of those allowed, by process id (Ray's workers share
    no counter), so that Open3D runs one thread."""
    cores = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cores[os.getpid() % len(cores)]})


class _RayMap:
    def __init__(self, pool: Any) -> None:
        self.pool = pool

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterator[Any]:
        return self.pool.imap(fn, list(items))


@contextmanager
def worker_pool(workers: int, scale: ScaleOut = ScaleOut(), pinned: bool = False) -> Iterator[Any]:
    """A pool whose ``map(fn, items)`` yields ``fn(item)`` in order as workers finish them:
    ``workers`` spawned processes here, or Ray workers (``scale``). ``pinned``: each worker
    on one core with one OpenMP thread (Open3D's reductions then give the same bits every run)."""
    if scale.backend == "ray":
        with _ray_pool(workers, scale, pinned) as pool:
            yield pool
        return
    with one_omp_thread() if pinned else nullcontext():
        # a fork would inherit Open3D's threads; on Linux a fork server would be the workers' parent
        ctx = multiprocessing.get_context("spawn" if pinned or sys.platform != "linux" else "fork")
        counter = ctx.Value("i", 0) if pinned else None
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_start_worker,
                                   initargs=(os.getpid(), counter))
        try:
            yield pool
        finally:
            pool.shutdown(cancel_futures=True)


@contextmanager
def _ray_pool(workers: int, scale: ScaleOut, pinned: bool) -> Iterator[_RayMap]:
    import ray
    from ray.util.multiprocessing import Pool

    started = not ray.is_initialized()
    if started:
        env = {"env_vars": {"OMP_NUM_THREADS": "1"}} if pinned else None
        # a Ray started here runs its workers at the driver's priority (Ray's default, nice 15, let
        # anything else on the machine starve them: 8x slower beside one busy process)
        system = {"worker_niceness": 0} if scale.address is None else None
        try:  # "local": a new Ray here, even where RAY_ADDRESS or a running cluster would be joined
            ray.init(address=scale.address or "local", runtime_env=env, include_dashboard=False, log_to_driver=False,
                     logging_level=logging.WARNING, _system_config=system)
        except (ConnectionError, ValueError, RuntimeError) as e:
            raise HspError(f"params.yaml: parallel.address = {scale.address!r}: Ray could not start or connect "
                           f"({str(e).splitlines()[0]})") from None
    pool = Pool(processes=workers, initializer=pin_to_a_core if pinned else None)
    try:
        yield _RayMap(pool)
    finally:
        pool.terminate()
        if started:
            ray.shutdown()


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
