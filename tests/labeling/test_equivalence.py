"""Targets the poses cannot tell apart: objects rigid with each other over a sub-task."""

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.labeling.equivalence import equivalent_targets, rigid_with

IDENTITY = [0, 0, 0, 1.0]


def _scene(H: int = 20) -> np.ndarray:
    """0 end-effector, 1 tool (moving along x), 2 a base block, 3 a block on it, 4 a far block."""
    world = np.tile(np.r_[0.0, 0.0, 0.0, IDENTITY], (H, 5, 1))
    world[:, 0, :3] = [0.0, 0.0, 0.5]
    world[:, 1, 0] = np.linspace(-0.2, 0.05, H)
    world[:, 1, 2] = 0.0
    world[:, 3, 2] = 0.04
    world[:, 4, :3] = [0.5, 0.5, 0.0]
    return world


def test_rigid_with_needs_position_and_orientation_kept():
    world = _scene()
    ok = np.ones(world.shape[:2], bool)
    assert list(rigid_with(world, ok, 2, 0.01, 10.0)) == [True, False, True, True, True]  # the still hand too
    world[:, 3, 3:] = Rotation.from_euler("z", np.linspace(0, 30, len(world))[:, None], degrees=True).as_quat()
    assert list(rigid_with(world, ok, 2, 0.01, 10.0)) == [True, False, True, False, True]
    world[5, 2, 1] += 0.05  # one frame of tracking glitch does not break the tower apart
    assert list(rigid_with(world, ok, 2, 0.01, 10.0)) == [True, False, True, False, True]
    world[:, 4, 0] += np.linspace(0, 0.05, len(world))
    ok[:, 0] = False  # never tracked with 2
    assert list(rigid_with(world, ok, 2, 0.01, 10.0)) == [False, False, True, False, False]


def test_heading_jitter_of_the_reference_does_not_swing_its_neighbours():
    """A lug nut's tracked heading drifting 8° moves a wheel 10 cm away by 14 mm in the
    nut's frame; the two still sit in the same place, so they stay rigid."""
    world = _scene()
    world[:, 4, :3] = [0.1, 0.0, 0.0]
    world[:, 2, 3:] = Rotation.from_euler("z", np.r_[np.zeros(10), np.full(10, 8.0)][:, None], degrees=True).as_quat()
    ok = np.ones(world.shape[:2], bool)
    assert rigid_with(world, ok, 2, 0.01, 15.0)[4]


def test_each_sub_task_s_set_holds_what_stays_rigid_with_its_target():
    """The tool (1) slides along x past the tower (2, 3) while 4 moves away: the set of a
    sub-task aimed at the base holds the block on it, never the tool, the end-effector or
    the block that moved; the next sub-task's is recomputed from its own frames."""
    world = _scene()
    H = len(world)
    world[10:, 4, 1] += np.linspace(0, 0.2, H - 10)  # 4 stays with the tower for half the run only
    ok = np.ones((H, 5), bool)
    tool = np.full(H, 1)
    target = np.r_[np.full(10, 2), np.full(H - 10, 3)]
    got = equivalent_targets(world, ok, tool, target, 0.01, 10.0)
    assert got.shape == (H, 5) and not got[:, :2].any()
    assert (got[:10] == [False, False, True, True, True]).all()
    assert (got[10:] == [False, False, True, True, False]).all()
