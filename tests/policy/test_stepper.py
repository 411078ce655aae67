"""The Stepper: a sub-task runs until its tool comes to rest; only then do π_h and π_m choose."""

import numpy as np

from hsp.policy.stepper import Stepper
from hsp.policy.train import TrainConfig, train
from tests.policy.test_features import CLASSES, _steps


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
