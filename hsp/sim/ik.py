"""Inverse kinematics of the Kuka iiwa accurate to well under a millimetre.

PyBullet's null-space IK (joint limits, rest pose) keeps a good posture but misses by
3–4 mm; plain damped least squares reaches 0.01 mm but lets the posture drift. So: one
null-space solve, then plain solves seeded from it, on a private copy of the arm in its
own physics client so that seeding never disturbs the simulated robot.
"""

from __future__ import annotations

import numpy as np
import pybullet as p
import pybullet_data

from hsp.geometry import rotation_angle_deg

KUKA_URDF = "kuka_iiwa/model.urdf"
EE_LINK = 6
UPPER = np.array([2.96, 2.09, 2.96, 2.09, 2.96, 2.09, 3.05]) - 0.05
"""The URDF's joint limits less a 0.05 rad margin (the physics clamps at the limits)."""
LOWER = -UPPER
ROTATION_ARM_M = 0.1
"""An orientation error of 1 rad counts as 0.1 m of position error (:meth:`KukaIK.pose_error`)."""
RANGES = UPPER - LOWER
REST = np.array([0.0, 0.55, 0.0, -1.35, 0.0, 1.25, 0.0])
"""Elbow up, flange pointing down about 0.6 m in front of the base, joint 7 mid-range."""


class KukaIK:
    """IK for the link-6 (flange) pose of a Kuka iiwa standing at the world origin."""

    def __init__(self, refine_iterations: int = 4, tolerance: float = 1e-5) -> None:
        self.client = p.connect(p.DIRECT)
        p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=self.client)
        self.body = p.loadURDF(KUKA_URDF, useFixedBase=True, physicsClientId=self.client)
        self.refine_iterations = refine_iterations
        self.tolerance = tolerance

    def _set(self, q: np.ndarray) -> None:
        for j, qj in enumerate(q):
            p.resetJointState(self.body, j, float(qj), physicsClientId=self.client)

    def flange_pose(self, q: np.ndarray) -> np.ndarray:
        """Forward kinematics: flange-link pose ``(7,)`` for joints ``q (7,)``."""
        self._set(q)
        s = p.getLinkState(self.body, EE_LINK, computeForwardKinematics=True, physicsClientId=self.client)
        return np.array([*s[4], *s[5]])

    def solve(self, T_world_flange: np.ndarray, q_seed: np.ndarray) -> np.ndarray:
        """Joint angles ``(7,)`` placing the flange link at ``T_world_flange (7,)``."""
        pos, orn = list(T_world_flange[:3]), list(T_world_flange[3:])
        self._set(q_seed)
        q = np.array(
            p.calculateInverseKinematics(
                self.body, EE_LINK, pos, orn,
                lowerLimits=LOWER.tolist(), upperLimits=UPPER.tolist(),
                jointRanges=RANGES.tolist(), restPoses=REST.tolist(),
                maxNumIterations=100, residualThreshold=1e-5, physicsClientId=self.client,
            )
        )
        for _ in range(self.refine_iterations):
            if np.linalg.norm(self.flange_pose(q)[:3] - T_world_flange[:3]) < self.tolerance:
                break
            q = np.array(
                p.calculateInverseKinematics(
                    self.body, EE_LINK, pos, orn, maxNumIterations=100,
                    residualThreshold=1e-6, physicsClientId=self.client,
                )
            )
        return np.clip(q, LOWER, UPPER)

    def pose_error(self, q: np.ndarray, T_world_flange: np.ndarray) -> float:
        """How far the flange at joints ``q`` is from ``T_world_flange``: position error (m)
        plus ``ROTATION_ARM_M`` per radian of orientation error."""
        got = self.flange_pose(q)
        angle = np.radians(rotation_angle_deg(got[3:], T_world_flange[3:]))
        return float(np.linalg.norm(got[:3] - T_world_flange[:3]) + ROTATION_ARM_M * angle)

    def solve_from(self, T_world_flange: np.ndarray, seeds: list[np.ndarray], tolerance: float = 1e-3) -> np.ndarray:
        """The solution from the first of ``seeds`` whose :meth:`pose_error` is within
        ``tolerance``, else the best one: a posture that cannot reach a pose by small joint
        changes (another IK branch, joint 7 at its limit) is left for one that can."""
        best, best_err = None, np.inf
        for seed in seeds:
            q = self.solve(T_world_flange, seed)
            err = self.pose_error(q, T_world_flange)
            if err < best_err:
                best, best_err = q, err
            if err <= tolerance:
                break
        return best  # type: ignore[return-value]

    def close(self) -> None:
        if p.isConnected(self.client):
            p.disconnect(self.client)
