"""``hsp parse`` on bad input: every recording is checked before any is tracked; a bad one is
one line naming the file and leaves nothing behind, or with --skip-bad is left out and listed."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from hsp.cli import app
from hsp.dataset.build import RecordingCheck, dataset_rate
from hsp.dataset.reader import episode_recordings, episode_sources, load_episodes
from hsp.errors import HspError
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from tests.recording.fixtures import write_bag

runner = CliRunner()
RIG = CameraRig(CameraConfig().scaled(160, 120), DepthNoiseConfig())


@pytest.fixture(scope="module")
def good(tasks, tmp_path_factory):
    """Two small stacking-1 recordings at 5 fps, and one at 10 fps."""
    root = tmp_path_factory.mktemp("inputs")
    record(tasks["stacking-1"], RecordConfig(episodes=2, seed=3, fps=5, workers=1, rig=RIG), root / "five")
    record(tasks["stacking-1"], RecordConfig(episodes=1, seed=4, fps=10, workers=1, rig=RIG), root / "ten")
    return root


def folder(good, tmp_path, bad_name=None, bad_bytes=None):
    d = tmp_path / "recordings"
    shutil.copytree(good / "five", d)
    if bad_name:
        (d / bad_name).write_bytes(bad_bytes)
    return d


def parse(recordings, tmp_path, *extra):
    return runner.invoke(app, ["parse", "stacking-1", "--recordings", str(recordings), "--out", str(tmp_path / "ds"),
                               "--reports", str(tmp_path / "reports"), "--workers", "1", *extra], terminal_width=400)


def assert_failed_cleanly(result, tmp_path, message):
    assert result.exit_code == 1, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], result.output
    assert "Traceback" not in result.output
    assert isinstance(result.exception, SystemExit), result.exception  # hsp's own error, not an escaped exception
    assert not (tmp_path / "ds").exists() and not list(tmp_path.glob(".ds*"))  # no dataset, no hidden partial one


def damaged(good, how):
    data = bytearray((good / "five" / "episode_000001.mcap").read_bytes())
    if how == "flip":
        data[len(data) // 2] ^= 0xFF
        return bytes(data)
    return bytes(data[: len(data) * 6 // 10])


@pytest.mark.parametrize(("name", "content", "message"), [
    ("picture.mcap", b"\x89PNG\r\n\x1a\n" + b"\x00" * 64, "picture.mcap: not MCAP but a PNG image"),
    ("empty.mcap", b"", "empty.mcap: empty file"),
])
def test_a_bad_file_among_good_ones(good, tmp_path, name, content, message):
    d = folder(good, tmp_path, name, content)
    assert_failed_cleanly(parse(d, tmp_path), tmp_path, message)
    result = parse(d, tmp_path, "--skip-bad")
    assert result.exit_code == 0, result.output
    report = json.loads((tmp_path / "reports" / "stacking-1" / "parse.json").read_text())
    assert report["episodes"] == 2 and len(report["skipped"]) == 1 and message in report["skipped"][0]


def test_skipped_recordings_do_not_shift_the_episodes(good, tmp_path):
    """Episodes name the recording they came from: label (and train, view) find each
    episode's own recording when --skip-bad left one out before it."""
    d = folder(good, tmp_path, "episode_000000a.mcap", b"")
    result = parse(d, tmp_path, "--skip-bad")
    assert result.exit_code == 0, result.output
    assert "WARNING" in result.output and "codec" not in result.output  # no video, no LeRobot codec line
    sources = episode_sources(tmp_path / "ds")
    assert [s["source"] for s in sources] == ["episode_000000.mcap", "episode_000001.mcap"]
    assert all(s["table_frame"] == "tf_static world" and len(s["T_world_cam"]) == 7 for s in sources)
    assert sources[0]["fps"] == pytest.approx(5.0) and sources[0]["intrinsics"] == list(RIG.camera.K[[0, 1, 0, 1], [0, 1, 2, 2]])
    assert episode_recordings(tmp_path / "ds", d) == [d / "episode_000000.mcap", d / "episode_000001.mcap"]
    result = runner.invoke(app, ["label", "stacking-1", "--dataset", str(tmp_path / "ds"), "--recordings", str(d),
                                 "--out", str(tmp_path / "labels.parquet"), "--reports", str(tmp_path / "reports")])
    assert result.exit_code == 0, result.output
    assert "tool_accuracy" in json.loads((tmp_path / "reports" / "stacking-1" / "labels.json").read_text())  # scored
    result = runner.invoke(app, ["view", "stacking-1", "--episode", "1", "--recordings", str(d), "--dataset",
                                 str(tmp_path / "ds"), "--labels", str(tmp_path / "labels.parquet"), "--out", str(tmp_path / "view")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "view" / "episode_000001.mp4").is_file()
    (d / "episode_000001.mcap").unlink()
    with pytest.raises(HspError, match="no recording 'episode_000001.mcap', which episode 1 of"):
        episode_recordings(tmp_path / "ds", d)
    lines = (tmp_path / "ds" / "meta" / "hsp_episodes.jsonl").read_text().splitlines()
    (tmp_path / "ds" / "meta" / "hsp_episodes.jsonl").write_text(lines[0] + "\n")  # one episode's source lost
    with pytest.raises(HspError, match="1 episode sources for the dataset's 2 episodes"):
        episode_sources(tmp_path / "ds")


def test_a_bag_cut_short_among_good_recordings(good, tmp_path):
    d = folder(good, tmp_path)
    (d / "bag_c").mkdir()
    shutil.copy(good / "five" / "episode_000000.mcap", d / "bag_c" / "bag_c_0.mcap")  # metadata.yaml never written
    assert_failed_cleanly(parse(d, tmp_path), tmp_path, "bag_c: a directory without metadata.yaml")


def test_mismatched_resolutions(good, tmp_path):
    d = folder(good, tmp_path)
    write_bag(d / "small_depth.mcap", depth_shape=(12, 16))
    assert_failed_cleanly(parse(d, tmp_path), tmp_path, "small_depth.mcap: depth 16x12 differs from colour 32x24")


def test_mixed_frame_rates(good, tmp_path):
    d = folder(good, tmp_path)
    shutil.copy(good / "ten" / "episode_000000.mcap", d / "episode_fast.mcap")
    assert_failed_cleanly(parse(d, tmp_path), tmp_path, "episode_fast.mcap: recorded at 10.00 fps, 2 other recording(s) at 5 fps")


def test_empty_directory(tmp_path):
    (tmp_path / "none").mkdir()
    assert_failed_cleanly(parse(tmp_path / "none", tmp_path), tmp_path, "none: no recordings")


@pytest.mark.parametrize("how", ["flip", "cut"])
def test_damaged_recording_keeps_what_survives(good, tmp_path, how):
    """A corrupt chunk is skipped and a truncated file keeps its frames before the break:
    warned (with its level, naming the file) and counted."""
    d = folder(good, tmp_path)
    (d / "episode_000001.mcap").write_bytes(damaged(good, how))
    result = parse(d, tmp_path)
    assert result.exit_code == 0, result.output
    assert "WARNING" in result.output and "episode_000001.mcap" in result.output
    report = json.loads((tmp_path / "reports" / "stacking-1" / "parse.json").read_text())
    assert report["episodes"] == 2 and report["warnings"] >= 1
    assert report["skipped_chunks"] == (1 if how == "flip" else 0) and report["truncated_recordings"] == (how == "cut")


def test_a_parse_killed_midway_leaves_the_previous_dataset(good, tmp_path):
    d = folder(good, tmp_path)
    assert parse(d, tmp_path).exit_code == 0
    before = (tmp_path / "ds" / "meta" / "info.json").read_text()
    args = [sys.executable, "-c", "from hsp.cli import app; app()", "parse", "stacking-1", "--recordings", str(d),
            "--out", str(tmp_path / "ds"), "--reports", str(tmp_path / "reports"), "--workers", "1"]
    proc = subprocess.Popen(args, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".ds.partial-*")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert list(tmp_path.glob(".ds.partial-*")), "the parse never started writing"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert (tmp_path / "ds" / "meta" / "info.json").read_text() == before
    assert load_episodes(tmp_path / "ds", "stacking-1")[2]["fps"] == 5
    assert parse(d, tmp_path).exit_code == 0 and not list(tmp_path.glob(".ds*"))  # the next run clears what was left


def test_the_dataset_rate_is_the_common_whole_one():
    checks = [RecordingCheck(Path(f"e{k}.mcap"), fps=f) for k, f in enumerate([15.02, 14.97, 7.5, 15.0])]
    assert dataset_rate(checks, 0.05) == 15
    assert [bool(c.error) for c in checks] == [False, False, True, False]
    assert "e2.mcap: recorded at 7.50 fps, 3 other recording(s) at 15 fps" in checks[2].error
    with pytest.raises(HspError, match="e0.mcap: recorded at 7.50 fps; a LeRobot dataset needs a whole number"):
        dataset_rate([RecordingCheck(Path("e0.mcap"), fps=7.5)], 0.05)
    # more recordings at a rate that is not whole than at one that is: the whole one is the dataset's
    checks = [RecordingCheck(Path(f"e{k}.mcap"), fps=f) for k, f in enumerate([7.5, 7.5, 7.5, 15.0, 15.0])]
    assert dataset_rate(checks, 0.05) == 15 and [bool(c.error) for c in checks] == [True, True, True, False, False]
