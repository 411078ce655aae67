"""The hierarchy one frame at a time on its own history: what runs on the robot.

A :class:`Stepper` holds, for a batch of episodes, the LSTM state and the tools, targets
and way-points it chose itself, and builds from them the same history features that
training builds from labels (:mod:`~hsp.policy.features`). Free-running validation steps
it over held-out recordings; the closed-loop runner steps it on the robot's observations.
Given ``forced`` choices (the labels), it reproduces the teacher-forced batch computation
of training exactly (tested), so what is trained is what runs.

A way-point holds until it is reached: π_m chooses w_t when the tool or target changes, or
once the tool has rested within ``policy.arrive_m`` of w_{t−1} for ``policy.settle_frames``
frames with π_h keeping the pair (π_h decides first whether the sub-task is over);
otherwise w_t = w_{t−1}. This is how the labels are made (w is one pose per sub-task
segment), and it keeps a way-point from drifting with the tool that follows it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hsp.policy.features import FLAGS, one_hot, remaining_way, way_length
from hsp.geometry import normalize_quat, relative


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


class Stepper:
    """Batched one-frame steps of a trained policy (``policy.net``, ``policy.norm``,
    ``policy.classes``, ``policy.n_classes``) over ``batch`` episodes."""

    def __init__(self, policy, batch: int = 1) -> None:
        self.net, self.norm = policy.net, policy.norm
        self.arrive_m, self.settle_frames = policy.arrive_m, policy.settle_frames
        self.classes = np.asarray(policy.classes)
        self.C = int(policy.n_classes)
        self.n = len(self.classes)
        self.B = batch
        self.class_codes = one_hot(self.classes, self.C)  # (n, C)
        self.members = np.maximum(self.class_codes.sum(0), 1.0)
        self.state: tuple[torch.Tensor, torch.Tensor] | None = None
        self.prev: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # tool, target, w at t − 1
        self.prev2_pair: tuple[np.ndarray, np.ndarray] | None = None  # tool, target at t − 2
        self.ended = np.zeros((batch, self.n), np.float32)
        self.rested = np.zeros(batch, np.int64)  # frames the tool has been at w_{t−1} with the pair kept

    def _history(self, world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """LSTM input ``(B, 2C + 7)``, g_t ``(B, 7)`` and flags ``(B, n, 3)`` at this frame."""
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
                self.ended[rows[switched], self.prev2_pair[1][switched]] = 1.0
        flags[..., 2] = self.ended
        return x, g, flags

    def step(self, world: np.ndarray, tracked: np.ndarray | None = None,
             forced: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Choice:
        """One frame: canonical world poses ``(B, n, 7)`` and whether each object is tracked
        ``(B, n)`` → the choice. ``forced`` (tool ``(B,)``, target ``(B,)``, w ``(B, 7)``)
        replaces the choice in the history (teacher forcing) and in the inputs of π_m and π_l."""
        B, n = world.shape[:2]
        if (B, n) != (self.B, self.n):
            raise ValueError(f"step: poses of {B} episodes × {n} objects, the stepper runs {self.B} × {self.n}")
        tracked = np.ones((B, n), bool) if tracked is None else tracked
        x, g, flags = self._history(world)
        ee_in = relative(np.repeat(world[:, :1], n, 1), world).astype(np.float32)  # p_t[0, j]
        done = ((flags[..., 2] @ self.class_codes) / self.members).astype(np.float32)
        net, norm = self.net, self.norm
        f = torch.from_numpy
        rows = np.arange(B)
        with torch.no_grad():
            memory, self.state = net.remember(norm.history(f(x))[:, None], self.state)
            objects, context = net.read(norm, f(self.class_codes), f(world.astype(np.float32)), f(ee_in), f(flags),
                                        f(tracked), f(g), f(done), memory[:, 0])
            log_tool = net.pi_tool(objects, context)
            tool = log_tool.argmax(-1).numpy() if forced is None else forced[0]
            tool_in = relative(world[rows, tool][:, None].repeat(n, 1), world).astype(np.float32)
            log_target = net.pi_target(objects, norm("tool_in_object", f(tool_in)), f(self.class_codes[tool]), context,
                                       f(tool))
            target = log_target.argmax(-1).numpy() if forced is None else forced[1]
            current = relative(world[rows, tool], world[rows, target]).astype(np.float32)
            pair_classes = f(np.concatenate([self.class_codes[tool], self.class_codes[target]], -1))
            pair_flags = f(np.concatenate([flags[rows, tool], flags[rows, target]], -1))
            w = norm.unscale("waypoint", net.pi_m(pair_classes, norm("current", f(current)), pair_flags, context)).numpy()
            w = np.concatenate([w[:, :3], normalize_quat(w[:, 3:].astype(np.float64))], -1).astype(np.float32)
            if forced is not None:
                w = forced[2].astype(np.float32)
            elif self.prev is not None:
                same = (tool == self.prev[0]) & (target == self.prev[1])
                at = way_length(remaining_way(current, self.prev[2])) < self.arrive_m
                self.rested = np.where(same & at, self.rested + 1, 0)
                hold = same & (self.rested < self.settle_frames)
                self.rested[~hold] = 0
                w = np.where(hold[:, None], self.prev[2], w)
            remaining = remaining_way(current, w).astype(np.float32)
            action, _ = net.pi_l(pair_classes, norm("current", f(current)), norm("waypoint", f(w)),
                                 norm("remaining", f(remaining)), f(remaining))
        self.prev2_pair = None if self.prev is None else (self.prev[0], self.prev[1])
        self.prev = (tool, target, w)
        return Choice(tool, target, w, action.numpy(), log_tool.numpy(), log_target.numpy())
