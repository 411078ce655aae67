"""What the networks read and predict, built from poses and labels."""

import numpy as np

from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig, pair_indices, pairs_of
from hsp.policy.features import episode_steps, pair_poses
from tests.labeling.test_em import _episode


def _steps():
    world, status = _episode(H=40)
    lab = label_episode(world, status, PriorConfig())
    pair = pair_indices(pairs_of(3), lab.tool, lab.target)
    return world, lab, pair, episode_steps(world, pair, lab.waypoint_index, np.array([0, 1, 1]), 2)


def test_history_and_progress_are_the_previous_frame_labels():
    world, lab, pair, s = _steps()
    rel = pair_poses(world)
    P = len(pairs_of(3))
    assert np.all(s.history[0] == 0) and np.all(s.progress[0] == 0)
    assert np.all(s.history[1:, :P].argmax(1) == pair[:-1]) and np.all(s.history[1:, :P].sum(1) == 1)
    np.testing.assert_allclose(s.history[1:, P:], s.waypoint[:-1])
    np.testing.assert_allclose(s.progress[1:], rel[np.arange(1, 40), pair[:-1]] - s.waypoint[:-1], atol=1e-6)


def test_waypoint_current_and_action_come_from_the_labelled_pair():
    world, lab, pair, s = _steps()
    rel = pair_poses(world)
    t = np.arange(40)
    np.testing.assert_allclose(s.current, rel[t, pair], atol=1e-6)
    np.testing.assert_allclose(s.waypoint, rel[lab.waypoint_index, pair], atol=1e-6)
    np.testing.assert_allclose(s.action[:-1, :3], rel[t[1:], pair[:-1], :3] - rel[t[:-1], pair[:-1], :3], atol=1e-6)
    assert np.all(s.action[-1] == 0) and np.abs(s.action[:, :3]).max() > 0.005  # the end-effector moves
    assert s.z.shape == (40, 7 * len(pairs_of(3))) and s.classes.shape == (40, 4)
    assert np.all(s.classes.sum(1) == 2)
