"""Recording episodes: MCAP round trip, determinism, refusal to overwrite, atomicity."""

import numpy as np
import pytest

from hsp.errors import HspError
from hsp.recording import record as record_module
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.record import RecordConfig, episode_seed, record
from hsp.sim.demonstration import demonstrate


def test_ground_truth_round_trips_through_mcap(tasks, tmp_path):
    """Poses and the sub-task annotation read back exactly as the demonstrator produced them."""
    task = tasks["stacking-1"]
    report = record(task, RecordConfig(episodes=1, seed=3, workers=1), tmp_path / "rec")
    gt = read_ground_truth(tmp_path / "rec" / "episode_000000.mcap")
    demo = demonstrate(task, episode_seed(3, 0), 15)
    assert report["frames"] == demo.frames == gt.poses.shape[0]
    assert gt.objects == task.names
    np.testing.assert_array_equal(gt.poses, demo.poses)
    np.testing.assert_array_equal(gt.tool, demo.tool)
    np.testing.assert_array_equal(gt.target, demo.target)
    np.testing.assert_array_equal(gt.waypoint, demo.waypoint)
    np.testing.assert_array_equal(gt.waypoint_index, demo.waypoint_index)
    np.testing.assert_array_equal(gt.grasped, demo.grasped)
    np.testing.assert_array_equal(np.diff(gt.stamps_ns), 1_000_000_000 // 15)
    assert gt.metadata["task"] == "stacking-1" and gt.metadata["demonstrator_success"] == "true"


def test_same_seed_gives_byte_identical_recordings(tasks, tmp_path):
    task = tasks["tire-removal"]
    record(task, RecordConfig(episodes=2, seed=11, workers=2), tmp_path / "a")
    record(task, RecordConfig(episodes=2, seed=11, workers=1), tmp_path / "b")
    record(task, RecordConfig(episodes=1, seed=12, workers=1), tmp_path / "c")
    for name in ("episode_000000.mcap", "episode_000001.mcap"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert (tmp_path / "a" / "episode_000000.mcap").read_bytes() != (tmp_path / "c" / "episode_000000.mcap").read_bytes()


def test_existing_output_is_refused_without_force(tasks, tmp_path):
    out = tmp_path / "rec"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(HspError, match="exists; pass --force"):
        record(tasks["stacking-1"], RecordConfig(episodes=1, seed=0, workers=1), out)
    assert (out / "keep.txt").read_text() == "mine"


def test_interrupted_run_leaves_previous_output_untouched(tasks, tmp_path, monkeypatch):
    """A crash mid-way keeps the old recordings and leaves no half-written directory."""
    task = tasks["stacking-1"]
    out = tmp_path / "rec"
    record(task, RecordConfig(episodes=1, seed=0, workers=1), out)
    before = (out / "episode_000000.mcap").read_bytes()
    calls = {"n": 0}
    real = record_module._record_one

    def crash_on_second(job):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(record_module, "_record_one", crash_on_second)
    with pytest.raises(KeyboardInterrupt):
        record(task, RecordConfig(episodes=3, seed=1, workers=1), out, force=True)
    assert sorted(p.name for p in out.iterdir()) == ["episode_000000.mcap"]
    assert (out / "episode_000000.mcap").read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["rec"]


def test_bad_config_is_rejected():
    with pytest.raises(HspError, match="record.fps = 7: must divide 240"):
        RecordConfig(episodes=1, seed=0, fps=7)
    with pytest.raises(HspError, match="record.episodes = 0"):
        RecordConfig(episodes=0, seed=0)


def test_truncated_file_gives_a_clear_error(tasks, tmp_path):
    record(tasks["stacking-1"], RecordConfig(episodes=1, seed=0, workers=1), tmp_path / "rec")
    path = tmp_path / "rec" / "episode_000000.mcap"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(HspError, match="episode_000000.mcap: cannot read ground truth"):
        read_ground_truth(path)
