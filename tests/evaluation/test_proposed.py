"""The runner of π_h, π_m, π_l: its history is its own output, never a label."""

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from hsp.evaluation.env import EnvConfig, HspEnv, world_poses
from hsp.evaluation.proposed import HierarchyRunner, apply_step
from hsp.geometry import rotvec_delta
from hsp.policy.networks import Hierarchy, Sizes
from hsp.policy.normalisation import FIELDS, Normalisation
from hsp.policy.stage import semantic_classes
from hsp.labeling.priors import pairs_of
from hsp.policy.train import Policy


def untrained_policy(task, seed: int = 0) -> Policy:
    """Random networks for ``task`` with unit normalisation (actions of a few mm)."""
    torch.manual_seed(seed)
    classes, n_classes = semantic_classes(task)
    P = len(pairs_of(len(task.objects)))
    net = Hierarchy(Sizes(P, n_classes)).eval()
    dims = {"z": 7 * P, "progress": 7, "current": 7, "target_in_tool": 7, "waypoint": 7, "action": 6}
    stats = {f"{k}.mean": torch.zeros(dims[k]) for k in FIELDS} | {f"{k}.std": torch.ones(dims[k]) for k in FIELDS}
    stats["action.std"] = torch.full((6,), 0.002)
    return Policy(net, Normalisation(stats), task.names, classes, n_classes)


def test_apply_step_inverts_rotvec_delta():
    rng = np.random.default_rng(0)
    a = np.concatenate([rng.normal(size=3), rng.normal(size=4)])
    a[3:] /= np.linalg.norm(a[3:])
    b = np.concatenate([rng.normal(size=3), rng.normal(size=4)])
    b[3:] /= np.linalg.norm(b[3:])
    got = apply_step(a, rotvec_delta(a, b))
    np.testing.assert_allclose(got[:3], b[:3], atol=1e-9)
    assert abs(abs(got[3:] @ b[3:]) - 1) < 1e-9


def test_the_history_is_the_runners_own_output(tasks):
    """At every step the LSTM reads the pair and way-point the runner chose one step before."""
    task = tasks["tire-removal"]
    runner = HierarchyRunner(untrained_policy(task), task)
    env = HspEnv(task, EnvConfig(max_steps=20))
    obs, _ = env.reset(seed=4)
    runner.reset(world_poses(obs), 4)
    for _ in range(6):
        action = runner.act(world_poses(obs))
        assert action.shape == (8,) and np.all(np.isfinite(action))
        tool = int(runner.pairs[runner.trace[-1]["pair"]][0])
        assert action[7] == tool  # the gripper is told to hold the chosen tool (0: the wrench itself)
        obs, *_ = env.step(action)
    env.close()
    P = len(runner.pairs)
    assert not runner.trace[0]["history"].any()
    for before, now in zip(runner.trace, runner.trace[1:]):
        assert np.flatnonzero(now["history"][:P]).tolist() == [before["pair"]]
        np.testing.assert_allclose(now["history"][P:], before["waypoint"], rtol=1e-6)


def test_identical_objects_keep_the_chosen_one(tasks):
    """Pairs of the same labels (a wrench on any of the four nuts) are one choice; while it
    stays the most likely, the runner keeps the nut it took."""
    task = tasks["tire-removal"]
    runner = HierarchyRunner(untrained_policy(task), task)
    runner.reset(None, 0)
    bolts = [i for i, (t, j) in enumerate(runner.pairs) if t == 0 and task.objects[j].label == "bolt"]
    logp = np.full(len(runner.pairs), -20.0)
    logp[bolts] = np.log([0.1, 0.15, 0.2, 0.25])
    first = runner._choose(logp)
    assert first == bolts[3]
    runner.pair = first
    logp[bolts] = np.log([0.4, 0.2, 0.2, 0.1])  # another nut now scores higher, the label pair is the same
    assert runner._choose(logp) == first


def test_the_labelled_step_commands_the_next_pose(tasks):
    """π_l's step (a frame's small motion), converted to a command for the hand holding a
    block, puts the hand where it must be for the block to make that step."""
    from hsp.evaluation.proposed import tcp_command
    from hsp.geometry import compose, relative
    from hsp.labeling.label import canonical_poses

    task = tasks["stacking-1"]
    sym = [o.symmetry for o in task.objects]
    rng = np.random.default_rng(2)

    def random_pose(z):
        q = rng.normal(size=4)
        return np.concatenate([rng.uniform(0.4, 0.6, 3) * [1, 1, z], q / np.linalg.norm(q)])

    now = np.stack([random_pose(1.0) for _ in task.objects])
    grasp = relative(now[0], now[1])  # the hand in the block's frame, rigid
    later = now.copy()
    small = np.concatenate([[0.02, -0.01, 0.015], Rotation.from_rotvec([0.03, -0.05, 0.08]).as_quat()])
    later[1] = compose(small, now[1])
    later[0] = compose(later[1], grasp)
    c_now, c_later = canonical_poses(now[None], sym)[0], canonical_poses(later[None], sym)[0]
    step = rotvec_delta(relative(c_now[1], c_now[3]), relative(c_later[1], c_later[3]))
    tcp = tcp_command(now, c_now, 1, 3, step)
    np.testing.assert_allclose(tcp[:3], later[0, :3], atol=1e-9)
    assert abs(abs(tcp[3:] @ later[0, 3:]) - 1) < 1e-9
