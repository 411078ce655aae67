"""bc and bc-rnn: they learn a toy reaching task that an untrained policy fails, and a saved
model acts exactly as the one trained."""

import numpy as np
import pytest
import torch

from hsp.baselines import bc
from hsp.baselines.common import BaselineConfig
from hsp.baselines.observations import Demonstrations, flat_observation
from hsp.evaluation.env import GRIP_CLOSED
from hsp.geometry import apply_rotvec_delta

STEPS = 30
ABOVE = np.array([0.0, 0.0, 0.03])
"""The toy's goal: 3 cm above block 1, the gripper closed once there (success: within 2 cm)."""


def toy_layout(task, rng: np.random.Generator) -> np.ndarray:
    """World poses ``(n, 7)``: the hand and the blocks at random on a 0.4 m square, upright."""
    n = len(task.names)
    poses = np.zeros((n, 7))
    poses[:, 3:] = [0, 0, 0, 1]
    poses[:, :2] = rng.uniform(0.3, 0.7, (n, 2))
    poses[:, 2] = 0.02
    poses[0, 2] = 0.25
    return poses


def toy_demonstrations(task, episodes: int, seed: int, layout=toy_layout) -> Demonstrations:
    """The hand moves a third of the way to the goal each frame (with a little noise) and
    closes the gripper within 1 cm of it; the blocks stay still."""
    rng = np.random.default_rng(seed)
    obs, action, grip = [], [], []
    for _ in range(episodes):
        world = layout(task, rng)
        o, a, g = [], [], []
        for _ in range(STEPS):
            o.append(flat_observation(world))
            step = np.zeros(6)
            step[:3] = (world[1, :3] + ABOVE - world[0, :3]) / 3
            step += rng.normal(0, 5e-4, 6)
            g.append(np.linalg.norm(world[1, :3] + ABOVE - world[0, :3]) < 0.01)
            a.append(step)
            world = world.copy()
            world[0] = apply_rotvec_delta(world[0], step)
        obs.append(np.array(o)), action.append(np.array(a)), grip.append(np.array(g))
    return Demonstrations(obs, action, grip, [np.ones(STEPS, bool) for _ in range(episodes)], fps=15)


def toy_success_rate(agent, task, layouts: int = 10, seed: int = 1, layout=toy_layout) -> float:
    """Closed loop without physics: the hand goes where the agent commands."""
    rng = np.random.default_rng(seed)
    wins = 0
    for _ in range(layouts):
        world = layout(task, rng)
        agent.reset(world, 0)
        for _ in range(STEPS):
            command = agent.act(world)
            world = world.copy()
            world[0] = command[:7]
        wins += np.linalg.norm(world[1, :3] + ABOVE - world[0, :3]) < 0.02 and command[7] == GRIP_CLOSED
    return wins / layouts


@pytest.mark.parametrize("method", ["bc", "bc-rnn"])
def test_learns_a_toy_reach_that_an_untrained_policy_fails(tasks, method, tmp_path):
    task = tasks["stacking-1"]
    demos = toy_demonstrations(task, 200, seed=0)
    cfg = BaselineConfig(iterations=1000, batch_steps=512, hidden=64, layers=2, learning_rate=3e-3, checkpoint_every=500)
    untrained, _ = bc.train(demos, task.names, method, BaselineConfig(iterations=1, hidden=64, checkpoint_every=1), seed=0)
    model, report = bc.train(demos, task.names, method, cfg, seed=0)
    held = demos.subset(list(range(4, 200, 5)))
    assert bc.validate(model.net, held)["nll_action"] < bc.validate(untrained.net, held)["nll_action"] - 5
    assert report["validation_episodes"] == 40 and report["validation_grip_accuracy"] > 0.9
    assert toy_success_rate(bc.BCAgent(untrained, task), task) == 0.0
    assert toy_success_rate(bc.BCAgent(model, task), task) >= 0.8

    bc.save(model, cfg, tmp_path / "m")
    loaded = bc.load(tmp_path / "m", method)
    world = toy_layout(task, np.random.default_rng(5))
    a, b = bc.BCAgent(model, task), bc.BCAgent(loaded, task)
    a.reset(world, 0), b.reset(world, 0)
    for _ in range(3):  # bc-rnn: the memory carries over identically too
        np.testing.assert_array_equal(a.act(world), b.act(world))


def test_the_same_seed_gives_the_same_weights(tasks):
    task = tasks["stacking-1"]
    demos = toy_demonstrations(task, 10, seed=0)
    cfg = BaselineConfig(iterations=20, batch_steps=64, hidden=16, checkpoint_every=10)
    first, second = (bc.train(demos, task.names, "bc-rnn", cfg, seed=3)[0].net.state_dict() for _ in range(2))
    assert all(torch.equal(first[k], second[k]) for k in first)
