"""taco: the forward recursion is the sum over alignments (with finite gradients), it learns a two-step toy task
(lift, then reach) from sketches alone, a saved model acts as the trained one, and bad sketches are refused."""

import itertools

import numpy as np
import pytest
import torch

from hsp.baselines import taco
from hsp.baselines.common import BaselineConfig, episode_batch
from hsp.baselines.observations import Demonstrations, flat_observation
from hsp.errors import HspError
from hsp.geometry import apply_rotvec_delta
from tests.baselines.test_bc import toy_layout

ABOVE = np.array([0.0, 0.0, 0.03])
STEPS = 40
LIFT = 0.4
SKETCH = ["hand>hand", "hand>block_green"]


def brute_force(log_act, log_stop, log_go, T, L):
    """log Σ_ζ over every monotone alignment of acting frames 0 … T−2 to 0 … L−1."""
    total = []
    for switches in itertools.combinations(range(1, T - 1), L - 1):
        z = np.searchsorted(np.array(switches), np.arange(T - 1), side="right")
        s = sum(log_act[t, z[t]] for t in range(T - 1))
        s += sum(log_stop[t, z[t - 1]] if z[t] != z[t - 1] else log_go[t, z[t]] for t in range(1, T - 1))
        total.append(s + log_stop[T - 1, L - 1])
    return np.logaddexp.reduce(total)


def test_forward_recursion_equals_the_sum_over_alignments():
    rng = np.random.default_rng(0)
    B, T, L = 3, 7, 3
    log_act = torch.from_numpy(rng.normal(-1, 1, (B, T, L)))
    stop_logit = torch.from_numpy(rng.normal(0, 1, (B, T, L)))
    log_stop, log_go = torch.nn.functional.logsigmoid(stop_logit), torch.nn.functional.logsigmoid(-stop_logit)
    lengths, sketch_lengths = torch.tensor([7, 5, 6]), torch.tensor([3, 2, 1])
    log_act.requires_grad_(True)
    stop_logit.requires_grad_(True)
    log_stop, log_go = torch.nn.functional.logsigmoid(stop_logit), torch.nn.functional.logsigmoid(-stop_logit)
    got = taco.log_likelihood(log_act, log_stop, log_go, lengths, sketch_lengths)
    got.sum().backward()
    assert torch.isfinite(log_act.grad).all() and torch.isfinite(stop_logit.grad).all()
    log_stop, log_go = log_stop.detach(), log_go.detach()
    for b in range(B):
        want = brute_force(log_act[b].detach().numpy(), log_stop[b].numpy(), log_go[b].numpy(), int(lengths[b]), int(sketch_lengths[b]))
        assert abs(got[b].item() - want) < 1e-9


def test_a_padded_batch_scores_each_episode_as_alone(tasks):
    """Episodes of different lengths and sketches (a symbol repeated) batched together."""
    task = tasks["stacking-1"]
    demos, _ = two_step_demonstrations(task, 3, seed=1)
    sketches = [SKETCH, SKETCH[::-1] + SKETCH[:1], SKETCH[1:]]
    model = taco.SubPolicies(sorted(set(SKETCH)), demos.obs[0].shape[1], 16, 1)
    for net in model.policies:
        net.standardise(demos)
    with torch.no_grad():
        together = taco.episode_log_likelihood(model, episode_batch(demos, [0, 1, 2]), sketches)
        alone = [taco.episode_log_likelihood(model, episode_batch(demos, [i]), sketches[i:i + 1])[0] for i in range(3)]
    assert len({len(o) for o in demos.obs}) > 1
    torch.testing.assert_close(together, torch.stack(alone))


def test_sketch_merges_repeats_in_order():
    names = ["hand", "a", "b"]
    assert taco.sketch_of(np.array([0, 0, 1, 1, 0]), np.array([1, 1, 2, 2, 2]), names) == ["hand>a", "a>b", "hand>b"]


def two_step_demonstrations(task, episodes: int, seed: int) -> tuple[Demonstrations, list[list[str]]]:
    """The hand rises straight up (a third of the way to 45 cm each frame) until it is above
    LIFT, then goes above block 2 (a third of the way each frame) until within 3 mm."""
    rng = np.random.default_rng(seed)
    obs, action = [], []
    for _ in range(episodes):
        world = toy_layout(task, rng)
        o, a = [], []
        for goal, done in ((np.r_[world[0, :2], 0.45], lambda w: w[0, 2] > LIFT),
                           (world[2, :3] + ABOVE, lambda w: np.linalg.norm(w[2, :3] + ABOVE - w[0, :3]) < 0.003)):
            while not done(world):
                o.append(flat_observation(world))
                step = np.r_[(goal - world[0, :3]) / 3, np.zeros(3)] + rng.normal(0, 5e-4, 6)
                a.append(step)
                world = world.copy()
                world[0] = apply_rotvec_delta(world[0], step)
        obs.append(np.array(o + [flat_observation(world)])), action.append(np.array(a + [np.zeros(6)]))
    return (Demonstrations(obs, action, [np.zeros(len(o), bool) for o in obs],
                           [np.arange(len(o)) < len(o) - 1 for o in obs], fps=15), [SKETCH] * episodes)


def lifts_then_reaches(agent, task, layouts: int = 10) -> float:
    rng = np.random.default_rng(1)
    wins = 0
    for seed in range(layouts):
        world = toy_layout(task, rng)
        agent.reset(world, seed)
        lifted = False
        for _ in range(STEPS):
            world = world.copy()
            world[0] = agent.act(world)[:7]
            lifted |= world[0, 2] > LIFT - 0.01
        wins += lifted and np.linalg.norm(world[2, :3] + ABOVE - world[0, :3]) < 0.02
    return wins / layouts


def test_learns_a_two_step_toy_from_sketches_alone(tasks, tmp_path):
    task = tasks["stacking-1"]
    demos, sketches = two_step_demonstrations(task, 300, seed=0)
    cfg = BaselineConfig(iterations=800, batch_steps=1024, hidden=64, learning_rate=3e-3, checkpoint_every=200)
    untrained, report0 = taco.train(demos, sketches, task.names, BaselineConfig(iterations=1, hidden=64), seed=0)
    model, report = taco.train(demos, sketches, task.names, cfg, seed=0)
    assert report["symbols"] == 2 and report["distinct_sketches"] == 1 and model.sketch == SKETCH
    assert report["validation_nll_per_frame"] < report0["validation_nll_per_frame"] - 5
    assert lifts_then_reaches(taco.TacoAgent(untrained, task), task) == 0.0
    assert lifts_then_reaches(taco.TacoAgent(model, task), task) >= 0.7

    taco.save(model, cfg, tmp_path / "m")
    a, b = taco.TacoAgent(model, task), taco.TacoAgent(taco.load(tmp_path / "m"), task)
    world = toy_layout(task, np.random.default_rng(5))
    a.reset(world, 0), b.reset(world, 0)
    for _ in range(3):
        np.testing.assert_array_equal(a.act(world), b.act(world))


def test_a_sketch_longer_than_its_episode_is_refused(tasks):
    task = tasks["stacking-1"]
    demos, sketches = two_step_demonstrations(task, 2, seed=0)
    acting = len(demos.obs[1]) - 1
    sketches[1] = SKETCH * acting
    with pytest.raises(HspError, match=f"rec: episode 1: a sketch of {2 * acting} sub-tasks does not fit its {acting} "
                                       "acting frames"):
        taco.train(demos, sketches, task.names, BaselineConfig(iterations=1), seed=0, source="rec")
