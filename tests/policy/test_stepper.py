"""The Stepper: a sub-task runs until its tool comes to rest; only then do π_h and π_m choose."""

import numpy as np
import pytest

from hsp.geometry import yaw_of
import hsp.policy.stepper as stepper_module
from hsp.policy.stepper import Stepper
from hsp.policy.train import TrainConfig, train
from hsp.policy.features import episode_steps
from tests.policy.test_features import CLASSES, _steps, reach_rest_reach


def test_choices_hold_while_the_tool_moves_and_are_made_again_once_it_has_rested():
    world, _, s = _steps()
    policy, _ = train([s], ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=3, batch_steps=40), seed=0)
    stepper = Stepper(policy, 1)
    first = stepper.step(world[:1], forced=(s.tool[:1], s.target[:1], s.waypoint[:1]))  # the end-effector reaches for a
    tool, target = int(first.tool[0]), int(first.target[0])
    moving = world[1:6]
    steps = np.linalg.norm(np.diff(world[:6, tool, :3] - world[:6, target, :3], axis=0), axis=-1)
    assert tool == 0 and (steps > policy.still_m).all()  # it moves on: nothing is chosen again, whatever π_h says now
    for frame in moving:
        c = stepper.step(frame[None])
        assert not c.decided[0]
        assert (int(c.tool[0]), int(c.target[0])) == (tool, target)
        np.testing.assert_array_equal(c.waypoint[0], first.waypoint[0])
    for _ in range(policy.settle_frames - 1):  # at rest: the sub-task goes on for these frames ...
        c = stepper.step(moving[-1:])
        assert not c.decided[0]
        np.testing.assert_array_equal(c.waypoint[0], first.waypoint[0])
    c = stepper.step(moving[-1:])  # ... and is over at the last
    assert c.decided[0] and stepper.rested[0] == 0


def test_stepped_over_its_labels_the_stepper_ends_each_sub_task_where_the_labels_do():
    """A demonstrator with a hand's tremor (0.3 mm per axis) who rests as long as the robot
    waits: the rest rule running fires at the decision frames of the labels
    (:func:`~hsp.policy.features.decisions`), so π_h and π_m are asked where they were
    trained to answer. (A longer rest is taken running as stopping short again every
    ``settle_frames``; the robot never rests longer.)"""
    world, target, k = reach_rest_reach(rest=3, tremor_m=0.0003)
    H = len(world)
    policy, _ = train([_steps()[2]], ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=1, batch_steps=40), seed=0)
    s = episode_steps(world, np.ones((H, 3), bool), np.zeros(H, np.int64), target, k, CLASSES, 2, policy.still_m,
                      policy.settle_frames)
    stepper = Stepper(policy, 1)
    decided = [stepper.step(world[t:t + 1], forced=(s.tool[t:t + 1], s.target[t:t + 1], s.waypoint[t:t + 1])).decided[0]
               for t in range(H - 1)]  # the last frame: the recording ends, not the sub-task
    np.testing.assert_array_equal(np.flatnonzero(decided), np.flatnonzero(s.decision[:-1]))


def test_over_a_recording_it_chooses_where_the_sub_tasks_end_however_long_the_demonstrator_rests():
    """The demonstrator rests 20 frames at object 1: the rule running would take the rest as
    stopping short every ``settle_frames``; told where the recording's sub-tasks end
    (free-running validation), the stepper chooses there and nowhere else, from its own history."""
    world, target, k = reach_rest_reach(rest=20)
    H = len(world)
    s = episode_steps(world, np.ones((H, 3), bool), np.zeros(H, np.int64), target, k, CLASSES, 2)
    policy, _ = train([s], ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=3, batch_steps=40), seed=0)
    own, told = Stepper(policy, 1), Stepper(policy, 1)
    by_rule = [own.step(world[t:t + 1]).decided[0] for t in range(H)]
    assert np.count_nonzero(by_rule) > np.count_nonzero(s.decision)  # re-decides during the rest
    by_recording = [told.step(world[t:t + 1], ended=s.decision[t:t + 1]).decided[0] for t in range(H)]
    np.testing.assert_array_equal(np.flatnonzero(by_recording), np.flatnonzero(s.decision))


