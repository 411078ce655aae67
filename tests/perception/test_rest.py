"""Objects at rest: upright, anchored, released, and hidden versus gone."""

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.perception.evidence import seen_through
from hsp.perception.rest import CUBE_AXES, UPRIGHT, RestConfig, RestState, upright

BOX = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (-0.02, 0.02)])
"""Corners of a 4 cm cube around its centre: enough for the lowest point."""


_GRID = np.linspace(-0.02, 0.02, 9)
FACES = np.unique([p for a in _GRID for b in _GRID for c in (-0.02, 0.02)
                   for p in ([a, b, c], [a, c, b], [c, a, b])], axis=0)
"""Samples 5 mm apart on the faces of a 4 cm cube: enough to tell what it stands on."""


def _pose(xyz, rotvec):
    return np.concatenate([xyz, Rotation.from_rotvec(rotvec).as_quat()])


def _heading_deg(q: np.ndarray) -> float:
    """Turn (deg) about z of an upright orientation ``q (4,)``."""
    return float(np.degrees(Rotation.from_quat(q).as_rotvec()[2]))


def test_upright_removes_the_tilt_and_keeps_the_heading():
    q = (Rotation.from_euler("z", 30, degrees=True) * Rotation.from_euler("x", 8, degrees=True)).as_quat()
    q_up, tilt = upright(q, UPRIGHT)
    R = Rotation.from_quat(q_up)
    assert abs(tilt - 8.0) < 1e-6
    assert np.allclose(R.apply([0, 0, 1]), [0, 0, 1], atol=1e-9)
    x = R.apply([1, 0, 0])
    assert abs(np.degrees(np.arctan2(x[1], x[0])) - 30.0) < 0.5


def test_a_cube_stands_on_whichever_face_is_down():
    q = (Rotation.from_euler("x", 90 + 5, degrees=True)).as_quat()  # on its side, 5 degrees off
    q_up, tilt = upright(q, CUBE_AXES)
    assert abs(tilt - 5.0) < 1e-6
    up = Rotation.from_quat(q_up).apply(CUBE_AXES)
    assert np.isclose(up[:, 2].max(), 1.0)


def test_a_still_object_is_anchored_settled_on_the_table_and_released_when_moved():
    cfg = RestConfig(rest_frames=3)
    rest = RestState([None, CUBE_AXES], [BOX, BOX], [0.0, np.pi / 2], cfg)
    rest.start(np.zeros((2, 7)), np.array([True, False]))  # the cube not found at the start
    rng = np.random.default_rng(0)
    hand = _pose([0.3, 0.0, 0.3], [0, 0, 0])
    out = None
    for _ in range(4):  # 3 mm above the table, tilted 4 degrees, jittering by 0.5 mm
        cube = _pose([0.5, 0.1, 0.023] + rng.normal(0, 0.0005, 3), [np.radians(4), 0, 0])
        out = rest.apply(np.stack([hand, cube]), np.array([True, True]))
    assert rest.anchored[1] and not rest.anchored[0]
    assert np.allclose(out[0], hand), "the end-effector never rests"
    assert abs(out[1, 2] - 0.02) < 1e-9, "its lowest point is on the table"
    assert np.isclose(Rotation.from_quat(out[1, 3:]).apply(CUBE_AXES)[:, 2].max(), 1.0)
    held = rest.apply(np.stack([hand, _pose([0.9, 0.9, 0.9], [0, 0, 0])]), np.array([True, False]))
    assert np.allclose(held[1, :3], out[1, :3]), "unseen, it stays where it rests"
    lifted = _pose([0.5, 0.1, 0.05], [0, 0, 0])
    kept = rest.apply(np.stack([hand, lifted]), np.array([True, True]))
    assert rest.anchored[1] and np.allclose(kept[1], out[1]), "3 cm up, 37 cm from the hand: ICP's jump, not a move"
    gripping = _pose([0.5, 0.1, 0.07], [0, 0, 0])  # the hand's box 1 cm above the cube's top
    moved = rest.apply(np.stack([gripping, lifted]), np.array([True, True]))
    assert not rest.anchored[1] and np.allclose(moved[1], lifted), "3 cm up in the hand: it is being moved"


