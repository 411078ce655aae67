"""The initial π_h, π_m, π_l of the paper (Section IV-A) as Viterbi scores.

States are pairs p = (tool i, target j) with j ≠ end-effector and j ≠ i, and way-point
indices k ≥ t; ``rel[t, p]`` is p_t[i, j], the tool's pose in the target's frame.

* π_h (:meth:`PriorScores.unary`): the tool is the object moving most relative to the
  other objects (end-effector excluded from the comparison); when none moves more than
  ``moving_m`` per frame but the end-effector does, the end-effector is the tool. When
  nothing moves (a held object pausing with the hand looks exactly like a released one),
  the tool is the last one that moved: a pause ends the motion before it, and the next
  sub-task starts when something moves again, as the demonstrator's annotation has it.
  Before anything moves there is no evidence. The evidence is soft: the evidenced tool
  gets 1 − ε, every other object ε/(n−1). Translation only: a lug nut turning in place is
  not a tool. A target the tool drives (:func:`driven`: it moves or turns in the world
  while the tool keeps its pose relative to it, a nut turned by the socket) costs a
  further ε per frame: the tool's motion cannot be expressed in the frame of an object
  that moves along with it.
* π_m (:meth:`PriorScores.jump`): the paper's formula is ambiguous about normalisation.
  Read as: keep the previous way-point index with probability β (a transition, see
  :mod:`viterbi`), or jump to a later index k ≥ t with weight (1−β)/(H−t)·exp(−α‖ŵ_k‖),
  ‖ŵ_k‖ being the tool's distance to the target at frame k. The weights are left
  unnormalised over k, exactly as written, so nearness to the target (α = 100 per metre)
  is what makes a frame a way-point, not the number of candidate frames. A way-point is
  where a motion toward it ends, so only frames where the tool is still relative to the
  target (it moves less than ``moving_m`` per frame there, a turn counted as in π_l), or
  the last frame, can be one: otherwise every frame of a descent onto a block would be a
  candidate, each nearer the block beside it than the one below.
* π_l (:meth:`PriorScores.motion`): the observed step of the tool in the target frame,
  Δ = p_{t+1}[i, j] − p_t[i, j], is scored as Gaussian (σ = ``motion_sigma_m``) around a
  straight-line step of the same length toward the way-point, not overshooting it. The
  paper's straight line is in R³ × SO(3); here poses are points of R⁷, the position and
  the orientation quaternion (signs made continuous in time) times 2·``rotation_arm_m``,
  so that a turn by θ counts as the arc a point at that arm sweeps, arm·θ. Without the
  rotation a socket turning a nut reads as a pause: the turn would get no way-point.

Frames where an object is lost carry no evidence about it: its motion terms are 0 and
such frames cannot be way-points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hsp.geometry import relative
from hsp.geometry.poses import rotation_angle_deg

NEG = -np.inf


@dataclass(frozen=True)
class PriorConfig:
    gamma: float = 0.95
    """γ: probability of keeping the (tool, target) pair (paper, Section V-C)."""
    alpha: float = 100.0
    """α (1/m): preference for way-points where the tool is near the target."""
    beta: float = 0.95
    """β: probability of keeping the way-point index."""
    tool_epsilon: float = 0.01
    """ε: probability mass left for tools other than the motion evidence."""
    moving_m: float = 0.002
    """Per-frame relative translation (m) above which an object counts as moving."""
    moving_deg: float = 0.5
    """Per-frame rotation (degrees) above which an object counts as turning."""
    motion_sigma_m: float = 0.005
    """σ of π_l around the straight-line step (m per frame)."""
    rotation_arm_m: float = 0.05
    """A turn by θ (rad) counts as a step of ``rotation_arm_m``·θ in π_l and in stillness,
    the arc of a point this far from the frame's origin (about an object's radius)."""
    rigid_m: float = 0.01
    """Objects whose relative position stays within this over a sub-task (in 90 % of the
    frames) are rigid with each other there: the poses cannot tell which is the target,
    and they form its equivalence set (:mod:`~hsp.labeling.equivalence`). About a hand's
    jitter of a held block under the tracker."""
    rigid_deg: float = 15.0
    """... and whose relative orientation stays within this (degrees)."""
    heading_median_frames: int = 15
    """Objects' orientations (not the end-effector's) are median-filtered over this many
    frames before labelling: tracking glitches in a target's heading would read as the
    tool's motion (:func:`~hsp.labeling.label.median_headings`); 1 turns it off."""


def pairs_of(n: int) -> np.ndarray:
    """All (tool, target) index pairs, target ≠ 0 (end-effector) and ≠ tool: ``(P, 2)``."""
    return np.array([(i, j) for i in range(n) for j in range(1, n) if j != i])


