"""The hierarchy one frame at a time on its own history: what runs on the robot.

A :class:`Stepper` holds, for a batch of episodes, the LSTM state and the tools, targets
and way-points it chose itself, and builds from them the same history features that
training builds from labels (:mod:`~hsp.policy.features`). Free-running validation steps
it over held-out recordings, asked where the recording's sub-tasks end; the closed-loop
runner steps it on the robot's observations, where it decides that itself.
Given ``forced`` choices (the labels), it reproduces the teacher-forced batch computation
of training exactly (tested), so what is trained is what runs.

A sub-task runs until its tool has come to rest at its way-point: the pair and the
way-point hold until, for ``policy.settle_frames`` frames in a row, the tool moves less
than ``policy.still_m`` and either is within ``policy.arrive_m`` of w_{t−1} (reached) or
its remaining way shrinks by less than half the least fraction π_l's step covers (stopped
short: something holds it, the way-point is not quite reachable, or the tool was not
grasped). Only then, and at the first frame, are π_h and π_m asked for the next tool,
target and way-point; they are trained on exactly those frames (the labels' decisions,
:func:`~hsp.policy.features.decisions`, end a sub-task where the demonstrator's tool came
to rest at its way-point). A slow step far from w_t is neither, so a low level that
crawls does not end its sub-task early. Over a recording the rule does not apply: the
policy does not move the tool, and a demonstrator who rests long after a decision would
be taken as stopped short again every ``settle_frames`` frames. Between decisions the
LSTM still reads the history every frame, as in training.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from hsp.policy.features import (FLAGS, done_fractions, in_view, moved_since, one_hot, remaining_way, seen_by_pi_m,
                                 way_length)
from hsp.geometry import normalize_quat, relative
from hsp.policy.networks import mixture_mode


def pi_m_waypoint(policy, tool: np.ndarray, target: np.ndarray, current: np.ndarray, flags: np.ndarray,
                  came_from: np.ndarray) -> np.ndarray:
    """π_m's way-point w_t (the heaviest component's mean, physical units, unit quaternion)
    ``(B, 7)`` for the pairs (``tool``, ``target``) ``(B,)`` with p_t[o+, o*] ``current``
    ``(B, 7)``, every object's history flags ``(B, n, FLAGS)`` and where the tool came from
    ``(B, CAME_FROM)`` (:func:`~hsp.policy.features.came_from`). π_m is asked, as it
    learnt every decision, from the turns of its target that make the tool's position and
    its heading canonical (:func:`~hsp.policy.features.seen_by_pi_m`), and its answer is
    turned back."""
    codes = one_hot(np.asarray(policy.classes), policy.n_classes)
    rows = np.arange(len(tool))
    classes = torch.from_numpy(np.concatenate([codes[tool], codes[target]], -1))
    pair_flags = torch.from_numpy(np.concatenate([flags[rows, tool], flags[rows, target]], -1))
    norm, net = policy.norm, policy.net
    seen, turns = seen_by_pi_m(np.asarray(current, np.float64), policy.object_folds()[target])
    x = torch.from_numpy(seen.astype(np.float32))
    came = norm("came_from", torch.from_numpy(np.asarray(came_from, np.float32)))
    mixture = net.pi_m(classes, norm("current", x), pair_flags, came, norm("waypoint", x))
    w = norm.unscale("waypoint", mixture_mode(mixture))
    w = in_view(w.numpy().astype(np.float64), -turns)
    return np.concatenate([w[..., :3], normalize_quat(w[..., 3:])], -1).astype(np.float32)


@dataclass
class Choice:
    """What the hierarchy chose at one frame, per batch element."""

    tool: np.ndarray
    """o+_t ``(B,)``."""
    target: np.ndarray
    """o*_t ``(B,)``."""
    waypoint: np.ndarray
    """w_t in the target's frame ``(B, 7)`` (unit quaternion)."""
    action: np.ndarray
    """π_l's mean a_t: the tool's step in the target's frame ``(B, 6)``."""
    log_tool: np.ndarray
    """log π_h(o+) over objects ``(B, n)``."""
    log_target: np.ndarray
    """log π_h(o* | o+_t) over objects ``(B, n)``."""
    decided: np.ndarray
    """Whether π_h and π_m chose at this frame (the sub-task before was over) ``(B,)``."""


