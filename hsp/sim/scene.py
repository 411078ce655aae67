"""A PyBullet (DIRECT) scene built from a task and a layout.

One private physics client per scene (``physicsClientId`` everywhere), the table top is
the plane z = 0 of the world frame, objects are loaded from the task's URDFs, index 0
is the end-effector: the floating hand of the demonstrations or a Kuka-held tool.
"""

from __future__ import annotations

import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pybullet as p

from hsp.errors import HspError
from hsp.geometry.mesh import obj_vertices
from hsp.sim.coupling import SocketCoupling
from hsp.sim.grasp import body_pose
from hsp.sim.hand import FloatingHand
from hsp.sim.robot import KukaArm
from hsp.tasks.layout import mesh_extent
from hsp.tasks.registry import Task

SIM_HZ = 240


def _revolute_urdf(urdf: Path, out_dir: Path) -> Path:
    """The object's link turning about z on a massless fixed mount (a lug nut on its stud)."""
    tree = ET.parse(urdf)
    link = tree.getroot().find("link")
    if link is None:
        raise HspError(f"{urdf}: no <link> element")
    for mesh in link.iter("mesh"):
        mesh.set("filename", str((urdf.parent / mesh.get("filename", "")).resolve()))
    robot = ET.Element("robot", name=f"{urdf.stem}_mount")
    mount = ET.SubElement(robot, "link", name="mount")
    inertial = ET.SubElement(mount, "inertial")
    ET.SubElement(inertial, "mass", value="0")
    ET.SubElement(inertial, "inertia", ixx="0", ixy="0", ixz="0", iyy="0", iyz="0", izz="0")
    joint = ET.SubElement(robot, "joint", name="spin", type="continuous")
    ET.SubElement(joint, "parent", link="mount")
    ET.SubElement(joint, "child", link=link.get("name", "base"))
    ET.SubElement(joint, "axis", xyz="0 0 1")
    robot.append(link)
    out = out_dir / f"{urdf.stem}_mount.urdf"
    ET.ElementTree(robot).write(out)
    return out


class Scene:
    """Objects of a task at a layout, plus the embodiment that moves object 0."""

    def __init__(self, task: Task, layout: np.ndarray, embodiment: str) -> None:
        self.task = task
        self.client = p.connect(p.DIRECT)
        self._tmp = tempfile.TemporaryDirectory(prefix="hsp_scene_")
        c = self.client
        p.setGravity(0, 0, -9.81, physicsClientId=c)
        p.setTimeStep(1.0 / SIM_HZ, physicsClientId=c)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=c)
        self.table = p.createMultiBody(0, plane, physicsClientId=c)
        p.changeDynamics(self.table, -1, lateralFriction=0.8, physicsClientId=c)

        tool_urdf = str(task.urdf(0))
        if embodiment == "hand":
            self.ee: FloatingHand | KukaArm = FloatingHand(c, tool_urdf, layout[0])
        elif embodiment == "kuka":
            self.ee = KukaArm(c, tool_urdf, tool_length=float(obj_vertices(task.mesh(0))[:, 2].max()))
            self.ee.reset_to(layout[0])
        else:
            raise HspError(f"unknown embodiment {embodiment!r} (hand, kuka)")

        self.bodies: list[int] = [self.ee.body]
        self.links: list[int] = [-1]
        for i, obj in enumerate(task.objects[1:], start=1):
            urdf, pose = task.urdf(i), layout[i]
            if obj.place.joint == "revolute_z":
                body = p.loadURDF(str(_revolute_urdf(urdf, Path(self._tmp.name))), pose[:3].tolist(), pose[3:].tolist(),
                                  useFixedBase=True, physicsClientId=c)
                p.setJointMotorControl2(body, 0, p.VELOCITY_CONTROL, targetVelocity=0, force=2.0, physicsClientId=c)
                self.links.append(0)
            else:
                body = p.loadURDF(str(urdf), pose[:3].tolist(), pose[3:].tolist(), useFixedBase=obj.place.fixed, physicsClientId=c)
                p.changeDynamics(body, -1, lateralFriction=0.8, physicsClientId=c)
                self.links.append(-1)
            self.bodies.append(body)
        self.coupling = SocketCoupling.for_task(self) if task.spec.kind == "tire_removal" else None
        self.radius = [mesh_extent(task.mesh(i))[0] for i in range(len(task.objects))]

    def object_poses(self) -> np.ndarray:
        """World poses ``(n, 7)`` of all task objects, index 0 the end-effector."""
        return np.stack([body_pose(self.client, b, l) for b, l in zip(self.bodies, self.links)])

    def substep(self, T_world_tcp: np.ndarray) -> None:
        """Command the end-effector and advance physics by 1/SIM_HZ s."""
        self.ee.command(T_world_tcp)
        if self.coupling is not None:
            self.coupling.update()
        p.stepSimulation(physicsClientId=self.client)
        if isinstance(self.ee, KukaArm):
            self.ee.reseat()

    def grasp(self, i: int) -> None:
        self.ee.gripper.grasp(self.bodies[i], self.links[i])

    def release(self) -> None:
        self.ee.gripper.release()

    def close(self) -> None:
        if isinstance(self.ee, KukaArm):
            self.ee.close()
        if p.isConnected(self.client):
            p.disconnect(self.client)
        self._tmp.cleanup()

    def __enter__(self) -> "Scene":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
