"""The baselines' observation, action and gripper from pose trajectories."""

import numpy as np

from hsp.baselines.observations import episode_arrays, flat_observation
from hsp.dataset.features import TrackStatus


def carry_episode() -> np.ndarray:
    """World poses ``(30, 3, 7)``: the hand moves 1 cm a frame along x, pausing from frame 14
    to 16; from x = 10 cm (frame 10) to 20 cm (frame 22) it carries block 1."""
    H = 30
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    steps = np.where((np.arange(H - 1) >= 14) & (np.arange(H - 1) < 16), 0.0, 0.01)
    world[:, 0, 0] = np.r_[0.0, np.cumsum(steps)]
    world[:, 0, 2] = 0.1
    world[:, 1, 0] = np.clip(world[:, 0, 0], 0.10, 0.20)
    world[:, 2, :2] = [0.5, 0.5]
    return world


def test_observation_is_positions_and_two_rotation_columns_whatever_the_quaternion_sign():
    world = carry_episode()
    flipped = world.copy()
    flipped[:, 1, 3:] *= -1
    obs = flat_observation(world)
    assert obs.shape == (30, 27)
    np.testing.assert_array_equal(obs, flat_observation(flipped))
    np.testing.assert_allclose(obs[5, :9], [0.05, 0, 0.1, 1, 0, 0, 1, 0, 0])


def test_gripper_closes_while_a_carried_object_moves_and_lost_steps_are_not_observed():
    """Closed from the first step that moves the block to its last: through a pause while
    holding and through a frame where the tracked block lags the hand by 3 cm (it still
    moves); open from the first step the hand moves alone."""
    world = carry_episode()
    world[13, 1, 0] -= 0.03
    status = np.zeros((30, 3), np.int64)
    status[3, 0] = TrackStatus.LOST
    obs, action, grip, observed = episode_arrays(world, status, ["none", "none", "none"], moving_m=0.002,
                                                 grasp_m=0.005)
    assert list(np.flatnonzero(grip)) == list(range(10, 22))
    np.testing.assert_allclose(action[5], [0.01, 0, 0, 0, 0, 0], atol=1e-12)
    assert list(np.flatnonzero(~observed)) == [2, 3, 29]


def test_gripper_closes_where_the_hand_came_to_rest_before_the_lift_whatever_its_jitter():
    """The hand rests on block 1 from frame 5 to 10, its tracked height jittering by 4 mm,
    then lifts it; the block's tracked pose lags the hand by one frame."""
    H = 20
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    world[:, 2, :2] = [0.5, 0.5]
    world[:, 1, :3] = [0.1, 0.0, 0.02]
    world[:, 0, 0] = np.minimum(0.02 * np.arange(H), 0.1)  # arrives at frame 5
    world[:, 0, 2] = 0.02 + np.maximum(0, np.arange(H) - 10) * 0.005  # lifts from frame 10
    world[6:10:2, 0, 2] += 0.004
    world[:, 1, 2] = 0.02 + np.maximum(0, np.arange(H) - 11) * 0.005
    grip = episode_arrays(world, np.zeros((H, 3), np.int64), ["none"] * 3, moving_m=0.002, grasp_m=0.01)[2]
    assert list(np.flatnonzero(grip)) == list(range(5, H))


def test_lost_frames_before_a_lift_neither_start_the_carry_nor_extend_the_look_back():
    """Block 1 is lost while the hand approaches (frames 0-4) and the frame before the lift;
    the gripper closes only where both are seen together at the grasp."""
    world = carry_episode()
    status = np.zeros((30, 3), np.int64)
    status[:5, 1] = status[9, 1] = TrackStatus.LOST
    grip = episode_arrays(world, status, ["none"] * 3, moving_m=0.002, grasp_m=0.005)[2]
    assert list(np.flatnonzero(grip)) == list(range(10, 22))
