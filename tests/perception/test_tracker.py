"""The frame-to-frame tracker follows every object of a noisy recording from its start pose."""

import numpy as np

from hsp.perception.metrics import rotation_error_deg
from hsp.perception.tracker import TrackerConfig, track
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.reader import read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from hsp.sim.render import load_mesh


def test_tracking_from_the_first_pose_stays_within_millimetres(tasks, tmp_path):
    task = tasks["stacking-1"]
    rig = CameraRig(CameraConfig(), DepthNoiseConfig())
    record(task, RecordConfig(episodes=1, seed=4, workers=1, rig=rig), tmp_path / "rec")
    path = tmp_path / "rec" / "episode_000000.mcap"
    rec, gt = read_recording(path), read_ground_truth(path)
    n = 60
    poses, status = track(rec.rgb[:n], rec.depth[:n], rec.K, rec.T_world_cam,
                          [load_mesh(task.mesh(i)) for i in range(len(task.objects))], gt.poses[0], TrackerConfig())
    err_mm = np.linalg.norm(poses[:, :, :3] - gt.poses[:n, :, :3], axis=-1) * 1000
    assert np.median(err_mm) < 3.0, np.median(err_mm, axis=0)
    assert np.percentile(err_mm, 95) < 10.0
    assert (status == 2).mean() < 0.05
    rot = rotation_error_deg(poses[:, 0, 3:], gt.poses[:n, 0, 3:], "none")
    assert np.median(rot) < 5.0  # first version; issue 4 asks for a 2° median
