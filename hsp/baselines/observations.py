"""What the low-level baselines see and do, from the same pose datasets as the hierarchy.

* o_t, the flat observation: every object's world pose, e_t first (the dataset's
  ``observation.state`` then ``observation.environment_state``), each as its position and
  the first two columns of its rotation matrix (continuous, where a quaternion jumps
  between q and −q), symmetric objects' orientations made canonical as the hierarchy sees
  them (:func:`~hsp.labeling.label.canonical_poses`); ``(9n,)``.
* a_t, the dataset's ``action``: e_t's change to the next frame (world translation and
  rotation vector, :func:`~hsp.dataset.writer.actions`); ``(6,)``.
* g_t, the gripper (:func:`gripper_closed`): a hand demonstration has no gripper signal;
  this is the one a robot would have needed, read from the poses alone.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.dataset.features import TrackStatus
from hsp.dataset.reader import load_episodes
from hsp.dataset.writer import actions
from hsp.errors import HspError
from hsp.labeling.label import canonical_poses
from hsp.tasks.registry import Task

POSE_FEATURES = 9
"""Per object: position (3) and two columns of the rotation matrix (6)."""


def flat_observation(world: np.ndarray) -> np.ndarray:
    """o_t ``(..., 9n)`` from world poses ``(..., n, 7)`` (orientations already canonical)."""
    R = Rotation.from_quat(world[..., 3:].reshape(-1, 4)).as_matrix()[:, :, :2]
    per_object = np.concatenate([world[..., :3], R.reshape(world.shape[:-1] + (6,))], axis=-1)
    return per_object.reshape(world.shape[:-2] + (-1,))


LIFT_LAG = 3
"""Steps after the hand leaves a rest within which the object must start moving with it
for the rest to count as the grasp, and steps the hand must move away from every object
to count as a release (a tracked object at rest lags its carrier by up to two frames)."""


def gripper_closed(world: np.ndarray, ok: np.ndarray, moving_m: float) -> np.ndarray:
    """g_t ``(H,)`` from world poses ``(H, n, 7)`` and tracked flags ``(H, n)``. The step
    t → t+1 closes the gripper when an object moves more than ``moving_m`` while its offset
    from the end-effector changes by less (it is carried), and so does every step of the
    end-effector's rest just before it starts such a carry (a robot closes where the hand
    arrived, not once the object is in the air); the gripper opens when the end-effector
    moves that much away from every object while none moves, for ``LIFT_LAG`` steps in a row
    (it left what it held; a tracked block held at rest lags the lift by two frames).
    Between such steps g_t keeps its last value: a pause while holding keeps holding.
    Steps touching a lost pose say nothing."""
    H = len(world)
    if H < 2:
        return np.zeros(H, bool)
    x = world[:, :, :3]
    move = np.linalg.norm(np.diff(x, axis=0), axis=-1)  # (H-1, n)
    offset = np.linalg.norm(np.diff(x[:, 1:] - x[:, :1], axis=0), axis=-1)  # (H-1, n-1)
    tracked = ok[1:] & ok[:-1]
    carried = ((move[:, 1:] > moving_m) & (offset < moving_m) & tracked[:, 1:] & tracked[:, :1]).any(axis=1)
    hand = (move[:, 0] > moving_m) & tracked[:, 0]
    steps = np.arange(H - 1)
    leaves = np.minimum.accumulate(np.where(hand, steps, H - 1)[::-1])[::-1]  # first step ≥ t the hand moves
    soon = np.r_[np.cumsum(carried), np.full(LIFT_LAG + 1, carried.sum())]
    carried_soon = soon[steps + LIFT_LAG] - np.r_[0, soon[:H - 2]] > 0  # a carry within [t, t + LIFT_LAG]
    grasp = ~hand & carried_soon[np.minimum(leaves, H - 2)] & (leaves < H - 1)
    still = ~((move[:, 1:] > moving_m) & tracked[:, 1:]).any(axis=1)
    leaving = hand & still & (offset > moving_m).all(axis=1) & tracked.all(axis=1)  # from objects at rest
    run = np.r_[np.cumsum(leaving), np.full(LIFT_LAG, leaving.sum())]
    alone = run[steps + LIFT_LAG - 1] - np.r_[0, run[:H - 2]] == np.minimum(LIFT_LAG, H - 1 - steps)  # all leaving
    event = np.where(carried | grasp, 1, np.where(alone, -1, 0))
    last = np.maximum.accumulate(np.where(event != 0, steps, -1))
    closed = np.where(last >= 0, event[np.maximum(last, 0)] == 1, False)
    return np.append(closed, closed[-1])


@dataclass
class Demonstrations:
    """Per episode: o_t ``(H, 9n)``, a_t ``(H, 6)``, g_t ``(H,)`` and whether a_t was
    observed (e_t tracked at t and t + 1) ``(H,)``."""

    obs: list[np.ndarray]
    action: list[np.ndarray]
    grip: list[np.ndarray]
    observed: list[np.ndarray]
    fps: int

    def __len__(self) -> int:
        return len(self.obs)

    def subset(self, idx: list[int]) -> "Demonstrations":
        return Demonstrations(*([getattr(self, k)[i] for i in idx] for k in ("obs", "action", "grip", "observed")),
                              fps=self.fps)


def episode_arrays(world: np.ndarray, status: np.ndarray, symmetries: list[str], moving_m: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """o_t, a_t, g_t and a_t observed of one episode of world poses ``(H, n, 7)`` and tracking
    status ``(H, n)``."""
    ok = status != TrackStatus.LOST
    observed = np.zeros(len(world), bool)
    observed[:-1] = ok[:-1, 0] & ok[1:, 0]
    grip = gripper_closed(world, ok, moving_m)
    return (flat_observation(canonical_poses(world, symmetries)), actions(world[:, 0], status[:, 0]), grip, observed)


def load_demonstrations(task: Task, dataset_dir: Path, moving_m: float) -> tuple[Demonstrations, list[np.ndarray]]:
    """Every episode of a pose dataset of ``task`` as :class:`Demonstrations`, and the
    episodes' world poses ``(H, n, 7)``."""
    poses, status, meta = load_episodes(dataset_dir, task.name, task.names)
    if not poses:
        raise HspError(f"{dataset_dir}: the dataset holds no episodes")
    symmetries = [o.symmetry for o in task.objects]
    parts = [episode_arrays(w, s, symmetries, moving_m) for w, s in zip(poses, status)]
    return Demonstrations(*(list(x) for x in zip(*parts)), fps=int(meta["fps"])), poses