def test_a_far_measurement_releases_only_what_is_touched_or_gone():
    """ICP finding a resting cube 8 mm off is its own noise unless something not anchored
    touches the cube or the frame sees through where the cube rests."""
    hand, cube, block = _pose([0.3, 0.0, 0.3], [0, 0, 0]), _pose([0.5, 0.1, 0.02], [0, 0, 0]), _pose([0.55, 0.1, 0.02], [0, 0, 0])
    jumped, seen = _pose([0.508, 0.1, 0.02], [0, 0, 0]), np.ones(3, bool)

    def state(block_rests: bool) -> RestState:
        rest = RestState([None, CUBE_AXES, CUBE_AXES], [BOX] * 3, [0.0, np.pi / 2, np.pi / 2])
        rest.start(np.stack([hand, cube, block]), np.array([True, True, block_rests]))
        return rest

    rest = state(True)
    hover = _pose([0.5, 0.1, 0.095], [0, 0, 0])  # the hand's box 3.5 cm above the cube's top
    for h in (hand, hover):
        out = rest.apply(np.stack([h, jumped, block]), seen, lambda i, p: 0.0)
        assert rest.anchored[1] and np.allclose(out[1], cube), "an anchored block 1 cm away, the hand 3.5 cm: ICP's jump"
    rest.apply(np.stack([hand, jumped, block]), seen, lambda i, p: 0.6)
    assert not rest.anchored[1], "the frame sees through where it rested: gone (pushed by a hand the tracker lost)"
    rest = state(False)
    rest.apply(np.stack([hand, jumped, block]), seen, lambda i, p: 0.0)
    assert not rest.anchored[1], "a block not at rest 1 cm away (being put down) moved it"


def test_a_fresh_heading_is_flagged_until_settled_on_a_better_estimate():
    cfg = RestConfig(rest_frames=3)
    rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], cfg, mounted=[False, True])
    hand, nut = _pose([0.3, 0.0, 0.3], [0, 0, 0]), _pose([0.5, 0.1, 0.02], [0, 0, 0.1])
    rest.start(np.stack([hand, nut]), np.array([True, True]))
    assert rest.fresh.tolist() == [False, True], "anchored at the start: its heading is ICP's"
    better = _pose([0.501, 0.1, 0.02], [0, 0, 0.15])
    settled = rest.settle(1, better)
    assert not rest.fresh[1] and np.allclose(settled[:2], better[:2]) and np.allclose(settled[3:], better[3:])
    for _ in range(3):  # ICP's own heading, 3 degrees off, barely moves the settled one
        out = rest.apply(np.stack([hand, nut]), np.array([True, True]))
    assert abs(np.degrees((Rotation.from_quat(out[1, 3:]) * Rotation.from_quat(better[3:]).inv()).magnitude())) < 0.5
    rest.apply(np.stack([hand, nut]), np.array([True, False]))  # hidden under the socket, maybe turned
    assert not rest.fresh[1]
    rest.apply(np.stack([hand, nut]), np.array([True, True]))
    assert rest.fresh[1], "seen again after a hidden spell: its heading is to be found again"
    block = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 2], cfg)  # not mounted: cannot turn in place unseen
    block.start(np.stack([hand, nut]), np.array([True, True]))
    block.settle(1, better)
    block.apply(np.stack([hand, nut]), np.array([True, False]))
    block.apply(np.stack([hand, nut]), np.array([True, True]))
    assert not block.fresh[1] and block.edged[1] == 1, "an unmounted block seen again keeps its heading's average"
    rest.apply(np.stack([_pose([0.5, 0.1, 0.08], [0, 0, 0]), _pose([0.5, 0.1, 0.06], [0, 0, 0])]), np.array([True, True]))
    assert not rest.anchored[1] and not rest.fresh[1], "lifted by the hand: released, nothing to settle"


