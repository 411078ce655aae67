"""Training π_h, π_m, π_l: each loss term, fitting, seeding, checkpoints, save and load."""

import numpy as np
import pytest
import torch

from hsp.errors import HspError
from hsp.policy.networks import LOG_SQRT_2PI, Hierarchy, Sizes
from hsp.policy.normalisation import Normalisation
from hsp.policy.stepper import Stepper
from hsp.policy.train import (FORMAT, Policy, TrainConfig, batch, forward, load, losses, save, split, train, validate,
                              waypoint_distance)
from hsp.policy.features import episode_steps
from hsp.labeling.label import label_episode
from hsp.labeling.priors import PriorConfig
from tests.labeling.test_em import _episode
from tests.policy.test_features import CLASSES, _steps

OBJECTS = ["ee", "a", "b"]


def _data():
    return [_steps()[2]] * 2


def _blank_policy(data, seed=0) -> Policy:
    """Random hidden layers, every output layer zero: uniform π_h, π_m's components at the
    data's mean and at the tool's pose with unit spread, π_l half-way between its least fraction and the
    whole remaining way with unit spread, retrieval uniform."""
    torch.manual_seed(seed)
    net = Hierarchy(Sizes(3, 2))
    with torch.no_grad():
        for layer in (net.tool_head.rest[-1], net.target_head.rest[-1], net.intermediate[-1], net.low[-1], net.retrieve):
            layer.weight.zero_()
            layer.bias.zero_()
    return Policy(net, Normalisation.fit(data), OBJECTS, CLASSES, 2)


def test_each_loss_term_has_its_hand_computed_value():
    data = _data()
    policy = _blank_policy(data)
    s, norm = data[0], policy.norm
    b = batch(data, [0])
    with torch.no_grad():
        got = {k: float(v) for k, v in losses(policy, b).items()}
        memory = forward(policy, b)["memory"][0].numpy()
    std = lambda name, x: (x - norm.stats[f"{name}.mean"].numpy()) / norm.stats[f"{name}.std"].numpy()  # noqa: E731
    # π_h uniform, at the decision frames: the tool among 3 objects; the target among the 2
    # (tool = ee) or 1 (tool = a) allowed
    assert got["tool"] == pytest.approx(np.log(3), abs=1e-5)
    assert got["target"] == pytest.approx(np.mean(np.where(s.tool[s.decision] == 0, np.log(2), 0.0)), abs=1e-5)
    # π_m's components equally weighted with unit spread in standardised units, half at the
    # data's mean, half at the tool's current pose p_t[o+, o*]
    w = std("waypoint", s.waypoint[s.decision])
    at_tool = std("waypoint", s.current[s.decision])
    density = lambda d: np.exp(-0.5 * (d**2).sum(1) - 7 * LOG_SQRT_2PI)  # noqa: E731
    assert got["waypoint"] == pytest.approx(np.mean(-np.log(0.5 * density(w) + 0.5 * density(w - at_tool))), rel=1e-4)
    assert 1 < s.decision.sum() < len(s) / 4
    scale = norm.stats["action.std"].numpy()
    lo = policy.net.sizes.min_fraction  # π_l's output zero: half-way between the floor and the whole way
    z = (s.action - (lo + (1 - lo) / 2) * s.remaining) / scale
    assert got["action"] == pytest.approx(np.mean((0.5 * z * z + LOG_SQRT_2PI).sum(1)[s.acted]), rel=1e-4)
    repeat = np.zeros(len(s), bool)
    repeat[1:] = (s.history[1:] == s.history[:-1]).all(1)
    assert 0 < repeat.sum() < len(s)
    drift = np.linalg.norm(memory[1:] - memory[:-1], axis=1)
    assert got["memory"] == pytest.approx(drift[repeat[1:]].mean(), rel=1e-4)
    w_prev = std("waypoint", s.history[1:, 4:])
    assert got["retrieval"] == pytest.approx(2 * np.log(2) + np.mean(w_prev**2), rel=1e-4)


