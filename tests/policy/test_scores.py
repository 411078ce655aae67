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
