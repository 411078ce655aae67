"""What the networks read and predict, built from poses and labels."""

import numpy as np

from scipy.spatial.transform import Rotation

from hsp.geometry import compose, relative, yaw_of
from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig, relative_poses
from hsp.policy.features import (came_from, episode_steps, history_flags, in_view, nearest_round_turn,
                                 nearest_symmetric, sector_turns, seen_by_pi_m, turned_about_z)
from tests.labeling.test_em import _episode

CLASSES = np.array([0, 1, 1])


def _steps(H=40):
    world, status = _episode(H=H)
    lab = label_episode(world, status, PriorConfig())
    return world, lab, episode_steps(world, status == 0, lab.tool, lab.target, lab.waypoint_index, CLASSES, 2)


def test_history_and_progress_are_the_previous_frame_labels():
    world, lab, s = _steps()
    rel = relative_poses(world)
    t = np.arange(1, 40)
    assert np.all(s.history[0] == 0) and np.all(s.progress[0] == 0) and np.all(s.flags[0] == 0)
    np.testing.assert_array_equal(s.history[1:, :2].argmax(1), CLASSES[lab.tool[:-1]])
    np.testing.assert_array_equal(s.history[1:, 2:4].argmax(1), CLASSES[lab.target[:-1]])
    np.testing.assert_allclose(s.history[1:, 4:], s.waypoint[:-1])
    np.testing.assert_allclose(s.progress[1:], rel[t, lab.tool[:-1], lab.target[:-1]] - s.waypoint[:-1], atol=1e-6)
    np.testing.assert_array_equal(s.flags[t, lab.tool[:-1], 0], 1)
    np.testing.assert_array_equal(s.flags[t, lab.target[:-1], 1], 1)


def test_waypoint_current_and_action_come_from_the_labelled_pair():
    world, lab, s = _steps()
    rel = relative_poses(world)
    t = np.arange(40)
    np.testing.assert_allclose(s.current, rel[t, lab.tool, lab.target], atol=1e-6)
    np.testing.assert_allclose(s.waypoint, rel[lab.waypoint_index, lab.tool, lab.target], atol=1e-6)
    np.testing.assert_allclose(s.action[:-1, :3], rel[t[1:], lab.tool[:-1], lab.target[:-1], :3] - s.current[:-1, :3],
                               atol=1e-6)
    np.testing.assert_allclose(s.remaining[:, :3], s.waypoint[:, :3] - s.current[:, :3], atol=1e-6)
    assert np.all(s.action[-1] == 0) and np.abs(s.action[:, :3]).max() > 0.005  # the end-effector moves
    np.testing.assert_allclose(s.ee_in_object[5, 2], relative(world[5, 0], world[5, 2]), atol=1e-6)
    assert s.labelled.all() and s.acted[:-1].all() and not s.acted[-1]


def test_flags_mark_targets_and_tools_of_ended_sub_tasks_from_the_frame_after_the_switch_shows():
    tool = np.array([0, 0, 0, 1, 1, 0, 0])
    target = np.array([1, 1, 1, 2, 2, 2, 2])
    f = history_flags(tool, target, 3)
    # the pair changes at frame 3 (target 1 ended) and at 5 (target 2 ended: (1, 2) → (0, 2))
    np.testing.assert_array_equal(f[:, :, 2], [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 1, 0], [0, 1, 0],
                                               [0, 1, 1]])
    # tools of ended sub-tasks: object 1 from frame 6 (the end-effector is never flagged)
    np.testing.assert_array_equal(f[:, :, 3], [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0],
                                               [0, 1, 0]])
    np.testing.assert_array_equal(f[1:, :, 0].argmax(1), tool[:-1])


def test_lost_objects_leave_their_frames_out_of_the_losses():
    world, status = _episode(H=20)
    status[5:8, 1] = 2  # object 1 lost
    lab = label_episode(world, status, PriorConfig())
    s = episode_steps(world, status == 0, lab.tool, lab.target, lab.waypoint_index, CLASSES, 2)
    involved = (lab.tool == 1) | (lab.target == 1)
    np.testing.assert_array_equal(s.labelled, ~(np.isin(np.arange(20), [5, 6, 7]) & involved))
    assert not s.acted[4] or not involved[4]


