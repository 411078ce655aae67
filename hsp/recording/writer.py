"""Writing one episode as an MCAP file (profile ``ros2``, CDR messages, zstd chunks with
CRCs, data CRC, full indexes, one ``hsp`` metadata record)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from mcap.writer import CompressionType, Writer
from mcap_ros2._dynamic import serialize_dynamic

from hsp.fileio import atomic_path
from hsp.recording.messages import GROUND_TRUTH_POSES, GROUND_TRUTH_SUBTASK, SUBTASK, TF_MESSAGE
from hsp.sim.demonstration import Demonstration
from hsp.tasks.registry import Task

WORLD_FRAME = "world"


class Ros2McapWriter:
    """Thin layer over ``mcap.writer.Writer`` that encodes ROS 2 messages with
    ``mcap_ros2``'s dynamic CDR serialiser."""

    def __init__(self, stream: Any) -> None:
        self._writer = Writer(stream, compression=CompressionType.ZSTD, enable_crcs=True, enable_data_crcs=True)
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


def write_episode(path: Path, task: Task, demo: Demonstration, episode: int) -> None:
    """Write ground-truth poses and sub-task annotation of one demonstration, atomically."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        w = Ros2McapWriter(f)
        w.metadata(
            "hsp",
            {
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
        period = 1_000_000_000 // demo.fps
        for t in range(demo.frames):
            ns = t * period
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
