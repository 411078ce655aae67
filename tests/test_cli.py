"""The ``hsp`` command line, driven through Typer's CliRunner with tiny budgets."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hsp.cli import app
from tests.conftest import TASKS

runner = CliRunner()


def test_tasks_lists_the_four_tasks_and_their_objects():
    result = runner.invoke(app, ["tasks"], terminal_width=200)
    assert result.exit_code == 0, result.output
    for name in TASKS + ["brush", "bucket", "canvas", "block_yellow", "wrench", "bolt_4"]:
        assert name in result.output
    assert "hand (hand)" in result.output and "bolt_4 (bolt)" in result.output, result.output  # the labels


def test_every_command_has_help():
    """Help texts go through rich markup: a bracket that reads as a closing tag breaks --help."""
    for command in app.registered_commands:
        name = command.name or command.callback.__name__
        result = runner.invoke(app, [name, "--help"], terminal_width=200)
        assert result.exit_code == 0 and "Usage" in result.output, (name, result.output[-300:])


def test_record_writes_recordings_and_report(tmp_path):
    out, reports = tmp_path / "rec", tmp_path / "reports"
    args = ["record", "stacking-2", "--episodes", "2", "--seed", "4", "--out", str(out), "--reports", str(reports),
            "--workers", "1", "--no-camera"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    report = json.loads((reports / "stacking-2" / "record.json").read_text())
    assert report["episodes"] == 2 and report["demonstrator_success_rate"] == 1.0
    assert report["frames"] > 100 and report["frames_per_second"] > 0
    assert sorted(p.name for p in out.iterdir()) == ["episode_000000.mcap", "episode_000001.mcap"]
    again = runner.invoke(app, args)
    assert again.exit_code == 1 and "--force" in again.output


def test_unknown_task_is_a_one_line_error(tmp_path):
    result = runner.invoke(app, ["record", "juggling", "--out", str(tmp_path / "x")])
    assert result.exit_code == 1
    assert "unknown task 'juggling'" in result.output and "painting" in result.output
    assert not (tmp_path / "x").exists()


def test_parse_ground_truth_ablation(tmp_path, monkeypatch):
    """record → parse --poses-from ground-truth → a dataset and a report; the tracker, with no
    images to track, fails and writes nothing."""
    rec, ds, reports = tmp_path / "rec", tmp_path / "ds", tmp_path / "reports"
    assert runner.invoke(app, ["record", "painting", "--episodes", "1", "--out", str(rec), "--no-camera", "--workers", "1",
                               "--reports", str(reports)]).exit_code == 0
    result = runner.invoke(app, ["parse", "painting", "--recordings", str(rec), "--out", str(ds), "--poses-from", "ground-truth",
                                 "--reports", str(reports)])
    assert result.exit_code == 0, result.output
    assert json.loads((reports / "painting" / "parse.json").read_text())["episodes"] == 1
    assert (ds / "meta" / "info.json").is_file()
    tracked = runner.invoke(app, ["parse", "painting", "--recordings", str(rec), "--out", str(tmp_path / "ds2")])
    assert tracked.exit_code == 1 and "no colour image topic" in tracked.output
    assert not (tmp_path / "ds2").exists()

    labels = tmp_path / "labels.parquet"
    result = runner.invoke(app, ["label", "painting", "--dataset", str(ds), "--out", str(labels), "--recordings", str(rec),
                                 "--reports", str(reports)])
    assert result.exit_code == 0, result.output
    report = json.loads((reports / "painting" / "labels.json").read_text())
    assert {"tool_accuracy", "target_accuracy", "boundary_error_frames_median", "waypoint_error_mm_median", "seconds"} <= set(report)
    import pandas as pd

    df = pd.read_parquet(labels)
    assert len(df) == report["frames"] and (df["target"] != 0).all()
    wrong = runner.invoke(app, ["label", "stacking-1", "--dataset", str(ds), "--out", str(tmp_path / "x.parquet")])
    assert wrong.exit_code == 1 and "not those of task 'stacking-1'" in wrong.output

    # train on the labels, then EM over the trained networks (two rounds: the second retrains)
    params = tmp_path / "params.yaml"
    params.write_text("train: {iterations: 3, batch_steps: 64}\nlabel: {em_iterations: 2}\n")
    model = tmp_path / "model"
    result = runner.invoke(app, ["train", "painting", "--dataset", str(ds), "--labels", str(labels), "--out", str(model),
                                 "--reports", str(reports), "--params", str(params)])
    assert result.exit_code == 0, result.output
    trained = json.loads((reports / "painting" / "proposed" / "train.json").read_text())
    assert trained["iterations"] == 3 and trained["frames"] == report["frames"] and {"final_loss", "seconds"} <= set(trained)
    assert sorted(p.name for p in model.iterdir()) == ["config.json", "model.safetensors"]
    monkeypatch.chdir(tmp_path)  # EM labels go beside the priors' labels, never over them
    result = runner.invoke(app, ["label", "painting", "--dataset", str(ds), "--policy", str(model),
                                 "--reports", str(reports), "--params", str(params)])
    assert result.exit_code == 0, result.output
    em = json.loads((reports / "painting" / "labels_em.json").read_text())
    em_labels = tmp_path / "data" / "labels" / "painting_em.parquet"
    assert 1 <= em["em_rounds"] <= 2 and len(pd.read_parquet(em_labels)) == report["frames"]
    assert not (tmp_path / "data" / "labels" / "painting.parquet").exists()
    other = runner.invoke(app, ["label", "stacking-1", "--dataset", str(ds), "--policy", str(model), "--out", str(tmp_path / "y.parquet")])
    assert other.exit_code == 1 and "not those of task 'stacking-1'" in other.output
    short = runner.invoke(app, ["train", "painting", "--dataset", str(ds), "--labels", str(tmp_path / "none.parquet"),
                                "--out", str(tmp_path / "m2")])
    assert short.exit_code == 1 and "labels file not found" in short.output
    # the supervised upper bound: the same networks on the demonstrator's annotation
    result = runner.invoke(app, ["train", "painting", "--method", "supervised", "--dataset", str(ds), "--recordings", str(rec),
                                 "--out", str(tmp_path / "sup"), "--reports", str(reports), "--params", str(params)])
    assert result.exit_code == 0, result.output
    sup = json.loads((reports / "painting" / "supervised" / "train.json").read_text())
    assert sup["frames"] == trained["frames"] and sup["final_loss"] != trained["final_loss"]
    # on true poses the annotation's labels are the demonstrator's own, way-points where each segment ends
    from hsp.dataset.reader import episode_recordings, load_episodes
    from hsp.policy.stage import annotation_labels
    from hsp.recording.ground_truth import read_ground_truth
    from hsp.tasks.registry import load_task

    task = load_task("painting")
    poses = load_episodes(ds, "painting", task.names)[0]
    (lab,), gt = annotation_labels(task, episode_recordings(ds, rec), poses), read_ground_truth(next(rec.glob("*.mcap")))
    assert (lab.tool == gt.tool).all() and (lab.target == gt.target).all()
    ends = np.flatnonzero(np.diff(gt.waypoint_index))
    assert set(lab.waypoint_index) == set(ends) | {len(gt.tool) - 1}
    baseline = runner.invoke(app, ["train", "painting", "--method", "dagger", "--dataset", str(ds)])
    assert baseline.exit_code == 1 and "unknown method 'dagger'" in baseline.output


def test_report_writes_the_summary_from_the_reports_it_finds(tmp_path):
    (tmp_path / "stacking-1" / "bc").mkdir(parents=True)
    (tmp_path / "stacking-1" / "bc" / "eval.json").write_text(json.dumps(
        {"episodes": 4, "success_rate": 0.25, "success_rate_ci95_low": 0.05, "success_rate_ci95_high": 0.7,
         "episode_length_mean": 20.0}))
    assert runner.invoke(app, ["report", "--reports", str(tmp_path), "--no-experiments"]).exit_code == 0
    assert "0.250 [0.050, 0.700]" in (tmp_path / "summary.md").read_text()
    (tmp_path / "stacking-1" / "bc" / "eval.json").write_text("{")
    result = runner.invoke(app, ["report", "--reports", str(tmp_path), "--no-experiments"])
    assert result.exit_code == 1 and "eval.json: not valid JSON" in result.output


def test_camera_settings_come_from_the_params_file(tmp_path):
    """A tiny camera from --params: the recording holds 80x60 images."""
    from hsp.recording.reader import read_recording

    params = tmp_path / "params.yaml"
    params.write_text("seed: 1\nrecord: {fps: 5, camera: true}\ncamera: {width: 80, height: 60, fx: 77.0, fy: 77.0, cx: 40.0, cy: 30.0}\n")
    out = tmp_path / "rec"
    result = runner.invoke(app, ["record", "stacking-1", "--episodes", "1", "--out", str(out), "--params", str(params),
                                 "--reports", str(tmp_path / "reports"), "--workers", "1"])
    assert result.exit_code == 0, result.output
    rec = read_recording(out / "episode_000000.mcap")
    assert rec.rgb.shape[1:] == (60, 80, 3) and rec.K[0, 0] == 77.0


def test_unknown_camera_key_is_named(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("camera: {widht: 80}\n")
    result = runner.invoke(app, ["record", "stacking-1", "--out", str(tmp_path / "x"), "--params", str(params)])
    assert result.exit_code == 1 and "camera: unknown keys ['widht']" in result.output


def test_label_with_something_that_is_not_a_policy_is_a_clear_error(tmp_path):
    result = runner.invoke(app, ["label", "painting", "--dataset", str(tmp_path), "--policy", str(tmp_path / "model"),
                                 "--out", str(tmp_path / "l.parquet")])
    assert result.exit_code == 1 and "not a trained policy" in result.output and "hsp train" in result.output


def test_view_writes_video_timeline_and_rerun_recording(tmp_path):
    """record (tiny camera) → parse → label → view: the three files of one episode."""
    import cv2

    params = tmp_path / "params.yaml"
    params.write_text("seed: 2\nrecord: {fps: 5, camera: true}\ncamera: {width: 80, height: 60, fx: 77.0, fy: 77.0, cx: 40.0, cy: 30.0}\n")
    rec, ds, labels, reports = tmp_path / "rec", tmp_path / "ds", tmp_path / "l.parquet", str(tmp_path / "reports")
    assert runner.invoke(app, ["record", "stacking-1", "--episodes", "1", "--out", str(rec), "--params", str(params),
                               "--reports", reports, "--workers", "1"]).exit_code == 0
    assert runner.invoke(app, ["parse", "stacking-1", "--recordings", str(rec), "--out", str(ds), "--poses-from",
                               "ground-truth", "--reports", reports]).exit_code == 0
    assert runner.invoke(app, ["label", "stacking-1", "--dataset", str(ds), "--out", str(labels), "--reports", reports]).exit_code == 0
    out = tmp_path / "view"
    result = runner.invoke(app, ["view", "stacking-1", "--episode", "0", "--recordings", str(rec), "--dataset", str(ds),
                                 "--labels", str(labels), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["episode_000000.mp4", "episode_000000.rrd", "episode_000000_timeline.png"]
    video = cv2.VideoCapture(str(out / "episode_000000.mp4"))
    frames = int(video.get(cv2.CAP_PROP_FRAME_COUNT))
    import pandas as pd

    assert frames == len(pd.read_parquet(labels)) and video.get(cv2.CAP_PROP_FRAME_WIDTH) == 80
    missing = runner.invoke(app, ["view", "stacking-1", "--episode", "3", "--recordings", str(rec), "--dataset", str(ds)])
    assert missing.exit_code == 1 and "no episode 3" in missing.output
