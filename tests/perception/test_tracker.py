"""The tracker and the first-frame initialiser on a noisy 640×480 recording."""

import numpy as np
import pytest

from hsp.dataset.features import TrackStatus
from hsp.geometry import transform_points
from hsp.perception.episode import first_frame_tracker, object_models, rest_state
from hsp.perception.initialize import initialize
from hsp.perception.metrics import rotation_error_deg
from hsp.perception.pointcloud import backproject, project
from hsp.perception.tracker import SurfaceModel, TrackerConfig, depth_noise, min_points, table_clearance, track
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.reader import read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig, look_at_pose
from hsp.sim.depth_noise import DepthNoiseConfig, add_depth_noise
from hsp.sim.render import RgbdRenderer, load_mesh


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


@pytest.fixture(scope="module")
def painting_tracked(painting):
    """The painting recording tracked from its true first poses: task, truth, poses, status."""
    task, rec, gt = painting
    models = object_models(task, TrackerConfig(), 0)
    poses, status = track(rec.rgb, rec.depth, rec.K, rec.T_world_cam, models, gt.poses[0], TrackerConfig(),
                          rest=rest_state(task, models))
    return task, gt, poses, status


def test_a_held_brush_follows_the_hand_where_icp_would_slide_it_along_its_handle(painting_tracked):
    """The brush is a long round handle: moved along it (dipped, stroked), ICP finds the same
    fit where it was. The depth image then sees past half of it; the tracker tries again from
    where the hand carried it. (Before, this recording's brush p95 was 48 mm, with 13 frames
    2–10 cm off marked ok.)"""
    task, gt, poses, status = painting_tracked
    brush = task.names.index("brush")
    err_mm = np.linalg.norm(poses[:, brush, :3] - gt.poses[:, brush, :3], axis=1) * 1000
    assert np.percentile(err_mm, 95) < 10.0, np.percentile(err_mm, [50, 95, 100])
    assert np.mean((err_mm > 20.0) & (status[:, brush] == TrackStatus.OK)) < 0.03


def test_a_held_brush_keeps_the_roll_of_its_grasp_and_what_fits_to_its_noise_is_ok(painting_tracked):
    """A frame's correlated depth noise turns the brush's head about its round handle by
    5–25°; held by the hand, it keeps the roll of its grasp (session 36: 40 % of this
    recording's frames more than 15° off, up to 90°; now at most 12°). The canvas and the bucket, 1.2 m from the
    camera, fit their points to the depth noise there, 3–4 mm: accurate, they are ok (they
    were suspect in 100 % and 85 % of the frames: a fixed 4 mm)."""
    task, gt, poses, status = painting_tracked
    brush = task.names.index("brush")
    roll = rotation_error_deg(poses[:, brush, 3:], gt.poses[:, brush, 3:], task.objects[brush].symmetry)
    assert np.mean(roll > 15.0) < 0.02 and np.median(roll) < 5.0, np.percentile(roll, [50, 90, 100])
    for name in ("canvas", "bucket"):
        i = task.names.index(name)
        err_mm = np.linalg.norm(poses[:, i, :3] - gt.poses[:, i, :3], axis=1) * 1000
        assert err_mm.max() < 10.0 and np.mean(status[:, i] == TrackStatus.OK) > 0.95, name


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


def test_the_table_is_as_thick_as_its_depth_noise_in_its_own_colours():
    """A stereo camera 1.8 m from a brown table sees it centimetres thick (noise grows with
    depth²). Table-coloured points within that noise are table, estimated from the frame's own
    points below the plane; a white 12 mm canvas lying on it and a hand 5 cm up keep theirs."""
    rng = np.random.default_rng(0)
    cfg = TrackerConfig()
    n = 20000
    depth = rng.uniform(1.2, 2.0, n)
    rays_z = np.full(n, -0.6)  # looking down at the table
    sigma = 0.0025 * depth**2 * 0.6  # 4.9 mm at 1.8 m
    brown, white = np.array([0.62, 0.48, 0.33]), np.array([0.9, 0.9, 0.9])
    table = np.c_[rng.uniform(0, 1, (n, 2)), rng.normal(0, sigma)]
    canvas = np.c_[rng.uniform(0, 1, (500, 2)), rng.uniform(0.004, 0.012, 500)]
    hand = np.c_[rng.uniform(0, 1, (500, 2)), np.full(500, 0.05)]
    pts = np.concatenate([table, canvas, hand])
    cols = np.concatenate([np.tile(brown, (n, 1)), np.tile(white, (500, 1)), np.tile(brown * 1.2, (500, 1))])
    depth, rays_z = np.r_[depth, np.full(1000, 1.8)], np.r_[rays_z, np.full(1000, -0.6)]
    k = depth_noise(pts[:, 2], depth, rays_z, cfg.min_points)
    assert k == pytest.approx(0.0025, rel=0.05), "the noise scale, from the points below the plane"
    clear = table_clearance(pts, cols, depth, rays_z, k, cfg)
    kept = pts[:, 2] > clear
    assert kept[:n].mean() < 0.005, "table noise left as points"
    assert (pts[:n, 2] > cfg.table_clearance_m).mean() > 0.1, "a fixed clearance keeps much of it"
    assert kept[n:].all(), "the canvas and the hand keep their points"


def test_a_small_object_far_away_needs_fewer_points_than_a_near_one(tasks):
    task = tasks["tire-removal"]
    wheel, nut = object_models(task, TrackerConfig(), 0)[1:3]
    cfg = TrackerConfig()
    assert min_points(wheel, 1.6, 615.0, cfg) == cfg.min_points
    assert min_points(nut, 0.8, 615.0, cfg) == cfg.min_points
    assert cfg.min_points_floor < min_points(nut, 1.6, 615.0, cfg) < min_points(nut, 1.2, 615.0, cfg) < cfg.min_points


def test_from_high_above_the_hand_is_found_among_a_table_of_its_colour(painting):
    """Seen from 1.7 m above and behind the table, the first frame of a painting recording:
    the table's noise reaches 1 cm and the hand has the table's colour. Each estimate must be
    explained by the frame. (Before: the hand was not found at all, on 3 recordings of 3.)"""
    task, rec, gt = painting
    cam = CameraConfig(eye=(1.15, 0.0, 1.25))
    T_world_cam = look_at_pose(np.asarray(cam.eye), np.asarray(cam.look_at))
    meshes = [load_mesh(task.mesh(i)) for i in range(len(task.objects))]
    rgb, depth, _ = RgbdRenderer(meshes, cam).render(T_world_cam, gt.poses[0])
    depth = add_depth_noise(depth, cam.fx, DepthNoiseConfig(), np.random.default_rng(0)).astype(np.float32) / 1000.0
    models = object_models(task, TrackerConfig(), 0)
    tracker = first_frame_tracker(task, rgb, depth, cam.K, T_world_cam, models)
    err_mm = np.linalg.norm(tracker.prev[:, :3] - gt.poses[0, :, :3], axis=1) * 1000
    assert tracker.known.all() and (err_mm < 6.0).all(), err_mm

