"""Symmetry groups and canonical orientations."""

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry.symmetry import (canonical_orientations, nearest_equivalent, symmetry_axis, symmetry_rotations,
                                   without_twist)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees((Rotation.from_quat(a).inv() * Rotation.from_quat(b)).magnitude())


def test_a_half_turn_about_x_is_the_brush_symmetry():
    S = symmetry_rotations("x_2fold")
    assert len(S) == 2 and np.allclose(S[1] @ [1, 0, 0], [1, 0, 0]) and np.allclose(S[1] @ [0, 0, 1], [0, 0, -1])
    assert len(symmetry_rotations("x_2fold", resting=True)) == 1


def test_a_round_objects_canonical_frame_ignores_its_turn_about_its_axis():
    rng = np.random.default_rng(0)
    tilt = Rotation.from_rotvec(rng.normal(0, 0.1, (50, 3)))
    turned = tilt * Rotation.from_euler("z", rng.uniform(-np.pi, np.pi, (50, 1)))
    a = canonical_orientations(tilt.as_quat(), "z_continuous")
    b = canonical_orientations(turned.as_quat(), "z_continuous")
    assert _angle_deg(a, b).max() < 1e-6
    assert np.allclose(Rotation.from_quat(b).apply([0, 0, 1]), turned.apply([0, 0, 1]))  # same axis


def test_a_cubes_canonical_frame_is_chosen_once_so_it_never_jumps():
    """Yaw drifting from 50 to 40 degrees: the first frame's closest equivalent is -40; it
    stays the same equivalent (-50 at the end), though 40 would be closer there."""
    yaw = np.radians(np.linspace(50.0, 40.0, 11))[:, None]
    c = canonical_orientations(Rotation.from_euler("z", yaw).as_quat(), "cube")
    c_yaw = np.degrees(Rotation.from_quat(c).as_euler("zyx")[:, 0])
    assert np.allclose(c_yaw, np.linspace(-40.0, -50.0, 11))


def test_an_object_without_symmetry_keeps_its_orientation():
    q = Rotation.from_rotvec([[0.3, -0.2, 1.0]]).as_quat()
    assert np.array_equal(canonical_orientations(q, "none"), q)


def test_the_nearest_look_alike_undoes_a_switch_and_keeps_a_real_turn():
    """A cube given lying on its side (a look-alike frame) comes back to the frame nearest
    the reference; a real 30° turn from the reference is kept."""
    ref = Rotation.from_euler("z", 20, degrees=True)
    turned = ref * Rotation.from_euler("z", 30, degrees=True)
    switched = turned * Rotation.from_euler("x", 90, degrees=True)
    out = Rotation.from_quat(nearest_equivalent(switched.as_quat()[None], "cube", ref.as_quat()[None]))
    assert (out[0].inv() * turned).magnitude() < 1e-9
    brush = Rotation.from_euler("y", 80, degrees=True)
    out = Rotation.from_quat(nearest_equivalent((brush * Rotation.from_euler("x", 180, degrees=True)).as_quat()[None],
                                                "x_2fold", brush.as_quat()[None]))
    assert (out[0].inv() * brush).magnitude() < 1e-9


def test_without_twist_keeps_the_swing_and_drops_the_turn_about_the_axis():
    swing, twist = Rotation.from_euler("z", 30, degrees=True), Rotation.from_euler("x", 50, degrees=True)
    q = (swing * twist).as_quat()[None]
    out = Rotation.from_quat(without_twist(q, symmetry_axis("x_2fold")))
    assert (out.inv() * swing).magnitude()[0] < 1e-9
    assert np.allclose(without_twist(twist.as_quat()[None], np.array([1.0, 0, 0])), [[0, 0, 0, 1]], atol=1e-9)
    assert symmetry_axis("cube") is None and symmetry_axis("none") is None
    assert np.allclose(symmetry_axis("z_6fold"), [0, 0, 1])
