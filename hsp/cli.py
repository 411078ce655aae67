"""The ``hsp`` command: one thin sub-command per pipeline stage.

Each command reads its defaults from ``params.yaml``, calls one library function, writes
its outputs atomically and a flat-key JSON report, and exits non-zero with a one-line
reason on bad input.
"""

from __future__ import annotations

import logging
import math
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.logging import RichHandler
from rich.table import Table

from hsp.config import load_params, param, section
from hsp.errors import HspError
from hsp.methods import BASELINES, METHODS

app = typer.Typer(add_completion=False, no_args_is_help=True, help=__doc__)
err = Console(stderr=True)
log = logging.getLogger("hsp")

PARAMS_OPTION = typer.Option(None, "--params", help="params file (default: ./params.yaml if present)")


@app.callback()
def _main(verbose: bool = typer.Option(False, "--verbose", "-v", help="debug logging")) -> None:
    """hsp's own log at INFO; the libraries' (LeRobot's codec choice for a dataset without
    video, ...) only from WARNING, unless --verbose."""
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.WARNING,
        format="%(message)s",
        handlers=[RichHandler(console=err, show_path=False)],
        force=True,
    )
    log.setLevel(logging.DEBUG if verbose else logging.INFO)


def _fail(e: Exception) -> None:
    err.print(f"[red]error:[/red] {e}", highlight=False, soft_wrap=True)
    raise typer.Exit(code=1)


@app.command()
def tasks(pipeline: Optional[Path] = typer.Option(None, help="pipeline directory (tasks/ and objects/)")) -> None:
    """List the tasks and their objects."""
    from hsp.tasks.registry import list_tasks, load_task

    try:
        table = Table("task", "objects (index 0 = end-effector)", "success")
        for name in list_tasks(pipeline):
            task = load_task(name, pipeline)
            objs = ", ".join(f"{o.name} ({o.label})" for o in task.objects)
            table.add_row(name, objs, task.spec.success.kind)
        Console().print(table)
    except HspError as e:
        _fail(e)


@app.command()
def record(
    task: str = typer.Argument(..., help="task name (see `hsp tasks`)"),
    episodes: Optional[int] = typer.Option(None, help="number of demonstrations [params: record.episodes.TASK]"),
    seed: Optional[int] = typer.Option(None, help="stage seed [params: seed]"),
    out: Optional[Path] = typer.Option(None, help="output directory [data/recordings/TASK]"),
    fps: Optional[int] = typer.Option(None, help="frame rate [params: record.fps]"),
    workers: Optional[int] = typer.Option(None, help="parallel processes [params: record.workers]"),
    camera: Optional[bool] = typer.Option(None, "--camera/--no-camera", help="render the RGB-D streams [params: record.camera]"),
    force: bool = typer.Option(False, "--force", help="replace an existing output directory"),
    reports: Path = typer.Option(Path("reports"), help="reports directory"),
    params_file: Optional[Path] = PARAMS_OPTION,
) -> None:
    """Run the scripted demonstrator on random layouts; one MCAP per episode."""
    from hsp.recording.record import RecordConfig, camera_rig
    from hsp.recording.record import record as record_episodes
    from hsp.tasks.registry import load_task

    try:
        params = load_params(params_file)
        use_camera = camera if camera is not None else bool(param(params, "record.camera", True))
        t = load_task(task)
        cfg = RecordConfig(
            episodes=episodes if episodes is not None else int(param(params, f"record.episodes.{task}", 40)),
            seed=seed if seed is not None else int(param(params, "seed", 0)),
            fps=fps if fps is not None else int(param(params, "record.fps", 15)),
            workers=workers if workers is not None else int(param(params, "record.workers", 2)),
            rig=camera_rig(params) if use_camera else None, scale=_scale(params),
        )
        out_dir = out or Path("data/recordings") / task
        log.info("record %s: read %s; %d episodes, seed %d, %d fps, camera %s", task, t.path, cfg.episodes, cfg.seed,
                 cfg.fps, "on" if cfg.rig else "off")
        report = record_episodes(t, cfg, out_dir, force=force)
        _write_report(reports / task / "record.json", report, out_dir)
        if report["demonstrator_success_rate"] < 1.0:
            log.warning("the demonstrator failed on %d of %d episodes", report["demonstrator_failures"], report["episodes"])
    except HspError as e:
        _fail(e)


def _write_report(path: Path, report: dict, output: Path) -> None:
    """The stage's flat-key JSON report, written atomically, and the closing log line."""
    from hsp.fileio import write_json

    write_json(path, report)
    log.info("wrote %s and %s in %.1f s", output, path, report["seconds"])


