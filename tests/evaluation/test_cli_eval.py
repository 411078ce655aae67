"""``hsp eval`` end to end through the CLI, and its refusals of bad input."""

import json

from typer.testing import CliRunner

from hsp.cli import app
from hsp.policy.train import TrainConfig, save
from tests.evaluation.test_proposed import untrained_policy

runner = CliRunner()


def test_oracle_eval_writes_report_episodes_and_videos(tmp_path):
    out = tmp_path / "r"
    result = runner.invoke(app, ["eval", "stacking-1", "--method", "oracle", "--episodes", "2", "--runs", "1",
                                 "--workers", "1", "--videos", "1", "--out", str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads((out / "eval.json").read_text())
    assert report["episodes"] == 2 and report["success_rate"] == 1.0
    assert 0 < report["success_rate_ci95_low"] < 1.0 == report["success_rate_ci95_high"]
    assert report["subgoal.placed.block_red"] == 1.0 and report["episode_length_mean"] > 50
    lines = [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines()]
    assert [x["episode"] for x in lines] == [0, 1] and all(x["ended"] == "success" for x in lines)
    assert [p.name for p in (out / "videos").iterdir()] == ["run0_episode000.mp4"]


def test_a_trained_policy_runs_closed_loop(tmp_path, tasks):
    """Random networks (nothing learnt) run to the step limit and fail, with a report."""
    save(untrained_policy(tasks["painting"]), TrainConfig(iterations=1), tmp_path / "m")
    params = tmp_path / "params.yaml"
    params.write_text("eval:\n  max_steps:\n    painting: 15\n")
    out = tmp_path / "r"
    result = runner.invoke(app, ["eval", "painting", "--method", "proposed", "--model", str(tmp_path / "m"),
                                 "--episodes", "2", "--runs", "2", "--workers", "2", "--videos", "0", "--out", str(out),
                                 "--params", str(params)])
    assert result.exit_code == 0, result.output
    report = json.loads((out / "eval.json").read_text())
    assert report["success_rate"] == 0.0 and report["episode_length_mean"] == 15 and report["runs"] == 2


def test_bad_input_is_one_line_and_writes_nothing(tmp_path, tasks):
    save(untrained_policy(tasks["painting"]), TrainConfig(iterations=1), tmp_path / "painting")
    out = tmp_path / "r"
    cases = [
        (["eval", "stacking-1", "--method", "dagger"], "unknown method 'dagger'"),
        (["eval", "stacking-1", "--method", "oracle", "--observer", "eyes"], "unknown observer 'eyes'"),
        (["eval", "stacking-1", "--model", str(tmp_path / "none")], "model directory not found"),
        (["eval", "stacking-1", "--model", str(tmp_path / "painting")], "not those of task 'stacking-1'"),
        (["eval", "no-such-task", "--method", "oracle"], "unknown task 'no-such-task'"),
    ]
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "config.json").write_text("{}")
    (tmp_path / "old" / "model.safetensors").write_bytes(b"")
    cases.append((["eval", "stacking-1", "--model", str(tmp_path / "old")], "not a trained policy"))
    for args, message in cases:
        result = runner.invoke(app, [*args, "--out", str(out), "--episodes", "1", "--runs", "1"], terminal_width=300)
        assert result.exit_code == 1, (args, result.output)
        assert message in result.output, (args, result.output)
        assert len(result.output.strip().splitlines()) == 1, result.output
    assert not out.exists()
