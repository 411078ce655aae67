"""The parallel map over episodes: the same face and the same results on local processes and on Ray."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hsp.cli import app
from hsp.errors import HspError
from hsp.parallel import ScaleOut, worker_pool

runner = CliRunner()


def _where(x: int) -> tuple[int, int, int, str | None]:
    return x, os.getpid(), len(os.sched_getaffinity(0)), os.environ.get("OMP_NUM_THREADS")


@pytest.mark.parametrize("backend", ["processes", "ray"])
def test_a_pinned_pool_maps_in_order_on_one_core_and_one_thread_per_worker(backend):
    with worker_pool(2, ScaleOut(backend), pinned=True) as pool:
        out = list(pool.map(_where, range(5)))
    assert [x for x, *_ in out] == list(range(5))
    assert all(pid != os.getpid() and cores == 1 and omp == "1" for _, pid, cores, omp in out)


def test_eval_on_ray_plays_the_episodes_of_local_processes(tmp_path):
    """A local Ray (what `parallel.address` would point at a cluster) runs the same held-out layouts."""
    lines = {}
    for backend in ("processes", "ray"):
        params = tmp_path / f"{backend}.yaml"
        params.write_text(f"parallel:\n  backend: {backend}\n")
        out = tmp_path / backend
        result = runner.invoke(app, ["eval", "stacking-1", "--method", "oracle", "--episodes", "3", "--runs", "1",
                                     "--workers", "2", "--videos", "0", "--out", str(out), "--params", str(params)])
        assert result.exit_code == 0, result.output
        lines[backend] = [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines()]
    assert lines["ray"] == lines["processes"] and len(lines["ray"]) == 3


def test_an_unknown_backend_is_refused():
    with pytest.raises(HspError, match="parallel.backend = 'dask': choose one of processes, ray"):
        ScaleOut("dask")


PARENT = """
import os, sys, time
from hsp.parallel import worker_pool

def busy(x):
    print(os.getpid(), flush=True)
    time.sleep(120)

if __name__ == "__main__":
    with worker_pool(1, pinned=sys.argv[1] == "pinned") as pool:
        list(pool.map(busy, [0]))
"""


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (ended, not yet reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(sys.platform != "linux", reason="a parent's death signal is Linux's")
@pytest.mark.parametrize("pinned", [False, True])
def test_a_worker_ends_when_its_stage_is_killed(tmp_path, pinned):
    """A stage killed mid-episode (SIGKILL: no clean-up of its own) leaves no worker running."""
    script = tmp_path / "stage.py"
    script.write_text(PARENT)
    stage = subprocess.Popen([sys.executable, str(script), "pinned" if pinned else "plain"], stdout=subprocess.PIPE,
                             text=True, env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])})
    worker = int(stage.stdout.readline())
    stage.kill()
    stage.wait()
    for _ in range(100):
        if not _running(worker):
            break
        time.sleep(0.1)
    else:
        os.kill(worker, signal.SIGKILL)
        pytest.fail(f"worker {worker} still runs after its stage was killed")
