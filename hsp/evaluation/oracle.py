"""``oracle``: the scripted demonstrator's own plan (tool, target, way-point sequence)
executed by the Kuka through the same environment and controller as every learned policy.

It proves the environment, the controller, grasping and the checkers before any learning
is blamed. The plan reads the poses the observer gives (the simulator's, or the tracker's
with ``--observer camera``), each symmetric object in the look-alike frame nearest the one
it had a step before (nearest the world axes at the first), and the object it holds turned
about its symmetry axis as the grasp holds it: a turn about that axis looks (nearly) the
same to a camera, so the grasp, not the frame, says it (a tracked brush rolling about its
round handle past 90° turned the wrist and the brush into the bucket); its position and
the rest of its orientation come from the observer (a grasp slips: a brush 17 mm under
its load in the simulator). Each way-point becomes a minimum-jerk segment of the
demonstrator's duration, followed by its pause, then by up to ``SETTLE_S`` of holding the
goal until the tool is there (a robot's lag is not a human's).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import compose, inverse, relative
from hsp.geometry.symmetry import nearest_equivalent, symmetry_axis, without_twist
from hsp.sim.demonstration import PlanContext, segment_duration
from hsp.sim.demonstrators import PLANS
from hsp.sim.demonstrators.steps import Grasp, Move, Release
from hsp.sim.motion import segment_poses
from hsp.tasks.registry import Task

SETTLE_S = 1.0
"""Longest wait at a way-point for the tool to arrive (s)."""
ARRIVED_M = 0.002
"""The tool has arrived when its origin is this close to the way-point (m)."""


class Oracle:
    """Stateful: ``reset(poses, seed)`` at the start of an episode, then ``act(poses)``
    once per control step with the observed world poses ``(n, 7)``; returns the action
    ``(8,)`` of :class:`~hsp.evaluation.env.HspEnv`."""

    def __init__(self, task: Task, fps: int, reach_error: Callable[[np.ndarray], float] | None = None) -> None:
        self.task, self.fps, self.reach_error = task, fps, reach_error

    def reset(self, poses: np.ndarray, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.poses = self._canonical(poses, np.tile([0.0, 0.0, 0.0, 1.0], (len(poses), 1)))  # the world axes
        self.plan = PLANS[self.task.spec.kind](PlanContext(self.task, self.rng, lambda: self.poses, self.reach_error))
        self.path: deque[np.ndarray] = deque()
        self.command = poses[0].copy()
        self.grip = 0
        self.grasp = np.zeros(4)  # the held object's orientation in the end-effector's frame at the grasp
        self.move: Move | None = None
        self.waited = 0

    def act(self, poses: np.ndarray) -> np.ndarray:
        self.poses = self._held(self._canonical(poses, self.poses[:, 3:]))
        while not self.path and not self._waiting():
            step = next(self.plan, None)
            if step is None:
                break
            if isinstance(step, Grasp):
                self.grip, self.grasp = step.obj, relative(self.poses[step.obj], self.poses[0])[3:]
            elif isinstance(step, Release):
                self.grip = 0
            else:
                self._plan_segment(step)
        if self.path:
            self.command = self.path.popleft()
        return np.concatenate([self.command, [self.grip]])

    def _canonical(self, poses: np.ndarray, last: np.ndarray) -> np.ndarray:
        """World poses ``(n, 7)`` with every object but the end-effector in the look-alike
        frame nearest its ``last (n, 4)`` orientation (the one it had a step before): the
        plans take a resting block's z axis to be up, and a tracker may give a cube in any
        of its 24 look-alike frames, or switch between them when it re-finds a covered block
        (a base seen lying on its side put the next block's place 8 cm beside the tower)."""
        out = np.asarray(poses, np.float64).copy()
        for i, o in enumerate(self.task.objects[1:], start=1):
            out[i, 3:] = nearest_equivalent(out[i:i + 1, 3:], o.symmetry, last[i:i + 1])[0]
        return out

    def _held(self, poses: np.ndarray) -> np.ndarray:
        """``poses (n, 7)`` with the held object's turn about its symmetry axis, relative to
        the grasp, taken out (the swing from the grasp's orientation kept)."""
        axis = symmetry_axis(self.task.objects[self.grip].symmetry) if self.grip else None
        if axis is not None:
            held = relative(poses[self.grip], poses[0])
            turn = Rotation.from_quat(self.grasp).inv() * Rotation.from_quat(held[3:])
            swing = without_twist(turn.as_quat()[None], axis)[0]
            held[3:] = (Rotation.from_quat(self.grasp) * Rotation.from_quat(swing)).as_quat()
            poses[self.grip] = compose(poses[0], held)
        return poses

    def _tcp_goal(self, move: Move) -> np.ndarray:
        """The tool-centre point's world pose that puts the tool at ``move.pose`` in the target's frame."""
        goal_tool = compose(self.poses[move.target], move.pose)
        if move.tool == 0:
            return goal_tool
        return compose(goal_tool, inverse(relative(self.poses[move.tool], self.poses[0])))

    def _plan_segment(self, move: Move) -> None:
        goal = self._tcp_goal(move)
        n = max(1, round(segment_duration(self.command, goal, move, self.task, self.rng) * self.fps))
        pause = round(self.rng.uniform(*self.task.spec.demonstrator.pause) * self.fps)
        self.path.extend(segment_poses(self.command, goal, np.arange(1, n + 1) / n, np.zeros(3)))
        self.path.extend([goal] * pause)
        self.move, self.waited = move, 0

    def _waiting(self) -> bool:
        """Hold the last way-point until the tool is there, for at most ``SETTLE_S``."""
        if self.move is None or self.waited >= SETTLE_S * self.fps:
            return False
        at = relative(self.poses[self.move.tool], self.poses[self.move.target])
        if np.linalg.norm(at[:3] - self.move.pose[:3]) <= ARRIVED_M:
            return False
        self.waited += 1
        return True