def reach_rest_reach(rest: int = 10, tremor_m: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The end-effector (tool) reaches object 1 by frame 10, rests there ``rest`` frames, then
    reaches object 2 (a hand's tremor of ``tremor_m`` per axis on top): world poses and the
    demonstrator's labels, target and way-point frame, switching at frame 10 + ``rest``."""
    x = np.concatenate([np.linspace(0, 0.3, 11), np.full(rest, 0.3), np.linspace(0.3, 0.0, 9)])
    y = np.concatenate([np.zeros(11 + rest), np.linspace(0.0, 0.3, 9)])
    H = len(x)
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    world[:, 1, :3] = [0.3, 0.0, 0.0]
    world[:, 2, :3] = [0.0, 0.3, 0.0]
    world[:, 0, 0], world[:, 0, 1] = x, y
    world[:, 0, :3] += np.random.default_rng(seed).normal(0.0, tremor_m, (H, 3))
    switch = 10 + rest
    return world, np.where(np.arange(H) < switch, 1, 2), np.where(np.arange(H) < switch, 10, H - 1)


def test_a_sub_task_ends_where_its_tool_has_rested_settle_frames_as_the_stepper_decides():
    """The switch moves from 20 to frame 10 + 3; the rest is waiting."""
    world, target, k = reach_rest_reach()
    H = len(world)
    s = episode_steps(world, np.ones((H, 3), bool), np.zeros(H, np.int64), target, k, CLASSES, 2, 0.002, 3)
    np.testing.assert_array_equal(s.target, np.where(np.arange(H) < 13, 1, 2))
    np.testing.assert_array_equal(np.flatnonzero(s.decision), [0, 13])
    np.testing.assert_array_equal(np.flatnonzero(~s.acted[:-1]), np.arange(10, 20))  # resting is not π_l's to imitate
    unchanged = episode_steps(world, np.ones((H, 3), bool), np.zeros(H, np.int64), target, k, CLASSES, 2)
    np.testing.assert_array_equal(unchanged.target, target)


def test_a_turned_pose_is_the_tool_turned_about_the_targets_z_axis():
    """Whatever the target's pose, p[i, j] seen from the target turned by θ about its z axis
    is object i's world pose turned by θ about that axis through the target's origin."""
    rng = np.random.default_rng(0)
    target = np.concatenate([rng.uniform(-1, 1, (5, 3)), Rotation.random(5, random_state=1).as_quat()], 1)
    tool = np.concatenate([rng.uniform(-1, 1, (5, 3)), Rotation.random(5, random_state=2).as_quat()], 1)
    angle = rng.uniform(-np.pi, np.pi, 5)
    got = compose(target, turned_about_z(relative(tool, target), angle))
    axis = Rotation.from_quat(target[:, 3:]).apply([0.0, 0.0, 1.0])
    turn = Rotation.from_rotvec(axis * angle[:, None])
    want = np.concatenate([target[:, :3] + turn.apply(tool[:, :3] - target[:, :3]),
                           (turn * Rotation.from_quat(tool[:, 3:])).as_quat()], 1)
    np.testing.assert_allclose(got[:, :3], want[:, :3], atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(got[:, 3:] * want[:, 3:], 1)), 1.0, atol=1e-9)


def test_the_sector_turn_brings_a_way_point_within_half_a_fold_of_the_x_axis():
    w = np.zeros((4, 7))
    w[:, 6] = 1.0
    w[:, :2] = [[0.0, 0.05], [-0.05, 0.001], [0.03, -0.04], [0.01, 0.02]]
    cube = sector_turns(w, np.array([4, 4, 4, 1]))
    np.testing.assert_allclose(cube, [-np.pi / 2, -np.pi, np.pi / 2, 0.0], atol=1e-9)
    turned = turned_about_z(w, cube)
    assert (np.abs(np.arctan2(turned[:3, 1], turned[:3, 0])) <= np.pi / 4 + 1e-9).all()
    any_turn = turned_about_z(w, sector_turns(w, np.zeros(4, int)))
    np.testing.assert_allclose(any_turn[:, 1], 0.0, atol=1e-12)
    assert (any_turn[:, 0] > 0).all()


def _yawed(yaw_deg: float, xyz=(0.0, 0.0, 0.0), tilt_deg: float = 0.0) -> np.ndarray:
    r = Rotation.from_euler("z", yaw_deg, degrees=True) * Rotation.from_euler("x", tilt_deg, degrees=True)
    return np.r_[xyz, r.as_quat()]


def test_the_nearest_symmetric_pose_turns_an_object_about_its_own_axis_by_its_symmetry_only():
    """A cube at 85° seen from a hand at 10° is the cube at −5°; a two-fold object at 85°
    stays (265° is farther); a round one takes the reference's heading; a tilted one keeps
    its tilt; the position never changes."""
    ref = np.stack([_yawed(10), _yawed(10), _yawed(100), _yawed(-170, tilt_deg=5)])
    poses = np.stack([_yawed(85, (0.1, 0.2, 0.3)), _yawed(85), _yawed(0), _yawed(95, tilt_deg=3)])
    got = nearest_symmetric(poses, ref, np.array([4, 2, 0, 2]))
    np.testing.assert_allclose(np.degrees(yaw_of(got[:, 3:])), [-5, 85, 100, -85], atol=1e-6)
    np.testing.assert_allclose(got[:, :3], poses[:, :3])
    z_axis = Rotation.from_quat(got[3:, 3:]).apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.degrees(np.arccos(z_axis[:, 2])), [3.0], atol=1e-6)