def test_a_settled_heading_is_the_mean_of_the_edges_and_is_looked_for_again():
    """Once the edges have given a resting nut's heading, ICP's (3° off, every frame, as a
    nut's depth points fit) no longer moves it; the edges are asked again every
    ``edge_every`` frames it is seen, and their headings (here 2° each way) are averaged."""
    cfg = RestConfig(rest_frames=3, edge_every=5)
    rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], cfg)
    hand, icp = _pose([0.3, 0.0, 0.3], [0, 0, 0]), _pose([0.5, 0.1, 0.02], [0, 0, np.radians(3)])
    rest.start(np.stack([hand, icp]), np.array([True, True]))
    rest.settle(1, _pose([0.5, 0.1, 0.02], [0, 0, np.radians(2)]))
    due = []
    for t in range(200):
        rest.apply(np.stack([hand, icp]), np.array([True, True]))
        if rest.fresh[1]:
            due.append(t)
            rest.settle(1, _pose([0.5, 0.1, 0.02], [0, 0, np.radians(2 if len(due) % 2 == 0 else -2)]))
    heading = _heading_deg(rest.anchor[1, 3:])
    assert np.diff(due).tolist() == [cfg.edge_every] * (len(due) - 1) and len(due) == 200 // cfg.edge_every
    assert abs(heading) < 0.3, heading


def test_a_mounted_object_turns_but_never_tilts_even_when_released():
    rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], RestConfig(rest_frames=3), mounted=[False, True])
    hand, nut = _pose([0.3, 0.0, 0.3], [0, 0, 0]), _pose([0.5, 0.1, 0.02], [0, 0, 0.2])
    rest.start(np.stack([hand, nut]), np.array([True, True]))
    pulled = _pose([0.5, 0.1, 0.04], [np.radians(60), 0, 0.3])  # ICP drags it 2 cm up, tipped over
    out = rest.apply(np.stack([hand, pulled]), np.array([True, True]))
    assert rest.anchored[1] and np.allclose(out[1], nut), "nothing touches it: held where it rests"
    hand = _pose([0.5, 0.1, 0.07], [0, 0, 0])  # the socket on it
    out = rest.apply(np.stack([hand, pulled]), np.array([True, True]))
    assert not rest.anchored[1], "2 cm away: released"
    assert np.allclose(out[1, :3], pulled[:3]) and np.isclose(Rotation.from_quat(out[1, 3:]).apply([0, 0, 1])[2], 1.0)
    free = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], RestConfig(rest_frames=3))
    free.start(np.stack([hand, nut]), np.array([True, True]))
    assert np.allclose(free.apply(np.stack([hand, pulled]), np.array([True, True]))[1], pulled), "unmounted: as measured"


def test_a_hidden_object_is_told_from_a_gone_one():
    """A camera 1 m above looking down at a cube on the table: a reading nearer than the
    cube hides it; one behind it means the camera sees where the cube would be."""
    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    T_world_cam = np.array([0, 0, 1.0, 1.0, 0, 0, 0])  # optical axis down
    g = np.linspace(-0.02, 0.02, 9)
    top = np.array([[x, y, 0.02] for x in g for y in g])
    normals = np.tile([0.0, 0.0, 1.0], (len(top), 1))
    M = np.eye(4)
    M[:3, 3] = [0, 0, 0.02]
    depth = np.full((480, 640), 1.0, np.float32)  # the table
    assert seen_through(top, normals, M, depth, K, T_world_cam) == 1.0
    depth[:] = 0.90  # a hand 6 cm above the cube's top
    assert seen_through(top, normals, M, depth, K, T_world_cam) == 0.0
    depth[:] = 0.0  # no readings: no evidence that it is hidden
    assert seen_through(top, normals, M, depth, K, T_world_cam) == 1.0


def test_a_hidden_mounted_object_turns_with_the_end_effector_on_its_axis():
    """A socket seated on a nut (its origin 9 mm above the nut's, on its axis) turns 50°
    while the nut is hidden: the nut's heading turns with it; turning off the axis, not."""
    def turned(ee_xy: list[float]) -> float:
        rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], RestConfig(rest_frames=3), mounted=[False, True])
        nut = _pose([0.5, 0.1, 0.02], [0, 0, 0.2])
        rest.start(np.stack([_pose([*ee_xy, 0.029], [0, 0, 0.0]), nut]), np.array([True, True]))
        for k in range(6):
            socket = _pose([*ee_xy, 0.029], [0, 0, np.radians(10.0 * k)])
            out = rest.apply(np.stack([socket, nut]), np.array([True, k == 0]))
        return float(np.degrees(Rotation.from_quat(out[1, 3:]).as_euler("xyz")[2] - 0.2))

    assert np.isclose(turned([0.501, 0.1]), 50.0, atol=1e-6)
    assert np.isclose(turned([0.52, 0.1]), 0.0, atol=1e-6), "2 cm off its axis: the socket is not on it"


