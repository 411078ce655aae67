"""Grasping by a fixed constraint: when the gripper closes on an object, the object is
welded to it at its current relative pose (Ravens does the same; friction grasps in
PyBullet dropped a 5 cm cube one time in three)."""

from __future__ import annotations

import numpy as np
import pybullet as p

from hsp.geometry import relative

GRASP_FORCE_N = 50.0


def body_pose(client: int, body: int, link: int = -1) -> np.ndarray:
    """World pose ``(7,)`` of a body's base (``link = -1``) or of one of its links."""
    if link < 0:
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
    else:
        s = p.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=client)
        pos, orn = s[4], s[5]
    return np.array([*pos, *orn])


class Gripper:
    """Holds at most one object of a scene by a JOINT_FIXED constraint to ``holder``."""

    def __init__(self, client: int, holder: int) -> None:
        self.client = client
        self.holder = holder
        self.constraint: int | None = None
        self.held: tuple[int, int] | None = None

    def grasp(self, body: int, link: int = -1) -> None:
        if self.constraint is not None:
            raise RuntimeError("gripper already holds an object")
        T_holder_obj = relative(body_pose(self.client, body, link), body_pose(self.client, self.holder))
        self.constraint = p.createConstraint(
            self.holder, -1, body, link, p.JOINT_FIXED, [0, 0, 0],
            parentFramePosition=T_holder_obj[:3].tolist(),
            childFramePosition=[0, 0, 0],
            parentFrameOrientation=T_holder_obj[3:].tolist(),
            childFrameOrientation=[0, 0, 0, 1],
            physicsClientId=self.client,
        )
        p.changeConstraint(self.constraint, maxForce=GRASP_FORCE_N, physicsClientId=self.client)
        self.held = (body, link)

    def release(self) -> None:
        if self.constraint is not None:
            p.removeConstraint(self.constraint, physicsClientId=self.client)
        self.constraint = None
        self.held = None

    @property
    def closed(self) -> bool:
        return self.constraint is not None
