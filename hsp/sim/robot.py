"""The Kuka iiwa from ``pybullet_data`` with a tool welded to its flange.

The tool (the gripper-shaped hand for pick-and-place, the socket wrench for tire removal)
is a separate body held by a stiff fixed constraint, put back on its mount after every
physics step (:meth:`KukaArm.reseat`); its frame is the tool-centre point, which is also
the end-effector object (index 0) of the task. Cartesian commands go
through :class:`~hsp.sim.ik.KukaIK` and joint position control.
"""

from __future__ import annotations

import numpy as np
import pybullet as p
import pybullet_data

from hsp.geometry import compose, inverse, rotation_angle_deg, slerp
from hsp.sim.grasp import Gripper, body_pose
from hsp.sim.ik import EE_LINK, KUKA_URDF, REST, KukaIK

FLANGE_OFFSET = 0.05
"""Distance from the link-6 frame to the flange face along its z axis (m)."""
PATH_STEP_M = 0.02
PATH_STEP_DEG = 5.0
"""Spacing of the poses at which :meth:`KukaArm.reach_error` checks a path."""
IK_EVERY = 4
"""Solve IK on every 4th physics step (60 Hz control at 240 Hz physics)."""


def _compose(T_a_b, T_b_c) -> tuple:
    """``T_a_c = T_a_b ∘ T_b_c`` for one pair of poses ``(position, quaternion)`` each, by
    PyBullet (25× faster than :func:`~hsp.geometry.compose` on one pose; used every physics step)."""
    return p.multiplyTransforms(T_a_b[0], T_a_b[1], T_b_c[0], T_b_c[1])


