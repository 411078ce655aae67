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
              drop_depth: tuple[int, ...] = (), color_topic: str = COLOR_IMAGE, chunk_size: int = 1 << 20) -> tuple[np.ndarray, np.ndarray]:
    """A bag of ``n`` frames; returns the colour and depth (mm) that went in."""
    rgb, depth_mm = frames(n)
    with open(path, "wb") as f:
        w = Ros2McapWriter(f, chunk_size=chunk_size)  # small chunks make single-chunk damage testable
        for t in range(n):
            ns = 1_700_000_000_000_000_000 + t * PERIOD
            header = {"stamp": stamp(ns), "frame_id": "camera_color_optical_frame"}
            if color:
                img = rgb[t][:, :, ::-1] if color_encoding == "bgr8" else rgb[t]
                w.write(color_topic, IMAGE, image_msg(header, np.ascontiguousarray(img), color_encoding), ns, t)
            if depth and t not in drop_depth:
                d_header = {"stamp": stamp(ns + depth_offset_ns), "frame_id": "camera_color_optical_frame"}
                d = depth_mm[t] if depth_shape == (H, W) else np.zeros(depth_shape, np.uint16)
                w.write(DEPTH_IMAGE, IMAGE, image_msg(d_header, d, "16UC1"), ns + depth_offset_ns, t)
            if info:
                w.write(COLOR_INFO, CAMERA_INFO, camera_info(CAM, header), ns, t)
        w.finish()
    return rgb, depth_mm


def write_rosbags_bag(directory: Path, n: int = 6, prefix: str = "/camera/camera") -> tuple[np.ndarray, np.ndarray]:
    """A rosbag2 directory (metadata.yaml + .mcap) written by the ``rosbags`` package, with
    big-endian depth rows padded beyond their width (``step`` > width × 2)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    Image, Header, Time = ts.types["sensor_msgs/msg/Image"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    CameraInfo, Roi = ts.types["sensor_msgs/msg/CameraInfo"], ts.types["sensor_msgs/msg/RegionOfInterest"]
    rgb, depth_mm = frames(n, seed=1)
    with Writer(directory, version=8, storage_plugin=StoragePlugin.MCAP) as w:
        c_img = w.add_connection(f"{prefix}/color/image_raw", Image.__msgtype__, typestore=ts)
        c_dep = w.add_connection(f"{prefix}/aligned_depth_to_color/image_raw", Image.__msgtype__, typestore=ts)
        c_inf = w.add_connection(f"{prefix}/color/camera_info", CameraInfo.__msgtype__, typestore=ts)
        for t in range(n):
            ns = 1_700_000_000_000_000_000 + t * PERIOD
            hdr = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="camera_color_optical_frame")
            log_time = ns + 5_000_000  # the recorder's clock, later than the stamp
            w.write(c_img, log_time, ts.serialize_cdr(Image(hdr, H, W, "rgb8", 0, W * 3, rgb[t].reshape(-1)), Image.__msgtype__))
            padded = np.zeros((H, W * 2 + 8), np.uint8)
            padded[:, : W * 2] = depth_mm[t].astype(">u2").view(np.uint8).reshape(H, W * 2)
            w.write(c_dep, log_time + 1000, ts.serialize_cdr(Image(hdr, H, W, "16UC1", 1, W * 2 + 8, padded.reshape(-1)), Image.__msgtype__))
            info = CameraInfo(hdr, H, W, "plumb_bob", np.zeros(5), CAM.K.ravel(), np.eye(3).ravel(),
                              np.concatenate([CAM.K, np.zeros((3, 1))], 1).ravel(), 0, 0, Roi(0, 0, 0, 0, False))
            w.write(c_inf, log_time, ts.serialize_cdr(info, CameraInfo.__msgtype__))
    return rgb, depth_mm
