"""Targets the poses cannot tell apart.

When several objects keep the same relative pose over a sub-task (the blocks on the table
while the hand reaches for one, a bucket and a canvas), the tool's trajectory is the same
up to one constant transform in each of their frames: π_l and β score them alike, and
only nearness (π_m's α) chooses among them, which says nothing about which object the
demonstrator aimed at. Such targets form an equivalence set: a label is right if it names
any member; training maximises the probability of the set, with the member chosen by how
well π_m explains the way-point in its frame (:func:`~hsp.policy.train.losses`), so that
EM settles one member consistently across episodes. No rule picks a member here.
"""

from __future__ import annotations

import numpy as np

from hsp.geometry.poses import relative, rotation_angle_deg
from hsp.labeling.metrics import boundaries


def rigid_with(world: np.ndarray, ok: np.ndarray, j: int, tol_m: float, tol_deg: float,
               share: float = 0.9) -> np.ndarray:
    """Objects that keep their pose relative to object j over frames ``world (T, n, 7)``:
    in ``share`` of the frames where both are tracked, within ``tol_m`` and ``tol_deg`` of
    a reference frame (the one nearest the median separation), so that a few frames of
    tracking glitch do not break a tower apart; j itself included; ``(n,)`` bool. The
    separation is measured along world axes, not in j's frame: there, a small nut's
    heading drifting 8° under the tracker would move a wheel 10 cm away by 14 mm. An
    object never tracked together with j is not rigid with it."""
    n = world.shape[1]
    both = ok & ok[:, j : j + 1]  # (T, n)
    rel = relative(world, np.broadcast_to(world[:, j : j + 1], world.shape))  # (T, n, 7): p[c, j]
    sep = world[..., :3] - world[:, j : j + 1, :3]  # (T, n, 3), world axes
    median = np.stack([np.median(sep[both[:, c], c], axis=0) if both[:, c].any() else np.zeros(3) for c in range(n)])
    off = np.where(both, np.linalg.norm(sep - median, axis=-1), np.inf)
    ref = off.argmin(axis=0)  # (n,)
    shift = np.linalg.norm(sep - sep[ref, np.arange(n)][None], axis=-1)
    turn = rotation_angle_deg(rel[..., 3:], rel[ref, np.arange(n), 3:][None])
    kept = np.where(both, (shift <= tol_m) & (turn <= tol_deg), False).sum(axis=0)
    return both.any(axis=0) & (kept >= share * both.sum(axis=0))


def equivalent_targets(world: np.ndarray, ok: np.ndarray, tool: np.ndarray, target: np.ndarray, tol_m: float,
                       tol_deg: float) -> np.ndarray:
    """Per frame, the objects rigid with its labelled target over the run of one (tool,
    target) pair it belongs to (:func:`rigid_with`), the target itself included and never
    the end-effector 0 or the tool: ``(H, n)`` bool."""
    H, n = world.shape[:2]
    cut = np.r_[0, boundaries(tool, target), H]
    out = np.zeros((H, n), bool)
    for a, b in zip(cut[:-1], cut[1:]):  # one per sub-task, not per frame
        members = rigid_with(world[a:b], ok[a:b], target[a], tol_m, tol_deg)
        members[[0, tool[a]]] = False
        members[target[a]] = True
        out[a:b] = members
    return out
