"""The RGB-D reader: exact round trips, foreign writers, and every bad input."""

import numpy as np
import pytest

from hsp.errors import HspError
from hsp.recording.reader import ReadOptions, ReadReport, _read_messages, find_recordings, read_recording
from hsp.recording.record import RecordConfig, record
from hsp.recording.writer import CameraRig
from hsp.sim.camera import CameraConfig
from hsp.sim.depth_noise import DepthNoiseConfig
from tests.recording.fixtures import CAM, write_bag, write_ros1_bag, write_rosbags_bag


def test_colour_and_depth_round_trip_bit_exactly(tmp_path):
    rgb, depth_mm = write_bag(tmp_path / "a.mcap", n=8)
    rec = read_recording(tmp_path / "a.mcap")
    np.testing.assert_array_equal(rec.rgb, rgb)
    np.testing.assert_array_equal(np.round(rec.depth * 1000).astype(np.uint16), depth_mm)
    np.testing.assert_array_equal(rec.K, CAM.K)
    assert rec.report.warnings == [] and rec.report.paired == 8


def test_recorded_episode_round_trips(tasks, tmp_path):
    """hsp record → reader: frames pair one to one, camera pose and intrinsics come back."""
    cam = CameraConfig().scaled(160, 120)
    rig = CameraRig(cam, DepthNoiseConfig())
    record(tasks["stacking-1"], RecordConfig(episodes=1, seed=2, fps=5, workers=1, rig=rig), tmp_path / "rec")
    rec = read_recording(tmp_path / "rec" / "episode_000000.mcap")
    assert rec.rgb.shape[1:] == (120, 160, 3) and rec.report.warnings == []
    np.testing.assert_allclose(rec.K, cam.K)
    assert rec.T_world_cam is not None and np.linalg.norm(rec.T_world_cam[:3] - cam.eye) < 0.1
    valid = rec.depth[rec.depth > 0]
    assert 0.5 < np.median(valid) < 2.5


def test_bgr8_is_converted(tmp_path):
    rgb, _ = write_bag(tmp_path / "b.mcap", n=3, color_encoding="bgr8")
    np.testing.assert_array_equal(read_recording(tmp_path / "b.mcap").rgb, rgb)


@pytest.mark.parametrize("prefix", ["/camera/camera", "/camera"])
def test_independent_rosbags_writer_with_realsense_names(tmp_path, prefix):
    """A rosbag2 directory from the `rosbags` package: big-endian, padded rows, either driver naming."""
    rgb, depth_mm = write_rosbags_bag(tmp_path / "bag", prefix=prefix)
    assert (tmp_path / "bag" / "metadata.yaml").is_file()
    rec = read_recording(tmp_path / "bag")
    np.testing.assert_array_equal(rec.rgb, rgb)
    np.testing.assert_array_equal(np.round(rec.depth * 1000).astype(np.uint16), depth_mm)
    assert rec.topics["depth"] == f"{prefix}/aligned_depth_to_color/image_raw"


def test_empty_file(tmp_path):
    (tmp_path / "e.mcap").write_bytes(b"")
    with pytest.raises(HspError, match="e.mcap: empty file"):
        read_recording(tmp_path / "e.mcap")


@pytest.mark.parametrize(("magic", "hint"), [
    (b"SQLite format 3\x00", "SQLite file; name its bag directory"), (b"#ROSBAG V2.0\n", "ROS 1 bag without the .bag suffix"),
    (b"\x89PNG\r\n\x1a\n", "not MCAP but a PNG image"), (b"hello", "not an MCAP")])
def test_not_mcap(tmp_path, magic, hint):
    (tmp_path / "x.mcap").write_bytes(magic + b"\x00" * 64)
    with pytest.raises(HspError, match=hint):
        read_recording(tmp_path / "x.mcap")


