"""Held-out seeds and the statistics of an evaluation."""

import numpy as np
import pytest

from hsp.evaluation.rollout import held_out_seeds
from hsp.evaluation.stats import summarise, wilson_interval
from hsp.recording.record import episode_seed


def test_test_layouts_never_reuse_a_recording_seed():
    recorded = {episode_seed(0, e) for e in range(70)}
    seeds = held_out_seeds(0, runs=5, episodes=50, recorded_episodes=70)
    assert seeds.shape == (5, 50)
    assert len(set(seeds.ravel().tolist())) == 250
    assert not recorded & set(seeds.ravel().tolist())
    np.testing.assert_array_equal(seeds, held_out_seeds(0, 5, 50, 70))
    assert not np.array_equal(seeds, held_out_seeds(1, 5, 50, 70))


def test_wilson_interval_matches_the_closed_form():
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert wilson_interval(0, 250)[0] == 0.0 and wilson_interval(250, 250)[1] == 1.0
    assert wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    low, high = wilson_interval(25, 50)
    assert low == pytest.approx(0.3664, abs=1e-4) and high == pytest.approx(0.6336, abs=1e-4)


def test_summary_rates_and_spread_across_runs():
    eps = [{"run": r, "success": s, "steps": 10 * (1 + s), "progress": {"a": True, "b": s}}
           for r, outcomes in enumerate([[True, True], [False, True]]) for s in outcomes]
    out = summarise(eps)
    assert out["success_rate"] == 0.75 and out["success_rate_std"] == 0.25
    assert out["subgoal.a"] == 1.0 and out["subgoal.b"] == 0.75
    assert out["episode_length_mean"] == 17.5 and out["episodes"] == 4 and out["runs"] == 2
