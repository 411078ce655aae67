"""The paper's success criteria accept the real thing and reject near misses."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsp.tasks.success import is_success, stacking_errors, straight_stroke

IDQ = np.array([0.0, 0.0, 0.0, 1.0])


def _pose(xyz, q=IDQ):
    return np.concatenate([np.asarray(xyz, float), q])


def _lerp(a, b, n):
    s = np.linspace(0, 1, n)[:, None]
    return (1 - s) * np.asarray(a, float) + s * np.asarray(b, float)


def painting_trajectory(task, dip_offset: float, stroke: float, stroke_first: bool = False) -> np.ndarray:
    """Brush tip: start → paint centre + offset → 10 cm above the canvas → stroke → lift."""
    tip_local = task.keypoint("brush", "tip")
    bucket, canvas = _pose([0.5, 0.25, 0.05]), _pose([0.5, -0.2, 0.006])
    paint = bucket[:3] + task.keypoint("bucket", "paint")
    plane = canvas[:3] + task.keypoint("canvas", "surface") + [0, 0, 0.10]
    dip = [_lerp([0.4, 0.0, 0.3], paint + [dip_offset, 0, 0], 20), _lerp(paint + [dip_offset, 0, 0.15], paint + [0, 0, 0.15], 5)]
    paint_path = [_lerp(plane + [-stroke / 2, 0, 0.05], plane - [stroke / 2, 0, 0], 10),
                  _lerp(plane - [stroke / 2, 0, 0], plane + [stroke / 2, 0, 0], 30),
                  _lerp(plane + [stroke / 2, 0, 0], plane + [stroke / 2, 0, 0.08], 10)]
    tips = np.concatenate(paint_path + dip if stroke_first else dip + paint_path)
    T = len(tips)
    poses = np.zeros((T, 4, 7))
    poses[:, 0] = _pose([0.3, 0, 0.4])
    poses[:, 1] = np.concatenate([tips - tip_local, np.tile(IDQ, (T, 1))], axis=1)
    poses[:, 2], poses[:, 3] = bucket, canvas
    return poses


@pytest.mark.parametrize(
    ("dip", "stroke", "expected"),
    [(0.0, 0.08, True), (0.025, 0.08, True), (0.035, 0.08, False), (0.0, 0.06, True), (0.0, 0.04, False)],
)
def test_painting_criterion(tasks, dip, stroke, expected):
    """Dip within 3 cm of the paint centre, then a ≥ 5 cm stroke 10 cm above the canvas."""
    assert is_success(tasks["painting"], painting_trajectory(tasks["painting"], dip, stroke)) is expected


def test_painting_stroke_before_dip_fails(tasks):
    assert not is_success(tasks["painting"], painting_trajectory(tasks["painting"], 0.0, 0.08, stroke_first=True))


def test_painting_stroke_off_the_plane_fails(tasks):
    poses = painting_trajectory(tasks["painting"], 0.0, 0.08)
    poses[25:, 1, 2] += 0.015  # 1.5 cm above the plane, tolerance is 1 cm
    assert not is_success(tasks["painting"], poses)


def test_straight_stroke_rejects_a_zigzag():
    x = np.linspace(0, 0.08, 41)
    zig = np.stack([x, 0.02 * (np.arange(41) % 2), np.zeros(41)], axis=1)
    assert not straight_stroke(zig, 0.05, 0.9)
    assert straight_stroke(np.stack([x, np.zeros(41), np.zeros(41)], axis=1), 0.05, 0.9)


def stacked(task, base_yaw: float, error: np.ndarray) -> np.ndarray:
    """Final poses with every block at its pattern place plus ``error`` (world frame)."""
    s = task.spec.success
    R = Rotation.from_euler("z", base_yaw)
    poses = np.tile(_pose([0.0, 0.0, 0.3]), (len(task.objects), 1))
    base = _pose([0.55, 0.05, 0.02], R.as_quat())
    poses[task.index(s.base)] = base
    for name, place in s.pattern.items():
        poses[task.index(name)] = _pose(base[:3] + R.apply(place) + error, R.as_quat())
    return poses[None]


@pytest.mark.parametrize("name", ["stacking-1", "stacking-2"])
@pytest.mark.parametrize(("off_mm", "expected"), [(0.0, True), (4.0, True), (6.0, False)])
def test_stacking_criterion(tasks, name, off_mm, expected):
    """Every block centre within 0.5 cm of its place: 6 mm off fails, 4 mm passes."""
    assert is_success(tasks[name], stacked(tasks[name], 0.4, np.array([off_mm / 1000, 0, 0]))) is expected


def test_stacking_pattern_respects_the_base_symmetry(tasks):
    """A cube base's frame is known up to 90° about z: rotating it keeps the pattern met."""
    task = tasks["stacking-2"]
    poses = stacked(task, 0.3, np.zeros(3))
    base = task.index("block_blue")
    poses[0, base, 3:] = Rotation.from_euler("z", 0.3 + np.pi / 2).as_quat()
    assert is_success(task, poses)
    blocks = [task.index(b) for b in task.spec.success.pattern]
    pattern = np.array(list(task.spec.success.pattern.values()))
    assert stacking_errors(poses[0], base, blocks, pattern, "none").max() > 0.05


def tire_trajectory(task, turn_deg: list[float], tip_offset: float = 0.0, centre_first: bool = False) -> np.ndarray:
    """Wrench over each bolt in turn while the bolt turns ``turn_deg``, then to the centre."""
    wheel = _pose([0.55, 0.0, 0.04])
    names = ["bolt_1", "bolt_2", "bolt_3", "bolt_4"]
    frames = []
    yaw = {b: 0.0 for b in names}
    centre = wheel[:3] + task.keypoint("wheel", "centre")

    def frame(tip):
        P = np.zeros((len(task.objects), 7))
        P[0] = _pose(tip)
        P[task.index("wheel")] = wheel
        for b in names:
            P[task.index(b)] = _pose(wheel[:3] + task.objects[task.index(b)].place.xyz, Rotation.from_euler("z", yaw[b]).as_quat())
        return P

    if centre_first:
        frames.append(frame(centre))
    for b, deg in zip(names, turn_deg):
        socket = wheel[:3] + task.objects[task.index(b)].place.xyz + task.keypoint(b, "socket")
        for a in np.linspace(0, np.radians(deg), 15):
            yaw[b] = a
            frames.append(frame(socket + [tip_offset, 0, 0]))
        frames.append(frame(socket + [0, 0, 0.05]))
    if not centre_first:
        frames.append(frame(centre))
    frames.append(frame(centre + [0, 0, 0.15]))
    return np.stack(frames)


@pytest.mark.parametrize(
    ("turns", "offset", "expected"),
    [([45, 45, 45, 45], 0.0, True), ([35, 31, 40, 33], 0.004, True), ([45, 25, 45, 45], 0.0, False),
     ([45, 45, 45, 45], 0.006, False), ([-45, 45, 45, 45], 0.0, False)],
)
def test_tire_removal_criterion(tasks, turns, offset, expected):
    """Each bolt turned ≥ 30° counter-clockwise with the socket within 5 mm, then the centre."""
    assert is_success(tasks["tire-removal"], tire_trajectory(tasks["tire-removal"], turns, offset)) is expected


def test_tire_removal_centre_must_come_last(tasks):
    poses = tire_trajectory(tasks["tire-removal"], [45] * 4, centre_first=True)
    assert not is_success(tasks["tire-removal"], poses)
