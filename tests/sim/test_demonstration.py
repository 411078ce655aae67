"""Each task is solved by its scripted demonstrator, and its annotation is truthful."""

import numpy as np
import pytest

from hsp.geometry import relative, rotation_angle_deg
from hsp.sim.demonstration import demonstrate
from tests.conftest import TASKS


@pytest.fixture(scope="module")
def demos(tasks):
    return {name: [demonstrate(tasks[name], seed, 15) for seed in (101, 202)] for name in TASKS}


@pytest.mark.parametrize("name", TASKS)
def test_demonstrator_solves_the_task(demos, name):
    assert [d.success for d in demos[name]] == [True, True]


@pytest.mark.parametrize("name", TASKS)
def test_annotation_changes_only_with_the_waypoint(demos, name):
    """Tool, target and w are constant within a way-point and the counter only increases."""
    for d in demos[name]:
        change = np.flatnonzero(np.diff(d.waypoint_index))
        assert np.all(np.diff(d.waypoint_index) >= 0)
        for arr in (d.tool, d.target):
            assert set(np.flatnonzero(np.diff(arr))) <= set(change)
        assert set(np.flatnonzero(np.any(np.diff(d.waypoint, axis=0) != 0, axis=1))) <= set(change)
        assert np.all(d.target != 0), "the end-effector is never a target"


@pytest.mark.parametrize("name", TASKS)
def test_waypoint_is_where_the_tool_ends_up(demos, name):
    """At the end of each way-point segment, p[tool, target] ≈ w (tremor and lag allowed)."""
    for d in demos[name]:
        ends = np.append(np.flatnonzero(np.diff(d.waypoint_index)), d.frames - 1)
        for t in ends[1:]:
            rel = relative(d.poses[t, d.tool[t]], d.poses[t, d.target[t]])
            assert np.linalg.norm(rel[:3] - d.waypoint[t, :3]) < 0.006
            assert rotation_angle_deg(rel[3:], d.waypoint[t, 3:]) < 3.0


def test_same_seed_same_demonstration(tasks):
    a, b = demonstrate(tasks["stacking-2"], 5, 15), demonstrate(tasks["stacking-2"], 5, 15)
    np.testing.assert_array_equal(a.poses, b.poses)
    np.testing.assert_array_equal(a.waypoint_index, b.waypoint_index)