def _scale(params: dict):
    """Where the parallel map over episodes runs: ``params.yaml: parallel`` (local processes or Ray)."""
    from hsp.parallel import ScaleOut

    return section(params, "parallel", ScaleOut)


def _intrinsics(text: Optional[str]) -> Optional[tuple[float, float, float, float]]:
    if text is None:
        return None
    try:
        fx, fy, cx, cy = (float(v) for v in text.split(","))
    except ValueError:
        raise HspError(f"--intrinsics {text!r}: expected four numbers fx,fy,cx,cy (pixels)") from None
    return fx, fy, cx, cy


def _pose(text: Optional[str]) -> Optional[tuple[float, ...]]:
    if text is None:
        return None
    try:
        pose = tuple(float(v) for v in text.split(","))
    except ValueError:
        pose = ()
    if len(pose) != 7 or not all(math.isfinite(v) for v in pose) or abs(math.hypot(*pose[3:]) - 1) > 1e-3:
        raise HspError(f"--camera-pose {text!r}: expected seven numbers x,y,z,qx,qy,qz,qw (m; a unit quaternion)")
    return pose


@app.command()
def parse(
    task: str = typer.Argument(..., help="task name (see `hsp tasks`)"),
    recordings: Optional[Path] = typer.Option(None, help="recordings directory [data/recordings/TASK]"),
    out: Optional[Path] = typer.Option(None, help="dataset directory [data/datasets/TASK]"),
    poses_from: str = typer.Option("tracker", help="tracker | ground-truth (the ablation without perception error)"),
    workers: Optional[int] = typer.Option(None, help="episodes tracked in parallel processes [params: parse.workers]"),
    color_topic: Optional[str] = typer.Option(None, help="colour Image topic, if not the RealSense driver's"),
    depth_topic: Optional[str] = typer.Option(None, help="depth Image topic, registered to colour"),
    info_topic: Optional[str] = typer.Option(None, help="colour CameraInfo topic"),
    intrinsics: Optional[str] = typer.Option(None, help="fx,fy,cx,cy in pixels, instead of the recording's CameraInfo"),
    camera_pose: Optional[str] = typer.Option(None, help="x,y,z,qx,qy,qz,qw of the colour optical frame in the table "
                                              "frame (z = 0 on the table, z up) (default: from /tf_static, else fitted to the depth)"),
    skip_bad: bool = typer.Option(False, "--skip-bad",
                                  help="leave out recordings that fail the check (listed in parse.json)"),
    reports: Path = typer.Option(Path("reports"), help="reports directory"),
    params_file: Optional[Path] = PARAMS_OPTION,
) -> None:
    """Track every object in the recordings and write the 6D poses as a LeRobot v3.0 dataset.

    RECORDINGS may be one rosbag2 directory, .mcap file or ROS 1 .bag, or a folder of them;
    every one is read and checked before any is tracked."""
    from hsp.dataset.build import parse as parse_recordings
    from hsp.perception.table import TableConfig
    from hsp.perception.tracker import TrackerConfig
    from hsp.recording.reader import ReadOptions
    from hsp.tasks.registry import load_task

    try:
        params = load_params(params_file)
        t = load_task(task)
        rec_dir = recordings or Path("data/recordings") / task
        out_dir = out or Path("data/datasets") / task
        options = ReadOptions(color_topic, depth_topic, info_topic, _intrinsics(intrinsics), _pose(camera_pose))
        n_workers = workers if workers is not None else int(param(params, "parse.workers", 1))
        cfg = section(params, "tracker", TrackerConfig)
        table = section(params, "parse.table", TableConfig)
        log.info("parse %s: read %s (poses from %s, %d workers)", task, rec_dir, poses_from, n_workers)
        report, tracking = parse_recordings(t, rec_dir, out_dir, poses_from, n_workers, options, cfg,
                                            int(param(params, "seed", 0)), table, skip_bad, _scale(params))
        if tracking is not None:
            from hsp.fileio import write_json

            write_json(reports / task / "tracking.json", tracking)
            log.info("tracking: %s", ", ".join(f"{k} {v:.4g}" for k, v in tracking.items()
                                                 if not k.startswith("objects.") and isinstance(v, float)))
        _write_report(reports / task / "parse.json", report, out_dir)
    except HspError as e:
        _fail(e)


