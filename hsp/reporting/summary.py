"""`hsp report`: ``reports/summary.md`` and ``reports/plots/`` from the stages' own reports.

Nothing is recomputed and nothing is filled in: every figure is read from the JSON a stage
wrote (``reports/TASK/record.json``, ``tracking.json``, ``labels.json``,
``reports/TASK/METHOD/eval.json`` and ``train.json``), and a method or task without one is
shown as not run. The paper's Table I (real Kuka, 5 trials per cell) stands beside our
simulated success rates; Figure 4's curves (success and episode length against the number
of demonstrations) get one point per task and method and demonstration count found.
"""

from __future__ import annotations

import csv
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.methods import METHODS

log = logging.getLogger(__name__)

PAPER_TRIALS = 5
PAPER_TABLE_I = {
    "proposed": {"painting": 5, "stacking-1": 5, "stacking-2": 5},
    "bc": {"painting": 0, "stacking-1": 0, "stacking-2": 0},
    "gail": {"painting": 0, "stacking-1": 0, "stacking-2": 0},
    "taco": {"painting": 1, "stacking-1": 1, "stacking-2": 2},
}
"""Successes of ``PAPER_TRIALS`` trials on the real Kuka (paper, Table I; tire removal was
evaluated in simulation only), with 70 demonstrations for painting and 40 for the others."""

CURVE_FIELDS = ("task", "method", "demonstrations", "success_rate", "success_rate_ci95_low",
                "success_rate_ci95_high", "episode_length_mean", "episodes")


@dataclass(frozen=True)
class Result:
    """One method's closed-loop evaluation on one task (``--observer sim``)."""

    task: str
    method: str
    demonstrations: int
    """Recorded demonstrations the method learnt from (0 for the oracle, which learns nothing)."""
    episodes: int
    runs: int
    success_rate: float
    success_rate_ci95_low: float
    success_rate_ci95_high: float
    success_rate_std: float
    episode_length_mean: float
    train_seconds: float | None
    eval_seconds: float | None


def _read(path: Path) -> dict | None:
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise HspError(f"{path}: not valid JSON ({e.msg}, line {e.lineno})") from None


def _number(value: object, name: str, source: object, default: float | None = None) -> float | None:
    """``value`` as a float (``default`` where absent); a one-line error naming ``source``
    and the field where it is not a number."""
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise HspError(f"{source}: {name} is not a number ({value!r})")
    return float(value)


def _need(report: dict, keys: tuple[str, ...], path: Path) -> None:
    missing = [k for k in keys if k not in report]
    if missing:
        raise HspError(f"{path}: missing {', '.join(missing)}")


def gather(reports: Path, tasks: list[str]) -> list[Result]:
    """Every ``reports/TASK/METHOD/eval.json`` of ``tasks`` and known methods, as results."""
    out = []
    for task in tasks:
        path = reports / task / "record.json"
        recorded = _number((_read(path) or {}).get("episodes"), "episodes", path)
        for method in METHODS:
            path = reports / task / method / "eval.json"
            ev = _read(path)
            if ev is None:
                continue
            _need(ev, ("episodes", "success_rate", "success_rate_ci95_low", "success_rate_ci95_high",
                       "episode_length_mean"), path)
            train = reports / task / method / "train.json"
            train_seconds = _number((_read(train) or {}).get("seconds"), "seconds", train)
            out.append(_result(task, method, recorded, ev, train_seconds, str(path)))
    return out


def _result(task: str, method: str, recorded: object, ev: dict, train_seconds: object, source: str) -> Result:
    """A :class:`Result` from one ``eval.json``'s fields ``ev`` (NaN where one is missing) and
    the number of ``recorded`` demonstrations of its task; a one-line error naming ``source``
    where a figure is not a number."""
    get = lambda field, default=float("nan"): _number(ev.get(field), field, source, default)  # noqa: E731
    return Result(task, method, 0 if method == "oracle" else int(_number(recorded, "demonstrations", source, 0)),
                  int(get("episodes", 0)), int(get("runs", 1)), get("success_rate"), get("success_rate_ci95_low"),
                  get("success_rate_ci95_high"), get("success_rate_std"), get("episode_length_mean"),
                  _number(train_seconds, "train seconds", source), get("seconds", None))


