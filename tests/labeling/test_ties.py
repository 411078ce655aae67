"""Targets rigid with each other: the closest approach at a way-point decides."""

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.labeling.ties import held_positions, resolve_target_ties
from tests.labeling.test_equivalence import IDENTITY, _scene


def test_the_rigid_candidate_nearest_at_a_way_point_becomes_the_target():
    world = _scene()
    H = len(world)
    world[:, 1, 2] = 0.05  # the tool ends beside the upper block, nearer it than the base
    ok = np.ones((H, 5), bool)
    tool, target = np.full(H, 1), np.full(H, 4)  # labelled relative to the far block
    k = np.full(H, H - 1)
    out = resolve_target_ties(world, ok, tool, target, k, 0.01, 10.0)
    assert np.all(out == 3)


def test_a_candidate_lost_at_the_way_point_is_still_where_it_was_seen():
    """The upper block is hidden under the tool set beside it in the last frames."""
    world = _scene()
    H = len(world)
    world[:, 1, 2] = 0.05
    ok = np.ones((H, 5), bool)
    ok[-3:, 3] = False
    world[-3:, 3, :3] = 9.0  # no pose there: must not be read
    tool, target, k = np.full(H, 1), np.full(H, 4), np.full(H, H - 1)
    assert np.all(resolve_target_ties(world, ok, tool, target, k, 0.01, 10.0) == 3)


def test_candidates_are_compared_where_they_were_during_the_run():
    """Block 1 is set beside the base (run 1) and its way-point is taken at a later frame,
    by which time block 4 has been carried next to it (run 2): 4 was far during run 1."""
    world = _scene()
    H, h = len(world), len(world) // 2
    world[h:, 1, 0] = 0.05
    world[:, 3, :3] = [0.5, -0.5, 0.0]
    world[h:, 4, :3] = np.c_[np.linspace(0.5, 0.05, H - h), np.zeros(H - h), np.linspace(0.0, 0.04, H - h)]
    ok = np.ones((H, 5), bool)
    tool, target = np.r_[np.full(h, 1), np.full(H - h, 4)], np.r_[np.full(h, 2), np.full(H - h, 1)]
    k = np.full(H, H - 1)
    assert np.all(resolve_target_ties(world, ok, tool, target, k, 0.01, 10.0)[:h] == 2)


def test_a_later_way_point_approached_at_another_candidate_starts_a_part_relative_to_it():
    """One run: the tool rests by block 4, then by the base 2 (the wrench gone from the last
    nut to the wheel's centre), then rises away, ending nearer block 3 than the base but
    farther from 3 than it was: the rise stays with the base."""
    H = 30
    world = _scene(H)
    world[:, 3, :3] = [0.0, 0.12, 0.0]
    stops = np.array([[0.47, 0.5, 0.0], [0.0, 0.05, 0.0], [0.0, 0.08, 0.2]])
    world[:, 1, :3] = np.repeat(stops, 10, axis=0)
    k = np.repeat([9, 19, 29], 10)
    out = _resolve(world, np.full(H, 1), np.full(H, 4), k)
    assert list(out[[0, 9, 10, 19, 20, 29]]) == [4, 4, 2, 2, 2, 2]


def test_held_positions_take_the_nearest_tracked_frame():
    world = np.zeros((6, 2, 7))
    world[:, 0, 0] = np.arange(6)
    world[:, 1, 0] = -1.0
    ok = np.array([[1, 0], [1, 0], [0, 0], [0, 0], [0, 0], [1, 0]], bool)
    assert list(held_positions(world, ok)[:, 0, 0]) == [0, 1, 1, 1, 5, 5]
    assert np.all(held_positions(world, ok)[:, 1, 0] == -1.0)  # never tracked: kept


