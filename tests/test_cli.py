"""The ``hsp`` command line, driven through Typer's CliRunner with tiny budgets."""

import json

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


def test_record_writes_recordings_and_report(tmp_path):
    out, reports = tmp_path / "rec", tmp_path / "reports"
    args = ["record", "stacking-2", "--episodes", "2", "--seed", "4", "--out", str(out), "--reports", str(reports), "--workers", "1"]
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


@pytest.mark.parametrize("stage", ["parse", "label", "train", "eval", "view"])
def test_unfinished_stages_say_so(stage):
    result = runner.invoke(app, [stage, "painting"])
    assert result.exit_code == 1
    assert "not available yet" in result.output


def test_camera_recording_is_not_faked(tmp_path):
    result = runner.invoke(app, ["record", "painting", "--camera", "--out", str(tmp_path / "x")])
    assert result.exit_code == 1 and "not available yet" in result.output
