"""``hsp train|eval --method bc|bc-rnn|taco|act|diffusion`` end to end on a tiny dataset, and the refusals."""

import json

import pytest
from typer.testing import CliRunner

from hsp.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Two stacking-1 demonstrations, their poses from the simulator."""
    tmp = tmp_path_factory.mktemp("bc")
    reports = str(tmp / "reports")
    assert runner.invoke(app, ["record", "stacking-1", "--episodes", "2", "--no-camera", "--workers", "1", "--out",
                               str(tmp / "rec"), "--reports", reports]).exit_code == 0
    assert runner.invoke(app, ["parse", "stacking-1", "--recordings", str(tmp / "rec"), "--out", str(tmp / "ds"),
                               "--poses-from", "ground-truth", "--reports", reports]).exit_code == 0
    return tmp / "ds"


TINY = {"bc": "hidden: 16", "bc-rnn": "hidden: 16", "taco": "hidden: 16",
        "act": "policy: {dim_model: 16, dim_feedforward: 16, n_heads: 2, latent_dim: 4, chunk_size: 4, n_action_steps: 4}",
        "diffusion": "policy: {down_dims: [8, 16], horizon: 4, n_action_steps: 2, num_train_timesteps: 10, num_inference_steps: 2}"}


@pytest.mark.parametrize("method", TINY)
def test_train_then_eval_closed_loop(dataset, tmp_path, method):
    params = tmp_path / "params.yaml"
    params.write_text(f"baselines:\n  {method}:\n    iterations: 20\n    {TINY[method]}\n    checkpoint_every: 10\n"
                      "eval:\n  max_steps:\n    stacking-1: 12\n")
    model, reports = tmp_path / "m", tmp_path / "reports"
    result = runner.invoke(app, ["train", "stacking-1", "--method", method, "--dataset", str(dataset), "--out", str(model),
                                 "--recordings", str(dataset.parent / "rec"), "--reports", str(reports), "--params", str(params)])
    assert result.exit_code == 0, result.output
    report = json.loads((reports / "stacking-1" / method / "train.json").read_text())
    assert report["method"] == method and report["config"]["iterations"] == 20 and report["episodes"] == 2
    saved = json.loads((model / ("hsp.json" if method in ("act", "diffusion") else "config.json")).read_text())["train"]
    assert saved == report["config"]
    out = tmp_path / "r"
    result = runner.invoke(app, ["eval", "stacking-1", "--method", method, "--model", str(model), "--episodes", "2",
                                 "--runs", "1", "--workers", "1", "--videos", "0", "--out", str(out), "--params", str(params)])
    assert result.exit_code == 0, result.output
    evaluated = json.loads((out / "eval.json").read_text())
    assert evaluated["episodes"] == 2 and evaluated["episode_length_mean"] == 12 and evaluated["success_rate"] == 0.0


def test_bad_input_is_one_line(dataset, tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("baselines:\n  bc:\n    iterations: 5\n    hidden: 8\n")
    model = tmp_path / "bc"
    assert runner.invoke(app, ["train", "stacking-1", "--method", "bc", "--dataset", str(dataset), "--out", str(model),
                               "--reports", str(tmp_path / "reports"), "--params", str(params)]).exit_code == 0
    (tmp_path / "bad.yaml").write_text("baselines:\n  bc:\n    iteratoins: 5\n")
    cases = [
        (["eval", "stacking-1", "--method", "gail", "--model", str(model)], "not a trained gail model"),
        (["train", "stacking-1", "--method", "taco", "--dataset", str(dataset), "--recordings", str(tmp_path)],
         "no recordings (.mcap or .bag files"),
        (["eval", "stacking-1", "--method", "taco", "--model", str(model)], "a bc model, not taco"),
        (["train", "stacking-1", "--method", "dagger", "--dataset", str(dataset)], "unknown method 'dagger'; valid methods: proposed, supervised, bc"),
        (["train", "stacking-1", "--method", "bc", "--dataset", str(tmp_path)], "not a LeRobot dataset"),
        (["train", "stacking-1", "--method", "bc", "--dataset", str(dataset), "--params", str(tmp_path / "bad.yaml")],
         "baselines.bc: unknown keys ['iteratoins']"),
        (["train", "stacking-2", "--method", "bc", "--dataset", str(dataset)], "are not those of task 'stacking-2'"),
        (["eval", "stacking-1", "--method", "bc-rnn", "--model", str(model)], "a bc model, not bc-rnn"),
        (["eval", "stacking-2", "--method", "bc", "--model", str(model)], "not those of task 'stacking-2'"),
        (["eval", "stacking-1", "--method", "bc", "--model", str(tmp_path / "none")], "model directory not found"),
        (["eval", "stacking-1", "--method", "bc", "--model", str(dataset)], "not a trained bc model"),
        (["eval", "stacking-1", "--method", "act", "--model", str(model)], "not a trained act model"),
    ]
    for args, message in cases:
        result = runner.invoke(app, [*args, "--out", str(tmp_path / "out")], terminal_width=300)
        assert result.exit_code == 1, (args, result.output)
        errors = [line for line in result.output.splitlines() if line.startswith("error:")]
        assert len(errors) == 1 and message in errors[0], (args, result.output)  # LeRobot may log its video codec
        assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists()