def from_experiments(rows: list[dict], tasks: list[str]) -> list[Result]:
    """Results of DVC experiments (rows of :func:`dvc.api.exp_show`: flat ``params`` keys
    such as ``record.episodes.TASK`` and ``reports/TASK/METHOD/eval.json:field`` metrics),
    the workspace's own (``typ`` baseline) left out: they are read from the files."""
    out = []
    for row in rows:
        if row.get("typ") == "baseline":
            continue
        for task in tasks:
            record = row.get(f"record.episodes.{task}")
            for method in METHODS:
                key = f"reports/{task}/{method}/eval.json:"
                if row.get(key + "success_rate") is None:
                    continue
                ev = {k[len(key):]: v for k, v in row.items() if k.startswith(key)}
                out.append(_result(task, method, record, ev, row.get(f"reports/{task}/{method}/train.json:seconds"),
                                   f"DVC experiment {row.get('rev') or row.get('name')}: {key[:-1]}"))
    return out


def experiment_rows(repo: Path) -> list[dict]:
    """:func:`dvc.api.exp_show` of the DVC project at ``repo``: the experiments run from its
    current commit (what ``dvc exp run --queue`` made of this configuration); none outside a
    DVC project, or in one without Git (``dvc init --no-scm``: no experiments)."""
    if not (repo / ".dvc").is_dir():
        return []
    import dvc.api
    from dvc.scm import SCMError

    try:
        return dvc.api.exp_show(repo=str(repo))
    except SCMError as e:
        log.info("report: no DVC experiments (%s)", str(e).splitlines()[0])
        return []


def merged(workspace: list[Result], experiments: list[Result]) -> list[Result]:
    """The workspace's results, then each experiment's for a task, method and number of
    demonstrations the workspace has not evaluated (the first one found)."""
    seen = {(r.task, r.method, r.demonstrations) for r in workspace}
    out = list(workspace)
    for r in experiments:
        if (r.task, r.method, r.demonstrations) not in seen:
            seen.add((r.task, r.method, r.demonstrations))
            out.append(r)
    return out


def _cell(r: Result | None) -> str:
    if r is None:
        return "not run"
    return f"{r.success_rate:.3f} [{r.success_rate_ci95_low:.3f}, {r.success_rate_ci95_high:.3f}]"


def table_i(results: list[Result], tasks: list[str]) -> str:
    """Markdown: per method, the paper's real-robot successes and our simulated success rate
    (95 % Wilson interval) for each task."""
    by = {(r.task, r.method): r for r in results}
    head = "| method | " + " | ".join(f"{t}: paper | {t}: ours" for t in tasks) + " |"
    rows = [head, "|---|" + "---|---|" * len(tasks)]
    for m in METHODS:
        cells = []
        for t in tasks:
            paper = PAPER_TABLE_I.get(m, {}).get(t)
            cells += ["—" if paper is None else f"{paper}/{PAPER_TRIALS}", _cell(by.get((t, m)))]
        rows.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def details(results: list[Result]) -> str:
    """Markdown: what each figure rests on (demonstrations, episodes, runs) and what it cost."""
    rows = ["| task | method | demonstrations | episodes (runs) | success ± std across runs | episode length | "
            "train s | eval s |", "|---|---|---|---|---|---|---|---|"]
    fmt = lambda x: "—" if x is None else f"{x:.0f}"  # noqa: E731
    for r in results:
        rows.append(f"| {r.task} | {r.method} | {r.demonstrations} | {r.episodes} ({r.runs}) | "
                    f"{r.success_rate:.3f} ± {r.success_rate_std:.3f} | {r.episode_length_mean:.1f} | "
                    f"{fmt(r.train_seconds)} | {fmt(r.eval_seconds)} |")
    return "\n".join(rows)


