"""The runner of π_h, π_m, π_l: its history is its own output, never a label."""

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from hsp.evaluation.env import EnvConfig, HspEnv, world_poses
from hsp.evaluation.proposed import HierarchyRunner, reachable_member
from hsp.geometry import apply_rotvec_delta, compose, rotvec_delta, yaw_of
from hsp.policy.features import CAME_FROM
from hsp.policy.networks import Hierarchy, Sizes
from hsp.policy.normalisation import FIELDS, Normalisation
from hsp.policy.stage import semantic_classes
from hsp.policy.train import Policy


def untrained_policy(task, seed: int = 0) -> Policy:
    """Random networks for ``task`` with unit normalisation (actions of a few mm)."""
    torch.manual_seed(seed)
    classes, n_classes = semantic_classes(task)
    net = Hierarchy(Sizes(len(task.objects), n_classes)).eval()
    dims = {k: 6 if k in ("remaining", "action") else CAME_FROM if k == "came_from" else 7 for k in FIELDS}
    stats = {f"{k}.mean": torch.zeros(d) for k, d in dims.items()} | {f"{k}.std": torch.ones(d) for k, d in dims.items()}
    stats["action.std"] = torch.full((6,), 0.002)
    return Policy(net, Normalisation(stats), task.names, classes, n_classes)


def test_the_history_is_the_runners_own_output(tasks):
    """At every step the history holds the tool, target and way-point the runner chose one
    step before, and the gripper is told to hold the chosen tool."""
    task = tasks["tire-removal"]
    runner = HierarchyRunner(untrained_policy(task), task)
    env = HspEnv(task, EnvConfig(max_steps=20))
    obs, _ = env.reset(seed=4)
    runner.reset(world_poses(obs), 4)
    for _ in range(6):
        action = runner.act(world_poses(obs))
        assert action.shape == (8,) and np.all(np.isfinite(action))
        assert action[7] == runner.trace[-1]["tool"]  # 0: the wrench itself
        obs, *_ = env.step(action)
    env.close()
    assert runner.trace[0]["previous"] is None
    for before, now in zip(runner.trace, runner.trace[1:]):
        tool, target, w = now["previous"]
        assert (tool, target) == (before["tool"], before["target"])
        np.testing.assert_array_equal(w, before["waypoint"])


def test_a_cube_turning_past_45_degrees_keeps_its_first_frames_equivalent(tasks):
    """Made canonical frame by frame, a cube turning from 40° to 50° about z would jump a
    quarter turn in its target's frame; the runner keeps the first frame's choice."""
    from hsp.geometry import rotation_angle_deg

    task = tasks["stacking-1"]
    runner = HierarchyRunner(untrained_policy(task), task)
    poses = np.tile([0.5, 0.0, 0.02, 0.0, 0.0, 0.0, 1.0], (len(task.objects), 1))
    poses[2, 3:] = Rotation.from_euler("z", 40, degrees=True).as_quat()
    runner.reset(poses, 0)
    before = runner.canonical(poses)[2, 3:]
    poses[2, 3:] = Rotation.from_euler("z", 50, degrees=True).as_quat()
    assert abs(rotation_angle_deg(before, runner.canonical(poses)[2, 3:]) - 10.0) < 1e-6


def test_the_labelled_step_commands_the_next_pose(tasks):
    """π_l's step (a frame's small motion), converted to a command for the hand holding a
    block, puts the hand where it must be for the block to make that step."""
    from hsp.evaluation.proposed import tcp_command
    from hsp.geometry import compose, relative
    from hsp.labeling.label import canonical_poses

    task = tasks["stacking-1"]
    sym = [o.symmetry for o in task.objects]
    rng = np.random.default_rng(2)

    def random_pose(z):
        q = rng.normal(size=4)
        return np.concatenate([rng.uniform(0.4, 0.6, 3) * [1, 1, z], q / np.linalg.norm(q)])

    now = np.stack([random_pose(1.0) for _ in task.objects])
    grasp = relative(now[0], now[1])  # the hand in the block's frame, rigid
    later = now.copy()
    small = np.concatenate([[0.02, -0.01, 0.015], Rotation.from_rotvec([0.03, -0.05, 0.08]).as_quat()])
    later[1] = compose(small, now[1])
    later[0] = compose(later[1], grasp)
    c_now, c_later = canonical_poses(now[None], sym)[0], canonical_poses(later[None], sym)[0]
    step = rotvec_delta(relative(c_now[1], c_now[3]), relative(c_later[1], c_later[3]))
    tcp = tcp_command(now, c_now, 1, 3, step)
    np.testing.assert_allclose(tcp[:3], later[0, :3], atol=1e-9)
    assert abs(abs(tcp[3:] @ later[0, 3:]) - 1) < 1e-9


def test_commands_make_up_an_arm_that_settles_short():
    """An arm that ends every move 1 mm short of its command, driven by steps of a fixed
    fraction f of the remaining way, stops 1 mm / f short of w_t; with the shortfall made
    up, it ends at w_t. A shortfall beyond the limit (an arm that cannot get there) is not."""
    from hsp.evaluation.proposed import with_shortfall

    w = np.array([0.5, 0.1, 0.2, *Rotation.from_euler("z", 30, degrees=True).as_quat()])
    short = np.array([0.001, 0.0, 0.0])
    f = 0.2

    def settle(make_up: bool) -> np.ndarray:
        pose, last = np.array([0.4, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0]), None
        for _ in range(300):
            command = apply_rotvec_delta(pose, f * rotvec_delta(pose, w))
            if make_up and last is not None:
                command = with_shortfall(command, pose, last, 0.01)
            pose, last = np.concatenate([command[:3] - short, command[3:]]), command
        return pose

    plain, made_up = settle(False), settle(True)
    np.testing.assert_allclose(plain[:3] - w[:3], -short / f, atol=1e-6)
    np.testing.assert_allclose(made_up[:3], w[:3], atol=1e-9)
    assert abs(abs(made_up[3:] @ w[3:]) - 1) < 1e-9
    far = w + np.array([0.0, 0.03, 0.04, 0, 0, 0, 0])
    np.testing.assert_array_equal(with_shortfall(w, w, far, 0.01), w)


def test_a_way_point_on_a_round_targets_axis_is_gone_to_at_the_nearest_turn_the_arm_reaches():
    """An arm that reaches only headings of its tool-centre point within ±30° of 90° goes
    to a dip learnt at 0° in a bucket turned by 17° turned by 45° (the nearest of 16 turns
    it reaches: 62°); a place
    10 cm off the axis (a nut on a round wheel) stays where it was learnt."""
    dip = np.r_[0.005, 0.0, 0.12, Rotation.from_euler("z", 0.0).as_quat()]
    bucket = np.r_[0.5, 0.1, 0.0, Rotation.from_euler("z", 0.3).as_quat()]
    grasp = np.r_[0.0, 0.0, 0.05, Rotation.from_euler("z", 0.0).as_quat()]
    reach = lambda tcps: 0.0 if abs(np.degrees(yaw_of(tcps[-1][3:])) - 90) <= 30 else 1.0  # noqa: E731
    got = reachable_member(dip, bucket, grasp, reach)
    np.testing.assert_allclose(np.degrees(yaw_of(got[3:])), 45.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(got[:2]), 0.005, atol=1e-12)
    assert reach([compose(compose(bucket, got), grasp)]) == 0.0
    off_axis = np.r_[0.1, 0.0, 0.05, dip[3:]]
    np.testing.assert_array_equal(reachable_member(off_axis, bucket, grasp, reach), off_axis)
