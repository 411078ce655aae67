"""The dataset's feature schema (DESIGN.md, data contracts).

``observation.state`` is the end-effector pose e_t (7), ``observation.environment_state``
the world poses of the other objects flattened to 1-D (LeRobot's ACT and Diffusion Policy
train on it without images, and ≥ 2-D features break LeRobot's dataset tools), ``action``
the change a_t of e_t to the next frame (translation in the world frame + rotation vector),
``tracking_status`` one code per object. Object names, labels and symmetries
ride along in the feature metadata; each episode's source in :data:`EPISODE_SOURCES`.
"""

from __future__ import annotations

from enum import IntEnum

from hsp.tasks.registry import Task

POSE_NAMES = ["x", "y", "z", "qx", "qy", "qz", "qw"]
ACTION_NAMES = ["dx", "dy", "dz", "rx", "ry", "rz"]
STATE = "observation.state"
ENV_STATE = "observation.environment_state"
ACTION = "action"
STATUS = "tracking_status"
"""Not an ``observation.*`` key: LeRobot's policies take every one of those as an input."""
EPISODE_SOURCES = "meta/hsp_episodes.jsonl"
"""One line per episode: the recording it came from (its name within the recordings folder)
and the table frame it was tracked in, ``T_world_cam`` and how it was found. LeRobot's own
episode metadata has no place for them."""


class TrackStatus(IntEnum):
    """Per object and frame: how far the pose can be trusted."""

    OK = 0
    SUSPECT = 1
    LOST = 2
    """No pose: the stored pose is the last good one and must not be used as data."""


def features(task: Task) -> dict[str, dict]:
    names, labels = task.names, task.labels
    return {
        STATE: {"dtype": "float32", "shape": (7,), "names": POSE_NAMES, "object": names[0], "label": labels[0]},
        ENV_STATE: {
            "dtype": "float32",
            "shape": (7 * (len(names) - 1),),
            "names": [f"{o}.{c}" for o in names[1:] for c in POSE_NAMES],
            "objects": names[1:],
            "labels": labels[1:],
            "symmetries": [o.symmetry for o in task.objects[1:]],
        },
        ACTION: {"dtype": "float32", "shape": (6,), "names": ACTION_NAMES},
        STATUS: {"dtype": "int64", "shape": (len(names),), "names": names,
                 "codes": {s.name.lower(): int(s) for s in TrackStatus}},
    }