STAGE_COLUMNS = {
    "tracking.json": ("translation_error_mm_median", "translation_error_mm_p95", "rotation_error_deg_median",
                      "lost_fraction", "ok_accurate", "inaccurate_flagged", "frames_per_second"),
    "labels.json": ("tool_accuracy", "target_accuracy", "boundary_error_frames_median", "waypoint_error_mm_median"),
}


def stage_table(reports: Path, tasks: list[str], name: str) -> str:
    """Markdown: the figures of one per-task stage report (``tracking.json``, ``labels.json``)."""
    keys = STAGE_COLUMNS[name]
    rows = ["| task | " + " | ".join(keys) + " |", "|---|" + "---|" * len(keys)]
    for t in tasks:
        path = reports / t / name
        rep = _read(path)
        if rep is None:
            rows.append(f"| {t} | " + " | ".join(["not run"] * len(keys)) + " |")
            continue
        vals = [_number(rep.get(k), k, path) for k in keys]
        rows.append(f"| {t} | " + " | ".join("—" if v is None else f"{v:.3g}" for v in vals) + " |")
    return "\n".join(rows)


def stage_minutes(reports: Path, tasks: list[str]) -> str:
    """Markdown: where the pipeline's time went, per task and stage (minutes, from each
    report's ``seconds``: as measured when the stage last ran); training and evaluation
    summed over the methods found."""
    rows = ["| task | record | parse | label | train (methods) | eval (methods) | total |", "|---|---|---|---|---|---|---|"]
    seconds = lambda path: _number((_read(path) or {}).get("seconds"), "seconds", path)  # noqa: E731
    for t in tasks:
        single = [seconds(reports / t / name) for name in ("record.json", "parse.json", "labels.json")]
        per_method = [[seconds(reports / t / m / name) for m in METHODS] for name in ("train.json", "eval.json")]
        cells = ["—" if x is None else f"{x / 60:.0f}" for x in single]
        for xs in per_method:
            found = [x for x in xs if x is not None]
            cells.append(f"{sum(found) / 60:.0f} ({len(found)})" if found else "—")
        total = sum(x for x in single if x is not None) + sum(x for xs in per_method for x in xs if x is not None)
        rows.append(f"| {t} | " + " | ".join(cells) + f" | {total / 60:.0f} |")
    return "\n".join(rows)


