"""Viterbi scores from a trained policy: the E-step of EM."""

import numpy as np
from scipy.special import logsumexp

from hsp.labeling.em import em_label
from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig, PriorScores
from hsp.labeling.viterbi import Transition, viterbi
from hsp.policy.features import episode_steps
from hsp.policy.scores import PolicyScores
from hsp.policy.train import TrainConfig, train
from tests.labeling.test_em import _episode
from tests.policy.test_features import CLASSES, _steps


def _policy(iterations=200):
    policy, _ = train([_steps()[2]] * 2, ["ee", "a", "b"], CLASSES, 2,
                      TrainConfig(iterations=iterations, batch_steps=40, learning_rate=3e-3), seed=0)
    return policy


def test_scores_are_log_probabilities_with_the_priors_way_point_rule():
    world, status = _episode()
    lab = label_episode(world, status, PriorConfig())
    scores = PolicyScores(world, status == 0, _policy(3), lab, PriorConfig())
    prior = PriorScores(world, status == 0, PriorConfig())
    assert (scores.H, scores.P) == (prior.H, prior.P)
    for t in (0, 17, scores.H - 1):
        np.testing.assert_allclose(logsumexp(scores.unary(t)), 0.0, atol=1e-5)
        j = scores.jump(t)
        assert j.shape == prior.jump(t).shape and j.dtype == np.float32
        np.testing.assert_array_equal(np.isfinite(j), np.isfinite(prior.jump(t)))
        np.testing.assert_array_equal(scores.motion(t), prior.motion(t))


def test_em_over_a_policy_trained_on_the_labels_keeps_them():
    """A policy fitted to clean labels scores them highest (as it was trained on them: each
    rest given to the next sub-task): EM stops without a change."""
    world, status = _episode()
    lab = label_episode(world, status, PriorConfig())
    policy = _policy()
    path = viterbi(PolicyScores(world, status == 0, policy, lab, PriorConfig()), Transition())
    decided = episode_steps(world, status == 0, lab.tool, lab.target, lab.waypoint_index, policy.classes,
                            policy.n_classes, policy.still_m, policy.settle_frames)
    assert np.mean(PriorScores(world, status == 0, PriorConfig()).pairs[path.pair][:, 1] == decided.target) > 0.95
    result = em_label([(world, status)], PriorConfig(),
                      lambda labels: lambda w, s, last: PolicyScores(w, s == 0, policy, last, PriorConfig()), 2)
    assert result.changed[-1] < 0.05


def _beside(seed: int, H: int = 40):
    """The end-effector rests at P, 1.5 cm from block 1 and 2.5 cm from block 2, then beside
    block 1; the demonstrator's labels: block 2 (what it aimed at), then block 1, each
    way-point where the rest ends. Nearness alone says block 1 throughout."""
    rng = np.random.default_rng(seed)
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    P = np.array([rng.uniform(0.4, 0.6), rng.uniform(-0.2, 0.2), 0.02])
    d = np.r_[np.cos(a := rng.uniform(0, 2 * np.pi)), np.sin(a), 0.0]
    world[:, 1, :3], world[:, 2, :3] = P + 0.015 * d - [0, 0, 0.02], P - 0.025 * d - [0, 0, 0.02]
    half = H // 2
    for start, end, (p, q) in ((0, half, (P + [0, 0, 0.28], P)), (half, H, (P, P + 0.035 * d))):
        n = (end - start) * 3 // 4
        world[start:start + n, 0, :3] = np.linspace(p, q, n)
        world[start + n:end, 0, :3] = q
    first = np.arange(H) < half
    return world, np.zeros((H, 3), np.int64), np.where(first, 2, 1), np.where(first, half - 1, H - 1)


def test_em_over_networks_that_encode_a_known_labelling_recovers_it():
    """Networks trained on the demonstrator's labels of four episodes; on a fifth, EM's
    E-steps (the networks fixed, their history from the round before) start from the
    priors' labels, which name the wrong block, and settle on the known labelling as the
    robot would act on it (the switch where the rest begins, within a frame: which frame of
    the rest is a tie the networks' initialisation breaks)."""
    classes = np.array([0, 1, 2])
    episodes = [_beside(seed) for seed in range(5)]
    steps = [episode_steps(w, s == 0, np.zeros(len(w), np.int64), target, k, classes, 3, 0.002, 3)
             for w, s, target, k in episodes]
    policy, _ = train(steps[1:], ["ee", "a", "b"], classes, 3, TrainConfig(iterations=150, batch_steps=80,
                                                                             learning_rate=3e-3), seed=0)
    world, status, target, _ = episodes[0]
    prior = label_episode(world, status, PriorConfig())
    assert np.all(prior.target == 1), "nearness alone names block 1 throughout"
    result = em_label([(world, status)], PriorConfig(),
                      lambda labels: lambda w, s, last: PolicyScores(w, s == 0, policy, last, PriorConfig()), 4)
    assert result.changed[-1] == 0.0
    switch = np.flatnonzero(np.diff(steps[0].target)) + 1
    wrong = np.flatnonzero(result.labels[0].target != steps[0].target)
    assert len(switch) == 1 and np.all(np.abs(wrong - switch[0]) <= 1), f"frames {wrong} differ, the switch is at {switch}"
