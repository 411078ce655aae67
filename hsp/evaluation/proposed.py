"""``proposed`` (and ``supervised``): π_h, π_m and π_l run closed loop on their own history.

Per control step, from the observed world poses (symmetric objects' orientations made
canonical, as in training): the LSTM reads the previous pair and way-point w_{t−1} that
this runner chose itself (never labels) and keeps its state across steps; π_h's most
likely (tool, target) pair is taken, π_m's mean way-point w_t and π_l's mean action a_t,
the tool's step in the target's frame. The step is turned into a command for the
tool-centre point through the tool's current grasp when the tool is an object, and the
gripper is told to hold that object.

Identical objects (the four lug nuts share a label) are interchangeable to the networks:
π_h's probabilities are summed over pairs of the same labels, and while that label pair
stays the most likely the runner keeps the object it chose, otherwise it takes the most
likely object of the label pair.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from hsp.errors import HspError
from hsp.geometry import compose, inverse, relative
from hsp.labeling.label import canonical_poses
from hsp.labeling.priors import pairs_of
from hsp.policy.features import class_codes, pair_poses
from hsp.policy.train import Policy
from hsp.tasks.registry import Task


def apply_step(current: np.ndarray, step: np.ndarray) -> np.ndarray:
    """The pose ``(7,)`` reached from ``current (7,)`` by an action ``(6,)`` of
    :func:`~hsp.geometry.rotvec_delta` (translation added, rotation vector left-multiplied)."""
    q = (Rotation.from_rotvec(step[3:]) * Rotation.from_quat(current[3:])).as_quat()
    return np.concatenate([current[:3] + step[:3], q])


def tcp_command(poses: np.ndarray, canonical: np.ndarray, tool: int, target: int, step: np.ndarray) -> np.ndarray:
    """The tool-centre point's world pose ``(7,)`` that moves ``tool`` by π_l's ``step (6,)``,
    given in the target's canonical frame, with the tool held as it is now. ``poses`` and
    ``canonical`` are the world poses ``(n, 7)`` as observed and with symmetric objects'
    orientations made canonical; the tool keeps its own symmetry offset, so the arm does
    not turn to a look-alike orientation."""
    rel = relative(canonical[tool], canonical[target])
    offset = relative(poses[tool], canonical[tool])
    tool_next = compose(compose(canonical[target], apply_step(rel, step)), offset)
    return tool_next if tool == 0 else compose(tool_next, relative(poses[0], poses[tool]))


class HierarchyRunner:
    """Stateful runner of a trained :class:`~hsp.policy.train.Policy`: ``reset(poses, seed)``
    then ``act(poses)`` per control step with world poses ``(n, 7)``; returns the action
    ``(8,)`` of :class:`~hsp.evaluation.env.HspEnv`. ``trace`` keeps, per step, the history
    the LSTM read and what the runner chose (pair, w_t)."""

    def __init__(self, policy: Policy, task: Task, source: str = "policy") -> None:
        if policy.objects != task.names:
            raise HspError(f"{source}: a policy for objects {policy.objects}, not those of task {task.name!r} {task.names}")
        self.policy, self.task = policy, task
        self.pairs = pairs_of(len(task.objects))
        self.symmetries = [o.symmetry for o in task.objects]
        self.codes = torch.from_numpy(class_codes(policy.classes, policy.n_classes, self.pairs))
        label_pairs = [(policy.classes[i], policy.classes[j]) for i, j in self.pairs]
        self.group = np.array([label_pairs.index(lp) for lp in label_pairs])
        """Index of each pair's label pair: pairs with equal labels are interchangeable."""

    def reset(self, poses: np.ndarray, seed: int) -> None:
        self.state: tuple[torch.Tensor, torch.Tensor] | None = None
        self.pair: int | None = None
        self.waypoint = np.zeros(7)
        self.trace: list[dict[str, np.ndarray | int]] = []

    def _choose(self, logp: np.ndarray) -> int:
        p = np.exp(logp - logp.max())
        group_p = np.bincount(self.group, weights=p, minlength=len(p))
        best = int(np.argmax(group_p))
        if self.pair is not None and self.group[self.pair] == best:
            return self.pair
        return int(np.flatnonzero(self.group == best)[np.argmax(p[self.group == best])])

    def act(self, poses: np.ndarray) -> np.ndarray:
        net, norm = self.policy.net, self.policy.norm
        world = canonical_poses(poses[None], self.symmetries)[0]
        rel = pair_poses(world[None])[0]  # (P, 7): p_t[i, j]
        P = len(self.pairs)
        history = np.zeros(P + 7, np.float32)
        progress = np.zeros(7, np.float32)
        if self.pair is not None:
            history[self.pair] = 1.0
            history[P:] = self.waypoint
            progress[:] = rel[self.pair] - self.waypoint
        f = lambda x: torch.as_tensor(np.asarray(x, np.float32))  # noqa: E731
        with torch.no_grad():
            out, self.state = net.memory(norm.history(f(history)[None, None]), self.state)
            memory = out[0, 0]
            g = norm("progress", f(progress))
            pair = self._choose(net.pi_h(norm("z", f(rel.reshape(-1))), memory, g).numpy())
            classes = self.codes[pair]
            w, _ = net.pi_m(classes, norm("current", f(rel[pair])), memory, g)
            w = w * norm.stats["waypoint.std"] + norm.stats["waypoint.mean"]
            a, _ = net.pi_l(norm("target_in_tool", f(inverse(rel[pair]))), norm("waypoint", w), classes)
            a = a * norm.stats["action.std"] + norm.stats["action.mean"]
        self.trace.append({"history": history, "pair": pair, "waypoint": w.numpy().astype(np.float64)})
        self.pair, self.waypoint = pair, w.numpy().astype(np.float64)
        tool, target = (int(x) for x in self.pairs[pair])
        tcp = tcp_command(poses, world, tool, target, a.numpy().astype(np.float64))
        return np.concatenate([tcp, [float(tool)]])