class Stepper:
    """Batched one-frame steps of a trained policy (``policy.net``, ``policy.norm``,
    ``policy.classes``, ``policy.n_classes``, ``policy.arrive_m``, ``policy.still_m``,
    ``policy.settle_frames``) over ``batch`` episodes. ``place(tool, target, w, world)``
    (arrays ``(B,)``, ``(B,)``, ``(B, 7)``, ``(B, n, 7)`` → ``(B, 7)``), when given, turns
    each new way-point into the one the robot goes to (a look-alike it can reach)."""

    def __init__(self, policy, batch: int = 1, place: Callable[..., np.ndarray] | None = None) -> None:
        self.place = place
        self.policy, self.net, self.norm = policy, policy.net, policy.norm
        self.arrive_m, self.still_m, self.settle_frames = policy.arrive_m, policy.still_m, policy.settle_frames
        self.classes = np.asarray(policy.classes)
        self.C = int(policy.n_classes)
        self.n = len(self.classes)
        self.B = batch
        self.class_codes = one_hot(self.classes, self.C)  # (n, C)
        self.state: tuple[torch.Tensor, torch.Tensor] | None = None
        self.prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # tool, target, w at t − 1
        self.prev2_pair: tuple[np.ndarray, np.ndarray] | None = None  # tool, target at t − 2
        self.ended = np.zeros((batch, self.n, 2), np.float32)  # target, tool of an ended sub-task
        self.rested = np.zeros(batch, np.int64)  # frames in a row the tool has been at rest at its way-point
        self.prev_current: np.ndarray | None = None  # p_{t−1}[o+_{t−1}, o*_{t−1}]
        self.last_decision: tuple[np.ndarray, ...] | None = None  # tool, target, the tool's position then
        self.remaining = np.zeros(batch)  # length of the way from the tool to w_{t−1} at t − 1
        self.shrink = 1.0 - 0.5 * policy.net.sizes.min_fraction  # less progress than this: stopped

    def _history(self, world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """LSTM input ``(B, 2C + 7)``, g_t ``(B, 7)`` and flags ``(B, n, FLAGS)`` at this frame."""
        B, n, C = self.B, self.n, self.C
        x = np.zeros((B, 2 * C + 7), np.float32)
        g = np.zeros((B, 7), np.float32)
        flags = np.zeros((B, n, FLAGS), np.float32)
        if self.prev is not None:
            tool, target, w = self.prev
            rows = np.arange(B)
            x[:, :C] = self.class_codes[tool]
            x[:, C:2 * C] = self.class_codes[target]
            x[:, 2 * C:] = w
            g[:] = relative(world[rows, tool], world[rows, target]) - w
            flags[rows, tool, 0] = 1.0
            flags[rows, target, 1] = 1.0
            if self.prev2_pair is not None:
                switched = (self.prev2_pair[0] != tool) | (self.prev2_pair[1] != target)
                self.ended[rows[switched], self.prev2_pair[1][switched], 0] = 1.0
                self.ended[rows[switched], self.prev2_pair[0][switched], 1] = 1.0
                self.ended[:, 0, 1] = 0.0  # the end-effector is not flagged as a tool
        flags[..., 2:] = self.ended
        return x, g, flags

    def _kept(self, i: int) -> np.ndarray:
        return np.zeros(self.B, np.int64) if self.prev is None else self.prev[i]

    def _decide(self, world: np.ndarray) -> np.ndarray:
        """Whether the sub-task is over at this frame ``(B,)``: the first frame, or the tool
        has now been at rest at its way-point (reached, or stopped short) for
        ``settle_frames`` frames, counting this one."""
        if self.prev is None:
            return np.ones(self.B, bool)
        rows = np.arange(self.B)
        current = relative(world[rows, self.prev[0]], world[rows, self.prev[1]])
        remaining = way_length(remaining_way(current, self.prev[2]))
        reached = remaining < self.arrive_m
        stopped = remaining > self.shrink * self.remaining
        rest = (way_length(remaining_way(self.prev_current, current)) < self.still_m) & (reached | stopped)
        self.rested = np.where(rest, self.rested + 1, 0)
        decide = self.rested >= self.settle_frames
        self.rested[decide] = 0
        return decide

    def step(self, world: np.ndarray, tracked: np.ndarray | None = None,
             forced: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             ended: np.ndarray | None = None) -> Choice:
        """One frame: canonical world poses ``(B, n, 7)`` and whether each object is tracked
        ``(B, n)`` → the choice. ``forced`` (tool ``(B,)``, target ``(B,)``, w ``(B, 7)``)
        replaces the choice in the history (teacher forcing) and in the inputs of π_m and π_l.
        ``ended`` ``(B,)`` says where the sub-task is over in place of the stepper's own rule
        (over a recording, the demonstrator ends its sub-tasks, not the policy)."""
        B, n = world.shape[:2]
        if (B, n) != (self.B, self.n):
            raise ValueError(f"step: poses of {B} episodes × {n} objects, the stepper runs {self.B} × {self.n}")
        tracked = np.ones((B, n), bool) if tracked is None else tracked
        x, g, flags = self._history(world)
        ee_in = relative(np.repeat(world[:, :1], n, 1), world).astype(np.float32)  # p_t[0, j]
        done = done_fractions(flags, self.classes, self.C)
        net, norm = self.net, self.norm
        f = torch.from_numpy
        rows = np.arange(B)
        with torch.no_grad():
            memory, self.state = net.remember(norm.history(f(x))[:, None], self.state)
            objects, context = net.read(norm, f(self.class_codes), f(world.astype(np.float32)), f(ee_in), f(flags),
                                        f(tracked), f(g), f(done), memory[:, 0])
            decide = self._decide(world) if ended is None or self.prev is None else np.asarray(ended, bool)
            log_tool = net.pi_tool(objects, context)
            tool = np.where(decide, log_tool.argmax(-1).numpy(), self._kept(0)) if forced is None else forced[0]
            tool_in = relative(world[rows, tool][:, None].repeat(n, 1), world).astype(np.float32)
            log_target = net.pi_target(objects, norm("tool_in_object", f(tool_in)), f(self.class_codes[tool]), context,
                                       f(tool))
            target = np.where(decide, log_target.argmax(-1).numpy(), self._kept(1)) if forced is None else forced[1]
            current = relative(world[rows, tool], world[rows, target]).astype(np.float32)
            pair_classes = f(np.concatenate([self.class_codes[tool], self.class_codes[target]], -1))
            position = world[rows, tool, :3]
            last = self.last_decision or (tool, target, position)
            same = (self.last_decision is not None) & (last[0] == tool) & (last[1] == target)
            before = last[2]
            w = pi_m_waypoint(self.policy, tool, target, current, flags, moved_since(same, before, position))
            if forced is not None:
                w = forced[2].astype(np.float32)
            else:
                if self.place is not None and decide.any():
                    w = self.place(tool, target, w, world).astype(np.float32)
                if self.prev is not None:
                    w = np.where(decide[:, None], w, self.prev[2])
            remaining = remaining_way(current, w).astype(np.float32)
            action, _ = net.pi_l(pair_classes, norm("current", f(current)), norm("waypoint", f(w)),
                                 norm("remaining", f(remaining)), f(remaining))
        self.last_decision = tuple(np.where(decide.reshape((B,) + (1,) * (x.ndim - 1)), x, old)
                                   for x, old in zip((tool, target, position), last))
        self.prev2_pair = None if self.prev is None else (self.prev[0], self.prev[1])
        self.prev = (tool, target, w)
        self.prev_current = current
        self.remaining = way_length(remaining.astype(np.float64))
        return Choice(tool, target, w, action.numpy(), log_tool.numpy(), log_target.numpy(), decide)
