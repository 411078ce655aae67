"""Reading the ground-truth topics of a recording back into arrays.

Only evaluation, the supervised variant and the ``--poses-from ground-truth`` ablation may
call this; the tracker and the labeller never do.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hsp.errors import HspError
from hsp.recording.messages import GROUND_TRUTH_POSES, GROUND_TRUTH_SUBTASK


@dataclass
class GroundTruth:
    """Per-frame truth of one episode: ``T`` frames, ``n`` objects."""

    metadata: dict[str, str]
    stamps_ns: np.ndarray
    poses: np.ndarray
    """World poses ``(T, n, 7)`` in the order of ``objects``."""
    objects: list[str]
    tool: np.ndarray
    target: np.ndarray
    waypoint: np.ndarray
    waypoint_index: np.ndarray
    grasped: np.ndarray


def read_ground_truth(path: Path) -> GroundTruth:
    """Decode ``/hsp/ground_truth/*`` of an MCAP file; CRCs are checked."""
    path = Path(path)
    poses: dict[int, list] = {}
    sub: dict[int, dict] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()], validate_crcs=True)
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}.get("hsp", {})
            for _, channel, message, msg in reader.iter_decoded_messages(topics=[GROUND_TRUTH_POSES, GROUND_TRUTH_SUBTASK]):
                if channel.topic == GROUND_TRUTH_POSES:
                    poses[message.log_time] = [
                        (tf.child_frame_id, [tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z,
                                             tf.transform.rotation.x, tf.transform.rotation.y, tf.transform.rotation.z,
                                             tf.transform.rotation.w])
                        for tf in msg.transforms
                    ]
                else:
                    p, q = msg.waypoint.position, msg.waypoint.orientation
                    sub[message.log_time] = {
                        "tool": msg.tool, "target": msg.target, "waypoint_index": msg.waypoint_index,
                        "waypoint": [p.x, p.y, p.z, q.x, q.y, q.z, q.w], "grasped": msg.grasped,
                    }
    except (McapError, OSError, ValueError, zstandard.ZstdError, RuntimeError) as e:  # lz4: RuntimeError
        raise HspError(f"{path}: cannot read ground truth: {e}") from None
    if not poses:
        raise HspError(f"{path}: no messages on {GROUND_TRUTH_POSES}")
    stamps = np.array(sorted(poses))
    objects = [name for name, _ in poses[stamps[0]]]
    missing = [int(s) for s in stamps if s not in sub]
    if missing:
        raise HspError(f"{path}: {len(missing)} frames have poses but no {GROUND_TRUTH_SUBTASK} message")
    return GroundTruth(
        metadata=meta,
        stamps_ns=stamps,
        poses=np.array([[v for _, v in poses[s]] for s in stamps]),
        objects=objects,
        tool=np.array([sub[s]["tool"] for s in stamps]),
        target=np.array([sub[s]["target"] for s in stamps]),
        waypoint=np.array([sub[s]["waypoint"] for s in stamps]),
        waypoint_index=np.array([sub[s]["waypoint_index"] for s in stamps]),
        grasped=np.array([sub[s]["grasped"] for s in stamps]),
    )


def episode_objects(meta: dict[str, str]) -> list[str]:
    return json.loads(meta.get("objects", "[]"))


def matching_ground_truth(path: Path, objects: list[str], frames: int) -> GroundTruth | None:
    """The recording's ground truth if it has one for these ``objects`` and ``frames``, else
    ``None`` (a real camera's recording has none; scoring and overlays then go without)."""
    try:
        gt = read_ground_truth(path)
    except HspError:
        return None
    return gt if gt.objects == objects and len(gt.poses) == frames else None
