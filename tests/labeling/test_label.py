"""Priors and labelling on demonstrations with a known annotation."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsp.dataset.features import TrackStatus
from hsp.errors import HspError
from hsp.geometry import rotation_angle_deg
from hsp.labeling.label import label_episode, median_headings
from hsp.labeling.metrics import boundaries, boundary_errors, label_metrics
from hsp.labeling.priors import PriorConfig, pairs_of, relative_poses, tool_evidence
from hsp.labeling.stage import canonical_waypoints
from hsp.sim.demonstration import demonstrate


def test_pairs_exclude_end_effector_targets_and_self_pairs():
    pairs = pairs_of(4)
    assert len(pairs) == 9 and not np.any(pairs[:, 1] == 0) and not np.any(pairs[:, 0] == pairs[:, 1])


def test_relative_poses_match_definition():
    from hsp.geometry import relative

    rng = np.random.default_rng(0)
    world = np.concatenate([rng.normal(size=(3, 4, 3)), np.tile([0, 0, np.sin(0.2), np.cos(0.2)], (3, 4, 1))], -1)
    rel = relative_poses(world)
    np.testing.assert_allclose(rel[2, 1, 3], relative(world[2, 1], world[2, 3]), atol=1e-12)


def test_tool_evidence_three_cases():
    """A block carried → the block; the hand alone moving → the hand; all still → no evidence."""
    H, n = 4, 3
    world = np.tile([0.5, 0.0, 0.02, 0, 0, 0, 1.0], (H, n, 1))
    world[:, 2, 0] += 0.3
    world[1, 0, 0] += 0.05  # hand moves between frames 0→1 and back 1→2
    world[3, :2, 1] += 0.05  # hand and block move together 2→3
    ev = tool_evidence(world, np.ones((H, n), bool), moving_m=0.002, half_window=0)
    assert list(ev[:3]) == [0, 0, 1]
    still = np.tile(world[:1], (H, 1, 1))
    assert np.all(tool_evidence(still, np.ones((H, n), bool), 0.002) == -1)


def test_a_pause_belongs_to_the_motion_it_ends():
    """Still at first (no evidence), the block carried, a pause (still the block: the hand has
    not let go of the sub-task yet), then the hand alone leaves."""
    H, n = 40, 3
    world = np.tile([0.5, 0.0, 0.02, 0, 0, 0, 1.0], (H, n, 1))
    world[:, 2, 0] += 0.3
    step = np.zeros(H)
    step[5:15] = 0.01  # frames 5–14: hand and block carried 1 cm a frame
    world[:, :2, 1] += np.cumsum(step)[:, None]
    world[25:, 0, 2] += 0.01 * np.arange(1, H - 24)  # from frame 25 the hand rises alone
    ev = tool_evidence(world, np.ones((H, n), bool), moving_m=0.002, half_window=0)
    assert np.all(ev[:4] == -1)
    assert np.all(ev[5:24] == 1), ev  # carried, then paused
    assert np.all(ev[25:] == 0)


def test_a_carried_object_lost_from_view_stays_the_tool():
    """The hand carries block 1 throughout; the tracker loses the block in frames 10–19.
    Its motion cannot be measured there, which is no reason to make the hand the tool;
    once the block is put down and seen, the hand moving alone is."""
    H, n = 40, 3
    world = np.tile([0.5, 0.0, 0.02, 0, 0, 0, 1.0], (H, n, 1))
    world[:, 2, 0] += 0.3
    world[:30, :2, 1] += 0.01 * np.arange(30)[:, None]
    world[30:, :2, 1] += 0.29
    world[30:, 0, 2] += 0.01 * np.arange(1, 11)  # the hand rises alone
    ok = np.ones((H, n), bool)
    ok[10:20, 1] = False
    ev = tool_evidence(world, ok, moving_m=0.002)
    assert np.all(ev[:29] == 1), ev
    assert np.all(ev[31:] == 0), ev


def test_tracking_jitter_is_not_tool_evidence_but_steady_motion_is():
    """A block jittering ±1.5 mm frame to frame (3 mm steps) is no tool; one carried 3 mm a frame is."""
    H, n = 30, 3
    world = np.tile([0.5, 0.0, 0.02, 0, 0, 0, 1.0], (H, n, 1))
    world[:, 2, 0] += 0.3
    jitter = world.copy()
    jitter[:, 1, 0] += 0.0015 * (-1) ** np.arange(H)
    assert np.all(tool_evidence(jitter, np.ones((H, n), bool), 0.002, half_window=0)[:-1] == 1), "per frame it looks moving"
    assert np.all(tool_evidence(jitter, np.ones((H, n), bool), 0.002) == -1)
    carried = world.copy()
    carried[:, 1, 1] += 0.003 * np.arange(H)
    assert np.all(tool_evidence(carried, np.ones((H, n), bool), 0.002) == 1)


def test_median_headings_drop_a_glitch_keep_a_turn_and_the_end_effector():
    """A target's heading glitch of 5 frames goes; a sustained turn and the end-effector's
    own rotation stay; q and −q from frame to frame do not upset the median."""
    H = 40
    world = np.tile([0.5, 0.0, 0.02, 0, 0, 0, 1.0], (H, 3, 1))
    yaw = np.zeros((H, 3))
    yaw[10:15, 1] = 21.0  # glitch
    yaw[20:, 2] = 50.0  # a nut turned and left there
    yaw[:, 0] = np.linspace(0, 90, H)  # the end-effector turning
    world[..., 3:] = Rotation.from_euler("z", yaw.reshape(-1, 1), degrees=True).as_quat().reshape(H, 3, 4)
    world[1::2, 1, 3:] *= -1  # the same rotations, alternate signs
    out = median_headings(world, 15)
    angle = lambda q, deg: rotation_angle_deg(q, Rotation.from_euler("z", deg, degrees=True).as_quat())
    assert np.all(angle(out[:, 1, 3:], 0.0) < 1e-6)
    assert np.all(angle(out[28:, 2, 3:], 50.0) < 1e-6) and np.all(angle(out[:12, 2, 3:], 0.0) < 1e-6)
    np.testing.assert_array_equal(out[:, 0], world[:, 0])
    np.testing.assert_array_equal(out[..., :3], world[..., :3])
    np.testing.assert_array_equal(median_headings(world, 1), world)


@pytest.mark.parametrize("name", ["stacking-1", "painting"])
def test_priors_recover_most_of_the_demonstrators_annotation(tasks, name):
    """On ground-truth poses the prior labels agree with the annotation on ≥ 90 % of frames,
    ≥ 95 % modulo equivalence (the true target in the label's set)."""
    d = demonstrate(tasks[name], 100, 15)
    lab = label_episode(d.poses, np.zeros(d.poses.shape[:2], int), PriorConfig())
    m = label_metrics([dict(tool=lab.tool, target=lab.target, waypoint=lab.waypoint, equivalent=lab.equivalent)],
                      [dict(tool=d.tool, target=d.target, waypoint=d.waypoint)])
    assert m["tool_accuracy"] >= 0.9 and m["target_accuracy"] >= 0.9 and m["target_accuracy_equivalent"] >= 0.95, m
    assert np.all(lab.target != 0) and np.all(lab.waypoint_index >= np.arange(d.frames))


def test_one_frame_episode_is_an_error(tasks):
    with pytest.raises(HspError, match="1 frame"):
        label_episode(np.zeros((1, 4, 7)), np.zeros((1, 4), int), PriorConfig())


def test_boundary_errors():
    assert list(boundaries(np.array([0, 0, 1, 1]), np.array([2, 2, 2, 3]))) == [2, 3]
    np.testing.assert_array_equal(boundary_errors(np.array([5]), np.array([3, 9]), 20), [2, 4])
    np.testing.assert_array_equal(boundary_errors(np.array([]), np.array([3]), 20), [20])


def test_a_way_point_is_where_the_tool_stops_not_where_it_passes_nearest():
    """The end-effector sweeps 2 mm past object 1 without slowing, stops 3 cm from object 2
    for 10 frames, then leaves: only the stop (and the last frame) can be a way-point."""
    from hsp.labeling.priors import PriorScores

    H = 50
    world = np.zeros((H, 3, 7))
    world[..., 6] = 1.0
    world[:, 1, :3] = [0.5, 0.0, 0.0]
    world[:, 2, :3] = [0.5, 0.2, 0.0]
    world[:30, 0, :3] = np.linspace([0.5, -0.2, 0.002], [0.5, 0.2, 0.03], 30)
    world[30:40, 0, :3] = [0.5, 0.2, 0.03]
    world[40:, 0, :3] = np.linspace([0.5, 0.2, 0.03], [0.5, 0.2, 0.3], 10)
    scores = PriorScores(world, np.ones((H, 3), bool), PriorConfig())
    hand_is_tool = scores.pairs[:, 0] == 0
    candidates = np.flatnonzero(np.isfinite(scores.jump(0)[hand_is_tool]).any(axis=0))
    assert set(candidates) == set(range(31, 39)) | {H - 1}, candidates
    lab = label_episode(world, np.zeros((H, 3), np.int64), PriorConfig())
    assert np.all(lab.target[:30] == 2) and np.allclose(lab.waypoint[:30, :3], [0.0, 0.0, 0.03], atol=1e-9)


def _socket_turn(nut_turns: bool, lift: bool = True) -> np.ndarray:
    """0 a wrench comes down onto nut 1 (frames 0–14), rests (15–19), turns 50° about it
    (20–29), rests (30–39) and lifts (40–49) or rests on; 2 is the wheel 10 cm away. The nut turns with the socket or,
    as a tracker that cannot see under the socket reports it, stays."""
    world = np.zeros((50, 3, 7))
    world[..., 6] = 1.0
    world[:, 2, :3] = [0.1, 0.0, 0.0]
    world[:15, 0, 2] = np.linspace(0.1, 0.01, 15)
    world[15:, 0, 2] = 0.01
    if lift:
        world[40:, 0, 2] = np.linspace(0.01, 0.1, 10)
    yaw = np.r_[np.zeros(20), np.linspace(0.0, 50.0, 10), np.full(20, 50.0)]
    world[:, 0, 3:] = Rotation.from_euler("z", yaw[:, None], degrees=True).as_quat()
    if nut_turns:
        world[:40, 1, 3:] = world[:40, 0, 3:]
        world[40:, 1, 3:] = world[39, 0, 3:]
    return world


def test_a_target_turning_with_the_tool_is_driven_and_the_turn_goes_to_the_wheel():
    from hsp.labeling.priors import driven

    ok = np.ones((50, 3), bool)
    pair = {tuple(p): c for c, p in enumerate(pairs_of(3))}
    for nut_turns in (True, False):
        world = _socket_turn(nut_turns)
        d = driven(world, ok, relative_poses(world)[:, pairs_of(3)[:, 0], pairs_of(3)[:, 1]], 0.002, 0.5)
        assert d[22:28, pair[0, 1]].all() == nut_turns and not d[:, pair[0, 2]].any()
        assert not d[:17, pair[0, 1]].any() and not d[33:, pair[0, 1]].any()
    lab = label_episode(_socket_turn(True), np.zeros((50, 3), int), PriorConfig())
    assert np.all(lab.tool == 0) and np.all(lab.target[:14] == 1) and np.all(lab.target[22:28] == 2), lab.target


def test_a_turn_in_place_has_its_own_way_point():
    """π_l's straight line is in R³ × SO(3): the socket's descent aims at the seated pose,
    the turn that follows at the turned one (translation alone would read it as a pause)."""
    lab = label_episode(_socket_turn(False, lift=False), np.zeros((50, 3), int), PriorConfig())
    assert np.all(lab.target[:40] == 1), lab.target
    assert np.all((lab.waypoint_index[:14] >= 14) & (lab.waypoint_index[:14] <= 20)), lab.waypoint_index
    assert np.all(lab.waypoint_index[22:28] >= 29), lab.waypoint_index
    assert rotation_angle_deg(lab.waypoint[25, 3:], Rotation.from_euler("z", 50, degrees=True).as_quat()) < 1.0


def test_lost_frames_are_never_way_points_of_the_lost_object():
    """Documented behaviour: a lost object's frames carry no evidence (no motion term) and
    cannot be way-points of pairs involving it; labelling still covers every frame."""
    from hsp.labeling.priors import PriorScores
    from tests.labeling.test_em import _episode

    world, status = _episode(60)
    status[40:46, 2] = TrackStatus.LOST
    scores = PriorScores(world, status != TrackStatus.LOST, PriorConfig())
    involves_2 = (scores.pairs == 2).any(axis=1)
    J = scores.jump(10)  # way-points k = 10 … 59
    unaffected = PriorScores(world, np.ones(status.shape, bool), PriorConfig()).jump(10)
    assert np.all(np.isneginf(J[involves_2][:, 30:36])) and np.array_equal(J[~involves_2], unaffected[~involves_2])
    assert np.isfinite(unaffected[involves_2][:, 30:36]).any(), "seen, the pause at object 2 is a way-point"
    assert np.all(scores.motion(42)[involves_2] == 0.0)
    lab = label_episode(world, status, PriorConfig())
    assert len(lab.tool) == 60 and np.all(lab.target != 0)


def test_way_points_in_a_round_targets_frame_do_not_depend_on_its_heading(tasks):
    """Turning the bucket about its axis (which no camera can see) changes neither the
    labels nor their way-points, and the annotation re-expressed in the canonical frame
    agrees with the labels where they agree on tool and target."""
    task = tasks["painting"]
    d = demonstrate(task, 101, 15)
    symmetries = [o.symmetry for o in task.objects]
    status = np.zeros(d.poses.shape[:2], int)
    turned = d.poses.copy()
    bucket = task.index(task.spec.success.source)
    turned[:, bucket, 3:] = (Rotation.from_quat(turned[:, bucket, 3:]) * Rotation.from_euler("z", 1.234)).as_quat()
    a = label_episode(d.poses, status, PriorConfig(), symmetries=symmetries)
    b = label_episode(turned, status, PriorConfig(), symmetries=symmetries)
    assert np.array_equal(a.target, b.target) and np.allclose(a.waypoint, b.waypoint, atol=1e-9)
    m = label_metrics([dict(tool=b.tool, target=b.target, waypoint=b.waypoint)],
                      [dict(tool=d.tool, target=d.target, waypoint=canonical_waypoints(d, symmetries))])
    assert m["waypoint_error_mm_median"] < 10.0, m
