"""``proposed`` (and ``supervised``): π_h, π_m and π_l run closed loop on their own history.

Per control step, from the observed world poses (symmetric objects' orientations made
canonical as in training: the equivalent chosen at the episode's first frame is kept, so
a cube turning past 45° does not jump by a quarter turn in its target's frame): the
history is the tools, targets and way-points this runner chose itself (never labels), the LSTM keeping its state across steps; π_h's most likely
tool, then its most likely target given that tool, π_m's way-point w_t and π_l's mean
action a_t, the tool's step in the target's frame. The step is turned into a command for the
tool-centre point through the tool's current grasp when the tool is an object, and the
gripper is told to hold that object. Each command also makes up the distance by which the
arm fell short of the last one (:func:`with_shortfall`): π_l's step is a fraction f of the
remaining way, so an arm settling e short of its commands would otherwise stop e / f short
of w_t (the simulated Kuka's position control settles about 1 mm short near the wheel;
the wrench stopped 5 mm from the nut, whose socket it must reach within 5 mm).

Identical objects (the four lug nuts share a label) are interchangeable to the networks:
π_h scores every object with the same weights from its own pose and history flags.

A way-point near a round target's axis (a dip into the bucket) is the same place turned
by any angle about that axis, and π_m learns it at the turn nearest the tool's heading
(:func:`~hsp.policy.features.nearest_round_turn`). Given the arm's ``reach_error``, the
runner goes to the turn nearest the learnt one that the arm reaches from where it is, as
the robot demonstrator does (:func:`reachable_member`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hsp.errors import HspError
from hsp.geometry import apply_rotvec_delta, compose, relative
from hsp.geometry.symmetry import z_folds
from hsp.labeling.label import canonical_poses
from hsp.policy.features import ARM_M, turned_about_z
from hsp.policy.stepper import Stepper
from hsp.policy.train import Policy
from hsp.sim.demonstrators.common import reachable_yaw
from hsp.tasks.registry import Task


def tcp_command(poses: np.ndarray, canonical: np.ndarray, tool: int, target: int, step: np.ndarray) -> np.ndarray:
    """The tool-centre point's world pose ``(7,)`` that moves ``tool`` by π_l's ``step (6,)``,
    given in the target's canonical frame, with the tool held as it is now. ``poses`` and
    ``canonical`` are the world poses ``(n, 7)`` as observed and with symmetric objects'
    orientations made canonical; the tool keeps its own symmetry offset, so the arm does
    not turn to a look-alike orientation."""
    rel = relative(canonical[tool], canonical[target])
    offset = relative(poses[tool], canonical[tool])
    tool_next = compose(compose(canonical[target], apply_rotvec_delta(rel, step)), offset)
    return tool_next if tool == 0 else compose(tool_next, relative(poses[0], poses[tool]))


def reachable_member(waypoint: np.ndarray, target_pose: np.ndarray, tcp_in_tool: np.ndarray,
                     reach_error: Callable[[list[np.ndarray]], float]) -> np.ndarray:
    """The way-point ``(7,)`` on a round target at world pose ``target_pose (7,)`` turned
    about the target's axis by the least angle at which the arm reaches it
    (:func:`~hsp.sim.demonstrators.common.reachable_yaw`), the tool held as
    ``tcp_in_tool (7,)`` says; unchanged when it lies farther than ``ARM_M`` from the axis,
    where a turn would take it elsewhere (a nut on a round wheel)."""
    if np.linalg.norm(waypoint[:2]) > ARM_M:
        return waypoint
    tcp_at = lambda yaw: [compose(compose(target_pose, turned_about_z(waypoint, yaw)), tcp_in_tool)]  # noqa: E731
    return turned_about_z(waypoint, reachable_yaw(0.0, tcp_at, reach_error))


SHORTFALL_M = 0.01
"""The largest shortfall of the arm on its last command that the next one makes up (m)."""


def with_shortfall(command: np.ndarray, observed: np.ndarray, last: np.ndarray, max_m: float) -> np.ndarray:
    """``command (7,)`` moved by the arm's shortfall on its ``last`` command: the world
    translation from the ``observed`` tool-centre point ``(7,)`` to ``last (7,)``, when it is
    within ``max_m`` (farther, the arm cannot go there, and pushing on would only take it
    farther off). Added to every command, it integrates π_l's steps, so an arm that settles
    short of its command (a position controller under load) still ends at w_t instead of
    e / f short of it (π_l's fraction f of the remaining way). Orientation is left as π_l
    commands it: made up too, the held brush's orientation cycled by 2-5° every frame and
    never came to rest."""
    move = last[:3] - observed[:3]
    if np.linalg.norm(move) > max_m:
        return command
    return np.concatenate([command[:3] + move, command[3:]])


class HierarchyRunner:
    """Stateful runner of a trained :class:`~hsp.policy.train.Policy`: ``reset(poses, seed)``
    then ``act(poses)`` per control step with world poses ``(n, 7)``; returns the action
    ``(8,)`` of :class:`~hsp.evaluation.env.HspEnv`. It steps the policy's
    :class:`~hsp.policy.stepper.Stepper`, whose history is its own earlier choices;
    ``trace`` keeps, per step, what the LSTM read and what was chosen."""

    def __init__(self, policy: Policy, task: Task, source: str = "policy",
                 reach_error: Callable[[list[np.ndarray]], float] | None = None) -> None:
        if policy.objects != task.names:
            raise HspError(f"{source}: a policy for objects {policy.objects}, not those of task {task.name!r} {task.names}")
        self.policy, self.task, self.reach_error = policy, task, reach_error
        self.symmetries = [o.symmetry for o in task.objects]
        self.round = np.array([z_folds(s) == 0 for s in self.symmetries])

    def reset(self, poses: np.ndarray, seed: int) -> None:
        self.first = np.asarray(poses, np.float64).copy()
        self.stepper = Stepper(self.policy, 1, None if self.reach_error is None else self._place)
        self.trace: list[dict[str, np.ndarray | int]] = []
        self.last: np.ndarray | None = None

    def _place(self, tool: np.ndarray, target: np.ndarray, w: np.ndarray, world: np.ndarray) -> np.ndarray:
        """The stepper's ``place``: a new way-point on a round target at a turn the arm reaches."""
        out = w.astype(np.float64)
        for b in np.flatnonzero(self.round[target]):
            out[b] = reachable_member(out[b], world[b, target[b]], relative(world[b, 0], world[b, tool[b]]),
                                      self.reach_error)
        return out

    def canonical(self, poses: np.ndarray) -> np.ndarray:
        """World poses ``(n, 7)`` with symmetric objects' orientations made canonical by the
        equivalent chosen at the episode's first frame (as training poses are)."""
        return canonical_poses(np.stack([self.first, poses]), self.symmetries)[1]

    def act(self, poses: np.ndarray) -> np.ndarray:
        world = self.canonical(poses)
        history = self.stepper.prev
        choice = self.stepper.step(world[None])
        tool, target = int(choice.tool[0]), int(choice.target[0])
        self.trace.append({"previous": None if history is None else (int(history[0][0]), int(history[1][0]),
                                                                     history[2][0].copy()),
                           "decided": bool(choice.decided[0]), "tool": tool, "target": target,
                           "waypoint": choice.waypoint[0].copy(),
                           "action": choice.action[0].astype(np.float64), "log_tool": choice.log_tool[0].copy()})
        tcp = tcp_command(poses, world, tool, target, self.trace[-1]["action"])
        if self.last is not None:
            tcp = with_shortfall(tcp, poses[0], self.last, SHORTFALL_M)
        self.last = tcp
        return np.concatenate([tcp, [float(tool)]])
