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


def gripper_closed(world: np.ndarray, ok: np.ndarray, moving_m: float, grasp_m: float) -> np.ndarray:
    """g_t ``(H,)`` from world poses ``(H, n, 7)`` and tracked flags ``(H, n)``.

    A step t → t+1 *carries* object j when j moves more than ``moving_m`` while its offset
    from the end-effector, r_t = x_j − x_0, changes by less. The gripper is closed over
    every run of steps in which a carried object keeps moving (a fast hand's tracked block
    lags it by centimetres, so r_t wanders; a block does not move by itself) and opens where
    the object comes to rest; it is closed too back from the first step s of such a run over
    the steps where r_t is still within ``grasp_m`` of r_s (the hand was already where it
    lifts from: a robot closes where the hand arrived, whatever the tracked hand's jitter at
    rest), and between two such runs of the same object when r_t stays within ``grasp_m``
    all along (a pause while holding). Steps touching a lost pose continue a run between
    observed moving steps but neither start nor end one, and a lost r_t ends the look-back."""
    H, n = world.shape[:2]
    closed = np.zeros(H, bool)
    if H < 2:
        return closed
    x = world[:, :, :3]
    r = x[:, 1:] - x[:, :1]  # (H, n-1, 3)
    tracked = ok[:, 1:] & ok[:, :1]  # (H, n-1)
    observed = tracked[1:] & tracked[:-1]
    move = np.linalg.norm(np.diff(x[:, 1:], axis=0), axis=-1) > moving_m  # (H-1, n-1)
    carried = move & (np.linalg.norm(np.diff(r, axis=0), axis=-1) < moving_m) & observed
    moving = move | ~observed
    for j in range(n - 1):
        edges = np.diff(np.r_[0, moving[:, j].astype(np.int8), 0])
        runs = []
        for s, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            if carried[s:e, j].any():
                seen = np.flatnonzero(move[s:e, j] & observed[s:e, j])
                runs.append((s + seen[0], s + seen[-1] + 1))
        for k, (s, e) in enumerate(runs):
            closed[s:e] = True
            away = ~tracked[:, j] | (np.linalg.norm(r[:, j] - r[s, j], axis=-1) >= grasp_m)
            closed[np.r_[-1, np.flatnonzero(away[:s])].max() + 1:s] = True
            if k + 1 < len(runs):
                gap = slice(e, runs[k + 1][0])
                closed[gap] |= not (tracked[gap, j] & (np.linalg.norm(r[gap, j] - r[e, j], axis=-1) >= grasp_m)).any()
    closed[-1] = closed[-2]
    return closed


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


def episode_arrays(world: np.ndarray, status: np.ndarray, symmetries: list[str], moving_m: float,
                   grasp_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """o_t, a_t, g_t and a_t observed of one episode of world poses ``(H, n, 7)`` and tracking
    status ``(H, n)``."""
    ok = status != TrackStatus.LOST
    observed = np.zeros(len(world), bool)
    observed[:-1] = ok[:-1, 0] & ok[1:, 0]
    grip = gripper_closed(world, ok, moving_m, grasp_m)
    return (flat_observation(canonical_poses(world, symmetries)), actions(world[:, 0], status[:, 0]), grip, observed)


def load_demonstrations(task: Task, dataset_dir: Path, moving_m: float, grasp_m: float
                        ) -> tuple[Demonstrations, list[np.ndarray]]:
    """Every episode of a pose dataset of ``task`` as :class:`Demonstrations`, and the
    episodes' world poses ``(H, n, 7)``."""
    poses, status, meta = load_episodes(dataset_dir, task.name, task.names)
    if not poses:
        raise HspError(f"{dataset_dir}: the dataset holds no episodes")
    symmetries = [o.symmetry for o in task.objects]
    parts = [episode_arrays(w, s, symmetries, moving_m, grasp_m) for w, s in zip(poses, status)]
    return Demonstrations(*(list(x) for x in zip(*parts)), fps=int(meta["fps"])), poses
