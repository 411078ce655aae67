"""The simulated Kuka: IK to 1 mm, grasping by constraint, the wrench turning bolts."""

import numpy as np
import pybullet as p
import pytest
from scipy.spatial.transform import Rotation

from hsp.geometry import rotation_angle_deg
from hsp.sim.ik import LOWER, REST, UPPER, KukaIK
from hsp.sim.robot import KukaArm
from hsp.sim.scene import SIM_HZ, Scene
from hsp.tasks.layout import sample_layout


def _targets(n: int, seed: int, z: tuple[float, float]) -> np.ndarray:
    """Poses pointing down in the arm's workspace (flange 0.45–0.70 m in front, |y| ≤ 0.25 m)."""
    rng = np.random.default_rng(seed)
    xyz = np.stack([rng.uniform(0.45, 0.7, n), rng.uniform(-0.25, 0.25, n), rng.uniform(*z, n)], 1)
    yaw = rng.uniform(-1.0, 1.0, n)
    q = np.stack([np.zeros(n), np.zeros(n), np.sin(yaw / 2), np.cos(yaw / 2)], 1)
    return np.concatenate([xyz, q], 1)


def test_ik_solution_is_exact_and_within_limits():
    ik = KukaIK()
    try:
        q = REST
        for T in _targets(30, 0, (0.2, 0.45)):
            q = ik.solve(np.array([*T[:3], 0, 1, 0, 0]), q)
            assert np.linalg.norm(ik.flange_pose(q)[:3] - T[:3]) < 1e-4
            assert np.all(q >= LOWER) and np.all(q <= UPPER)
    finally:
        ik.close()


def _settle(scene: Scene, T: np.ndarray, seconds: float) -> None:
    for _ in range(int(seconds * SIM_HZ)):
        scene.substep(T)


@pytest.fixture
def kuka_scene(tasks):
    task = tasks["stacking-1"]
    scene = Scene(task, sample_layout(task, np.random.default_rng(0)), "kuka")
    yield scene
    scene.close()


def test_kuka_reaches_commanded_tool_pose_within_1mm(kuka_scene):
    """Cartesian control: after settling, the tool-centre point is within 1 mm and 1°."""
    assert isinstance(kuka_scene.ee, KukaArm)
    for T in _targets(6, 1, (0.05, 0.25)):
        _settle(kuka_scene, T, 1.0)
        actual = kuka_scene.ee.tcp_pose()
        assert np.linalg.norm(actual[:3] - T[:3]) < 1e-3
        assert rotation_angle_deg(actual[3:], T[3:]) < 1.0


def test_kuka_grasps_lifts_and_releases_a_block(kuka_scene):
    scene = kuka_scene
    block = scene.task.index("block_red")
    start = scene.object_poses()[block]
    above = np.array([*start[:3] + [0, 0, 0.1], 0, 0, 0, 1])
    at = np.array([*start[:3], 0, 0, 0, 1])
    _settle(scene, above, 1.0)
    _settle(scene, at, 1.0)
    scene.grasp(block)
    _settle(scene, above, 1.5)
    lifted = scene.object_poses()[block]
    assert lifted[2] - start[2] > 0.09, "the block rises with the gripper"
    scene.release()
    _settle(scene, above, 1.0)
    assert abs(scene.object_poses()[block][2] - start[2]) < 0.005, "released, the block falls back to the table"


def test_wrench_turns_a_bolt_only_when_seated(tasks):
    task = tasks["tire-removal"]
    layout = sample_layout(task, np.random.default_rng(3))
    with Scene(task, layout, "kuka") as scene:
        bolt, other = task.index("bolt_1"), task.index("bolt_2")
        socket = scene.object_poses()[bolt][:3] + task.keypoint("bolt_1", "socket")
        before = scene.object_poses()
        for yaw in np.radians(np.linspace(-20, 30, 6)):
            hover = np.array([*socket + [0, 0, 0.02], 0, 0, np.sin(yaw / 2), np.cos(yaw / 2)])
            _settle(scene, hover, 0.3)
        assert rotation_angle_deg(before[bolt, 3:], scene.object_poses()[bolt, 3:]) < 0.5, "hovering 2 cm above: no turn"
        seated = np.array([*socket, 0, 0, np.sin(-0.35 / 2), np.cos(-0.35 / 2)])
        _settle(scene, seated, 1.0)
        q0 = p.getJointState(scene.bodies[bolt], 0, physicsClientId=scene.client)[0]
        for yaw in np.radians(np.linspace(-20, 25, 10)):
            _settle(scene, np.array([*socket, 0, 0, np.sin(yaw / 2), np.cos(yaw / 2)]), 0.2)
        q1 = p.getJointState(scene.bodies[bolt], 0, physicsClientId=scene.client)[0]
        assert np.degrees(q1 - q0) == pytest.approx(45.0, abs=3.0), "the bolt turns with the wrench"
        assert rotation_angle_deg(before[other, 3:], scene.object_poses()[other, 3:]) < 0.5


def test_tool_keeps_its_orientation_on_the_flange_while_the_arm_turns_a_held_brush(tasks):
    """The tool turns exactly as commanded when it holds something: turned by 80° and
    back with a brush in hand, the tool does not stay turned on the flange (without
    :meth:`KukaArm.reseat`, 0.64° here and 49° with the brush held farther out, through
    the drift of PyBullet's fixed constraint under a load)."""
    task = tasks["painting"]
    scene = Scene(task, sample_layout(task, np.random.default_rng(3)), "kuka")
    try:
        down = np.array([0.0, 1.0, 0.0, 0.0])  # the tool pointing down
        start = np.array([0.55, 0.0, 0.35, *down])
        _settle(scene, start, 1.0)
        brush = scene.bodies[task.index("brush")]
        p.resetBasePositionAndOrientation(brush, scene.ee.tcp_pose()[:3].tolist(), [0, 0, 0, 1],
                                          physicsClientId=scene.client)
        scene.grasp(task.index("brush"))
        for turn in (80, 30, 80, 30):
            T = np.array([*start[:3], *(Rotation.from_euler("x", turn, degrees=True) * Rotation.from_quat(down)).as_quat()])
            _settle(scene, T, 1.0)
            assert rotation_angle_deg(scene.ee.tcp_pose()[3:], T[3:]) < 0.3
            assert np.linalg.norm(scene.ee.tcp_pose()[:3] - T[:3]) < 1e-3
            assert np.linalg.norm(scene.object_poses()[task.index("brush")][:3] - T[:3]) < 0.01, "the brush is held"
    finally:
        scene.close()
