"""Small synthetic RGB-D bags for reader tests, written with hsp's writer or with the
independent ``rosbags`` writer (as ``ros2 bag record`` would write them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hsp.recording.messages import CAMERA_INFO, COLOR_IMAGE, COLOR_INFO, DEPTH_IMAGE, IMAGE
from hsp.recording.writer import Ros2McapWriter, camera_info, image_msg, stamp
from hsp.sim.camera import CameraConfig

H, W = 24, 32
CAM = CameraConfig(width=W, height=H, fx=30.0, fy=30.0, cx=15.5, cy=11.5)
PERIOD = 66_666_666


def frames(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 256, (n, H, W, 3), dtype=np.uint8)
    depth_mm = rng.integers(300, 2000, (n, H, W), dtype=np.uint16)
    depth_mm[:, 0, 0] = 0
    return rgb, depth_mm


def write_bag(path: Path, n: int = 10, *, color: bool = True, depth: bool = True, info: bool = True,
              depth_shape: tuple[int, int] = (H, W), color_encoding: str = "rgb8", depth_offset_ns: int = 0,
              drop_depth: tuple[int, ...] = (), color_topic: str = COLOR_IMAGE, chunk_size: int = 1 << 20,
              K: np.ndarray = CAM.K, extra_topics: tuple[str, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """A bag of ``n`` frames; returns the colour and depth (mm) that went in. ``extra_topics``
    carry the colour images too (the driver's infrared streams, say)."""
    rgb, depth_mm = frames(n)
    with open(path, "wb") as f:
        w = Ros2McapWriter(f, chunk_size=chunk_size)  # small chunks make single-chunk damage testable
        for t in range(n):
            ns = 1_700_000_000_000_000_000 + t * PERIOD
            header = {"stamp": stamp(ns), "frame_id": "camera_color_optical_frame"}
            if color:
                img = rgb[t][:, :, ::-1] if color_encoding == "bgr8" else rgb[t]
                for topic in (color_topic, *extra_topics):
                    w.write(topic, IMAGE, image_msg(header, np.ascontiguousarray(img), color_encoding), ns, t)
            if depth and t not in drop_depth:
                d_header = {"stamp": stamp(ns + depth_offset_ns), "frame_id": "camera_color_optical_frame"}
                d = depth_mm[t] if depth_shape == (H, W) else np.zeros(depth_shape, np.uint16)
                w.write(DEPTH_IMAGE, IMAGE, image_msg(d_header, d, "16UC1"), ns + depth_offset_ns, t)
            if info:
                w.write(COLOR_INFO, CAMERA_INFO, {**camera_info(CAM, header), "k": np.ravel(K).tolist()}, ns, t)
        w.finish()
    return rgb, depth_mm


DRIVER_TF = [("camera_link", "camera_color_frame", [0.0, 0.015, 0.0], [0.0, 0.0, 0.0, 1.0]),
             ("camera_color_frame", "camera_color_optical_frame", [0.0, 0.0, 0.0], [-0.5, 0.5, -0.5, 0.5])]
"""``/tf_static`` as the RealSense driver publishes it: the camera's own frames, no table or world."""


def write_rosbags_bag(directory: Path, n: int = 6, prefix: str = "/camera/camera", *, storage: str = "mcap",
                      compression: str | None = None, split: bool = False, tf: list | None = None,
                      rgb: np.ndarray | None = None, depth_mm: np.ndarray | None = None, K: np.ndarray = CAM.K,
                      encoding: str = "rgb8", period_ns: int = PERIOD, stamps_ns: np.ndarray | None = None,
                      ) -> tuple[np.ndarray, np.ndarray]:
    """A rosbag2 directory written by the ``rosbags`` package as ``ros2 bag record`` writes
    it: ``storage`` "mcap" or "sqlite3", ``compression`` None, "message" or "file" (zstd),
    ``split`` into two files, ``tf`` transforms (parent, child, xyz, xyzw) on ``/tf_static``.
    Depth is big-endian with rows padded beyond their width (``step`` > width × 2). Returns
    the colour and depth (mm) that went in (random unless given)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Image, Header, Time = T["sensor_msgs/msg/Image"], T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    CameraInfo, Roi = T["sensor_msgs/msg/CameraInfo"], T["sensor_msgs/msg/RegionOfInterest"]
    if rgb is None:
        rgb, depth_mm = frames(n, seed=1)
    n, h, w = rgb.shape[:3]
    stamps = np.asarray(stamps_ns if stamps_ns is not None else 1_700_000_000_000_000_000 + np.arange(n) * period_ns)
    parts = [range(n // 2), range(n // 2, n)] if split else [range(n)]
    for k, part in enumerate(parts):
        writer = Writer(directory if k == 0 else directory.with_name(directory.name + f"_{k}"), version=8,
                        storage_plugin=StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3)
        if compression:
            writer.set_compression(CompressionMode[compression.upper()], CompressionFormat.ZSTD)
        with writer as wr:
            topics = [(f"{prefix}/color/image_raw", Image), (f"{prefix}/aligned_depth_to_color/image_raw", Image),
                      (f"{prefix}/color/camera_info", CameraInfo)]
            order = [0, 1, 2] if k == 0 else [2, 0, 1]  # the second file of a split bag numbers its channels anew
            conns = {i: wr.add_connection(topics[i][0], topics[i][1].__msgtype__, typestore=ts) for i in order}
            c_img, c_dep, c_inf = conns[0], conns[1], conns[2]
            if tf and k == 0:
                TFMessage, Stamped = T["tf2_msgs/msg/TFMessage"], T["geometry_msgs/msg/TransformStamped"]
                Tf, V3, Q = T["geometry_msgs/msg/Transform"], T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
                c_tf = wr.add_connection("/tf_static", TFMessage.__msgtype__, typestore=ts)
                msg = TFMessage([Stamped(Header(Time(sec=int(stamps[0] // 10**9), nanosec=0), parent), child,
                                         Tf(V3(*map(float, xyz)), Q(*map(float, q)))) for parent, child, xyz, q in tf])
                wr.write(c_tf, int(stamps[0]), ts.serialize_cdr(msg, TFMessage.__msgtype__))
            for t in part:
                ns = int(stamps[t])
                hdr = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="camera_color_optical_frame")
                log_time = ns + 5_000_000  # the recorder's clock, later than the stamp
                img = rgb[t][:, :, ::-1] if encoding == "bgr8" else rgb[t]
                wr.write(c_img, log_time, ts.serialize_cdr(Image(hdr, h, w, encoding, 0, w * 3, np.ascontiguousarray(img).reshape(-1)),
                                                           Image.__msgtype__))
                padded = np.zeros((h, w * 2 + 8), np.uint8)
                padded[:, : w * 2] = depth_mm[t].astype(">u2").view(np.uint8).reshape(h, w * 2)
                wr.write(c_dep, log_time + 1000, ts.serialize_cdr(Image(hdr, h, w, "16UC1", 1, w * 2 + 8, padded.reshape(-1)),
                                                                  Image.__msgtype__))
                info = CameraInfo(hdr, h, w, "plumb_bob", np.zeros(5), K.ravel(), np.eye(3).ravel(),
                                  np.concatenate([K, np.zeros((3, 1))], 1).ravel(), 0, 0, Roi(0, 0, 0, 0, False))
                wr.write(c_inf, log_time, ts.serialize_cdr(info, CameraInfo.__msgtype__))
    if split:
        _merge_split(directory, directory.with_name(directory.name + "_1"))
    return rgb, depth_mm


def _merge_split(first: Path, second: Path) -> None:
    """Make ``first`` a split bag of two files, as ``ros2 bag record --max-bag-size`` does."""
    import yaml

    meta_path = first / "metadata.yaml"
    meta, meta2 = (yaml.safe_load((d / "metadata.yaml").read_text()) for d in (first, second))
    info, info2 = meta["rosbag2_bagfile_information"], meta2["rosbag2_bagfile_information"]
    (f2,) = info2["relative_file_paths"]
    name = f"{first.name}_1{Path(f2).suffix if not f2.endswith('.zstd') else ''.join(Path(f2).suffixes[-2:])}"
    (second / Path(f2).name).rename(first / name)
    info["relative_file_paths"].append(name)
    info["files"].append({**info2["files"][0], "path": name})
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info2["topics_with_message_count"]}
    for t in info["topics_with_message_count"]:
        t["message_count"] += counts.get(t["topic_metadata"]["name"], 0)
    info["message_count"] += info2["message_count"]
    meta_path.write_text(yaml.safe_dump(meta))
    for f in second.iterdir():
        f.unlink()
    second.rmdir()


def write_ros1_bag(path: Path, n: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A ROS 1 ``.bag`` as the RealSense ROS 1 driver's topics are recorded by ``rosbag record``."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    Image, Header, Time = T["sensor_msgs/msg/Image"], T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    CameraInfo, Roi = T["sensor_msgs/msg/CameraInfo"], T["sensor_msgs/msg/RegionOfInterest"]
    rgb, depth_mm = frames(n, seed=2)
    with Writer(path) as w:
        c_img = w.add_connection("/camera/color/image_raw", Image.__msgtype__, typestore=ts)
        c_dep = w.add_connection("/camera/aligned_depth_to_color/image_raw", Image.__msgtype__, typestore=ts)
        c_inf = w.add_connection("/camera/color/camera_info", CameraInfo.__msgtype__, typestore=ts)
        for t in range(n):
            ns = 1_700_000_000_000_000_000 + t * PERIOD
            hdr = Header(seq=t, stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="camera_color_optical_frame")
            w.write(c_img, ns, ts.serialize_ros1(Image(hdr, H, W, "rgb8", 0, W * 3, rgb[t].reshape(-1)), Image.__msgtype__))
            w.write(c_dep, ns, ts.serialize_ros1(Image(hdr, H, W, "16UC1", 0, W * 2, depth_mm[t].view(np.uint8).reshape(-1)),
                                                 Image.__msgtype__))
            info = CameraInfo(hdr, H, W, "plumb_bob", np.zeros(5), CAM.K.ravel(), np.eye(3).ravel(),
                              np.concatenate([CAM.K, np.zeros((3, 1))], 1).ravel(), 0, 0, Roi(0, 0, 0, 0, False))
            w.write(c_inf, ns, ts.serialize_ros1(info, CameraInfo.__msgtype__))
    return rgb, depth_mm
