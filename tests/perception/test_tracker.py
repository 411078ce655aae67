"""The tracker and the first-frame initialiser on a noisy 640×480 recording."""

import numpy as np
import pytest

from hsp.dataset.features import TrackStatus
from hsp.geometry import transform_points
from hsp.perception.episode import object_models, rest_state
from hsp.perception.initialize import initialize
from hsp.perception.metrics import rotation_error_deg
from hsp.perception.pointcloud import backproject, project
from hsp.perception.tracker import SurfaceModel, TrackerConfig, track
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.reader import read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from hsp.sim.render import load_mesh


def _recorded(task, seed, tmp_path_factory):
    """One noisy 640×480 recording of ``task``: the recording and its ground truth."""
    out = tmp_path_factory.mktemp("rec") / task.name
    record(task, RecordConfig(episodes=1, seed=seed, workers=1, rig=CameraRig(CameraConfig(), DepthNoiseConfig())), out)
    path = out / "episode_000000.mcap"
    return read_recording(path), read_ground_truth(path)


@pytest.fixture(scope="module")
def episode(tasks, tmp_path_factory):
    task = tasks["stacking-1"]
    rec, gt = _recorded(task, 4, tmp_path_factory)
    return task, rec, gt, [load_mesh(task.mesh(i)) for i in range(len(task.objects))]


def test_tracking_from_the_first_pose_stays_within_millimetres(episode):
    task, rec, gt, meshes = episode
    n = 60
    models = [SurfaceModel(m, 1500) for m in meshes]
    poses, status = track(rec.rgb[:n], rec.depth[:n], rec.K, rec.T_world_cam, models, gt.poses[0], TrackerConfig())
    err_mm = np.linalg.norm(poses[:, :, :3] - gt.poses[:n, :, :3], axis=-1) * 1000
    assert np.median(err_mm) < 3.0, np.median(err_mm, axis=0)
    assert np.percentile(err_mm, 95) < 10.0
    assert (status == 2).mean() < 0.05
    rot = rotation_error_deg(poses[:, 0, 3:], gt.poses[:n, 0, 3:], "none")
    assert np.median(rot) < 5.0  # first version; issue 4 asks for a 2° median


def test_initialiser_finds_the_blocks_on_the_table(episode):
    """The hand in the air and the blocks resting on the table are found within 5 mm."""
    task, rec, gt, meshes = episode
    pts, cols = backproject(rec.depth[0], rec.rgb[0], rec.K, rec.T_world_cam, 2)
    keep = pts[:, 2] > 0.003
    poses, found = initialize(task, pts[keep], cols[keep], [SurfaceModel(m, 1500) for m in meshes], rec.T_world_cam[:3])
    assert found[0] and np.linalg.norm(poses[0, :3] - gt.poses[0, 0, :3]) < 0.005, "the hand, in the air"
    for i in range(1, len(task.objects)):
        assert found[i]
        assert np.linalg.norm(poses[i, :3] - gt.poses[0, i, :3]) < 0.005
        assert rotation_error_deg(poses[i, 3:], gt.poses[0, i, 3:], "cube") < 10.0


@pytest.mark.parametrize("shift_m, expected", [(-0.05, TrackStatus.SUSPECT), (0.03, TrackStatus.LOST)])
def test_a_resting_block_hidden_by_something_nearer_is_held_and_one_seen_through_is_lost(episode, shift_m, expected):
    """From frame 10 on, the pixels of the block farthest from the hand read 5 cm nearer and
    grey (something covers it) or 3 cm deeper (it is gone): held where it rests, marked
    suspect, in the first case; lost in the second."""
    task, rec, gt, meshes = episode
    n, start = 25, 10
    models = object_models(task, TrackerConfig(), 0)
    i = 1 + int(np.argmax(np.linalg.norm(gt.poses[0, 1:, :3] - gt.poses[0, 0, :3], axis=1)))
    uv, _ = project(transform_points(gt.poses[0, i], models[i].surface), rec.K, rec.T_world_cam)
    (u0, v0), (u1, v1) = np.floor(uv.min(axis=0)).astype(int) - 4, np.ceil(uv.max(axis=0)).astype(int) + 4
    rgb, depth = rec.rgb[:n].copy(), rec.depth[:n].copy()
    depth[start:, v0:v1, u0:u1] += shift_m
    rgb[start:, v0:v1, u0:u1] = 128
    poses, status = track(rgb, depth, rec.K, rec.T_world_cam, models, gt.poses[0], TrackerConfig(),
                          rest=rest_state(task, models))
    assert (status[start + 1:, i] == expected).all(), status[:, i]
    if expected == TrackStatus.SUSPECT:
        assert np.linalg.norm(poses[start:, i, :3] - gt.poses[start:n, i, :3], axis=1).max() < 0.003


@pytest.fixture(scope="module")
def painting(tasks, tmp_path_factory):
    return tasks["painting"], *_recorded(tasks["painting"], 13, tmp_path_factory)


def test_a_held_brush_follows_the_hand_where_icp_would_slide_it_along_its_handle(painting):
    """The brush is a long round handle: moved along it (dipped, stroked), ICP finds the same
    fit where it was. The depth image then sees past half of it; the tracker tries again from
    where the hand carried it. (Before, this recording's brush p95 was 48 mm, with 13 frames
    2–10 cm off marked ok.)"""
    task, rec, gt = painting
    models = object_models(task, TrackerConfig(), 0)
    poses, status = track(rec.rgb, rec.depth, rec.K, rec.T_world_cam, models, gt.poses[0], TrackerConfig(),
                          rest=rest_state(task, models))
    brush = task.names.index("brush")
    err_mm = np.linalg.norm(poses[:, brush, :3] - gt.poses[:, brush, :3], axis=1) * 1000
    assert np.percentile(err_mm, 95) < 10.0, np.percentile(err_mm, [50, 95, 100])
    assert np.mean((err_mm > 20.0) & (status[:, brush] == TrackStatus.OK)) < 0.03


def test_a_demonstrator_twice_as_fast_is_followed_and_its_status_can_be_trusted(episode):
    """Every second frame only: the hand moves twice as far between frames (up to 6 cm, four
    times the first gate). Whatever ICP makes of the prediction, the frame must support the
    pose; where it does not, the hand is looked for again. (Before: p95 285 mm, 13 % of the
    frames marked ok more than 1 cm off.)"""
    task, rec, gt, _ = episode
    models = object_models(task, TrackerConfig(), 0)
    truth = gt.poses[::2]
    poses, status = track(rec.rgb[::2], rec.depth[::2], rec.K, rec.T_world_cam, models, truth[0], TrackerConfig(),
                          rest=rest_state(task, models))
    err_mm = np.linalg.norm(poses[:, :, :3] - truth[:, :, :3], axis=-1) * 1000
    assert np.percentile(err_mm, 95) < 5.0, np.percentile(err_mm, 95, axis=0)
    ok = status == TrackStatus.OK
    assert np.mean(err_mm[ok] <= 10.0) >= 0.99 and ok.mean() > 0.9