@app.command()
def label(
    task: str = typer.Argument(..., help="task name (see `hsp tasks`)"),
    dataset: Optional[Path] = typer.Option(None, help="pose dataset [data/datasets/TASK]"),
    out: Optional[Path] = typer.Option(None, help="labels parquet [data/labels/TASK.parquet; with --policy TASK_em.parquet]"),
    recordings: Optional[Path] = typer.Option(None, help="recordings, to score the labels against the demonstrator's annotation"),
    policy: Optional[Path] = typer.Option(None, help="trained policy directory: EM refinement for up to label.em_iterations "
                                          "rounds (report: labels_em.json)"),
    reports: Path = typer.Option(Path("reports"), help="reports directory"),
    params_file: Optional[Path] = PARAMS_OPTION,
) -> None:
    """Infer tool, target and way-point per frame with Viterbi over the paper's priors
    (with --policy, then EM rounds over the trained networks)."""
    from hsp.labeling.priors import PriorConfig
    from hsp.labeling.stage import label_dataset
    from hsp.tasks.registry import load_task

    try:
        params = load_params(params_file)
        cfg = section(params, "label", PriorConfig, ignore=("em_iterations",))
        t = load_task(task)
        ds = dataset or Path("data/datasets") / task
        out_file = out or Path("data/labels") / f"{task}{'_em' if policy else ''}.parquet"
        em = None
        if policy is not None:
            from hsp.policy.stage import PolicyRefinement
            from hsp.policy.train import TrainConfig, load

            em = PolicyRefinement(load(policy), policy, section(params, "train", TrainConfig),
                                  int(param(params, "label.em_iterations", 1)), int(param(params, "seed", 0)))
        log.info("label %s: read %s%s", task, ds, f" (EM over {policy})" if policy else "")
        report = label_dataset(t, ds, out_file, cfg, recordings, em)
        _write_report(reports / task / ("labels_em.json" if em else "labels.json"), report, out_file)
    except HspError as e:
        _fail(e)


def env_config(params: dict, task: str):
    """The task's environment as ``params.yaml`` sets it (``record.fps``, ``eval.*``): the
    one every method is scored in and GAIL trains in."""
    from hsp.evaluation.env import EnvConfig

    return EnvConfig(fps=int(param(params, "record.fps", 15)),
                     max_steps=int(param(params, f"eval.max_steps.{task}", 600)),
                     **{k: float(v) for k in ("grasp_reach_m", "max_speed_m_s", "max_turn_deg_s")
                        if (v := param(params, f"eval.{k}", None)) is not None})


@app.command()
def train(
    task: str = typer.Argument(..., help="task name (see `hsp tasks`)"),
    method: str = typer.Option("proposed", help="proposed (the hierarchy on pseudo-labels) | supervised (on the "
                               f"demonstrator's annotation: the upper bound) | a baseline: {' | '.join(BASELINES)}"),
    dataset: Optional[Path] = typer.Option(None, help="pose dataset [data/datasets/TASK]"),
    labels: Optional[Path] = typer.Option(None, help="pseudo-labels, for proposed [data/labels/TASK.parquet]"),
    recordings: Optional[Path] = typer.Option(None, help="recordings with the annotation, for supervised and taco's sketches "
                                              "[data/recordings/TASK]"),
    out: Optional[Path] = typer.Option(None, help="model directory [data/models/TASK/METHOD]"),
    iterations: Optional[int] = typer.Option(None, help="gradient steps, gail: environment steps [params: "
                                            "train.iterations, baselines.METHOD.iterations|timesteps]"),
    reports: Path = typer.Option(Path("reports"), help="reports directory"),
    params_file: Optional[Path] = PARAMS_OPTION,
) -> None:
    """Train π_h, π_m and π_l on the pose dataset and its pseudo-labels (or the annotation),
    or a baseline on the pose dataset."""
    import dataclasses

    from hsp.baselines import check_method, config_class, train_baseline
    from hsp.policy.stage import train_task
    from hsp.policy.train import TrainConfig
    from hsp.tasks.registry import load_task

    try:
        params = load_params(params_file)
        hierarchy = method in ("proposed", "supervised")
        if not hierarchy:
            check_method(method, ("proposed", "supervised"))
        cfg = section(params, "train", TrainConfig) if hierarchy else section(params, f"baselines.{method}",
                                                                               config_class(method))
        if iterations is not None:
            cfg = dataclasses.replace(cfg, **{"timesteps" if method == "gail" else "iterations": iterations})
        t = load_task(task)
        ds = dataset or Path("data/datasets") / task
        out_dir = out or Path("data/models") / task / method
        seed = int(param(params, "seed", 0))
        if hierarchy:
            source = ({"labels_file": labels or Path("data/labels") / f"{task}.parquet"} if method == "proposed"
                      else {"recordings_dir": recordings or Path("data/recordings") / task})
            report = train_task(t, ds, out_dir, cfg, seed, **source)
        else:
            report = train_baseline(t, method, ds, out_dir, cfg, seed, recordings or Path("data/recordings") / task,
                                    env_config(params, task))
        _write_report(reports / task / method / "train.json", report, out_dir)
    except HspError as e:
        _fail(e)