def _onto_a_cube(rng: np.random.Generator, side: float | None, H: int = 16) -> np.ndarray:
    """The end-effector goes from a random start to cube 1 and rests: ``side`` 0.05 m from
    it on one of its sides drawn at random (which side a person takes depends on the cube's
    true frame, which its symmetric pose does not tell), facing it as a hand reaching for
    it would, or with ``side`` None on top of it, 1 cm above its centre with a hand's 2 mm
    scatter, turned any way."""
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    world[:, 1, :3] = [0.5, 0.0, 0.0]
    world[:, 2, :3] = [0.2, 0.3, 0.0]
    if side is None:
        q = rng.uniform(-np.pi, np.pi)
        goal = world[0, 1, :3] + np.append(0.002 * rng.standard_normal(2), 0.01)
    else:
        q = rng.integers(4) * np.pi / 2
        goal = world[0, 1, :3] + side * np.array([np.cos(q), np.sin(q), 0.0])
    world[:, 0, 5:] = [np.sin(q / 2), np.cos(q / 2)]
    start = world[0, 1, :3] + np.append(0.3 * rng.uniform(-1, 1, 2), 0.2)
    world[:, 0, :3] = np.concatenate([np.linspace(start, goal, 11), np.repeat(goal[None], H - 11, 0)])
    return world


def _learnt_places(side: float | None) -> np.ndarray:
    """π_m's way-points ``(4, 2)`` (x, y in cube 1's frame) on four new starts, trained on 32
    demonstrations of :func:`_onto_a_cube` with cube 1's four-fold symmetry."""
    rng = np.random.default_rng(0)
    H = 16
    classes = np.array([0, 1, 2])  # the cube is told from the other object by its label (π_h reads no x, y)
    data = [episode_steps(_onto_a_cube(rng, side, H), np.ones((H, 3), bool), np.zeros(H, np.int64),
                          np.ones(H, np.int64), np.full(H, H - 1), classes, 3) for _ in range(32)]
    policy, _ = train(data, ["ee", "a", "b"], classes, 3, TrainConfig(iterations=300, batch_steps=H * 32), seed=0,
                      folds=np.array([1, 4, 1]))
    out = []
    for _ in range(4):
        c = Stepper(policy, 1).step(_onto_a_cube(rng, side, H)[:1])
        assert (int(c.tool[0]), int(c.target[0])) == (0, 1)
        out.append(c.waypoint[0, :2])
    return np.array(out)


def test_a_place_on_any_side_of_a_cube_is_learnt_as_one_side_not_their_middle():
    """Nothing observed tells which side the demonstrator took: π_m's way-point is on a
    side's axis, 5 cm out, not in the middle of the four (the mean of the four sides is the
    centre)."""
    xy = _learnt_places(0.05)
    r = np.linalg.norm(xy, axis=-1)
    assert ((0.04 < r) & (r < 0.06)).all() and (np.abs(xy).min(-1) < 0.01).all()


def test_a_place_on_top_of_a_cube_is_learnt_on_its_axis_from_whichever_side_the_tool_comes():
    """Places on top scatter by a hand's 2 mm all round the axis: their mean is on it, and so
    is π_m's way-point, within 2.5 mm (32 places: the mean's own error is 0.35 mm per axis;
    folding the scatter into one sector of the cube put it 3.8 mm toward the side the tool
    came from, and two blocks so placed end past a tower's 5 mm tolerance)."""
    assert np.linalg.norm(_learnt_places(None), axis=-1).max() < 0.0025


