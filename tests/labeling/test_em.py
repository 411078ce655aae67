"""EM refinement: the loop around Viterbi with any score model standing in for the networks."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsp.errors import HspError
from hsp.labeling.em import em_label
from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig, PriorScores, pairs_of


def _episode(H=40):
    """End-effector (0) carries nothing and visits object 1, then object 2, pausing at each
    for the last quarter of its half (a way-point is where a motion ends)."""
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    world[:, 1, :3] = [0.5, 0.1, 0.0]
    world[:, 2, :3] = [0.5, -0.1, 0.0]
    half = H // 2
    for start, (a, b) in zip((0, half), (([0.5, 0.0, 0.3], [0.5, 0.1, 0.02]), ([0.5, 0.1, 0.3], [0.5, -0.1, 0.02]))):
        n = (H - half if start else half) * 3 // 4
        world[start:start + n, 0, :3] = np.linspace(a, b, n)
        world[start + n:(H if start else half), 0, :3] = b
    return world, np.zeros((H, 3), np.int64)


class Prefer(PriorScores):
    """The priors, but π_h all but forbids every pair other than ``pair``."""

    def __init__(self, world, status, pair):
        super().__init__(world, status == 0, PriorConfig())
        self.pair = pair

    def unary(self, t):
        u = np.full(self.P, -50.0)
        u[self.pair] = 0.0
        return u


def test_a_model_that_agrees_with_the_labels_stops_em_after_one_round():
    ep = _episode()
    result = em_label([ep], PriorConfig(), lambda labels: lambda w, s, last: PriorScores(w, s == 0, PriorConfig()), iterations=3)
    assert result.changed == [0.0]


def test_the_fitted_model_replaces_the_priors_until_labels_settle():
    ep = _episode()
    fits = []

    def fit(labels):
        fits.append([lab.target.copy() for lab in labels])
        return lambda w, s, last: Prefer(w, s, pair=int(np.flatnonzero((pairs_of(3) == [1, 2]).all(axis=1))[0]))

    result = em_label([ep], PriorConfig(), fit, iterations=5)
    assert len(fits) == 2 and result.changed[0] > 0 and result.changed[1] == 0.0
    assert np.all(result.labels[0].tool == 1) and np.all(result.labels[0].target == 2)
    assert not np.all(fits[0][0] == 2), "round 1 was fitted on the prior labels"


def test_a_model_of_the_wrong_shape_is_a_clear_error():
    ep = _episode()
    short = (ep[0][:10], ep[1][:10])
    with pytest.raises(HspError, match="scored 10 frames"):
        em_label([ep], PriorConfig(), lambda labels: lambda w, s, last: PriorScores(*short[:1], short[1] == 0, PriorConfig()), 1)


def test_with_symmetries_the_model_sees_canonical_poses():
    """Object 2 is round (z_continuous) and turned about its axis: the score model is given
    its canonical orientation, and the labels are those of label_episode with symmetries."""
    world, status = _episode()
    world[:, 2, 3:] = Rotation.from_euler("z", 0.7).as_quat()
    symmetries = ["none", "none", "z_continuous"]
    seen = []

    def fit(labels):
        def model(w, s, last):
            seen.append(w[:, 2, 3:].copy())
            return PriorScores(w, s == 0, PriorConfig())
        return model

    result = em_label([(world, status)], PriorConfig(), fit, iterations=1, symmetries=symmetries)
    assert np.allclose(np.abs(seen[0][:, 3]), 1.0), "the turn about z is removed"
    direct = label_episode(world, status, PriorConfig(), symmetries=symmetries)
    assert np.array_equal(result.labels[0].target, direct.target)
    assert np.allclose(result.labels[0].waypoint, direct.waypoint)
