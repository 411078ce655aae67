"""What a frame says of a pose: surface samples rendered at the pose against depth and colour."""

import numpy as np
import pytest

from hsp.geometry import compose, pose_to_matrix
from hsp.perception.episode import object_models
from hsp.perception.evidence import explained
from hsp.perception.tracker import TrackerConfig
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.reader import read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig


@pytest.fixture(scope="module")
def frame(tasks, tmp_path_factory):
    task = tasks["stacking-1"]
    out = tmp_path_factory.mktemp("rec") / task.name
    record(task, RecordConfig(episodes=1, seed=4, workers=1, rig=CameraRig(CameraConfig(), DepthNoiseConfig())), out)
    rec, gt = read_recording(out / "episode_000000.mcap"), read_ground_truth(out / "episode_000000.mcap")
    return rec, gt.poses[0], object_models(task, TrackerConfig(), 0)


def _share(frame, i, pose, rgb=None):
    rec, _, models = frame
    m = models[i]
    return explained(m.surface, m.normals, m.sample_rgb, pose_to_matrix(pose), rec.rgb[0] if rgb is None else rgb,
                     rec.depth[0], rec.K, rec.T_world_cam, 0.06)


@pytest.mark.parametrize("i", [0, 1, 2, 3])
def test_the_true_pose_is_explained_and_one_slid_off_by_3_cm_is_not(frame, i):
    _, truth, _ = frame
    share, seen = _share(frame, i, truth[i])
    assert share > 0.8 and seen > 100, (share, seen)
    for shift in np.eye(3)[:2] * 0.03:  # along the table
        assert _share(frame, i, compose(truth[i], np.r_[shift, 0, 0, 0, 1]))[0] < 0.5


def test_a_pose_on_surfaces_of_another_colour_is_not_explained(frame):
    rec, truth, _ = frame
    grey = np.full_like(rec.rgb[0], 128)
    assert _share(frame, 1, truth[1], grey)[0] < 0.1


def test_an_object_outside_the_image_is_not_seen(frame):
    _, truth, _ = frame
    assert _share(frame, 1, truth[1] + np.r_[0, 5.0, 0, 0, 0, 0, 0]) == (0.0, 0)