def test_a_target_set_is_learnt_through_the_way_point_each_member_explains():
    """Where the labelled target cannot be told from another (both blocks stay still while
    the hand moves), L_o* is −log Σ_S π(j | o+) and L_w the rest of the set's joint
    likelihood, −log Σ_S π(j | o+) π_m(p_k[o+, j] | j) / Σ_S π(j | o+)."""
    world, status = _episode()
    lab = label_episode(world, status, PriorConfig())
    s = episode_steps(world, status == 0, lab.tool, lab.target, lab.waypoint_index, CLASSES, 2, equivalent=lab.equivalent)
    policy = _blank_policy([s, s])
    with torch.no_grad():
        got = {k: float(v) for k, v in losses(policy, batch([s, s], [0])).items()}
    std = lambda x: (x - policy.norm.stats["waypoint.mean"].numpy()) / policy.norm.stats["waypoint.std"].numpy()  # noqa: E731
    density = lambda d: np.exp(-0.5 * (d**2).sum(-1) - 7 * LOG_SQRT_2PI)  # noqa: E731
    d = s.decision & s.labelled
    members = s.equivalent[d]
    assert members.sum(1).max() == 2
    allowed = (np.arange(3) != 0) & (np.arange(3) != s.tool[d][:, None])
    pi = allowed / allowed.sum(1, keepdims=True)  # π_h uniform over the allowed targets
    w, at = std(s.candidate_waypoint[d]), std(s.candidate_current[d])
    m = 0.5 * density(w) + 0.5 * density(w - at)  # (D, n)
    mass = (pi * members).sum(1)
    assert got["target"] == pytest.approx(np.mean(-np.log(mass)), abs=1e-5)
    assert got["waypoint"] == pytest.approx(np.mean(-np.log((pi * m * members).sum(1) / mass)), rel=1e-4)


def test_a_model_overfits_one_short_episode():
    """The end-effector visits object 1, then object 2 (hand-made labels: each target until
    the frame its pause ends, decided where it rests)."""
    world, status = _episode(H=30)
    target = np.where(np.arange(30) < 15, 1, 2)
    k = np.where(np.arange(30) < 15, 14, 29)
    data = [episode_steps(world, status == 0, np.zeros(30, np.int64), target, k, CLASSES, 2, 0.002, 3)]
    policy, last = train(data, OBJECTS, CLASSES, 2, TrainConfig(iterations=400, batch_steps=30, learning_rate=3e-3), seed=0)
    assert last["loss_tool"] < 0.1 and last["loss_target"] < 0.1 and last["loss_waypoint"] < 0.1
    figures = validate(policy, data)
    assert figures["pair_accuracy_free"] == 1.0 and figures["waypoint_error_mm_free"] < 5.0


def test_the_stepper_with_the_labels_reproduces_the_training_forward_pass():
    """What runs on the robot is what was trained: stepping frame by frame with the labels
    as history gives the batch computation's outputs."""
    data = _data()
    policy, _ = train(data, OBJECTS, CLASSES, 2, TrainConfig(iterations=20, batch_steps=40, learning_rate=3e-3), seed=1)
    s = data[0]
    with torch.no_grad():
        out = forward(policy, batch(data, [0]))
    stepper = Stepper(policy, 1)
    for t in range(len(s)):
        c = stepper.step(s.world[t][None].astype(np.float64), s.tracked[t][None],
                         forced=(s.tool[t:t + 1], s.target[t:t + 1], s.waypoint[t:t + 1]))
        np.testing.assert_allclose(c.log_tool[0], out["log_tool"][0, t].numpy(), atol=1e-4)
        np.testing.assert_allclose(c.log_target[0], out["log_target"][0, t].numpy(), atol=1e-4)
        np.testing.assert_allclose(c.action[0], out["action"][0, t].numpy(), atol=1e-6)


