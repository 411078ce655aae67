"""Socket wrench on lug nut: while the wrench's socket sits on a bolt (tool point within
the task's tolerance of the bolt's socket point), the bolt's revolute joint is driven to
follow the wrench's rotation about the bolt axis; otherwise joint friction holds it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pybullet as p

from hsp.geometry import yaw_of
from hsp.sim.grasp import body_pose

if TYPE_CHECKING:
    from hsp.sim.scene import Scene

HOLD_TORQUE = 2.0
DRIVE_TORQUE = 20.0


class SocketCoupling:
    def __init__(self, scene: "Scene", bolts: list[int], tool_point: np.ndarray, bolt_point: np.ndarray, tolerance: float) -> None:
        self.scene = scene
        self.bolts = bolts
        self.tool_point = tool_point
        self.bolt_point = bolt_point
        self.tolerance = tolerance
        self.engaged: dict[int, tuple[float, float]] = {}

    @classmethod
    def for_task(cls, scene: "Scene") -> "SocketCoupling":
        s, task = scene.task.spec.success, scene.task
        return cls(
            scene,
            [task.index(b) for b in s.bolts],  # type: ignore[union-attr]
            task.keypoint(s.tool, s.tool_point),  # type: ignore[union-attr]
            task.keypoint(s.bolts[0], s.bolt_point),  # type: ignore[union-attr]
            s.tolerance,  # type: ignore[union-attr]
        )

    def _point(self, pose: np.ndarray, local: np.ndarray) -> np.ndarray:
        return np.array(p.multiplyTransforms(pose[:3].tolist(), pose[3:].tolist(), local.tolist(), [0, 0, 0, 1])[0])

    def update(self) -> None:
        sc = self.scene
        wrench = sc.ee.tcp_pose()
        tip = self._point(wrench, self.tool_point)
        wrench_yaw = float(yaw_of(wrench[3:]))
        for i in self.bolts:
            body = sc.bodies[i]
            socket = self._point(body_pose(sc.client, body, 0), self.bolt_point)
            if np.linalg.norm(tip - socket) <= self.tolerance:
                q = p.getJointState(body, 0, physicsClientId=sc.client)[0]
                yaw0, q0 = self.engaged.setdefault(i, (wrench_yaw, q))
                turn = np.angle(np.exp(1j * (wrench_yaw - yaw0)))
                p.setJointMotorControl2(body, 0, p.POSITION_CONTROL, targetPosition=q0 + turn, force=DRIVE_TORQUE,
                                        physicsClientId=sc.client)
            elif self.engaged.pop(i, None) is not None:
                p.setJointMotorControl2(body, 0, p.VELOCITY_CONTROL, targetVelocity=0, force=HOLD_TORQUE,
                                        physicsClientId=sc.client)
