"""Writing one episode as an MCAP file (profile ``ros2``, CDR messages, zstd chunks with
CRCs, data CRC, full indexes, one ``hsp`` metadata record)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic

from hsp.fileio import atomic_path
from hsp.recording.messages import (
    CAMERA_INFO,
    COLOR_FRAME,
    COLOR_IMAGE,
    COLOR_INFO,
    DEPTH_IMAGE,
    DEPTH_INFO,
    GROUND_TRUTH_POSES,
    GROUND_TRUTH_SUBTASK,
    IMAGE,
    SUBTASK,
    TF_MESSAGE,
    TF_STATIC,
)
from hsp.sim.camera import CameraConfig, sample_camera_pose
from hsp.sim.demonstration import Demonstration
from hsp.sim.depth_noise import DepthNoiseConfig, add_depth_noise
from hsp.sim.render import RgbdRenderer, load_mesh
from hsp.tasks.registry import Task

WORLD_FRAME = "world"


class Ros2McapWriter:
    """Thin layer over ``mcap.writer.Writer`` that encodes ROS 2 messages with
    ``mcap_ros2``'s dynamic CDR serialiser."""

    def __init__(self, stream: Any, chunk_size: int = 1 << 20) -> None:
        self._writer = Writer(stream, chunk_size=chunk_size, compression=CompressionType.ZSTD, enable_crcs=True,
                              enable_data_crcs=True)
        self._writer.start(profile="ros2", library="hsp")
        self._channels: dict[str, tuple[int, Any]] = {}
        self._schemas: dict[str, tuple[int, Any]] = {}

    def _channel(self, topic: str, msgdef: tuple[str, str]) -> tuple[int, Any]:
        if topic not in self._channels:
            name, text = msgdef
            if name not in self._schemas:
                sid = self._writer.register_schema(name, "ros2msg", text.encode())
                self._schemas[name] = (sid, serialize_dynamic(name, text)[name])
            sid, encode = self._schemas[name]
            self._channels[topic] = (self._writer.register_channel(topic, "cdr", sid), encode)
        return self._channels[topic]

    def write(self, topic: str, msgdef: tuple[str, str], message: dict, stamp_ns: int, sequence: int = 0) -> None:
        cid, encode = self._channel(topic, msgdef)
        self._writer.add_message(cid, log_time=stamp_ns, data=encode(message), publish_time=stamp_ns, sequence=sequence)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, data)

    def finish(self) -> None:
        self._writer.finish()


def stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _xyz(v: np.ndarray) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quat(q: np.ndarray) -> dict:
    return {"x": float(q[0]), "y": float(q[1]), "z": float(q[2]), "w": float(q[3])}


def camera_info(cam: CameraConfig, header: dict) -> dict:
    """``sensor_msgs/CameraInfo`` of an undistorted pinhole (``plumb_bob`` with zero d)."""
    K = cam.K
    P = np.concatenate([K, np.zeros((3, 1))], axis=1)
    return {
        "header": header, "height": cam.height, "width": cam.width, "distortion_model": "plumb_bob",
        "d": [0.0] * 5, "k": K.ravel().tolist(), "r": np.eye(3).ravel().tolist(), "p": P.ravel().tolist(),
        "binning_x": 0, "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def image_msg(header: dict, image: np.ndarray, encoding: str) -> dict:
    h, w = image.shape[:2]
    return {"header": header, "height": h, "width": w, "encoding": encoding, "is_bigendian": 0,
            "step": image.strides[0], "data": np.ascontiguousarray(image).tobytes()}


@dataclass(frozen=True)
class CameraRig:
    """What the recording camera is: intrinsics, pose distribution, depth sensor model."""

    camera: CameraConfig
    noise: DepthNoiseConfig


def write_episode(path: Path, task: Task, demo: Demonstration, episode: int, rig: CameraRig | None = None) -> None:
    """Write one demonstration atomically: ground truth, and with a ``rig`` the RealSense
    streams (colour, aligned depth, camera info, camera pose on ``/tf_static``)."""
    rng = np.random.default_rng([demo.seed, 1])  # camera pose and sensor noise, apart from the demo's stream
    renderer = RgbdRenderer([load_mesh(task.mesh(i)) for i in range(len(task.objects))], rig.camera) if rig else None
    T_world_cam = sample_camera_pose(rig.camera, rng) if rig else None
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = Ros2McapWriter(f)
        w.metadata(
            "hsp",
            {
                "camera": json.dumps(rig is not None),
                "depth_unit": "mm",
                "depth_noise": json.dumps(asdict(rig.noise) if rig else None),
                "source": "simulation",
                "task": task.name,
                "episode": str(episode),
                "seed": str(demo.seed),
                "fps": str(demo.fps),
                "frames": str(demo.frames),
                "objects": json.dumps(task.names),
                "labels": json.dumps(task.labels),
                "demonstrator_success": json.dumps(bool(demo.success)),
            },
        )
        if rig is not None:
            w.write(TF_STATIC, TF_MESSAGE, {"transforms": [{
                "header": {"stamp": stamp(0), "frame_id": WORLD_FRAME}, "child_frame_id": COLOR_FRAME,
                "transform": {"translation": _xyz(T_world_cam[:3]), "rotation": _quat(T_world_cam[3:])},
            }]}, 0)
        period = 1_000_000_000 // demo.fps
        for t in range(demo.frames):
            ns = t * period
            if rig is not None:
                rgb, depth, _ = renderer.render(T_world_cam, demo.poses[t])  # type: ignore[union-attr]
                depth_mm = add_depth_noise(depth, rig.camera.fx, rig.noise, rng)
                cam_header = {"stamp": stamp(ns), "frame_id": COLOR_FRAME}
                w.write(COLOR_IMAGE, IMAGE, image_msg(cam_header, rgb, "rgb8"), ns, t)
                w.write(DEPTH_IMAGE, IMAGE, image_msg(cam_header, depth_mm, "16UC1"), ns, t)
                w.write(COLOR_INFO, CAMERA_INFO, camera_info(rig.camera, cam_header), ns, t)
                w.write(DEPTH_INFO, CAMERA_INFO, camera_info(rig.camera, cam_header), ns, t)
            header = {"stamp": stamp(ns), "frame_id": WORLD_FRAME}
            transforms = [
                {"header": header, "child_frame_id": name, "transform": {"translation": _xyz(P[:3]), "rotation": _quat(P[3:])}}
                for name, P in zip(task.names, demo.poses[t])
            ]
            w.write(GROUND_TRUTH_POSES, TF_MESSAGE, {"transforms": transforms}, ns, t)
            tool, target = int(demo.tool[t]), int(demo.target[t])
            w.write(
                GROUND_TRUTH_SUBTASK,
                SUBTASK,
                {
                    "header": {"stamp": stamp(ns), "frame_id": task.names[target]},
                    "tool": tool,
                    "target": target,
                    "tool_name": task.names[tool],
                    "target_name": task.names[target],
                    "waypoint_index": int(demo.waypoint_index[t]),
                    "waypoint": {"position": _xyz(demo.waypoint[t, :3]), "orientation": _quat(demo.waypoint[t, 3:])},
                    "grasped": bool(demo.grasped[t]),
                },
                ns,
                t,
            )
        w.finish()
