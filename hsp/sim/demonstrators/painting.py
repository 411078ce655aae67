"""Painting: grasp the brush, dip its tip in the paint, stroke a line 10 cm above the canvas.

Sub-tasks (tool o+, target o*): (hand, brush) reach and grasp; (brush, bucket) dip;
(brush, canvas) stroke.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import compose
from hsp.sim.demonstrators.common import hand_yaw, nearest_yaw, pose, reachable_yaw
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
    roll = rng.normal(0, 0.05)

    def hand_on_brush(yaw: float, height: float) -> np.ndarray:
        return pose([along, 0.0, height], Rotation.from_euler("xz", [roll, yaw]))

    # a robot takes the mirrored grasp (the hand looks the same turned by π) if its arm cannot reach this one
    yaw = reachable_yaw(yaw, lambda y: [compose(ctx.poses()[brush], hand_on_brush(y, h)) for h in (d.approach_height, 0.0)],
                        ctx.reach_error, candidates=2)
    tilt = Rotation.from_euler("xz", [roll, yaw])
    grasp = pose([along, 0.0, 0.0], tilt)
    yield Move(hand, brush, pose([along, 0.0, d.approach_height], tilt))
    yield Move(hand, brush, grasp, straight=True, slow=1.3)
    yield Grasp(brush)

    def hand_at(target: int, *brush_poses: np.ndarray) -> list[np.ndarray]:
        """World poses of the hand holding the brush at these poses in the target's frame."""
        T_world_target = ctx.poses()[target]
        return [compose(compose(T_world_target, b), grasp) for b in brush_poses]

    # (brush, bucket): tip down above the paint, dip, lift back out; a robot turns the
    # brush about the vertical to the nearest heading its arm reaches.
    heading = rng.uniform(-np.pi, np.pi)
    pitch = np.pi / 2 + rng.normal(0, 0.08)
    offset = np.concatenate([rng.uniform(-0.008, 0.008, 2), [rng.uniform(-0.005, 0.005)]])

    def dip(heading: float) -> list[np.ndarray]:
        """The dip's way-points, the brush in the bucket's frame: above the paint, in it, out."""
        R = Rotation.from_euler("z", heading) * Rotation.from_euler("y", pitch)
        at = paint + offset - R.apply(tip)
        above = at + [0, 0, 0.13]
        return [pose(above, R), pose(at, R), pose(above + [0, 0, 0.02], R)]

    above, at_paint, lifted = dip(reachable_yaw(heading, lambda h: hand_at(bucket, *dip(h)), ctx.reach_error))
    yield Move(brush, bucket, above)
    yield Move(brush, bucket, at_paint, straight=True, slow=1.2)
    yield Move(brush, bucket, lifted, straight=True)

    # (brush, canvas): onto the plane above the canvas, a straight stroke, lift.
    hx, hy = s.surface_half_extent or (0.1, 0.07)
    length = rng.uniform(1.4, 2.4) * s.stroke_length
    direction = rng.uniform(-np.pi, np.pi)
    half = 0.5 * length * np.array([np.cos(direction), np.sin(direction), 0.0])
    room = np.maximum(np.array([hx, hy]) - np.abs(half[:2]) - 0.01, 0.0)
    centre = surface + np.concatenate([rng.uniform(-room, room), [s.plane_height]])
    heading = rng.uniform(-np.pi, np.pi)
    pitch = np.pi / 2 - rng.uniform(0.0, 0.3)

    def stroke(heading: float) -> list[np.ndarray]:
        """The stroke's way-points, the brush in the canvas's frame: over the start, at it, to the end, lifted."""
        R = Rotation.from_euler("z", heading) * Rotation.from_euler("y", pitch)
        start, end = centre - half - R.apply(tip), centre + half - R.apply(tip)
        return [pose(start + [0, 0, 0.06], R), pose(start, R), pose(end, R), pose(end + [0, 0, 0.08], R)]

    over, start, end, lifted = stroke(reachable_yaw(heading, lambda h: hand_at(canvas, *stroke(h)), ctx.reach_error))
    yield Move(brush, canvas, over)
    yield Move(brush, canvas, start, straight=True, slow=1.2)
    yield Move(brush, canvas, end, straight=True, slow=1.5)
    yield Move(brush, canvas, lifted, straight=True)