def pair_indices(pairs: np.ndarray, tool: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Index into ``pairs`` of each (tool, target) ``(H,)``."""
    n = int(pairs.max()) + 1
    lookup = np.full((n, n), -1)
    lookup[pairs[:, 0], pairs[:, 1]] = np.arange(len(pairs))
    return lookup[tool, target]


def relative_poses(world: np.ndarray) -> np.ndarray:
    """p_t[i, j] for all objects: ``(H, n, n, 7)`` from world poses ``(H, n, 7)``."""
    H, n, _ = world.shape
    return relative(world[:, :, None, :].repeat(n, 2), world[:, None, :, :].repeat(n, 1))


def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(H, ..., 4)`` over time, each sign-flipped into the hemisphere of the
    one before (q and −q are one rotation), so that they change smoothly."""
    flip = np.sign(np.sum(q[1:] * q[:-1], axis=-1))
    flip[flip == 0] = 1.0
    sign = np.concatenate([np.ones((1,) + q.shape[1:-1]), np.cumprod(flip, axis=0)])
    return q * sign[..., None]


def pose_points(rel: np.ndarray, arm: float) -> np.ndarray:
    """Poses ``(H, ..., 7)`` over time as points of R⁷ in which straight lines and step
    lengths mean something: the position, and the continuous quaternion
    (:func:`continuous_quaternions`) times 2·``arm`` (the chord between unit quaternions
    is 2 sin(θ/4), so a small turn θ moves the point by arm·θ)."""
    return np.concatenate([rel[..., :3], 2.0 * arm * continuous_quaternions(rel[..., 3:])], axis=-1)


def tool_evidence(world: np.ndarray, ok: np.ndarray, moving_m: float, half_window: int = 2) -> np.ndarray:
    """Per frame: the object moving most relative to the other non-end-effector objects
    (mean per-frame change of their separation, world translation, so a rotating object
    does not make the others look as if they moved); 0 (end-effector) when no such object
    moves more than ``moving_m`` but the end-effector does; when everything is still, the
    last tool that moved (a pause belongs to the motion it ends), or −1 (no evidence)
    before anything has moved; ``(H,)``. Each change is averaged over ``half_window``
    frames either side: tracking jitter cancels, motion does not. While the last object
    that moved is lost, the end-effector's motion is no evidence either: the hand may be
    carrying it (a brush swung to the canvas faster than the tracker follows), so that
    object stays the tool."""
    H, n = world.shape[:2]
    x = world[:, :, :3]
    sep = x[:, :, None, :] - x[:, None, :, :]  # (H, n, n, 3)
    a = np.clip(np.arange(H - 1) - half_window, 0, H - 1)  # step t → t+1 measured over [t − w, t + 1 + w]
    b = np.clip(np.arange(H - 1) + 1 + half_window, 0, H - 1)
    change = np.linalg.norm(sep[b] - sep[a], axis=-1) / (b - a)[:, None, None]  # (H-1, n, n), per frame
    valid = ok[b] & ok[a]
    pair_ok = valid[:, :, None] & valid[:, None, :]
    pair_ok[:, np.arange(n), np.arange(n)] = False
    pair_ok[:, :, 0] = False  # separations from the end-effector do not count
    motion = np.where(pair_ok, change, 0.0).sum(axis=2) / np.maximum(pair_ok.sum(axis=2), 1)
    ee_ok = valid[:, :1] & valid
    ee_ok[:, 0] = False
    ee_motion = np.where(ee_ok, change[:, 0, :], 0.0).sum(axis=1) / np.maximum(ee_ok.sum(axis=1), 1)
    motion[:, 0] = 0.0
    tool = np.where(motion.max(axis=1) > moving_m, motion.argmax(axis=1), np.where(ee_motion > moving_m, 0, -1))
    last_object = np.maximum.accumulate(np.where(tool > 0, np.arange(H - 1), -1))
    unseen = (last_object >= 0) & ~valid[np.arange(H - 1), tool[np.maximum(last_object, 0)]]
    tool = np.where((tool == 0) & unseen, -1, tool)  # the hand may be carrying it out of sight
    tool = np.append(tool, tool[-1]) if len(tool) else np.zeros(H, int)
    last_moved = np.maximum.accumulate(np.where(tool >= 0, np.arange(H), -1))
    return np.where(last_moved >= 0, tool[np.maximum(last_moved, 0)], -1)


def driven(world: np.ndarray, ok: np.ndarray, rel: np.ndarray, moving_m: float, moving_deg: float,
           half_window: int = 2) -> np.ndarray:
    """Per frame and pair of ``rel (H, P, 7)`` (p_t[i, j], from ``world (H, n, 7)``):
    whether target j is driven by tool i, i.e. j moves more than ``moving_m`` or turns
    more than ``moving_deg`` per frame in the world while p[i, j] changes by less than
    both; each averaged over ``half_window`` frames either side; ``(H, P)`` bool. Only
    pairs tracked at both ends of the window can be driven."""
    H = len(world)
    a = np.clip(np.arange(H) - half_window, 0, H - 1)
    b = np.clip(np.arange(H) + half_window, 0, H - 1)
    span = np.maximum(b - a, 1)[:, None]

    def steps(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        move = np.linalg.norm(x[b, ..., :3] - x[a, ..., :3], axis=-1) / span
        turn = rotation_angle_deg(x[b, ..., 3:], x[a, ..., 3:]) / span
        return move, turn

    move, turn = steps(world)  # (H, n)
    rel_move, rel_turn = steps(rel)  # (H, P)
    i, j = pairs_of(world.shape[1]).T
    moves = (move[:, j] > moving_m) | (turn[:, j] > moving_deg)
    held = (rel_move < moving_m) & (rel_turn < moving_deg)
    tracked = ok[a][:, i] & ok[b][:, i] & ok[a][:, j] & ok[b][:, j]
    return moves & held & tracked


class PriorScores:
    """:class:`~hsp.labeling.viterbi.Scores` from the hand-set priors of Section IV-A, in
    float32: the recursion streams (P, H) arrays every frame, and float64 only doubled the
    memory traffic (the labels of all four tasks' tracked episodes came out the same)."""

    def __init__(self, world: np.ndarray, ok: np.ndarray, cfg: PriorConfig) -> None:
        self.H, n = world.shape[:2]
        self.cfg = cfg
        self.pairs = pairs_of(n)
        self.P = len(self.pairs)
        rel = relative_poses(world)
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        self.rel = rel[:, i, j]  # (H, P, 7)
        self.ok = ok[:, i] & ok[:, j]  # (H, P)
        evidence = tool_evidence(world, ok, cfg.moving_m)
        hit = np.log1p(-cfg.tool_epsilon)
        miss = np.log(cfg.tool_epsilon / max(n - 1, 1))
        self._unary = np.where(evidence[:, None] == i[None, :], hit, miss)  # (H, P)
        self._unary[evidence < 0] = np.log(1.0 / n)  # nothing has moved yet: no evidence
        drives = driven(world, ok, self.rel, cfg.moving_m, cfg.moving_deg)
        self._unary += np.where(drives, np.log(cfg.tool_epsilon), 0.0)  # a target moving with the tool
        self._unary = self._unary.astype(np.float32)
        self._v = np.ascontiguousarray(pose_points(self.rel, cfg.rotation_arm_m).transpose(1, 0, 2),
                                       dtype=np.float32)  # (P, H, 7)
        self._sq = np.sum(self._v**2, axis=-1)  # (P, H)
        dist = np.linalg.norm(self.rel[..., :3], axis=-1).T  # nearness: translation only
        self._near = np.where(self.ok.T & self._still(), -cfg.alpha * dist, NEG).astype(np.float32)

    def _still(self, half_window: int = 2) -> np.ndarray:
        """Frames where the tool is still relative to the target ``(P, H)``: its mean step
        in R⁷ (:func:`pose_points`) over ``half_window`` frames either side is under
        ``moving_m``; the last frame too."""
        a = np.clip(np.arange(self.H) - half_window, 0, self.H - 1)
        b = np.clip(np.arange(self.H) + half_window, 0, self.H - 1)
        step = np.linalg.norm(self._v[:, b] - self._v[:, a], axis=-1) / np.maximum(b - a, 1)
        still = step < self.cfg.moving_m
        still[:, -1] = True
        return still

    def candidates(self) -> np.ndarray:
        """Where π_m lets a way-point be ``(P, H)``: frames where the tool is still relative
        to the target, both tracked, and the last frame."""
        return np.isfinite(self._near)

    def unary(self, t: int) -> np.ndarray:
        return self._unary[t]

    def jump(self, t: int) -> np.ndarray:
        return self._near[:, t:] - float(np.log(self.H - t))

    def motion(self, t: int) -> np.ndarray:
        """‖δ − m·u/‖u‖‖² expanded so that no (P, H, 7) temporary is built: δ is the step
        t → t+1, u = w_k − x_t the way to way-point k, m = min(‖δ‖, ‖u‖), all in R⁷
        (:func:`pose_points`)."""
        usable = self.ok[t] & self.ok[t + 1] if t < self.H - 1 else np.zeros(self.P, bool)
        if not usable.any():
            return np.zeros((self.P, self.H - t), np.float32)
        x = self._v[:, t]  # (P, 7)
        delta = self._v[:, t + 1] - x
        dots = np.matmul(self._v[:, t:], np.stack([x, delta], axis=-1))  # (P, H - t, 2)
        d2 = self._sq[:, t:] - 2 * dots[..., 0] + np.sum(x * x, axis=1)[:, None]
        dist = np.sqrt(np.maximum(d2, 0.0))
        s2 = np.sum(delta * delta, axis=1)[:, None]
        m = np.minimum(np.sqrt(s2), dist)
        delta_u = dots[..., 1] - np.sum(delta * x, axis=1)[:, None]
        err2 = s2 + m * m - 2 * m / np.maximum(dist, 1e-9) * delta_u
        err2 *= -1.0 / (2 * self.cfg.motion_sigma_m**2)
        return err2 if usable.all() else np.where(usable[:, None], err2, np.float32(0.0))
