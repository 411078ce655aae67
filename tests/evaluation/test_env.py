"""The environments: registered, laid out as the dataset, graspping within reach only,
and checkers that say no to a wrong policy."""

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import hsp.evaluation  # noqa: F401  (registers hsp/<Task>-v0)
from hsp.dataset.features import ENV_STATE, STATE, features
from hsp.errors import HspError
from hsp.evaluation import env_id
from hsp.evaluation.env import GRIP_CLOSED, EnvConfig, HspEnv, world_poses
from hsp.evaluation.oracle import Oracle
from hsp.evaluation.rollout import run_episode
from tests.conftest import TASKS


@pytest.mark.parametrize("name", TASKS)
def test_a_few_steps_hold_still_and_observe_as_the_dataset(tasks, name):
    """Holding the pose for a few steps: observations have the dataset's layout and equal
    the simulator's poses in task order; nothing is achieved."""
    env = gym.make(env_id(name), max_steps=5)
    obs, info = env.reset(seed=3)
    feats = features(tasks[name])
    assert obs["agent_pos"].shape == feats[STATE]["shape"]
    assert obs["environment_state"].shape == feats[ENV_STATE]["shape"]
    assert obs["agent_pos"].dtype == np.float32
    hold = np.concatenate([obs["agent_pos"], [0.0]])
    steps = 0
    while True:
        obs, reward, terminated, truncated, info = env.step(hold)
        steps += 1
        if terminated or truncated:
            break
    inner = env.unwrapped
    np.testing.assert_allclose(world_poses(obs), inner.scene.object_poses(), atol=1e-6)
    assert steps == 5 and truncated and not terminated and reward == 0.0
    assert info["is_success"] is False and not any(info["progress"].values())
    # the tool-centre point stayed where it was held (object 0 is the tool on the Kuka)
    assert np.linalg.norm(obs["agent_pos"][:3] - hold[:3]) < 0.005
    env.close()


def test_the_same_seed_gives_the_same_layout():
    a = gym.make(env_id("stacking-2")).reset(seed=11)[0]
    b = gym.make(env_id("stacking-2")).reset(seed=11)[0]
    c = gym.make(env_id("stacking-2")).reset(seed=12)[0]
    np.testing.assert_array_equal(a["environment_state"], b["environment_state"])
    assert not np.allclose(a["environment_state"], c["environment_state"])


def test_the_gripper_closes_only_within_reach(tasks):
    env = HspEnv(tasks["stacking-1"], EnvConfig(max_steps=10))
    obs, _ = env.reset(seed=0)
    poses = world_poses(obs)
    env.step(np.concatenate([poses[0], [1.0]]))  # block 1 is far from the hand
    assert env.held == 0
    above = poses[1].copy()
    env.step(np.concatenate([above, [0.0]]))
    for _ in range(8):
        obs, *_ = env.step(np.concatenate([above, [1.0]]))
    assert env.held == 1
    with pytest.raises(HspError, match="grip command 7"):
        env.step(np.concatenate([above, [7.0]]))
    with pytest.raises(HspError, match="8 finite numbers"):
        env.step(np.full(8, np.nan))
    env.close()


def test_a_plain_gripper_closes_on_the_nearest_object_within_reach(tasks):
    """GRIP_CLOSED (a policy that knows no objects): nothing far from the hand, then the block
    the hand is on, held while the command stays closed and let go when it opens."""
    env = HspEnv(tasks["stacking-1"], EnvConfig(max_steps=20))
    poses = world_poses(env.reset(seed=0)[0])
    env.step(np.concatenate([poses[0], [GRIP_CLOSED]]))
    assert env.held == 0
    target = int(np.argmin(np.linalg.norm(poses[1:, :2] - poses[0, :2], axis=1))) + 1
    env.step(np.concatenate([poses[target], [0.0]]))
    for _ in range(8):
        obs, *_ = env.step(np.concatenate([poses[target], [GRIP_CLOSED]]))
    assert env.held == target
    lifted = world_poses(obs)[0] + np.r_[0, 0, 0.05, 0, 0, 0, 0]
    for _ in range(3):
        obs, *_ = env.step(np.concatenate([lifted, [GRIP_CLOSED]]))
    assert env.held == target and world_poses(obs)[target, 2] > poses[target, 2] + 0.03
    env.step(np.concatenate([lifted, [0.0]]))
    assert env.held == 0
    env.close()


