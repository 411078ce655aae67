"""Pose datasets: LeRobot v3.0 round trip, episode boundaries, bad input leaves nothing."""

import numpy as np
import pytest

from hsp.dataset.build import parse
from hsp.dataset.features import TrackStatus
from hsp.dataset.reader import load_episodes
from hsp.dataset.writer import EpisodePoses, actions, write_dataset
from hsp.errors import HspError
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.record import RecordConfig, record


@pytest.fixture(scope="module")
def recordings(tasks, tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "stacking-1"
    record(tasks["stacking-1"], RecordConfig(episodes=3, seed=9, workers=1), out)
    return out


def test_ground_truth_dataset_opens_with_lerobot_and_matches_recordings(tasks, recordings, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    report, tracking = parse(tasks["stacking-1"], recordings, tmp_path / "ds", poses_from="ground-truth")
    assert tracking is None
    gts = [read_ground_truth(p) for p in sorted(recordings.glob("*.mcap"))]
    ds = LeRobotDataset("hsp/stacking-1", root=tmp_path / "ds")
    assert ds.num_episodes == 3 == report["episodes"]
    assert len(ds) == sum(len(g.poses) for g in gts) == report["frames"]
    assert ds.fps == 15
    ends = np.cumsum([len(g.poses) for g in gts])
    assert list(ds.meta.episodes["dataset_to_index"]) == list(ends)
    item = ds[int(ends[0])]  # first frame of the second episode
    assert int(item["episode_index"]) == 1 and item["task"] == "stacking-1"
    poses, status, meta = load_episodes(tmp_path / "ds", "stacking-1")
    assert meta["objects"] == tasks["stacking-1"].names
    with pytest.raises(HspError, match="are not those of task 'stacking-2'"):
        load_episodes(tmp_path / "ds", "stacking-2", tasks["stacking-2"].names)
    for p, g, s in zip(poses, gts, status):
        np.testing.assert_allclose(p, g.poses, atol=1e-6)  # stored as float32
        assert np.all(s == TrackStatus.OK)


def test_action_is_the_next_end_effector_change():
    ee = np.array([[0, 0, 0, 0, 0, 0, 1.0], [0.01, 0, 0, 0, 0, np.sin(0.05), np.cos(0.05)], [0.01, 0, 0, 0, 0, np.sin(0.05), np.cos(0.05)]])
    a = actions(ee, np.zeros(3, int))
    np.testing.assert_allclose(a[0], [0.01, 0, 0, 0, 0, 0.1], atol=1e-12)
    np.testing.assert_allclose(a[1:], 0, atol=1e-12)


def test_task_mismatch_writes_nothing(tasks, recordings, tmp_path):
    with pytest.raises(HspError, match="do not match task 'stacking-2'"):
        parse(tasks["stacking-2"], recordings, tmp_path / "ds", poses_from="ground-truth")
    assert not (tmp_path / "ds").exists() and not any(tmp_path.iterdir())


def test_tracking_recordings_without_images_is_an_error_naming_the_file(tasks, recordings, tmp_path):
    with pytest.raises(HspError, match="episode_000000.mcap: no colour image topic"):
        parse(tasks["stacking-1"], recordings, tmp_path / "ds")
    assert not any(tmp_path.iterdir())


def _episode(task, T=5, seed=0):
    rng = np.random.default_rng(seed)
    n = len(task.objects)
    poses = np.tile([0.5, 0, 0.1, 0, 0, 0, 1.0], (T, n, 1))
    poses[..., :3] += rng.normal(0, 0.01, (T, n, 3))
    return EpisodePoses("synthetic", poses, np.zeros((T, n), np.int64))


def test_lost_frames_are_marked_not_interpolated(tasks, tmp_path):
    task = tasks["stacking-1"]
    ep = _episode(task, T=6)
    ep.poses[3, 2] = np.nan
    with pytest.raises(HspError, match="NaN or infinite poses in frames not marked lost"):
        write_dataset(task, [ep], tmp_path / "ds", 15)
    ep.status[3, 2] = TrackStatus.LOST
    ep.poses[3, 2] = ep.poses[2, 2]  # the writer stores a placeholder; the status says it is not data
    write_dataset(task, [ep], tmp_path / "ds", 15)
    _, status, _ = load_episodes(tmp_path / "ds", "stacking-1")
    assert status[0][3, 2] == TrackStatus.LOST and (status[0] == TrackStatus.LOST).sum() == 1
    ep.poses[4, 1] = np.inf
    with pytest.raises(HspError, match="NaN or infinite"):
        write_dataset(task, [ep], tmp_path / "ds", 15)  # a failed rewrite keeps the dataset
    assert [p.name for p in tmp_path.iterdir()] == ["ds"] and len(load_episodes(tmp_path / "ds", "stacking-1")[1]) == 1


@pytest.mark.parametrize(("T", "n_extra", "match"), [(1, 0, "needs at least 2"), (4, 1, "do not match")])
def test_bad_episode_shapes(tasks, tmp_path, T, n_extra, match):
    task = tasks["stacking-1"]
    ep = _episode(task, T=T)
    if n_extra:
        ep = EpisodePoses("x", np.concatenate([ep.poses, ep.poses[:, :1]], 1), np.zeros((T, ep.poses.shape[1] + 1), np.int64))
    with pytest.raises(HspError, match=match):
        write_dataset(task, [ep], tmp_path / "ds", 15)
    assert not (tmp_path / "ds").exists()