def test_pi_m_reads_a_tools_position_from_its_direction_and_its_orientation_from_its_heading():
    """A hand 5 cm from a cube's axis in the direction 130°, heading −70°, is read at 40°
    (a quarter turn back) and heading 20° (a quarter turn on); turning the answer back by
    the same turns gives the pose again."""
    pose = _yawed(-70, (0.05 * np.cos(np.radians(130)), 0.05 * np.sin(np.radians(130)), 0.08))
    seen, turns = seen_by_pi_m(pose[None], np.array([4]))
    np.testing.assert_allclose(np.degrees(turns), [[-90, 90]], atol=1e-9)
    np.testing.assert_allclose(np.degrees(np.arctan2(seen[0, 1], seen[0, 0])), 40, atol=1e-6)
    np.testing.assert_allclose(np.degrees(yaw_of(seen[:, 3:])), [20], atol=1e-6)
    back = in_view(seen, -turns)
    np.testing.assert_allclose(back[0, :3], pose[:3], atol=1e-12)
    np.testing.assert_allclose(abs(np.dot(back[0, 3:], pose[3:])), 1.0, atol=1e-12)


def test_on_a_round_target_a_way_point_on_its_axis_takes_the_tools_heading_and_one_off_it_stays():
    """A brush dipped tip down into a round bucket at a heading of 150° while it arrives at
    20° is the dip at 20° (the bucket looks the same turned); a wrench's 50° turn on a nut
    10 cm from a round wheel's axis is kept, since turning it back would carry it 8.7 cm
    round the wheel; a target that is not round keeps both."""
    tip_down = Rotation.from_euler("y", 90, degrees=True)
    dip = np.r_[0.0, 0.0, 0.13, (Rotation.from_euler("z", 150, degrees=True) * tip_down).as_quat()]
    arriving = np.r_[0.1, 0.1, 0.3, Rotation.from_euler("ZY", [20, 30], degrees=True).as_quat()]
    turn = _yawed(50, (0.1, 0.0, 0.05))
    seated = _yawed(0, (0.1, 0.0, 0.05))
    got = nearest_round_turn(np.stack([dip, turn, dip]), np.stack([arriving, seated, arriving]),
                             np.array([True, True, False]))
    want = Rotation.from_euler("z", 20, degrees=True) * tip_down
    assert (Rotation.from_quat(got[0, 3:]) * want.inv()).magnitude() < np.radians(1)
    np.testing.assert_allclose(got[0, :3], dip[:3], atol=1e-12)
    np.testing.assert_allclose(got[1:], np.stack([turn, dip]), atol=1e-12)


def test_pi_m_reads_where_the_tool_came_from_within_its_sub_task():
    """Over, start, end of a stroke, with the same pair: at the start the brush has come
    6 cm down, at the end 9 cm along; the first decision of a pair has come from nowhere."""
    pos = np.array([[0.0, 0, 0.3], [0.1, 0, 0.16], [0.1, 0, 0.10], [0.19, 0, 0.10], [0.19, 0, 0.18]])
    world = np.zeros((5, 3, 7))
    world[..., 6] = 1.0
    world[:, 1, :3] = pos
    tool, target = np.array([1, 1, 1, 1, 1]), np.array([2, 2, 2, 2, 2])
    tool[0] = 0
    got = came_from(world, np.ones((5, 3), bool), tool, target, np.ones(5, bool))
    np.testing.assert_allclose(got, [[0, 0, 0], [0, 0, 0], [1, 0.06, 0], [1, 0, 0.09], [1, -0.08, 0]], atol=1e-6)
