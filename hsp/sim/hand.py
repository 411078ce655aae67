"""The demonstrator's floating hand: a gripper-shaped body moved like a mocap target."""

from __future__ import annotations

import numpy as np
import pybullet as p

from hsp.sim.grasp import Gripper, body_pose


class FloatingHand:
    """End-effector of the human demonstrations (painting, stacking).

    The hand is a fixed-base body that is teleported to each commanded pose; it has no
    collision shapes, and what it holds follows through the grasp constraint.
    """

    def __init__(self, client: int, urdf: str, start: np.ndarray) -> None:
        self.client = client
        self.body = p.loadURDF(urdf, start[:3].tolist(), start[3:].tolist(), useFixedBase=True, physicsClientId=client)
        self.gripper = Gripper(client, self.body)

    def tcp_pose(self) -> np.ndarray:
        return body_pose(self.client, self.body)

    def command(self, T_world_tcp: np.ndarray) -> None:
        p.resetBasePositionAndOrientation(self.body, T_world_tcp[:3].tolist(), T_world_tcp[3:].tolist(), physicsClientId=self.client)

    def settle(self) -> None:
        """Nothing to wait for: the hand is where it was commanded."""
