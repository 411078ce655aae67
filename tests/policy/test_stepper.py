"""The Stepper: a way-point holds until the tool has rested at it."""

import numpy as np

from hsp.geometry import compose, relative
from hsp.policy.stepper import Stepper
from hsp.policy.train import TrainConfig, train
from tests.policy.test_features import CLASSES, _steps


def test_a_way_point_holds_until_the_tool_has_rested_at_it():
    world, _, s = _steps()
    policy, _ = train([s], ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=3, batch_steps=40), seed=0)
    stepper = Stepper(policy, 1)
    first = stepper.step(world[:1])
    tool, target, w = int(first.tool[0]), int(first.target[0]), first.waypoint[0].astype(np.float64)
    for t in range(1, 6):  # the end-effector moves on, far from w: w is kept, whatever π_m says now
        c = stepper.step(world[t:t + 1])
        assert (int(c.tool[0]), int(c.target[0])) == (tool, target)  # these networks keep the pair here
        np.testing.assert_array_equal(c.waypoint[0], first.waypoint[0])
    at_w = world[5].copy()
    at_w[tool] = compose(at_w[target], w)  # the tool exactly at its way-point
    assert np.linalg.norm(relative(at_w[tool], at_w[target])[:3] - w[:3]) < 1e-9
    for _ in range(policy.settle_frames - 1):  # resting: π_h has these frames to end the sub-task
        c = stepper.step(at_w[None])
        assert (int(c.tool[0]), int(c.target[0])) == (tool, target)
        np.testing.assert_array_equal(c.waypoint[0], first.waypoint[0])
    assert stepper.rested[0] == policy.settle_frames - 1
    stepper.step(at_w[None])
    assert stepper.rested[0] == 0  # the last frame of rest: π_m was asked again