class _Shifted(Oracle):
    """The demonstrator's plan with every command 1.5 cm off to the side."""

    def act(self, poses):
        a = super().act(poses)
        a[1] += 0.015
        return a


def test_the_checkers_say_no_to_a_wrong_policy(tasks):
    """The oracle stacks the tower; the same plan 1.5 cm off does not (tolerance 5 mm)."""
    task = tasks["stacking-1"]
    env = HspEnv(task, EnvConfig(max_steps=400))
    good = run_episode(env, Oracle(task, 15, env.reach_error), seed=21)
    bad = run_episode(env, _Shifted(task, 15, env.reach_error), seed=21)
    env.close()
    assert good["success"] and good["ended"] == "success"
    assert not bad["success"] and bad["ended"] == "step limit" and bad["steps"] == 400
    assert not all(bad["progress"].values())


class _LookAlikeFrames:
    """The simulator's poses with every block switched, from step 50 on, to another of a
    cube's 24 look-alike frames (a quarter turn about its x axis: its z axis horizontal),
    as a tracker may give a block it re-finds."""

    def __init__(self, blocks: list[int]) -> None:
        self.blocks = blocks

    def reset(self, true_poses: np.ndarray, seed: int) -> np.ndarray:
        self.steps = 0
        return true_poses

    def observe(self, true_poses: np.ndarray) -> np.ndarray:
        self.steps += 1
        out = true_poses.copy()
        if self.steps >= 50:
            q = Rotation.from_quat(out[self.blocks, 3:]) * Rotation.from_euler("x", 90, degrees=True)
            out[self.blocks, 3:] = q.as_quat()
        return out


def test_the_oracle_stacks_blocks_whose_frames_switch_to_look_alikes(tasks):
    """A cube's frame is ambiguous to a camera: the plan follows each block in the
    look-alike frame nearest its last one, so the arm does not stand a block on its side."""
    task = tasks["stacking-1"]
    blocks = [i for i, o in enumerate(task.objects) if o.symmetry == "cube"]
    env = HspEnv(task, EnvConfig(max_steps=400), observer=_LookAlikeFrames(blocks))
    record = run_episode(env, Oracle(task, 15, env.reach_error), seed=21)
    env.close()
    assert record["success"], record


class _RollingHandle:
    """The simulator's poses with the brush, once lifted, turned about its handle's axis
    (its x) by 5° more every step, up to 170°: the roll a camera leaves free on a round
    handle, which a tracker let drift so."""

    def __init__(self, brush: int) -> None:
        self.brush = brush

    def reset(self, true_poses: np.ndarray, seed: int) -> np.ndarray:
        self.rest_z, self.lifted = true_poses[self.brush, 2], 0
        return true_poses

    def observe(self, true_poses: np.ndarray) -> np.ndarray:
        out = true_poses.copy()
        if self.lifted or out[self.brush, 2] > self.rest_z + 0.02:
            self.lifted = min(self.lifted + 5, 170)
            q = Rotation.from_quat(out[self.brush, 3:]) * Rotation.from_euler("x", self.lifted, degrees=True)
            out[self.brush, 3:] = q.as_quat()
        return out


def test_the_oracle_holds_what_it_grasped_as_it_grasped_it(tasks):
    """A grasp is rigid: the plan takes the held brush where the grasp holds it, not where
    the observer's drifting roll puts it, so the arm does not turn its wrist to follow it."""
    task = tasks["painting"]
    brush = next(i for i, o in enumerate(task.objects) if o.symmetry == "x_2fold")
    env = HspEnv(task, EnvConfig(max_steps=400), observer=_RollingHandle(brush))
    record = run_episode(env, Oracle(task, 15, env.reach_error), seed=21)
    env.close()
    assert record["success"], record


def test_the_oracle_follows_a_brush_that_slips_in_its_grasp(tasks):
    """In this layout the brush slips 17 mm in the gripper under its load as it is lifted:
    the plan takes its position from the observer, not from the grasp, and strokes."""
    task = tasks["painting"]
    env = HspEnv(task, EnvConfig(max_steps=400))
    record = run_episode(env, Oracle(task, 15, env.reach_error), seed=1735236722)
    env.close()
    assert record["success"], record
