"""Tire removal by the Kuka with a socket wrench on its flange (paper, Section V-A):
each lug nut in a random order — above it, socket on, turn counter-clockwise, lift —
then the wrench to the wheel centre and pull away.

Sub-tasks: (wrench, bolt) approach and seat the socket; (wrench, wheel) turn and lift,
the wheel being the frame in which the turn shows (the bolt turns with the wrench);
(wrench, wheel) to the centre and pull.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import compose
from hsp.sim.demonstrators.common import in_frame, pose
from hsp.sim.demonstrators.steps import Move, Step

if TYPE_CHECKING:
    from hsp.sim.demonstration import PlanContext


def tire_removal_plan(ctx: "PlanContext") -> Iterator[Step]:
    task, rng, d = ctx.task, ctx.rng, ctx.task.spec.demonstrator
    s = task.spec.success
    wrench, wheel = 0, task.index(s.wheel)
    bolts = [task.index(b) for b in s.bolts]
    socket = task.keypoint(s.bolts[0], s.bolt_point)
    centre = task.keypoint(s.wheel, s.wheel_point)
    tip = task.keypoint(s.tool, s.tool_point)

    for b in rng.permutation(bolts):
        poses = ctx.poses()
        start_yaw = np.radians(rng.uniform(-45.0, -10.0))
        seated_world = pose(compose(poses[b], pose(socket, Rotation.identity()))[:3], Rotation.from_euler("z", start_yaw))
        seated_world[:3] -= Rotation.from_euler("z", start_yaw).apply(tip)
        seated_world[:2] += rng.uniform(-0.001, 0.001, 2)
        above_world = seated_world.copy()
        above_world[2] += d.approach_height
        yield Move(wrench, b, in_frame(poses[b], above_world))
        yield Move(wrench, b, in_frame(poses[b], seated_world), straight=True, slow=1.5)

        turned = seated_world.copy()
        turned[3:] = Rotation.from_euler("z", start_yaw + np.radians(rng.uniform(*d.rotation_deg))).as_quat()
        yield Move(wrench, wheel, in_frame(poses[wheel], turned), straight=True, slow=2.0)
        lifted = turned.copy()
        lifted[2] += d.approach_height
        yield Move(wrench, wheel, in_frame(poses[wheel], lifted), straight=True)

    poses = ctx.poses()
    at_centre = compose(poses[wheel], pose(centre - tip, Rotation.identity()))
    at_centre[3:] = Rotation.from_euler("z", np.radians(rng.uniform(-30, 30))).as_quat()
    above = at_centre.copy()
    above[2] += d.approach_height
    yield Move(wrench, wheel, in_frame(poses[wheel], above))
    yield Move(wrench, wheel, in_frame(poses[wheel], at_centre), straight=True, slow=1.5)
    pulled = at_centre.copy()
    pulled[2] += d.lift_height
    yield Move(wrench, wheel, in_frame(poses[wheel], pulled), straight=True)
