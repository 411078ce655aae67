"""What the three networks see and predict, per frame of one labelled episode (paper, Section III).

Everything is relative: the observation z_t is p_t[i, j] for every (tool, target) pair, so
a policy does not depend on where the layout put the objects. Poses are ``[x, y, z, qx,
qy, qz, qw]`` with canonical orientations of symmetric objects (as the labels use).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hsp.geometry import inverse, rotvec_delta
from hsp.labeling.priors import pairs_of, relative_poses


@dataclass
class Steps:
    """One episode of ``H`` frames, every array float32 except ``pair``."""

    z: np.ndarray
    """z_t: p_t[i, j] of all ``P`` pairs, flattened ``(H, 7P)``."""
    history: np.ndarray
    """What the LSTM reads at t: the previous pair (one-hot) and way-point w_{t−1} ``(H, P + 7)``."""
    progress: np.ndarray
    """g_t = p_t[o+_{t−1}, o*_{t−1}] − w_{t−1} ``(H, 7)`` (zero at t = 0)."""
    pair: np.ndarray
    """(o+_t, o*_t) as an index into :func:`~hsp.labeling.priors.pairs_of` ``(H,)``."""
    classes: np.ndarray
    """Semantic labels of the pair's tool and target, one-hot each ``(H, 2C)``."""
    current: np.ndarray
    """p_t[o+_t, o*_t] ``(H, 7)``: the tool in the target's frame."""
    target_in_tool: np.ndarray
    """The target in the tool's frame ``(H, 7)`` (π_l's input)."""
    waypoint: np.ndarray
    """w_t ``(H, 7)``."""
    action: np.ndarray
    """a_t: the tool's step t → t+1 in the target's frame, translation and rotation vector ``(H, 6)`` (zero at the end)."""


def class_codes(classes: np.ndarray, n_classes: int, pairs: np.ndarray) -> np.ndarray:
    """One-hot semantic labels of each pair's tool and target ``(P, 2C)``."""
    out = np.zeros((len(pairs), 2 * n_classes), np.float32)
    rows = np.arange(len(pairs))
    out[rows, classes[pairs[:, 0]]] = 1.0
    out[rows, n_classes + classes[pairs[:, 1]]] = 1.0
    return out


def pair_poses(world: np.ndarray) -> np.ndarray:
    """p_t[i, j] of every pair of :func:`~hsp.labeling.priors.pairs_of` ``(H, P, 7)``."""
    pairs = pairs_of(world.shape[1])
    return relative_poses(world)[:, pairs[:, 0], pairs[:, 1]]


def memory_inputs(rel: np.ndarray, pair: np.ndarray, waypoint: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The LSTM's input (previous pair one-hot, w_{t−1}) and g_t, ``(H, P + 7)`` and
    ``(H, 7)``, from the pairs' poses ``rel`` ``(H, P, 7)`` and labels ``pair`` ``(H,)``,
    ``waypoint`` ``(H, 7)``, shifted one frame."""
    H, P = rel.shape[:2]
    history = np.zeros((H, P + 7), np.float32)
    progress = np.zeros((H, 7), np.float32)
    if H > 1:
        history[np.arange(1, H), pair[:-1]] = 1.0
        history[1:, P:] = waypoint[:-1]
        progress[1:] = rel[np.arange(1, H), pair[:-1]] - waypoint[:-1]
    return history, progress


def episode_steps(world: np.ndarray, pair: np.ndarray, waypoint_index: np.ndarray, classes: np.ndarray,
                  n_classes: int) -> Steps:
    """:class:`Steps` of one episode from canonical world poses ``(H, n, 7)`` and its labels:
    pair index per frame ``(H,)`` and way-point frame k ``(H,)`` (w_t = p_k[o+_t, o*_t])."""
    H, n = world.shape[:2]
    pairs = pairs_of(n)
    rel = pair_poses(world)
    t = np.arange(H)
    current = rel[t, pair]
    waypoint = rel[waypoint_index, pair]
    history, progress = memory_inputs(rel, pair, waypoint)
    action = np.zeros((H, 6))
    if H > 1:  # the step of the same pair's relative pose, as the low level would have to command it
        action[:-1] = rotvec_delta(current[:-1], rel[t[1:], pair[:-1]])
    f32 = np.float32
    return Steps(rel.reshape(H, -1).astype(f32), history, progress, pair.astype(np.int64),
                 class_codes(classes, n_classes, pairs)[pair], current.astype(f32), inverse(current).astype(f32),
                 waypoint.astype(f32), action.astype(f32))