def write_curves(results: list[Result], plots: Path) -> list[Path]:
    """Figure 4's data in the new directory ``plots``: ``demonstrations.csv`` (one row per task, method and number of
    demonstrations; what ``dvc plots show`` draws) and, per task, a PNG of success rate
    (with its interval) and episode length against the number of demonstrations."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    learnt = [r for r in results if r.method != "oracle"]
    names = plot_names(results)
    plots.mkdir(parents=True)
    with (plots / "demonstrations.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, CURVE_FIELDS)
        w.writeheader()
        for r in sorted(learnt, key=lambda r: (r.task, r.method, r.demonstrations)):
            w.writerow({k: v for k, v in asdict(r).items() if k in CURVE_FIELDS})
    for name in names[1:]:
        task = name.removesuffix(".png")
        fig, (ax_s, ax_l) = plt.subplots(1, 2, figsize=(9, 3.5))
        for m in METHODS:
            rs = sorted((r for r in learnt if r.task == task and r.method == m), key=lambda r: r.demonstrations)
            if not rs:
                continue
            x = np.array([r.demonstrations for r in rs])
            y = np.array([r.success_rate for r in rs])
            err = np.array([[r.success_rate - r.success_rate_ci95_low, r.success_rate_ci95_high - r.success_rate]
                            for r in rs]).T
            ax_s.errorbar(x, y, yerr=err, marker="o", capsize=3, label=m)
            ax_l.plot(x, [r.episode_length_mean for r in rs], marker="o", label=m)
        most = max(1, *(r.demonstrations for r in learnt if r.task == task))
        ax_s.set(xlabel="demonstrations", ylabel="success rate", xlim=(0, 1.1 * most), ylim=(-0.05, 1.05), title=task)
        ax_l.set(xlabel="demonstrations", ylabel="episode length (steps)", xlim=(0, 1.1 * most), title=task)
        ax_l.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(plots / name, dpi=100)
        plt.close(fig)
    return [plots / n for n in names]


def plot_names(results: list[Result]) -> list[str]:
    """The files :func:`write_curves` writes for ``results``: the CSV, then a PNG per task a learnt method was
    evaluated on."""
    return ["demonstrations.csv"] + [f"{t}.png" for t in sorted({r.task for r in results if r.method != "oracle"})]


def summary_markdown(reports: Path, tasks: list[str], results: list[Result], curves: list[Result], params: dict,
                     plots: list[Path]) -> str:
    """The text of ``reports/summary.md``: Table I and its details from ``results`` (this
    workspace's), Figure 4 from ``curves`` (with the experiments')."""
    counts = sorted({(r.task, r.demonstrations) for r in curves if r.method != "oracle"})
    images = "\n".join(f"![{p.stem}](plots/{p.name})" for p in plots if p.suffix == ".png")
    return "\n\n".join([
        "# hsp: results",
        "Written by `hsp report` from the stages' reports under `reports/`; a cell reads *not run* where "
        "no stage has written one. Success is scored by the paper's criteria on the simulated Kuka with "
        "`--observer sim`, over held-out layouts.",
        "## Table I: success rate",
        f"Paper: successes out of {PAPER_TRIALS} trials on the real Kuka (tire removal was not run on the robot). "
        "Ours: success rate in simulation with its 95 % Wilson interval.",
        table_i(results, tasks),
        "What each figure rests on and what it cost on this machine:",
        details(results) if results else "No method has been evaluated.",
        "## Figure 4: success and episode length against the number of demonstrations",
        "Demonstration counts found (this workspace and its DVC experiments): "
        + (", ".join(f"{t} {n}" for t, n in counts) or "none") + ". "
        "The points are in `plots/demonstrations.csv` (`dvc plots show`).",
        images or "No learnt method has been evaluated.",
        "## Tracking (`hsp parse`, against the recordings' ground truth)",
        stage_table(reports, tasks, "tracking.json"),
        "## Pseudo-labels (`hsp label`, against the demonstrator's annotation: a diagnostic)",
        stage_table(reports, tasks, "labels.json"),
        "## Where the time went (minutes, each stage as it last ran)",
        stage_minutes(reports, tasks),
        "## Configuration",
        "```yaml\n" + _yaml(params) + "```",
    ]) + "\n"


def _yaml(params: dict) -> str:
    import yaml

    return yaml.safe_dump(params, sort_keys=False, default_flow_style=None, width=120)


def write_report(reports: Path, tasks: list[str], params: dict, experiments: list[dict] = ()) -> dict:
    """Write ``reports/summary.md`` and ``reports/plots/`` from the reports under ``reports``
    and the rows of DVC ``experiments`` (:func:`experiment_rows`); what was found, for the log."""
    current = gather(reports, tasks)
    results = merged(current, from_experiments(list(experiments), tasks))
    plots = [reports / "plots" / n for n in plot_names(results)]
    text = summary_markdown(reports, tasks, current, results, params, plots)  # every report read before any write
    with atomic_path(reports / "plots") as tmp:  # the whole directory, replaced at once
        write_curves(results, tmp)
    with atomic_path(reports / "summary.md") as tmp:
        tmp.write_text(text)
    log.info("report: %d evaluations of %d tasks read from %s, %d more from DVC experiments", len(current),
             len(tasks), reports, len(results) - len(current))
    return {"evaluations": len(current), "experiments": len(results) - len(current), "plots": [str(p) for p in plots]}