@app.command(name="eval")
def evaluate(
    task: str = typer.Argument(..., help="task name (see `hsp tasks`)"),
    method: str = typer.Option("proposed", help=" | ".join(METHODS) + " (oracle: the demonstrator's plan)"),
    observer: str = typer.Option("sim", help="sim (the simulator's poses) | camera (rendered RGB-D, tracked online)"),
    episodes: Optional[int] = typer.Option(None, help="episodes per run [params: eval.episodes]"),
    runs: Optional[int] = typer.Option(None, help="runs, each on its own held-out layouts [params: eval.runs]"),
    workers: Optional[int] = typer.Option(None, help="episodes in parallel processes [params: eval.workers]"),
    videos: Optional[int] = typer.Option(None, help="episodes of each run saved as MP4 [params: eval.videos]"),
    model: Optional[Path] = typer.Option(None, help="model directory [data/models/TASK/METHOD]"),
    out: Optional[Path] = typer.Option(None, help="report directory [reports/TASK/METHOD]"),
    params_file: Optional[Path] = PARAMS_OPTION,
) -> None:
    """Run a method closed loop on the simulated Kuka over held-out layouts and score it
    with the paper's success criteria (eval.json, episodes.jsonl, videos/)."""
    from hsp.evaluation.rollout import EvalConfig
    from hsp.perception.tracker import TrackerConfig
    from hsp.recording.record import camera_rig
    from hsp.evaluation.rollout import evaluate as run_evaluation
    from hsp.tasks.registry import load_task

    try:
        params = load_params(params_file)
        t = load_task(task)
        pick = lambda given, key, default: given if given is not None else param(params, key, default)  # noqa: E731
        cfg = EvalConfig(
            episodes=int(pick(episodes, "eval.episodes", 50)), runs=int(pick(runs, "eval.runs", 5)),
            seed=int(param(params, "seed", 0)), workers=int(pick(workers, "eval.workers", 2)),
            videos=int(pick(videos, "eval.videos", 1)),
            recorded_episodes=int(param(params, f"record.episodes.{task}", 0)),
            env=env_config(params, task),
            rig=camera_rig(params), tracker=section(params, "tracker", TrackerConfig), scale=_scale(params),
        )
        model_dir = None if method == "oracle" else (model or Path("data/models") / task / method)
        run_evaluation(t, method, observer, model_dir, cfg, out or Path("reports") / task / method)
    except HspError as e:
        _fail(e)


@app.command()
def report(
    reports: Path = typer.Option(Path("reports"), help="reports directory the stages wrote"),
    experiments: bool = typer.Option(True, help="add the DVC experiments' results to the curves"),
    params_file: Optional[Path] = PARAMS_OPTION,
) -> None:
    """Write reports/summary.md (the paper's Table I beside ours, tracking and labelling
    figures, the configuration) and reports/plots/ (Figure 4's points) from the stages' reports."""
    import time

    from hsp.reporting.summary import experiment_rows, write_report
    from hsp.tasks.registry import list_tasks

    try:
        t0 = time.perf_counter()
        rows = experiment_rows(Path.cwd()) if experiments else []
        out = write_report(reports, list_tasks(), load_params(params_file), rows)
        log.info("wrote %s and %d plots in %.1f s", reports / "summary.md", len(out["plots"]), time.perf_counter() - t0)
    except HspError as e:
        _fail(e)


@app.command()
def view(
    task: str = typer.Argument(..., help="task name (see `hsp tasks`)"),
    episode: int = typer.Option(0, help="episode index"),
    recordings: Optional[Path] = typer.Option(None, help="recordings directory [data/recordings/TASK]"),
    dataset: Optional[Path] = typer.Option(None, help="pose dataset [data/datasets/TASK]"),
    labels: Optional[Path] = typer.Option(None, help="labels parquet [data/labels/TASK.parquet], for the timeline"),
    out: Optional[Path] = typer.Option(None, help="output directory [reports/TASK/view]"),
    rrd_every: int = typer.Option(2, help="every n-th frame goes into the Rerun recording (0.7 MB per frame)"),
) -> None:
    """Overlay video, label timeline and Rerun recording (.rrd) of one episode."""
    from hsp.tasks.registry import load_task
    from hsp.view.episode import view_episode

    try:
        t = load_task(task)
        view_episode(t, episode, recordings or Path("data/recordings") / task, dataset or Path("data/datasets") / task,
                     labels or Path("data/labels") / f"{task}.parquet", out or Path("reports") / task / "view", rrd_every)
    except HspError as e:
        _fail(e)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