def test_a_hover_way_point_does_not_outweigh_the_closest_approach():
    world = _scene()
    H = len(world)
    world[: H // 2, 1, :3] = [0.0, 0.0, 0.2]  # hovers high above the tower (nearer block 3) ...
    world[H // 2 :, 1, :3] = [0.06, 0.0, 0.0]  # ... then is set down beside the base (nearer 2)
    ok = np.ones((H, 5), bool)
    tool, target = np.full(H, 1), np.full(H, 3)
    k = np.r_[np.full(H // 2, 2), np.full(H - H // 2, H - 1)]
    assert np.all(resolve_target_ties(world, ok, tool, target, k, 0.01, 10.0) == 2)


def test_moving_objects_the_tool_and_the_end_effector_are_never_swapped_in():
    world = _scene()
    H = len(world)
    world[:, 0, :3] = world[:, 1, :3]  # the end-effector sits on the tool: nearest of all
    world[:, 3, 0] += np.linspace(0, 0.1, H)  # the upper block slides away: not rigid
    ok = np.ones((H, 5), bool)
    tool = np.r_[np.full(H // 2, 1), np.full(H - H // 2, 0)]
    target = np.full(H, 2)
    k = np.r_[np.full(H // 2, H // 2 - 1), np.full(H - H // 2, H - 1)]
    out = resolve_target_ties(world, ok, tool, target, k, 0.01, 10.0)
    assert set(out) <= {2, 4} and not np.any(out == 3)
    assert np.all(out[: H // 2] == 2)  # the base is nearer the tool than the far block


def _resolve(world: np.ndarray, tool: np.ndarray, target: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Targets resolved with every object tracked, within 1 cm and 10°."""
    return resolve_target_ties(world, np.ones(world.shape[:2], bool), tool, target, k, 0.01, 10.0)


def _two_runs(H: int, first: tuple[int, int], second: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """Tool, target and way-point frame k of two runs, (tool, target) = ``first`` over the
    first H // 2 frames and ``second`` after, each aiming at its own last frame."""
    h = H // 2
    tool = np.r_[np.full(h, first[0]), np.full(H - h, second[0])]
    target = np.r_[np.full(h, first[1]), np.full(H - h, second[1])]
    k = np.r_[np.full(h, h - 1), np.full(H - h, H - 1)]
    return tool, target, k


def _release(H: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The hand (0) carries block 1 beside block 3, lets go, and rises to a pose nearer 3."""
    world = _scene(H)
    h = H // 2
    world[:h, 1, :3] = np.c_[np.linspace(-0.2, 0.05, h), np.zeros(h), np.zeros(h)]
    world[h:, 1, :3] = [0.05, 0.0, 0.0]
    world[:h, 0, :3] = world[:h, 1, :3]
    world[h:, 0, :3] = np.c_[np.full(H - h, 0.05), np.zeros(H - h), np.linspace(0.0, 0.08, H - h)]
    world[:, 3, :3] = [0.02, 0.0, 0.06]  # block 3 nearer the risen hand (3.6 cm) than block 1 (8 cm)
    return (world, *_two_runs(H, (1, 2), (0, 3)))


def test_the_hand_letting_go_keeps_the_block_it_carried_as_its_target():
    world, tool, target, k = _release()
    out = _resolve(world, tool, target, k)
    assert np.all(out[tool == 0] == 1)


def test_a_block_jittering_in_the_hand_was_carried():
    """Under the hand the tracker puts the block 1.2 cm off in a third of the frames."""
    world, tool, target, k = _release()
    world[: len(world) // 2 : 3, 1, 1] += 0.012
    out = _resolve(world, tool, target, k)
    assert np.all(out[tool == 0] == 1)


def test_a_block_that_moved_without_the_hand_was_not_let_go():
    world, tool, target, k = _release()
    world[: len(world) // 2, 0, :3] = [0.3, 0.3, 0.3]  # the hand stayed away: a tracking glitch moved 1
    out = _resolve(world, tool, target, k)
    assert np.all(out[tool == 0] == 3)


def test_a_block_the_hand_only_paused_beside_was_not_let_go():
    world, tool, target, k = _release()
    h = len(world) // 2
    world[:h, 1, :3] = world[:h, 0, :3] = [0.05, 0.0, 0.0]  # both still: kept their places, nothing carried
    out = _resolve(world, tool, target, k)
    assert np.all(out[tool == 0] == 3)


def _lift_then_carry(H: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tool 1 rises from beside block 4 (run 1, labelled relative to 4, the block nearest
    the lifted pose), then is carried onto the tower of 2 and 3 (run 2)."""
    world = _scene(H)
    h = H // 2
    world[:, 4, :3] = [-0.3, 0.0, 0.0]
    world[:h, 1, :3] = np.c_[np.full(h, -0.2), np.zeros(h), np.linspace(0.0, 0.1, h)]
    world[h:, 1, :3] = np.c_[np.linspace(-0.2, 0.0, H - h), np.zeros(H - h), np.linspace(0.1, 0.08, H - h)]
    return (world, *_two_runs(H, (1, 4), (1, 3)))


def test_a_lift_away_from_everything_is_the_first_leg_of_the_carry():
    world, tool, target, k = _lift_then_carry()
    assert np.all(_resolve(world, tool, target, k) == 3)


def test_a_run_that_comes_nearer_its_target_keeps_it():
    """A dip: the tool comes down by block 4 before it is carried on to the tower."""
    world, tool, target, k = _lift_then_carry()
    h = len(world) // 2
    world[:h, 1, :3] = np.c_[np.linspace(-0.1, -0.25, h), np.zeros(h), np.linspace(0.2, 0.05, h)]
    out = _resolve(world, tool, target, k)
    assert np.all(out[:h] == 4) and np.all(out[h:] == 3)


def _retreat(H: int = 30) -> tuple[np.ndarray, ...]:
    """The end-effector seats on nut 2 (run 1), turns it and rises (way-point at frame 19),
    then goes above nut 3 (frame 29); Viterbi labelled the turn, the rise and the approach
    as one run relative to 3. Wheel 1 is 10 cm from nut 2, nut 3 is 20 cm from it."""
    world = np.tile(np.r_[0.0, 0.0, 0.0, IDENTITY], (H, 4, 1))
    world[:, 1, :3] = [0.1, 0.0, 0.0]
    world[:, 3, :3] = [0.2, 0.0, 0.0]
    world[10:, 2, 3:] = Rotation.from_euler("z", np.linspace(0, 50, H - 10)[:, None], degrees=True).as_quat()
    world[:10, 0, :3] = np.c_[np.zeros(10), np.zeros(10), np.linspace(0.1, 0.01, 10)]
    world[10:20, 0, :3] = np.c_[np.zeros(10), np.zeros(10), np.linspace(0.01, 0.1, 10)]
    world[20:, 0, :3] = np.c_[np.linspace(0.0, 0.2, 10), np.zeros(10), np.full(10, 0.05)]
    tool, target = np.zeros(H, int), np.r_[np.full(10, 2), np.full(H - 10, 3)]
    k = np.repeat([9, 19, 29], 10)
    return world, tool, target, k


def test_a_retreat_belongs_to_what_the_tool_was_nearest_when_it_began():
    """The rise moves away from every candidate: it ends the work at the nut, relative to
    the wheel (the nut, turning with the socket, is no candidate); the approach is to 3."""
    world, tool, target, k = _retreat()
    out = _resolve(world, tool, target, k)
    assert list(out[[0, 9, 10, 19, 20, 29]]) == [2, 2, 1, 1, 3, 3]


def test_a_run_after_another_tool_has_no_retreat():
    """The same motion right after a block's run is not the end of the end-effector's work."""
    world, tool, target, k = _retreat()
    tool[:10] = 1
    world[:, 1, :3] = world[:, 0, :3] + [0.0, 0.05, 0.0]  # a block beside the hand, never a candidate
    out = _resolve(world, tool, target, k)
    assert np.all(out[10:] == 3)


def test_a_lift_after_a_dip_of_the_same_tool_belongs_to_the_dip():
    """Tool 1 comes down by block 4 (the dip), rises (a run of its own, labelled relative to
    the tower), then is carried to the tower: the rise is the dip's end, not the carry's start."""
    H = 30
    world = _scene(H)
    world[:, 4, :3] = [-0.3, 0.0, 0.0]
    world[:10, 1, :3] = np.c_[np.full(10, -0.25), np.zeros(10), np.linspace(0.1, 0.02, 10)]
    world[10:20, 1, :3] = np.c_[np.full(10, -0.25), np.zeros(10), np.linspace(0.02, 0.15, 10)]
    world[20:, 1, :3] = np.c_[np.linspace(-0.25, 0.0, 10), np.zeros(10), np.full(10, 0.08)]
    tool, target = np.full(H, 1), np.r_[np.full(10, 4), np.full(10, 3), np.full(10, 3)]
    k = np.repeat([9, 19, 29], 10)
    out = _resolve(world, tool, target, k)
    assert np.all(out[:20] == 4) and np.all(out[20:] == 3)