def _grasping_a_cube(rng: np.random.Generator, H: int = 16) -> np.ndarray:
    """The end-effector (a two-fingered hand: a half turn leaves it unchanged) goes from a
    random start and heading to 1 cm above cube 1 (any heading), turning on the way to the
    quarter of the cube nearest its start, fingers on two faces, as the demonstrator does."""
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    cube = rng.uniform(-np.pi, np.pi)
    world[:, 1] = np.r_[0.5, 0.0, 0.0, 0.0, 0.0, np.sin(cube / 2), np.cos(cube / 2)]
    world[:, 2, :3] = [0.2, 0.3, 0.0]
    start = rng.uniform(-np.pi, np.pi)
    end = cube + np.round((start - cube) / (np.pi / 2)) * np.pi / 2
    heading = np.concatenate([np.linspace(start, end, 11), np.full(H - 11, end)])
    world[:, 0, 5:] = np.stack([np.sin(heading / 2), np.cos(heading / 2)], -1)
    goal = world[0, 1, :3] + [0.0, 0.0, 0.01]
    begin = world[0, 1, :3] + np.append(0.3 * rng.uniform(-1, 1, 2), 0.2)
    world[:, 0, :3] = np.concatenate([np.linspace(begin, goal, 11), np.repeat(goal[None], H - 11, 0)])
    return world


def test_a_grasp_from_above_is_learnt_with_the_fingers_on_the_faces_whatever_the_hands_heading():
    """The grasp's heading in the cube's frame is the hand's own rounded to a quarter turn: a
    staircase of what π_m reads, unless π_m reads it from the turn of the cube that brings
    the hand's heading within ±45° (then every grasp is at 0°). Learnt so, on new starts the
    fingers are within 5° of the faces (seen with the hand's position, as before, 14° off
    here, 15-40° closed loop, where the block slipped)."""
    rng = np.random.default_rng(0)
    H = 16
    classes = np.array([0, 1, 2])
    data = [episode_steps(_grasping_a_cube(rng, H), np.ones((H, 3), bool), np.zeros(H, np.int64),
                          np.ones(H, np.int64), np.full(H, H - 1), classes, 3) for _ in range(32)]
    policy, _ = train(data, ["ee", "a", "b"], classes, 3, TrainConfig(iterations=300, batch_steps=H * 32), seed=0,
                      folds=np.array([2, 4, 1]))
    for _ in range(6):
        c = Stepper(policy, 1).step(_grasping_a_cube(rng, H)[:1])
        fingers = np.degrees(yaw_of(c.waypoint[0, 3:].astype(np.float64)))
        assert abs((fingers + 45) % 90 - 45) < 5, f"fingers at {fingers:.1f}° in the cube's frame"


def test_running_pi_m_reads_where_the_tool_came_from_as_it_was_trained_to():
    """Over object 1, down onto it (one pair, two way-points), then to object 2: at each
    decision the stepper gives π_m where its own tool was at its decision before, which is
    what training gives it from the labels (:func:`~hsp.policy.features.came_from`)."""
    x = np.concatenate([np.linspace(0, 0.3, 6), np.full(14, 0.3), np.linspace(0.3, 0.0, 8)])
    z = np.concatenate([np.linspace(0.1, 0.2, 6), np.full(4, 0.2), np.linspace(0.2, 0.05, 6), np.full(12, 0.05)])
    H = len(x)
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    world[:, 1, :3] = [0.3, 0.0, 0.05]
    world[:, 2, :3] = [0.0, 0.3, 0.05]
    world[:, 0, 0], world[:, 0, 2] = x, z
    world[20:, 0, 1] = np.linspace(0.0, 0.3, 8)
    target = np.where(np.arange(H) < 20, 1, 2)
    k = np.select([np.arange(H) < 9, np.arange(H) < 20], [5, 15], H - 1)
    s = episode_steps(world, np.ones((H, 3), bool), np.zeros(H, np.int64), target, k, CLASSES, 2)
    policy, _ = train([s], ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=1, batch_steps=40), seed=0)
    read = []
    real = stepper_module.pi_m_waypoint
    with pytest.MonkeyPatch.context() as m:
        m.setattr(stepper_module, "pi_m_waypoint", lambda *a: read.append(a[-1]) or real(*a))
        stepper = Stepper(policy, 1)
        for t in range(H):
            stepper.step(world[t:t + 1], forced=(s.tool[t:t + 1], s.target[t:t + 1], s.waypoint[t:t + 1]),
                         ended=s.decision[t:t + 1])
    at = np.flatnonzero(s.decision)
    assert s.came_from[at, 0].tolist() == [0, 1, 0]  # over object 1, down onto it (the same pair), on to object 2
    np.testing.assert_allclose(np.concatenate(read)[at], s.came_from[at], atol=1e-6)
