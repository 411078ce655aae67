import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hsp.geometry import (
    IDENTITY_POSE,
    apply_rotvec_delta,
    compose,
    inverse,
    pose_from_matrix,
    pose_to_matrix,
    relative,
    rotation_angle_deg,
    rotvec_delta,
    slerp,
    transform_points,
    yaw_of,
)


def random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.concatenate([rng.normal(size=(n, 3)), Rotation.random(n, random_state=rng.integers(1 << 30)).as_quat()], axis=1)


def test_compose_with_inverse_is_identity():
    """T ∘ T⁻¹ = identity for a batch of random poses."""
    T = random_poses(np.random.default_rng(0), 50)
    I = compose(T, inverse(T))
    np.testing.assert_allclose(I[:, :3], 0, atol=1e-12)
    assert np.all(rotation_angle_deg(I[:, 3:], IDENTITY_POSE[3:]) < 1e-5)


def test_compose_matches_matrix_product():
    rng = np.random.default_rng(1)
    a, b = random_poses(rng, 20), random_poses(rng, 20)
    np.testing.assert_allclose(pose_to_matrix(compose(a, b)), pose_to_matrix(a) @ pose_to_matrix(b), atol=1e-12)


def test_relative_pose_recovers_world_pose():
    """p[i, j] = T_j⁻¹ T_i, so T_j ∘ p[i, j] = T_i."""
    rng = np.random.default_rng(2)
    Ti, Tj = random_poses(rng, 10), random_poses(rng, 10)
    back = compose(Tj, relative(Ti, Tj))
    np.testing.assert_allclose(back[:, :3], Ti[:, :3], atol=1e-12)
    assert np.all(rotation_angle_deg(back[:, 3:], Ti[:, 3:]) < 1e-5)


def test_read_only_and_broadcast_poses_are_accepted():
    """Datasets come back read-only (zero-copy) and tie-breaking broadcasts one object's
    poses; scipy's Rotation.apply rejects both buffers as they are."""
    rng = np.random.default_rng(3)
    Ti, Tj = random_poses(rng, 6), random_poses(rng, 1)
    Ti.setflags(write=False)
    expected = relative(Ti.copy(), np.repeat(Tj, 6, axis=0))
    np.testing.assert_allclose(relative(Ti, np.broadcast_to(Tj, Ti.shape)), expected, atol=1e-12)
    np.testing.assert_allclose(compose(inverse(Ti), Ti)[:, :3], 0, atol=1e-12)


def test_q_and_minus_q_are_the_same_rotation():
    q = Rotation.random(random_state=3).as_quat()
    assert rotation_angle_deg(q, -q) == pytest.approx(0.0, abs=1e-5)
    T = np.concatenate([[1, 2, 3], q])
    T_neg = np.concatenate([[1, 2, 3], -q])
    np.testing.assert_allclose(transform_points(T, np.ones(3)), transform_points(T_neg, np.ones(3)), atol=1e-12)


def test_pose_from_matrix_reorthonormalises_drifted_rotation():
    """A float32-drifted rotation block still gives a unit quaternion of the nearest rotation."""
    M = pose_to_matrix(random_poses(np.random.default_rng(4), 1))[0]
    noisy = M.copy()
    noisy[:3, :3] += np.random.default_rng(5).normal(scale=1e-3, size=(3, 3))
    T = pose_from_matrix(noisy)
    assert np.linalg.norm(T[3:]) == pytest.approx(1.0)
    assert rotation_angle_deg(T[3:], pose_from_matrix(M)[3:]) < 0.2


def test_rotvec_delta_of_known_motion():
    a = np.array([0, 0, 0, 0, 0, 0, 1.0])
    b = np.concatenate([[0.1, -0.2, 0.3], Rotation.from_rotvec([0, 0, 0.5]).as_quat()])
    np.testing.assert_allclose(rotvec_delta(a, b), [0.1, -0.2, 0.3, 0, 0, 0.5], atol=1e-12)


def test_apply_rotvec_delta_inverts_rotvec_delta_batched():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 5, 7))
    a[:, 3:] /= np.linalg.norm(a[:, 3:], axis=1, keepdims=True)
    b[:, 3:] /= np.linalg.norm(b[:, 3:], axis=1, keepdims=True)
    got = apply_rotvec_delta(a, rotvec_delta(a, b))
    np.testing.assert_allclose(got[:, :3], b[:, :3], atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(got[:, 3:] * b[:, 3:], axis=1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(apply_rotvec_delta(a[0], rotvec_delta(a[0], b[0])), got[0], atol=1e-12)


def test_yaw_and_slerp():
    q0 = Rotation.from_euler("z", 0.2).as_quat()
    q1 = Rotation.from_euler("z", 1.0).as_quat()
    mid = slerp(q0, q1, np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(yaw_of(mid), [0.2, 0.6, 1.0], atol=1e-9)


def test_transform_points_batched_matches_loop():
    rng = np.random.default_rng(6)
    T = random_poses(rng, 7)
    P = rng.normal(size=(7, 3))
    expected = np.stack([transform_points(T[i], P[i]) for i in range(7)])
    np.testing.assert_allclose(transform_points(T, P), expected, atol=1e-12)