def test_pi_m_learns_decisions_from_the_targets_symmetric_equivalents():
    """With each object's symmetry, π_m's input and label are those of the target turned by
    one of its symmetries (here the cylinder's any turn), so L_w changes; the rest does not."""
    data = [_steps(40)[2], _steps(30)[2]]
    cfg = TrainConfig(iterations=1, batch_steps=80, learning_rate=0.0)
    _, plain = train(data, OBJECTS, CLASSES, 2, cfg, seed=0)
    _, turned = train(data, OBJECTS, CLASSES, 2, cfg, seed=0, folds=np.array([1, 0, 0]))
    _, unchanged = train(data, OBJECTS, CLASSES, 2, cfg, seed=0, folds=np.array([1, 1, 1]))
    assert turned["loss_waypoint"] != pytest.approx(plain["loss_waypoint"], rel=1e-3)
    assert unchanged["loss_waypoint"] == pytest.approx(plain["loss_waypoint"], rel=1e-5)
    for term in ("tool", "target", "action", "memory", "retrieval"):
        assert turned[f"loss_{term}"] == pytest.approx(plain[f"loss_{term}"], rel=1e-5)


def test_the_same_seed_gives_the_same_weights():
    cfg = TrainConfig(iterations=5, batch_steps=40)
    a, _ = train(_data(), OBJECTS, CLASSES, 2, cfg, seed=3)
    b, _ = train(_data(), OBJECTS, CLASSES, 2, cfg, seed=3)
    for (k, x), y in zip(a.net.state_dict().items(), b.net.state_dict().values()):
        assert torch.equal(x, y), k


def test_the_report_gives_the_figures_of_the_policy_returned_in_evaluation_mode():
    data = _data()
    policy, report = train(data, OBJECTS, CLASSES, 2, TrainConfig(iterations=60, batch_steps=40, learning_rate=3e-3,
                                                                   checkpoint_every=20), seed=0, held_out=data[:1])
    assert {report[f"checkpoint_iteration_{level}"] for level in ("pi_h", "pi_m", "pi_l")} <= {20, 40, 60}
    assert not policy.net.training
    assert report["validation_decision_subtask_accuracy"] == pytest.approx(
        validate(policy, data[:1])["decision_subtask_accuracy"])


def test_every_weight_belongs_to_exactly_one_level():
    net = Hierarchy(Sizes(len(OBJECTS), 2))
    owners = [id(p) for modules in net.levels().values() for m in modules for p in m.parameters()]
    assert len(owners) == len(set(owners)) and set(owners) == {id(p) for p in net.parameters()}


def test_each_level_is_kept_from_its_own_best_checkpoint(monkeypatch):
    """π_h by held-out decisions, then running free (ties: the later); π_m by how often its
    way-point is right, then its error; π_l by step error: each level's weights are those
    of its best validation."""
    import hsp.policy.train as train_module

    # (decisions right, running free, way-points right, way-point mm, step mm) at iterations 20, 40, 60, 80
    scripted = iter([(0.9, 0.5, 0.9, 1.0, 3.0), (1.0, 0.5, 1.0, 2.0, 2.0), (1.0, 0.6, 1.0, 5.0, 1.0),
                     (1.0, 0.6, 1.0, np.nan, 9.0)])
    kept: dict[int, dict] = {}
    returned: list[dict] = []

    def fake_validate(policy, episodes):
        snapshot = {k: v.clone() for k, v in policy.net.state_dict().items()}
        right, free, hit, mm, step = next(scripted, (0.0, 0.0, 0.0, 0.0, 0.0))
        if len(kept) < 4:  # the four checkpoints' validations, then that of the policy returned
            kept[20 * (len(kept) + 1)] = snapshot
        else:
            returned.append(snapshot)
        return {"decision_accuracy_teacher_forced": right, "pair_accuracy_free": free, "decision_subtask_accuracy": right,
                "waypoint_hit_teacher_forced": hit, "waypoint_error_mm_teacher_forced": mm,
                "waypoint_turn_deg_teacher_forced": 0.0, "action_error_mm": step}

    monkeypatch.setattr(train_module, "validate", fake_validate)
    _, report = train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=80, batch_steps=40, checkpoint_every=20,
                                                                pi_m_restarts=1), seed=0, held_out=_data()[:1])
    assert (report["checkpoint_iteration_pi_h"], report["checkpoint_iteration_pi_m"],
            report["checkpoint_iteration_pi_l"]) == (80, 40, 60)
    assert len(returned) == 1
    source = {"pi_h": 80, "pi_m": 40, "pi_l": 60}
    net = Hierarchy(Sizes(len(OBJECTS), 2))
    level_of = {f"{name}.{key}": level for level, modules in net.levels().items()
                for name, module in net.named_children() if module in modules for key in module.state_dict()}
    assert set(level_of) == set(returned[0])
    for name, value in returned[0].items():
        assert torch.equal(value, kept[source[level_of[name]]][name]), name
        assert not torch.equal(kept[20][name], kept[80][name]), name  # the checkpoints do differ


