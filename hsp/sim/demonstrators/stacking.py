"""Stacking: build the task's pattern of blocks on the base block, in a random order
that respects support (a block goes down only after the block beneath it).

Sub-tasks: (hand, block) reach and grasp; (block, support) carry and place, where the
support is the block beneath in the pattern or the base; (hand, block) let go and rise.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import compose
from hsp.sim.demonstrators.common import hand_yaw, in_frame, nearest_yaw, pose
from hsp.sim.demonstrators.steps import Grasp, Move, Release, Step

if TYPE_CHECKING:
    from hsp.sim.demonstration import PlanContext

PLACE_CLEARANCE = 0.002
"""Blocks are let go this far above their resting place (m)."""


def supports(pattern: dict[str, np.ndarray], base: str) -> dict[str, str]:
    """The block each pattern block rests on: the one right beneath it, else the base."""
    out = {}
    for name, xyz in pattern.items():
        below = [o for o, oxyz in pattern.items() if o != name and np.linalg.norm(oxyz[:2] - xyz[:2]) < 0.01 and oxyz[2] < xyz[2]]
        out[name] = max(below, key=lambda o: pattern[o][2]) if below else base
    return out


def random_order(support: dict[str, str], base: str, rng: np.random.Generator) -> list[str]:
    """A uniformly drawn order in which every block comes after its support."""
    order: list[str] = []
    placed = {base}
    while len(order) < len(support):
        ready = sorted(b for b in support if b not in placed and support[b] in placed)
        pick = ready[rng.integers(len(ready))]
        order.append(pick)
        placed.add(pick)
    return order


def stacking_plan(ctx: "PlanContext") -> Iterator[Step]:
    task, rng, d = ctx.task, ctx.rng, ctx.task.spec.demonstrator
    s = task.spec.success
    pattern = {k: np.asarray(v) for k, v in s.pattern.items()}
    support = supports(pattern, s.base)
    hand, base = 0, task.index(s.base)
    quarter = np.arange(4) * np.pi / 2

    for name in random_order(support, s.base, rng):
        block, target = task.index(name), task.index(support[name])
        poses = ctx.poses()
        # (hand, block): fingers on two opposite faces, from above.
        block_yaw = float(Rotation.from_quat(poses[block, 3:]).as_euler("xyz")[2])
        yaw = nearest_yaw(block_yaw + quarter, hand_yaw(poses[hand])) - block_yaw
        grasp = pose([0.0, 0.0, rng.uniform(-0.004, 0.004)], Rotation.from_euler("z", yaw))
        yield Move(hand, block, compose(pose([0, 0, d.approach_height], Rotation.identity()), grasp))
        yield Move(hand, block, grasp, straight=True, slow=1.3)
        yield Grasp(block)

        # (block, support): lift, carry above the pattern place aligned with the base, lower.
        poses = ctx.poses()
        lifted = poses[block].copy()
        lifted[2] += d.lift_height
        yield Move(block, target, in_frame(poses[target], lifted), straight=True)
        base_yaw = float(Rotation.from_quat(poses[base, 3:]).as_euler("xyz")[2])
        held_yaw = float(Rotation.from_quat(poses[block, 3:]).as_euler("xyz")[2])
        goal_yaw = nearest_yaw(base_yaw + quarter, held_yaw)
        place_world = compose(poses[base], pose(pattern[name] + [0, 0, PLACE_CLEARANCE], Rotation.identity()))
        place_world[3:] = Rotation.from_euler("z", goal_yaw).as_quat()
        above_world = place_world.copy()
        above_world[2] += d.approach_height
        yield Move(block, target, in_frame(poses[target], above_world))
        yield Move(block, target, in_frame(poses[target], place_world), straight=True, slow=1.6)
        yield Release()

        # (hand, block): let go and rise.
        poses = ctx.poses()
        rise = in_frame(poses[block], poses[hand])
        rise[2] += d.approach_height
        yield Move(hand, block, rise, straight=True)
