"""Painting: grasp the brush, dip its tip in the paint, stroke a line 10 cm above the canvas.

Sub-tasks (tool o+, target o*): (hand, brush) reach and grasp; (brush, bucket) dip;
(brush, canvas) stroke.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.sim.demonstrators.common import hand_yaw, nearest_yaw, pose
from hsp.sim.demonstrators.steps import Grasp, Move, Step

if TYPE_CHECKING:
    from hsp.sim.demonstration import PlanContext


def painting_plan(ctx: "PlanContext") -> Iterator[Step]:
    task, rng, d = ctx.task, ctx.rng, ctx.task.spec.demonstrator
    s = task.spec.success
    hand, brush, bucket, canvas = 0, task.index(s.tool), task.index(s.source), task.index(s.surface)
    tip = task.keypoint(s.tool, s.tool_point)
    paint = task.keypoint(s.source, s.source_point)
    surface = task.keypoint(s.surface, s.surface_point)

    # (hand, brush): from above onto the handle, fingers across it (hand x = brush y).
    poses = ctx.poses()
    along = rng.uniform(-0.06, -0.06 + 2 * d.grasp_offset)
    world_yaw = float(Rotation.from_quat(poses[brush, 3:]).as_euler("xyz")[2])
    yaw = nearest_yaw(world_yaw + np.pi / 2 + np.array([0.0, np.pi]), hand_yaw(poses[hand])) - world_yaw
    tilt = Rotation.from_euler("xz", [rng.normal(0, 0.05), yaw])
    grasp = pose([along, 0.0, 0.0], tilt)
    yield Move(hand, brush, pose([along, 0.0, d.approach_height], tilt))
    yield Move(hand, brush, grasp, straight=True, slow=1.3)
    yield Grasp(brush)

    # (brush, bucket): tip down above the paint, dip, lift back out.
    heading = rng.uniform(-np.pi, np.pi)
    R_dip = Rotation.from_euler("z", heading) * Rotation.from_euler("y", np.pi / 2 + rng.normal(0, 0.08))
    offset = np.concatenate([rng.uniform(-0.008, 0.008, 2), [rng.uniform(-0.005, 0.005)]])
    at_paint = paint + offset - R_dip.apply(tip)
    above = at_paint + [0, 0, 0.13]
    yield Move(brush, bucket, pose(above, R_dip))
    yield Move(brush, bucket, pose(at_paint, R_dip), straight=True, slow=1.2)
    yield Move(brush, bucket, pose(above + [0, 0, 0.02], R_dip), straight=True)

    # (brush, canvas): onto the plane above the canvas, a straight stroke, lift.
    hx, hy = s.surface_half_extent or (0.1, 0.07)
    length = rng.uniform(1.4, 2.4) * s.stroke_length
    direction = rng.uniform(-np.pi, np.pi)
    half = 0.5 * length * np.array([np.cos(direction), np.sin(direction), 0.0])
    room = np.maximum(np.array([hx, hy]) - np.abs(half[:2]) - 0.01, 0.0)
    centre = surface + np.concatenate([rng.uniform(-room, room), [s.plane_height]])
    R_paint = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi)) * Rotation.from_euler("y", np.pi / 2 - rng.uniform(0.0, 0.3))
    start, end = centre - half - R_paint.apply(tip), centre + half - R_paint.apply(tip)
    yield Move(brush, canvas, pose(start + [0, 0, 0.06], R_paint))
    yield Move(brush, canvas, pose(start, R_paint), straight=True, slow=1.2)
    yield Move(brush, canvas, pose(end, R_paint), straight=True, slow=1.5)
    yield Move(brush, canvas, pose(end + [0, 0, 0.08], R_paint), straight=True)
