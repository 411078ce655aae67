"""The whole DVC pipeline, every stage through the real code, on a tiny configuration:
a broken hand-over between stages (a path, a report key, a params name) fails here."""

import csv
import json
import os
import re
import shutil
import subprocess
import sys

import yaml

from tests.conftest import REPO

TASK = "stacking-1"
TINY = {
    "record": {"episodes": {TASK: 2}},
    "train": {"iterations": 2, "checkpoint_every": 1, "pi_m_restarts": 1},
    "eval": {"episodes": 2, "runs": 1, "oracle": {"episodes": 2, "runs": 1}, "max_steps": {TASK: 20}},
    "baselines": {
        **{m: {"iterations": 2, "checkpoint_every": 1} for m in ("bc", "bc-rnn", "taco")},
        "act": {"iterations": 2, "batch_size": 4, "checkpoint_every": 1},
        "diffusion": {"iterations": 2, "batch_size": 4, "checkpoint_every": 1},
        "gail": {"timesteps": 32, "envs": 1, "n_steps": 32, "batch_size": 32, "epochs": 1, "disc_updates": 1,
                 "disc_batch": 32},
    },
}


def _merge(base: dict, tiny: dict) -> dict:
    out = dict(base)
    for k, v in tiny.items():
        out[k] = _merge(base.get(k, {}), v) if isinstance(v, dict) and k != "episodes" else v
    return out


def _run(repo, *args, program=(sys.executable, "-m", "dvc")):
    env = {**os.environ, "PATH": f"{os.path.dirname(sys.executable)}:{os.environ['PATH']}", "HF_HUB_OFFLINE": "1"}
    result = subprocess.run([*program, *args], cwd=repo, env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result.stdout


def _git(repo, *args):
    return _run(repo, "-c", "user.name=hsp", "-c", "user.email=hsp@example.org", *args, program=("git",))


def _ran(output: str) -> set[str]:
    return set(re.findall(r"Running stage '([^']+)'", output))


def test_every_stage_runs_end_to_end_a_second_repro_does_nothing_and_a_remote_restores_it(tmp_path):
    """One task (the others' entries taken out of the stage lists), two short recordings, a
    few iterations and evaluation steps: record → parse → label → train (the hierarchy and
    every baseline) → eval → report, through `dvc repro` as a user runs it; then `dvc push`
    to a local remote and `dvc pull` into an emptied cache bring every artifact back."""
    repo = tmp_path / "repo"
    shutil.copytree(REPO / "hsp", repo / "hsp", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "pipeline", repo / "pipeline")
    shutil.copy(REPO / ".gitignore", repo / ".gitignore")
    others = [t for t in ("painting", "stacking-1", "stacking-2", "tire-removal") if t != TASK]
    stages = (REPO / "dvc.yaml").read_text().replace("[painting, stacking-1, stacking-2, tire-removal]", f"[{TASK}]")
    stages = "\n".join(line for line in stages.splitlines() if line.strip() not in {f"- reports/{t}" for t in others})
    (repo / "dvc.yaml").write_text(stages + "\n")
    params = yaml.safe_load((REPO / "params.yaml").read_text())
    (repo / "params.yaml").write_text(yaml.safe_dump(_merge(params, TINY), sort_keys=False))
    _git(repo, "init", "-q")
    _run(repo, "init", "-q")
    shutil.copytree(REPO / ".dvc" / "plots", repo / ".dvc" / "plots")

    _run(repo, "repro")
    summary = (repo / "reports" / "summary.md").read_text()
    methods = ("oracle", "proposed", "supervised", "bc", "bc-rnn", "taco", "gail", "act", "diffusion")
    for m in methods:
        report = yaml.safe_load((repo / "reports" / TASK / m / "eval.json").read_text())
        assert report["episodes"] == 2 and 0.0 <= report["success_rate"] <= 1.0, m
        assert f"| {TASK} | {m} | {0 if m == 'oracle' else 2} | 2 (1) |" in summary, m
    assert (repo / "reports" / "plots" / f"{TASK}.png").is_file()
    plots = json.loads(_run(repo, "plots", "show", "--json"))["data"]
    assert set(plots) == {"success", "episode_length"}  # Figure 4, one line per method
    assert {v["method"] for v in plots["success"][0]["content"]["data"]["values"]} == set(methods) - {"oracle"}
    assert "up to date" in _run(repo, "status")
    assert "Stage 'record@stacking-1' didn't change, skipping" in _run(repo, "repro")
    tiny = yaml.safe_load((repo / "params.yaml").read_text())
    tiny["baselines"]["bc"]["learning_rate"] *= 2
    (repo / "params.yaml").write_text(yaml.safe_dump(tiny, sort_keys=False))
    assert _ran(_run(repo, "repro")) == {f"train-baseline@{TASK}-bc", f"eval-baseline@{TASK}-bc", "report"}

    _run(repo, "remote", "add", "-d", "local", str(tmp_path / "remote"))
    _run(repo, "push")
    shutil.rmtree(repo / "data")
    shutil.rmtree(repo / ".dvc" / "cache")
    for videos in (repo / "reports").glob("*/*/videos"):
        shutil.rmtree(videos)
    _run(repo, "pull")
    assert (repo / "data" / "models" / TASK / "proposed").is_dir() and "up to date" in _run(repo, "status")

    # A point of the demonstration sweep: a DVC experiment with 3 recordings, gathered by `hsp report`.
    _git(repo, "add", "-A")
    _git(repo, "commit", "-qm", "tiny pipeline")
    _run(repo, "exp", "run", "--temp", "-S", f"record.episodes.{TASK}=3")
    _run(repo, "report", program=(os.path.join(os.path.dirname(sys.executable), "hsp"),))
    points = {(r["method"], r["demonstrations"]) for r in csv.DictReader((repo / "reports" / "plots" /
                                                                          "demonstrations.csv").open())}
    assert points == {(m, n) for m in methods if m != "oracle" for n in ("2", "3")}
