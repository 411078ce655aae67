"""Targets the poses cannot tell apart.

When several objects keep the same relative pose over a sub-task (blocks of a tower, a
bucket and a canvas on the table), the tool's trajectory is the same up to one constant
transform in each of their frames, so π_l and β score them alike and only the α term of
π_m chooses among them: it multiplies the tool's nearness over every way-point of the
sub-task, so a block that hovers over the pattern nearer the neighbouring tower than the
block it is then lowered beside is put relative to the tower. The tie is broken by the
closest approach instead: the rigid candidate the tool comes nearest at any one of the
sub-task's way-points (the frames it is still at relative to its target) is the target.
Three motions aim at no nearest object and are put relative to the object they belong to:
the hand's retreat from an object it has just let go of (rising from a block set beside a
tower, it ends nearer the tower); a tool's retreat from where it was at work (a brush
lifted out of the bucket, a wrench rising from a nut), which ends that work; and a lift,
which ends nearer some block on the table than the support the carry then goes to.
Viterbi's segmentation and tools are kept; only the target among rigid equivalents moves.

These rules encode the scripted demonstrator's conventions. They apply to the labels over
the hand-set priors only; Viterbi over trained networks (EM) has no rule layer after it,
so the networks can overrule them. Without them (each sub-task's target the member of its
equivalence set that Viterbi's nearness chose, :mod:`~hsp.labeling.equivalence`),
stacking-1's closed-loop success fell from 0.65 to 0.09 (session 16): those members are
not consistent across episodes.
"""

from __future__ import annotations

import numpy as np

from hsp.labeling.equivalence import rigid_with
from hsp.labeling.metrics import boundaries


def held_positions(world: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Positions ``(T, n, 3)`` with each object's frames without a pose (``ok`` false)
    given its position at the nearest frame in time where it was tracked (kept where it
    never was): a block covered by the one just set on it is still there."""
    T, n = ok.shape
    t = np.arange(T)[:, None]
    last = np.maximum.accumulate(np.where(ok, t, -1), axis=0)
    following = np.minimum.accumulate(np.where(ok, t, T)[::-1], axis=0)[::-1]
    src = np.where((following < T) & ((last < 0) | (following - t < t - last)), following, last)
    src = np.where(src < 0, t, src)
    return world[src, np.arange(n), :3]


def carried(world: np.ndarray, ok: np.ndarray, x: int, tol_m: float) -> bool:
    """Whether the end-effector (0) carried object x over frames ``world (T, n, 7)``: over
    the frames where both are tracked, x moved by more than ``tol_m`` and its separation
    from the end-effector changed by at most ``tol_m``, each measured between the medians
    of the first and the last quarter of those frames (a block in the hand jitters by up
    to 1 cm under the tracker; a glitch that moves a block while the hand is elsewhere
    changes the separation)."""
    both = ok[:, 0] & ok[:, x]
    if both.sum() < 2:
        return False
    pos, sep = world[both, x, :3], world[both, x, :3] - world[both, 0, :3]
    q = max(1, len(pos) // 4)
    moved = np.linalg.norm(np.median(pos[-q:], axis=0) - np.median(pos[:q], axis=0))
    slipped = np.linalg.norm(np.median(sep[-q:], axis=0) - np.median(sep[:q], axis=0))
    return bool(moved > tol_m >= slipped)


def resolve_target_ties(world: np.ndarray, ok: np.ndarray, tool: np.ndarray, target: np.ndarray, k: np.ndarray,
                        tol_m: float, tol_deg: float) -> np.ndarray:
    """o* per frame ``(H,)``, chosen among the objects rigid with the labelled target over
    each run of one (tool, target) pair (never the end-effector 0 or the tool):

    - a run of the end-effector right after a run of tool x that it :func:`carried` takes
      x: the hand retreats from what it let go of;
    - in a run right after one of the same tool, the leading way-points farther from every
      candidate than the tool was at the run's first frame (a retreat) take the candidate
      it was nearest there: the retreat ends the work before, as the demonstrator's
      annotation has it (the brush's lift with the dip; the wrench's turn and rise with the
      wheel when the nut, turning with the socket, is no candidate);
    - any other run, or the rest of it, takes the candidate nearest its way-points (the
      tool at frames k), each candidate where it sat beside the target during the run,
      since a way-point frame k may come after a block was set next to it (the labelled
      target when it is as near itself). After that closest approach, the first way-point
      nearer another candidate, and nearer it than the way-point before, starts the part
      of the run relative to that one, and so on: the wrench gone from the last nut to the
      wheel's centre, a stroke left in the run of the dip (Viterbi's γ outweighed π_m's
      nearness);
    - then, from the last run back, a run that only takes an object tool away from its
      target (nearer at the run's first frame than at any way-point: a lift) takes the
      target of the next run of the same tool when that one is a candidate: it is where
      the carry begins, not a sub-task aimed at whatever block it ends nearest. A run after
      one of the same tool is not a lift: its retreat was settled above.
    """
    cut = np.r_[0, boundaries(tool, target), len(tool)]
    runs = list(zip(cut[:-1], cut[1:]))
    previous = np.r_[-1, tool[cut[1:-1] - 1]]  # the tool of the run before each run (−1: none)
    out = target.copy()
    at = held_positions(world, ok)
    for r, (a, b) in enumerate(runs):
        i, j, f = tool[a], target[a], np.unique(k[a:b])
        candidates = rigid_with(world[a:b], ok[a:b], j, tol_m, tol_deg)
        candidates[[0, i]] = False
        candidates[j] = True
        x = previous[r] if i == 0 and previous[r] > 0 else 0  # the object the end-effector may have let go of
        if x and candidates[x] and carried(world[cut[r - 1] : a], ok[cut[r - 1] : a], x, tol_m):
            out[a:b] = x
            continue
        beside = np.median(at[a:b] - at[a:b, j : j + 1], axis=0)  # (n, 3): candidates' place by j in the run
        dist = np.linalg.norm((at[np.r_[a, f], i] - at[np.r_[a, f], j])[:, None] - beside, axis=-1)  # (1 + F, n)
        start, own = np.split(np.where(candidates, dist, np.inf), [1])
        back = 0
        if previous[r] == i:  # the tool was at work before: a retreat from there is its end
            back = int(np.cumprod(np.all(own[:, candidates] > start[:, candidates], axis=1)).sum())
            out[a:b][np.isin(k[a:b], f[:back])] = int(start.argmin())
        if back == len(f):
            continue
        f, own = f[back:], own[back:]
        near = own.min(axis=0)
        j = j if near[j] <= near.min() else int(near.argmin())
        out[a:b][np.isin(k[a:b], f)] = j
        for w in range(own[:, j].argmin() + 1, len(f)):  # the way-points after the closest approach
            c = int(own[w].argmin())
            if own[w, c] < min(own[w, j], own[w - 1, c]):  # nearer c than j, and coming nearer c
                j = c
            out[a:b][k[a:b] == f[w]] = j
    for r in range(len(runs) - 2, -1, -1):
        a, b = runs[r]
        i, j, following = tool[a], out[a], out[b]
        if i == 0 or tool[b] != i or following == j or previous[r] == i:
            continue
        f = np.r_[a, np.unique(k[a:b])]
        dist = np.linalg.norm(at[f, i] - at[f, j], axis=-1)
        if dist[1:].min() > dist[0] and rigid_with(world[a:b], ok[a:b], j, tol_m, tol_deg)[following]:
            out[a:b] = following
    return out