def test_no_image_topic_lists_what_was_found(tmp_path):
    write_bag(tmp_path / "n.mcap", color=False, depth=False)
    with pytest.raises(HspError, match=r"no colour image topic; Image topics: none; all topics: \['/camera/camera/color/camera_info'\]"):
        read_recording(tmp_path / "n.mcap")


def test_no_camera_info_needs_intrinsics(tmp_path):
    write_bag(tmp_path / "i.mcap", info=False)
    with pytest.raises(HspError, match="no CameraInfo topic and no intrinsics given"):
        read_recording(tmp_path / "i.mcap")
    rec = read_recording(tmp_path / "i.mcap", ReadOptions(intrinsics=(30.0, 30.0, 15.5, 11.5)))
    np.testing.assert_array_equal(rec.K, CAM.K)


@pytest.mark.parametrize("K", [np.zeros((3, 3)), np.diag([30.0, 30.0, 1.0])])
def test_uncalibrated_intrinsics(tmp_path, K):
    """A CameraInfo of zeros (an uncalibrated camera), or with the principal point at a
    corner, is an error naming the file; --intrinsics overrides it."""
    write_bag(tmp_path / "k.mcap", K=K)
    with pytest.raises(HspError, match=r"k.mcap: intrinsics from /camera/camera/color/camera_info .* of a 32x24 camera"):
        read_recording(tmp_path / "k.mcap")
    rec = read_recording(tmp_path / "k.mcap", ReadOptions(intrinsics=(30.0, 30.0, 15.5, 11.5)))
    np.testing.assert_array_equal(rec.K, CAM.K)


def test_only_the_chosen_topics_are_decoded(tmp_path):
    """The driver records infrared and unaligned depth streams too; only the topics read_recording
    picks are decoded (each stream would hold the whole recording in memory again)."""
    infrared = ("/camera/camera/infra1/image_rect_raw", "/camera/camera/infra2/image_rect_raw")
    rgb, _ = write_bag(tmp_path / "m.mcap", n=4, extra_topics=infrared)
    np.testing.assert_array_equal(read_recording(tmp_path / "m.mcap").rgb, rgb)
    write_rosbags_bag(tmp_path / "bag", n=4)
    for path in (tmp_path / "m.mcap", tmp_path / "bag"):
        seen = []
        bag = _read_messages(path, ReadReport(), lambda types: seen.append(sorted(types)) or {t for t in types if "info" in t})
        assert len(seen[0]) >= 3 and {topic for topic, _, _ in bag.messages} == {"/camera/camera/color/camera_info"}


def test_what_parse_is_pointed_at(tmp_path):
    """A folder lists its bags, bare files and bags cut short (which the check then reports),
    not a sub-folder of other files; one file of a bag is refused, the bag is named instead."""
    write_rosbags_bag(tmp_path / "d" / "bag_a", n=4, split=True)
    write_bag(tmp_path / "d" / "b.mcap", n=4)
    cut = tmp_path / "d" / "bag_c"
    write_rosbags_bag(cut, n=4)
    (cut / "metadata.yaml").unlink()
    (tmp_path / "d" / "notes.txt").write_text("")
    (tmp_path / "d" / "old").mkdir()
    write_bag(tmp_path / "d" / "old" / "episode_000000.mcap", n=4)
    assert [p.name for p in find_recordings(tmp_path / "d")] == ["b.mcap", "bag_a", "bag_c"]
    assert find_recordings(cut) == [cut]  # named directly: one recording, not its files
    with pytest.raises(HspError, match="bag_c: a directory without metadata.yaml.*ros2 bag reindex"):
        read_recording(cut)
    part = next((tmp_path / "d" / "bag_a").glob("*.mcap"))
    with pytest.raises(HspError, match=f"{part.name}: one file of the rosbag2 bag .*bag_a; name the bag directory"):
        find_recordings(part)
    assert find_recordings(tmp_path / "d" / "bag_a") == [tmp_path / "d" / "bag_a"]


