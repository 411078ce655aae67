"""Training π_h, π_m, π_l: it fits, it is seeded, and it saves and loads."""

import numpy as np
import pytest
import torch

from hsp.errors import HspError
from hsp.policy.train import TrainConfig, _batch, load, losses, save, split, train, validate
from tests.policy.test_features import _steps

CLASSES = np.array([0, 1, 1])


def _data():
    return [_steps()[3]] * 2


def test_training_lowers_every_loss():
    data = _data()
    before, _ = train(data, ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=1, batch_steps=40), seed=0)
    after, last = train(data, ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=300, batch_steps=40, learning_rate=3e-3), seed=0)
    with torch.no_grad():
        b = _batch(data, [0, 1])
        l0, l1 = losses(before.net, before.norm, b), losses(after.net, after.norm, b)
    for k in ("pair", "waypoint", "action"):
        assert l1[k] < l0[k] - 0.5, (k, float(l0[k]), float(l1[k]))
    assert np.isfinite(last["total"])


def test_the_same_seed_gives_the_same_weights():
    cfg = TrainConfig(iterations=5, batch_steps=40)
    a, _ = train(_data(), ["ee", "a", "b"], CLASSES, 2, cfg, seed=3)
    b, _ = train(_data(), ["ee", "a", "b"], CLASSES, 2, cfg, seed=3)
    for (k, x), y in zip(a.net.state_dict().items(), b.net.state_dict().values()):
        assert torch.equal(x, y), k


def test_save_and_load_give_the_same_policy(tmp_path):
    policy, _ = train(_data(), ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=3, batch_steps=40), seed=0)
    save(policy, TrainConfig(iterations=1), tmp_path / "m")
    save(policy, TrainConfig(iterations=3), tmp_path / "m")  # a second run replaces the first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]
    assert '"iterations": 3' in (tmp_path / "m" / "config.json").read_text()
    again = load(tmp_path / "m")
    assert again.objects == ["ee", "a", "b"] and list(again.classes) == [0, 1, 1]
    with torch.no_grad():
        b = _batch(_data(), [0])
        for k, v in losses(policy.net, policy.norm, b).items():
            assert float(v) == pytest.approx(float(losses(again.net, again.norm, b)[k]), abs=1e-6)


def test_bad_inputs_are_clear_errors(tmp_path):
    with pytest.raises(HspError, match="not a trained policy"):
        load(tmp_path)
    with pytest.raises(HspError, match="iterations"):
        train(_data(), ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=0), seed=0)
    with pytest.raises(HspError, match="no labelled episodes"):
        train([], ["ee"], CLASSES, 2, TrainConfig(), seed=0)


def test_every_fifth_episode_validates_and_a_trained_policy_is_closer_on_it():
    assert split(10, 5) == ([0, 1, 2, 3, 5, 6, 7, 8], [4, 9])
    assert split(2, 2) == ([0, 1], []) and split(7, 0) == (list(range(7)), [])
    data = _data()
    untrained, _ = train(data, ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=1, batch_steps=40), seed=0)
    trained, _ = train(data, ["ee", "a", "b"], CLASSES, 2, TrainConfig(iterations=300, batch_steps=40, learning_rate=3e-3), seed=0)
    before, after = validate(untrained, data[:1]), validate(trained, data[:1])
    assert after["pair_accuracy"] > 0.9 and after["pair_accuracy"] > before["pair_accuracy"]
    assert after["waypoint_error_mm"] < before["waypoint_error_mm"] and after["action_error_mm"] < before["action_error_mm"]
