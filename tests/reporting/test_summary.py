import csv
import json

import pytest

from hsp.errors import HspError
from hsp.reporting.summary import Result, gather, table_i, write_curves, write_report

TASKS = ["painting", "stacking-1"]


def _write(path, data):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))


def _eval(rate, low, high, length=100.0, episodes=250):
    return {"episodes": episodes, "runs": 5, "success_rate": rate, "success_rate_ci95_low": low,
            "success_rate_ci95_high": high, "success_rate_std": 0.01, "episode_length_mean": length, "seconds": 60.0}


@pytest.fixture
def reports(tmp_path):
    _write(tmp_path / "stacking-1" / "record.json", {"episodes": 40})
    _write(tmp_path / "stacking-1" / "proposed" / "eval.json", _eval(0.968, 0.938, 0.984, 186.8))
    _write(tmp_path / "stacking-1" / "proposed" / "train.json", {"seconds": 174.0})
    _write(tmp_path / "stacking-1" / "oracle" / "eval.json", _eval(1.0, 0.963, 1.0, 229.3, 100))
    _write(tmp_path / "stacking-1" / "tracking.json", {"translation_error_mm_p95": 2.16, "lost_fraction": 0.0009})
    return tmp_path


def test_table_puts_the_papers_trials_beside_ours_and_says_what_was_not_run(reports):
    results = gather(reports, TASKS)
    assert {(r.task, r.method, r.demonstrations) for r in results} == {("stacking-1", "proposed", 40),
                                                                       ("stacking-1", "oracle", 0)}
    rows = {line.split(" | ")[0].strip("| "): line for line in table_i(results, TASKS).splitlines()}
    assert "| 5/5 | 0.968 [0.938, 0.984] |" in rows["proposed"]  # stacking-1: paper, then ours
    assert rows["proposed"].startswith("| proposed | 5/5 | not run |")  # painting: the paper's, none of ours
    assert rows["taco"].startswith("| taco | 1/5 | not run | 1/5 | not run |")
    assert "diffusion" in rows and "supervised" in rows  # every method has its row


def test_the_summary_holds_table_curves_tracking_and_configuration(reports):
    out = write_report(reports, TASKS, {"seed": 7, "record": {"episodes": {"stacking-1": 40}}})
    text = (reports / "summary.md").read_text()
    assert "0.968 [0.938, 0.984]" in text and "![stacking-1](plots/stacking-1.png)" in text
    assert "| stacking-1 | 0.0009 |" not in text and "2.16" in text  # tracking figures, columns in order
    assert "| painting | not run |" in text and "seed: 7" in text
    assert "| stacking-1 | — | — | — | 3 (1) | 2 (2) | 5 |" in text  # minutes: train 174 s, eval 2 × 60 s
    assert sorted(p.rsplit("/", 1)[1] for p in out["plots"]) == ["demonstrations.csv", "stacking-1.png"]
    assert (reports / "plots" / "stacking-1.png").read_bytes()[:4] == b"\x89PNG"


def test_curves_have_a_point_per_method_and_number_of_demonstrations(tmp_path):
    r = lambda n, rate: Result("painting", "proposed", n, 50, 1, rate, rate, rate, 0.0, 300.0, None, None)  # noqa: E731
    oracle = Result("painting", "oracle", 0, 50, 1, 1.0, 0.9, 1.0, 0.0, 200.0, None, None)
    write_curves([r(20, 0.5), r(5, 0.1), oracle], tmp_path / "plots")
    rows = list(csv.DictReader((tmp_path / "plots" / "demonstrations.csv").open()))
    assert [(row["method"], row["demonstrations"], row["success_rate"]) for row in rows] == [
        ("proposed", "5", "0.1"), ("proposed", "20", "0.5")]  # the oracle learns from none: not a point


def test_a_broken_report_names_its_file_and_nothing_is_written(reports):
    (reports / "summary.md").write_text("previous")
    _write(reports / "stacking-1" / "supervised" / "eval.json", {"episodes": 10})
    with pytest.raises(HspError, match=r"supervised/eval.json: missing success_rate"):
        write_report(reports, TASKS, {})
    (reports / "stacking-1" / "supervised" / "eval.json").unlink()
    (reports / "stacking-1" / "tracking.json").write_text("{")  # read only for the summary's text
    with pytest.raises(HspError, match=r"tracking.json: not valid JSON"):
        write_report(reports, TASKS, {})
    assert (reports / "summary.md").read_text() == "previous" and not (reports / "plots").exists()


def test_experiments_add_points_for_other_numbers_of_demonstrations(reports):
    """Rows as dvc.api.exp_show gives them: the workspace's own row is read from the files instead."""
    metric = "reports/stacking-1/proposed/eval.json:"
    row = lambda typ, n, rate: {"typ": typ, "record.episodes.stacking-1": n, metric + "success_rate": rate,  # noqa: E731
                                metric + "success_rate_ci95_low": rate / 2, metric + "success_rate_ci95_high": 1.0,
                                metric + "episodes": 50, metric + "episode_length_mean": 300.0}
    rows = [row("baseline", 40, 0.5), row("branch_commit", 5, 0.1), row("branch_commit", 40, 0.2), {"typ": "branch_base"}]
    write_report(reports, TASKS, {}, rows)
    points = [(r["demonstrations"], r["success_rate"]) for r in csv.DictReader((reports / "plots" / "demonstrations.csv").open())]
    assert points == [("5", "0.1"), ("40", "0.968")]  # 40 from the workspace's files, 5 from an experiment
    assert "stacking-1 5, stacking-1 40" in (reports / "summary.md").read_text()


@pytest.mark.parametrize("name, field, value", [("stacking-1/proposed/eval.json", "success_rate", "0.9"),
                                                ("stacking-1/proposed/train.json", "seconds", True),
                                                ("stacking-1/record.json", "episodes", "forty"),
                                                ("stacking-1/tracking.json", "lost_fraction", [0.1])])
def test_a_figure_that_is_not_a_number_names_its_file_and_field(reports, name, field, value):
    path = reports / name
    _write(path, json.loads(path.read_text()) | {field: value})
    with pytest.raises(HspError, match=rf"{name}: {field} is not a number"):
        write_report(reports, TASKS, {})
    assert not (reports / "summary.md").exists()