def test_pi_m_is_kept_from_the_restart_and_checkpoint_that_validate_best(monkeypatch):
    """π_m's other initialisations compete with the first at every checkpoint: the weights
    returned are those of the best (restart, checkpoint) on the held-out episodes."""
    import hsp.policy.train as train_module

    real_validate = train_module.validate
    first = iter([0.5, 0.6])  # restart 0's way-points right at iterations 20, 40
    other = iter([0.9, 0.4])  # restart 1's
    seen: list[dict] = []

    def fake_validate(policy, episodes):
        return real_validate(policy, episodes) | {"waypoint_hit_teacher_forced": next(first, 0.0)}

    def fake_pi_m_figures(policy, episodes):
        seen.append({k: v.clone() for k, v in policy.net.intermediate.state_dict().items()})
        return {"waypoint_hit_teacher_forced": next(other), "waypoint_error_mm_teacher_forced": 1.0,
                "waypoint_turn_deg_teacher_forced": 1.0}

    monkeypatch.setattr(train_module, "validate", fake_validate)
    monkeypatch.setattr(train_module, "pi_m_figures", fake_pi_m_figures)
    policy, report = train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=40, batch_steps=40, checkpoint_every=20,
                                                                     pi_m_restarts=2), seed=0, held_out=_data()[:1])
    assert (report["checkpoint_restart_pi_m"], report["checkpoint_iteration_pi_m"]) == (1, 20)
    assert len(seen) == 2
    for k, v in policy.net.intermediate.state_dict().items():
        assert torch.equal(v, seen[0][k]), k
        assert not torch.equal(seen[0][k], seen[1][k]), k  # the restart did train on


def test_pi_m_alone_is_judged_as_validate_judges_it():
    from hsp.policy.train import pi_m_figures

    data = _data()
    policy, _ = train(data, OBJECTS, CLASSES, 2, TrainConfig(iterations=20, batch_steps=40), seed=0)
    full = validate(policy, data)
    assert pi_m_figures(policy, data) == {k: full[k] for k in ("waypoint_error_mm_teacher_forced",
                                                               "waypoint_hit_teacher_forced",
                                                               "waypoint_turn_deg_teacher_forced")}


def test_the_restarts_loss_trains_only_the_restarts():
    """L_w of π_m's other initialisations reaches their weights alone: π_h learns from the
    π_m it runs with."""
    from hsp.policy.train import _reinitialised

    data = _data()
    policy = _blank_policy(data)
    restart = _reinitialised(policy.net.intermediate)
    assert not torch.equal(restart[0].weight, policy.net.intermediate[0].weight)
    losses(policy, batch(data, [0, 1]), [restart])["waypoint_restarts"].backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in restart.parameters())
    assert all(p.grad is None for p in policy.net.parameters())