def test_unaligned_depth_resolution(tmp_path):
    write_bag(tmp_path / "u.mcap", depth_shape=(12, 16))
    with pytest.raises(HspError, match=r"depth 16x12 differs from colour 32x24.*align_depth.enable:=true"):
        read_recording(tmp_path / "u.mcap")


def test_unsupported_encoding(tmp_path):
    write_bag(tmp_path / "y.mcap", color_encoding="yuv422")
    with pytest.raises(HspError, match="unsupported image encoding 'yuv422'"):
        read_recording(tmp_path / "y.mcap")


def test_too_few_pairs_reports_the_offset(tmp_path):
    """Depth stamped on another clock (5 s off): nothing pairs, the message says by how much."""
    write_bag(tmp_path / "o.mcap", depth_offset_ns=5_000_000_000)
    with pytest.raises(HspError, match=r"only 0 of 10 colour frames pair with depth \(median stamp offset 4700.0 ms\)"):
        read_recording(tmp_path / "o.mcap")


def test_small_offsets_pair_with_nearest_and_unpaired_frames_are_dropped(tmp_path):
    write_bag(tmp_path / "p.mcap", n=10, depth_offset_ns=2_000_000, drop_depth=(3, 7))
    rec = read_recording(tmp_path / "p.mcap")
    assert len(rec.rgb) == 8 and rec.report.paired_nearest == 8
    assert any("unpaired" in w for w in rec.report.warnings)


def test_truncated_file_keeps_frames_before_the_break(tmp_path):
    write_bag(tmp_path / "t.mcap", n=40, chunk_size=4096)
    data = (tmp_path / "t.mcap").read_bytes()
    (tmp_path / "t.mcap").write_bytes(data[: int(len(data) * 0.6)])
    rec = read_recording(tmp_path / "t.mcap")
    assert rec.report.truncated
    assert 18 <= len(rec.rgb) <= 24, len(rec.rgb)


def test_corrupt_chunk_is_skipped_by_crc(tmp_path):
    rgb, _ = write_bag(tmp_path / "c.mcap", n=40, chunk_size=4096)
    data = bytearray((tmp_path / "c.mcap").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (tmp_path / "c.mcap").write_bytes(bytes(data))
    rec = read_recording(tmp_path / "c.mcap")
    assert rec.report.skipped_chunks == 1
    assert 35 <= len(rec.rgb) < 40
    for t, s in enumerate(rec.stamps_ns):
        k = int(round((s - 1_700_000_000_000_000_000) / 66_666_666))
        np.testing.assert_array_equal(rec.rgb[t], rgb[k])


def test_override_topic_names(tmp_path):
    write_bag(tmp_path / "r.mcap", color_topic="/my_cam/rgb")
    with pytest.raises(HspError, match="no colour image topic"):
        read_recording(tmp_path / "r.mcap")
    rec = read_recording(tmp_path / "r.mcap", ReadOptions(color_topic="/my_cam/rgb"))
    assert rec.topics["color"] == "/my_cam/rgb"


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("compression", [None, "message", "file"])
def test_rosbag2_as_ros2_bag_record_writes_it(tmp_path, storage, compression):
    """Both storages, each compression mode, split in two files: every frame comes back."""
    rgb, depth_mm = write_rosbags_bag(tmp_path / "bag", n=6, storage=storage, compression=compression, split=True)
    rec = read_recording(tmp_path / "bag")
    np.testing.assert_array_equal(rec.rgb, rgb)
    np.testing.assert_array_equal(np.round(rec.depth * 1000).astype(np.uint16), depth_mm)
    np.testing.assert_array_equal(rec.K, CAM.K)
    assert rec.report.warnings == []


def test_ros1_bag(tmp_path):
    rgb, depth_mm = write_ros1_bag(tmp_path / "a.bag")
    rec = read_recording(tmp_path / "a.bag")
    np.testing.assert_array_equal(rec.rgb, rgb)
    np.testing.assert_array_equal(np.round(rec.depth * 1000).astype(np.uint16), depth_mm)
    np.testing.assert_array_equal(rec.K, CAM.K)
