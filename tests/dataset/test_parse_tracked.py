"""``parse`` with the tracker: a dataset and a tracking report from RGB-D alone."""

import json

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from hsp.dataset.build import parse
from hsp.dataset.features import TrackStatus
from hsp.dataset.reader import load_episodes
from hsp.errors import HspError
from hsp.perception.tracker import TrackerConfig
from hsp.recording.ground_truth import read_ground_truth
from hsp.recording.messages import GROUND_TRUTH_PREFIX
from hsp.recording.reader import ReadOptions, read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from tests.recording.fixtures import DRIVER_TF, write_rosbags_bag

KEYS = {"translation_error_mm_median", "translation_error_mm_p95", "rotation_error_deg_median", "adds_auc",
        "ok_accurate", "inaccurate_flagged",
        "lost_fraction", "frames_per_second"}


def strip_ground_truth(src, dst):
    """Copy an MCAP file without its ``/hsp/ground_truth/*`` channels."""
    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        writer = Writer(g)
        writer.start()
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages():
            if channel.topic.startswith(GROUND_TRUTH_PREFIX):
                continue
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas[schema.id], channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time)
        writer.finish()


@pytest.fixture(scope="module")
def camera_recordings(tasks, tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "stacking-1"
    record(tasks["stacking-1"], RecordConfig(episodes=1, seed=5, workers=1, rig=CameraRig(CameraConfig(), DepthNoiseConfig())), out)
    stripped = out.parent / "stripped"
    stripped.mkdir()
    strip_ground_truth(out / "episode_000000.mcap", stripped / "episode_000000.mcap")
    return out, stripped


def test_tracked_dataset_matches_the_truth_within_millimetres(tasks, camera_recordings, tmp_path):
    out, _ = camera_recordings
    report, tracking = parse(tasks["stacking-1"], out, tmp_path / "ds")
    assert KEYS <= set(tracking) and tracking["episodes_with_ground_truth"] == 1
    assert tracking["translation_error_mm_median"] < 3.0, tracking
    assert tracking["adds_auc"] > 90.0 and tracking["lost_fraction"] < 0.05
    json.dumps(tracking)  # flat, JSON-serialisable
    poses, status, meta = load_episodes(tmp_path / "ds", "stacking-1")
    assert len(poses) == 1 and len(poses[0]) == report["frames"] and poses[0].shape[1] == 4


def test_tracker_never_reads_the_ground_truth(tasks, camera_recordings, tmp_path):
    """Stripping the ground-truth topics changes nothing (and two processes give what one does)."""
    out, stripped = camera_recordings
    parse(tasks["stacking-1"], out, tmp_path / "a", workers=1)
    _, tracking = parse(tasks["stacking-1"], stripped, tmp_path / "b", workers=2)
    assert tracking["episodes_with_ground_truth"] == 0 and "translation_error_mm_median" not in tracking
    (pa,), (sa,), _ = load_episodes(tmp_path / "a", "stacking-1")
    (pb,), (sb,), _ = load_episodes(tmp_path / "b", "stacking-1")
    np.testing.assert_array_equal(pa, pb)
    np.testing.assert_array_equal(sa, sb)


def test_a_wrong_topic_is_a_clear_error_naming_the_file_and_the_topics(tasks, camera_recordings, tmp_path):
    _, stripped = camera_recordings
    with pytest.raises(HspError, match=r"episode_000000.mcap: no .*Image topic '/nope' \(found: .*color/image_raw"):
        parse(tasks["stacking-1"], stripped, tmp_path / "ds", options=ReadOptions(color_topic="/nope"))
    assert not (tmp_path / "ds").exists()


def test_an_object_lost_at_the_start_is_marked_lost_not_invented(tasks, camera_recordings, tmp_path):
    """With a demand of more points than any object has, every pose is marked lost."""
    out, _ = camera_recordings
    _, tracking = parse(tasks["stacking-1"], out, tmp_path / "ds", cfg=TrackerConfig(min_points=10**6, min_points_floor=10**6))
    assert tracking["lost_fraction"] == 1.0


def as_realsense_bag(recording, bag, storage="sqlite3"):
    """An hsp recording re-written by ``rosbags`` as the RealSense driver and ``ros2 bag record``
    write it: bgr8 colour, 16UC1 aligned depth, the driver's /tf_static (no table frame), no ground truth."""
    rec = read_recording(recording)
    write_rosbags_bag(bag, rgb=rec.rgb, depth_mm=np.round(rec.depth * 1000).astype(np.uint16), K=rec.K,
                      encoding="bgr8", stamps_ns=rec.stamps_ns, storage=storage, tf=DRIVER_TF)


def test_realsense_bags_parse_to_the_same_object_distances(tasks, camera_recordings, tmp_path):
    """A folder of two such bags, SQLite and MCAP storage: no table frame in either, so it is
    fitted to the depth, and every object-to-object distance comes out as in the recorded
    truth (p95 within 5 mm)."""
    out, _ = camera_recordings
    for storage in ("sqlite3", "mcap"):
        as_realsense_bag(out / "episode_000000.mcap", tmp_path / "bags" / storage, storage)
    report, _ = parse(tasks["stacking-1"], tmp_path / "bags", tmp_path / "ds", workers=2)
    assert report["table_frame.fitted"] == 2 and report["episodes"] == 2
    poses, status, _ = load_episodes(tmp_path / "ds", "stacking-1")
    truth = read_ground_truth(out / "episode_000000.mcap").poses
    i, j = np.triu_indices(truth.shape[1], 1)
    d_true = np.linalg.norm(truth[:, i, :3] - truth[:, j, :3], axis=-1)
    for P, S in zip(poses, status):
        seen = (S[:, i] != TrackStatus.LOST) & (S[:, j] != TrackStatus.LOST)
        err = np.abs(np.linalg.norm(P[:, i, :3] - P[:, j, :3], axis=-1) - d_true)[seen]
        assert seen.mean() > 0.95 and np.percentile(err, 95) < 0.005, (seen.mean(), np.percentile(err, [50, 95]))
    np.testing.assert_array_equal(poses[0], poses[1])  # the same frames, whichever storage