def test_save_and_load_give_the_same_policy(tmp_path):
    policy, _ = train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=3, batch_steps=40), seed=0)
    save(policy, TrainConfig(iterations=1), tmp_path / "m")
    save(policy, TrainConfig(iterations=3), tmp_path / "m")  # a second run replaces the first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m"]
    assert '"iterations": 3' in (tmp_path / "m" / "config.json").read_text()
    again = load(tmp_path / "m")
    assert again.objects == OBJECTS and list(again.classes) == [0, 1, 1]
    with torch.no_grad():
        b = batch(_data(), [0])
        for k, v in forward(policy, b).items():
            torch.testing.assert_close(v, forward(again, b)[k], rtol=0, atol=0)


def test_bad_inputs_are_clear_errors(tmp_path):
    with pytest.raises(HspError, match="not a trained policy"):
        load(tmp_path)
    policy, _ = train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=1, batch_steps=40), seed=0)
    save(policy, TrainConfig(iterations=1), tmp_path / "old")
    config = tmp_path / "old" / "config.json"
    config.write_text(config.read_text().replace(f'"format": {FORMAT}', '"format": 1'))
    with pytest.raises(HspError, match="model format 1"):
        load(tmp_path / "old")
    with pytest.raises(HspError, match="iterations"):
        train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=0), seed=0)
    with pytest.raises(HspError, match="no labelled episodes"):
        train([], ["ee"], CLASSES, 2, TrainConfig(), seed=0)


def test_every_fifth_episode_validates_and_free_running_is_reported_beside_its_baselines():
    assert split(10, 5) == ([0, 1, 2, 3, 5, 6, 7, 8], [4, 9])
    assert split(2, 2) == ([0, 1], []) and split(7, 0) == (list(range(7)), [])
    data = _data()
    figures = validate(_blank_policy(data), data[:1])
    for key in ("pair_accuracy_free", "pair_accuracy_copy_previous", "decision_accuracy_teacher_forced",
                "decision_copy_previous", "decision_subtask_accuracy",
                "free_subtask_accuracy", "waypoint_error_mm_free", "waypoint_error_mm_teacher_forced", "action_error_mm"):
        assert key in figures
    assert figures["pair_accuracy_copy_previous"] > 0.9  # one switch in 40 frames


def test_a_way_point_is_as_far_from_a_label_as_from_its_nearest_symmetric_equivalent():
    policy = _blank_policy(_data())
    policy.folds = np.array([1, 4, 1])
    beside, other_side = np.array([0.05, 0, 0, 0, 0, 0, 1.0]), np.array([0, 0.05, 0, 0, 0, 0, 1.0])
    d = waypoint_distance(policy, np.stack([other_side] * 2), np.stack([beside] * 2), np.array([1, 2]))
    np.testing.assert_allclose(d, [0.0, 0.05 * np.sqrt(2)], atol=1e-9)


def test_a_dropout_outside_0_to_1_or_no_pi_m_start_is_refused():
    with pytest.raises(HspError, match="dropout"):
        train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=1, batch_steps=40, dropout=1.0), seed=0)
    with pytest.raises(HspError, match="pi_m_restarts"):
        train(_data(), OBJECTS, CLASSES, 2, TrainConfig(iterations=1, batch_steps=40, pi_m_restarts=0), seed=0)


def test_a_figure_with_nothing_to_judge_scores_worst():
    from hsp.policy.train import level_scores

    figures = {"decision_accuracy_teacher_forced": 0.5, "pair_accuracy_free": 0.5, "waypoint_hit_teacher_forced": 0.5,
               "waypoint_error_mm_teacher_forced": 2.0, "waypoint_turn_deg_teacher_forced": 1.0, "action_error_mm": 2.0}
    judged = level_scores(figures)
    for name in figures:
        unjudged = level_scores(figures | {name: float("nan")})
        assert all(unjudged[level] <= judged[level] for level in judged), name
        assert any(unjudged[level] < judged[level] for level in judged), name