class KukaArm:
    """Kuka iiwa + tool. ``command`` sets joint targets; ``tcp_pose`` reads the tool."""

    def __init__(self, client: int, tool_urdf: str, tool_length: float, max_force: float = 300.0) -> None:
        self.client = client
        self.robot = p.loadURDF(pybullet_data.getDataPath() + "/" + KUKA_URDF, useFixedBase=True, physicsClientId=client)
        self.joints = list(range(7))
        for j, q in zip(self.joints, REST):
            p.resetJointState(self.robot, j, float(q), physicsClientId=client)
        self.T_flange_tcp = np.array([0.0, 0.0, FLANGE_OFFSET + tool_length, 0.0, 1.0, 0.0, 0.0])
        self._flange_tcp = (tuple(self.T_flange_tcp[:3]), tuple(self.T_flange_tcp[3:]))
        self._tcp_flange = p.invertTransform(*self._flange_tcp)
        start = compose(self._flange(), self.T_flange_tcp)
        self.body = p.loadURDF(tool_urdf, start[:3].tolist(), start[3:].tolist(), physicsClientId=client)
        # Constraint frames are relative to the link's centre of mass, not its URDF frame.
        com_pos, com_orn = p.getDynamicsInfo(self.robot, EE_LINK, physicsClientId=client)[3:5]
        T_com_tcp = compose(inverse(np.array([*com_pos, *com_orn])), self.T_flange_tcp)
        cid = p.createConstraint(
            self.robot, EE_LINK, self.body, -1, p.JOINT_FIXED, [0, 0, 0],
            parentFramePosition=T_com_tcp[:3].tolist(), childFramePosition=[0, 0, 0],
            parentFrameOrientation=T_com_tcp[3:].tolist(), childFrameOrientation=[0, 0, 0, 1],
            physicsClientId=client,
        )
        p.changeConstraint(cid, maxForce=5000.0, physicsClientId=client)
        self.max_force = max_force
        self.ik = KukaIK()
        self.gripper = Gripper(client, self.body)
        self.q_target = REST.copy()
        self._last_command: np.ndarray | None = None
        self._calls = 0

    def _flange(self) -> np.ndarray:
        return body_pose(self.client, self.robot, EE_LINK)

    def joint_positions(self) -> np.ndarray:
        return np.array([s[0] for s in p.getJointStates(self.robot, self.joints, physicsClientId=self.client)])

    def _flange_for(self, T_world_tcp: np.ndarray) -> np.ndarray:
        """The flange pose ``(7,)`` that puts the tool-centre point at ``T_world_tcp (7,)``."""
        return np.concatenate(_compose((T_world_tcp[:3], T_world_tcp[3:]), self._tcp_flange))

    def tcp_pose(self) -> np.ndarray:
        return body_pose(self.client, self.body)

    def command(self, T_world_tcp: np.ndarray) -> None:
        """Joint position targets that put the tool-centre point at ``T_world_tcp (7,)``."""
        self._calls += 1
        if self._last_command is not None and (
            self._calls % IK_EVERY or np.allclose(T_world_tcp, self._last_command, atol=1e-7)
        ):
            return
        self._last_command = np.array(T_world_tcp, copy=True)
        self.q_target = self.ik.solve_from(self._flange_for(T_world_tcp), [self.q_target, REST])
        p.setJointMotorControlArray(
            self.robot, self.joints, p.POSITION_CONTROL, targetPositions=self.q_target.tolist(),
            forces=[self.max_force] * 7, positionGains=[0.3] * 7, velocityGains=[1.0] * 7,
            physicsClientId=self.client,
        )

    def reseat(self) -> None:
        """Put the tool back where its mount on the flange holds it, moving as the flange
        does, and what it holds (a body) with it, after each physics step. Loaded (a brush
        held), PyBullet's fixed constraint between the arm (a multibody) and the tool body
        keeps the position but lets the tool turn on the flange while the arm turns, and
        never takes it back: 2.4° as a policy turned a brush tip-down (its tip 3.5 cm off
        the paint), 49° when commanded an 80° turn at once. Bolting the tool into the arm's
        multibody by a fixed joint moves the same drift to the grasp (a held brush slid 3
        cm)."""
        c = self.client
        s = p.getLinkState(self.robot, EE_LINK, computeLinkVelocity=True, computeForwardKinematics=True,
                           physicsClientId=c)
        tcp = _compose((s[4], s[5]), self._flange_tcp)
        (wx, wy, wz), (vx, vy, vz), com = s[7], s[6], s[0]
        fix = _compose(tcp, p.invertTransform(*p.getBasePositionAndOrientation(self.body, physicsClientId=c)))
        bodies = [self.body] + ([self.gripper.held[0]] if self.gripper.held and self.gripper.held[1] < 0 else [])
        for b in bodies:  # moved by the world-frame correction; velocity v + ω × r, the flange's rigid motion
            pos, orn = _compose(fix, p.getBasePositionAndOrientation(b, physicsClientId=c))
            rx, ry, rz = pos[0] - com[0], pos[1] - com[1], pos[2] - com[2]
            v = (vx + wy * rz - wz * ry, vy + wz * rx - wx * rz, vz + wx * ry - wy * rx)
            p.resetBasePositionAndOrientation(b, pos, orn, physicsClientId=c)
            p.resetBaseVelocity(b, v, s[7], physicsClientId=c)

    def reach_error(self, T_world_tcps: list[np.ndarray]) -> float:
        """Worst :meth:`~hsp.sim.ik.KukaIK.pose_error` of the flange on the way from the
        last commanded pose through a chain of tool-centre-point poses ``(7,)`` each, the way
        :meth:`command` would go: straight lines and slerps sampled every ``PATH_STEP_M`` or
        ``PATH_STEP_DEG``, each IK solve seeded with the one before, the first with the
        arm's present posture. Near 0 where the arm gets there by small joint changes."""
        q, worst = self.q_target, 0.0
        start = self._last_command if self._last_command is not None else self.tcp_pose()
        for T in T_world_tcps:
            n = int(max(1, np.ceil(np.linalg.norm(T[:3] - start[:3]) / PATH_STEP_M),
                        np.ceil(rotation_angle_deg(start[3:], T[3:]) / PATH_STEP_DEG)))
            s = np.arange(1, n + 1) / n
            path = np.concatenate([start[:3] + s[:, None] * (T[:3] - start[:3]), slerp(start[3:], T[3:], s)], axis=1)
            for P in path:
                T_world_flange = self._flange_for(P)
                q = self.ik.solve(T_world_flange, q)
                worst = max(worst, self.ik.pose_error(q, T_world_flange))
            start = T
        return worst

    def reset_to(self, T_world_tcp: np.ndarray) -> None:
        """Teleport the arm (and tool) so that the TCP is at ``T_world_tcp``; for layouts."""
        T_world_flange = self._flange_for(T_world_tcp)
        self.q_target = self.ik.solve(T_world_flange, REST)
        for j, q in zip(self.joints, self.q_target):
            p.resetJointState(self.robot, j, float(q), physicsClientId=self.client)
        tcp = compose(self._flange(), self.T_flange_tcp)
        p.resetBasePositionAndOrientation(self.body, tcp[:3].tolist(), tcp[3:].tolist(), physicsClientId=self.client)
        self._last_command = None
        self.command(T_world_tcp)

    def close(self) -> None:
        self.ik.close()