def test_a_large_turn_is_taken_only_when_something_touches_the_object():
    """ICP's heading of a resting nut 23° off (a socket 3 cm beside and 5 cm above it hides
    part of it) is noise; the same heading with the socket on the nut is a turn."""
    def heading_after(hand: np.ndarray) -> float:
        rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], RestConfig(rest_frames=3),
                         mounted=[False, True])
        rest.start(np.stack([hand, _pose([0.5, 0.1, 0.02], [0, 0, 0])]), np.array([True, True]))
        out = rest.apply(np.stack([hand, _pose([0.5, 0.1, 0.02], [0, 0, np.radians(23)])]), np.array([True, True]))
        return _heading_deg(out[1, 3:])

    assert abs(heading_after(_pose([0.53, 0.1, 0.11], [0, 0, 0]))) < 1e-6, "the socket 3 cm beside, 5 cm above the top"
    assert np.isclose(heading_after(_pose([0.5, 0.1, 0.06], [0, 0, 0])), 23.0), "the socket on the nut turned it"


def test_an_untouched_heading_is_taken_when_looked_for_again_or_measured_for_long():
    """Nothing near: a mounted nut seen again after a hidden spell takes the heading it is
    seen at; a heading that ``edge_every`` frames in a row measure replaces a wrong anchor."""
    cfg = RestConfig(rest_frames=3, edge_every=5)
    hand, nut = _pose([0.3, 0.0, 0.3], [0, 0, 0]), _pose([0.5, 0.1, 0.02], [0, 0, 0])
    off = _pose([0.5, 0.1, 0.02], [0, 0, 0.4])

    rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], cfg, mounted=[False, True])
    rest.start(np.stack([hand, nut]), np.array([True, True]))
    rest.apply(np.stack([hand, nut]), np.array([True, False]))  # hidden
    assert np.isclose(_heading_deg(rest.apply(np.stack([hand, off]), np.array([True, True]))[1, 3:]), np.degrees(0.4))
    rest = RestState([None, UPRIGHT], [BOX, BOX], [0.0, np.pi / 3], cfg, mounted=[False, True])
    rest.start(np.stack([hand, nut]), np.array([True, True]))
    seen = [_heading_deg(rest.apply(np.stack([hand, off]), np.array([True, True]))[1, 3:])
            for _ in range(cfg.edge_every)]
    assert np.allclose(seen[:-1], 0.0) and np.isclose(seen[-1], np.degrees(0.4)), seen


def test_an_object_held_still_in_the_air_is_not_anchored_one_standing_on_another_is():
    """Still for longer than ``rest_frames`` beside the base block or 12 cm over it, a block is
    held, not at rest: lowered, it is where ICP finds it at once. Put on the base, it rests."""
    rest = RestState([None, CUBE_AXES, CUBE_AXES], [FACES] * 3, [0.0, np.pi / 2, np.pi / 2], RestConfig(rest_frames=3))
    base, seen = _pose([0.5, 0.1, 0.02], [0, 0, 0]), np.ones(3, bool)
    rest.start(np.stack([_pose([0.3, 0.0, 0.3], [0, 0, 0]), base, base]), np.array([True, True, False]))

    def frame(x: float, z: float) -> np.ndarray:  # the block at (x, 0.1, z), the hand's origin 4 cm above it
        hand, block = _pose([x, 0.1, z + 0.04], [0, 0, 0]), _pose([x, 0.1, z], [0, 0, 0])
        return rest.apply(np.stack([hand, base, block]), seen)

    for _ in range(5):
        frame(0.545, 0.05)
    assert not rest.anchored[2], "held still 5 mm beside the base, 3 cm up"
    for _ in range(5):
        frame(0.5, 0.18)
    assert not rest.anchored[2], "held still in the air"
    assert np.isclose(frame(0.5, 0.17)[2, 2], 0.17), "lowered 1 cm: tracked where ICP finds it"
    for _ in range(5):
        out = frame(0.5, 0.0615)  # on the base, ICP 1.5 mm high
    assert rest.anchored[2] and np.isclose(out[2, 2], 0.0615), "standing on the base block"
