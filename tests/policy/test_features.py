"""What the networks read and predict, built from poses and labels."""

import numpy as np

from hsp.geometry import relative
from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig, relative_poses
from hsp.policy.features import episode_steps, history_flags
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


def test_flags_mark_targets_of_ended_sub_tasks_from_the_frame_after_the_switch_shows():
    tool = np.array([0, 0, 0, 1, 1, 0, 0])
    target = np.array([1, 1, 1, 2, 2, 2, 2])
    f = history_flags(tool, target, 3)
    # the pair changes at frame 3 (target 1 ended) and at 5 (target 2 ended: (1, 2) → (0, 2))
    np.testing.assert_array_equal(f[:, :, 2], [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 1, 0], [0, 1, 0],
                                               [0, 1, 1]])
    np.testing.assert_array_equal(f[1:, :, 0].argmax(1), tool[:-1])


def test_lost_objects_leave_their_frames_out_of_the_losses():
    world, status = _episode(H=20)
    status[5:8, 1] = 2  # object 1 lost
    lab = label_episode(world, status, PriorConfig())
    s = episode_steps(world, status == 0, lab.tool, lab.target, lab.waypoint_index, CLASSES, 2)
    involved = (lab.tool == 1) | (lab.target == 1)
    np.testing.assert_array_equal(s.labelled, ~(np.isin(np.arange(20), [5, 6, 7]) & involved))
    assert not s.acted[4] or not involved[4]
