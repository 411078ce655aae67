"""Vectorised SE(3) operations on poses ``(..., 7)`` = ``[x, y, z, qx, qy, qz, qw]``.

Quaternions are scalar-last (PyBullet, SciPy and ROS order). Every function accepts
arbitrary leading batch dimensions and broadcasts them.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

IDENTITY_POSE = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])


def _rot(q_xyzw: np.ndarray) -> Rotation:
    return Rotation.from_quat(np.asarray(q_xyzw, dtype=float).reshape(-1, 4))


def _flat(T: np.ndarray) -> np.ndarray:
    """Poses as a writable ``(N, 7)`` array: scipy's ``Rotation.apply`` rejects read-only
    buffers (datasets read zero-copy, broadcast views)."""
    return np.require(np.asarray(T, float).reshape(-1, 7), requirements="W")


def normalize_quat(q_xyzw: np.ndarray) -> np.ndarray:
    """Unit quaternions with a non-negative scalar part (canonical sign), shape kept."""
    q = np.asarray(q_xyzw, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def compose(T_a_b: np.ndarray, T_b_c: np.ndarray) -> np.ndarray:
    """``T_a_c = T_a_b ∘ T_b_c``; poses ``(..., 7)``, broadcast over leading axes."""
    T_a_b, T_b_c = np.broadcast_arrays(np.asarray(T_a_b, float), np.asarray(T_b_c, float))
    shape = T_a_b.shape
    a, b = _flat(T_a_b), _flat(T_b_c)
    r_ab = _rot(a[:, 3:])
    t = a[:, :3] + r_ab.apply(b[:, :3])
    q = (r_ab * _rot(b[:, 3:])).as_quat()
    return np.concatenate([t, normalize_quat(q)], axis=-1).reshape(shape)


def inverse(T_a_b: np.ndarray) -> np.ndarray:
    """``T_b_a`` from ``T_a_b``; poses ``(..., 7)``."""
    T = np.asarray(T_a_b, float)
    shape = T.shape
    flat = _flat(T)
    r_inv = _rot(flat[:, 3:]).inv()
    t = -r_inv.apply(flat[:, :3])
    return np.concatenate([t, normalize_quat(r_inv.as_quat())], axis=-1).reshape(shape)


def relative(T_world_i: np.ndarray, T_world_j: np.ndarray) -> np.ndarray:
    """Pose of object i in the frame of object j: ``p[i, j] = T_j^-1 ∘ T_i``."""
    return compose(inverse(T_world_j), T_world_i)


def transform_points(T_a_b: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """Points ``(..., 3)`` expressed in frame b mapped to frame a by one pose ``(7,)``
    or by a batch of poses ``(..., 7)`` matching the points' leading axes."""
    T = np.asarray(T_a_b, float)
    P = np.asarray(points_b, float)
    if T.ndim == 1:
        return _rot(T[3:]).apply(P.reshape(-1, 3)).reshape(P.shape) + T[:3]
    shape = np.broadcast_shapes(T.shape[:-1], P.shape[:-1]) + (3,)
    Tb = np.broadcast_to(T, shape[:-1] + (7,)).reshape(-1, 7).copy()
    Pb = np.broadcast_to(P, shape).reshape(-1, 3).copy()
    return (_rot(Tb[:, 3:]).apply(Pb) + Tb[:, :3]).reshape(shape)


def pose_to_matrix(T: np.ndarray) -> np.ndarray:
    """Homogeneous matrices ``(..., 4, 4)`` from poses ``(..., 7)``."""
    T = np.asarray(T, float)
    flat = T.reshape(-1, 7)
    M = np.tile(np.eye(4), (flat.shape[0], 1, 1))
    M[:, :3, :3] = _rot(flat[:, 3:]).as_matrix()
    M[:, :3, 3] = flat[:, :3]
    return M.reshape(T.shape[:-1] + (4, 4))


def pose_from_matrix(M: np.ndarray) -> np.ndarray:
    """Poses ``(..., 7)`` from homogeneous matrices ``(..., 4, 4)``.

    The rotation block is re-orthonormalised by SVD first, so accumulated float32 error
    (PyBullet's view matrices, composed rotations) never leaks into the quaternion.
    """
    M = np.asarray(M, float)
    flat = M.reshape(-1, 4, 4)
    U, _, Vt = np.linalg.svd(flat[:, :3, :3])
    R = U @ Vt
    R[np.linalg.det(R) < 0] = (U @ np.diag([1.0, 1.0, -1.0]) @ Vt)[np.linalg.det(R) < 0]
    q = normalize_quat(Rotation.from_matrix(R).as_quat())
    return np.concatenate([flat[:, :3, 3], q], axis=-1).reshape(M.shape[:-2] + (7,))


def rotvec_delta(T_from: np.ndarray, T_to: np.ndarray) -> np.ndarray:
    """Action between two world poses: translation difference (world frame) and the
    rotation vector of ``R_to R_from^-1`` (world frame); ``(..., 6)``."""
    a, b = np.broadcast_arrays(np.asarray(T_from, float), np.asarray(T_to, float))
    shape = a.shape[:-1]
    a, b = a.reshape(-1, 7), b.reshape(-1, 7)
    rv = (_rot(b[:, 3:]) * _rot(a[:, 3:]).inv()).as_rotvec()
    return np.concatenate([b[:, :3] - a[:, :3], rv], axis=-1).reshape(shape + (6,))


def apply_rotvec_delta(T: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """The inverse of :func:`rotvec_delta`: the pose ``(..., 7)`` reached from ``T (..., 7)``
    by ``delta (..., 6)`` (translation added, rotation vector left-multiplied, world frame)."""
    a, d = np.asarray(T, float), np.asarray(delta, float)
    shape = np.broadcast_shapes(a.shape[:-1], d.shape[:-1])
    a, d = np.broadcast_to(a, shape + (7,)).reshape(-1, 7), np.array(np.broadcast_to(d, shape + (6,))).reshape(-1, 6)
    q = (Rotation.from_rotvec(d[:, 3:]) * _rot(a[:, 3:])).as_quat()
    return np.concatenate([a[:, :3] + d[:, :3], q], axis=-1).reshape(shape + (7,))


def rotation_angle_deg(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Geodesic angle between two rotations (degrees); ``q`` and ``-q`` agree."""
    qa = normalize_quat(q_a)
    qb = normalize_quat(q_b)
    dot = np.clip(np.abs(np.sum(qa * qb, axis=-1)), 0.0, 1.0)
    return np.degrees(2.0 * np.arccos(dot))


def yaw_of(q_xyzw: np.ndarray) -> np.ndarray:
    """Rotation about the world z axis (radians) of the frame's x axis, ``(...,)``."""
    q = np.asarray(q_xyzw, float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Spherical interpolation of two quaternions at fractions ``s (K,)`` → ``(K, 4)``;
    takes the short way."""
    q0 = normalize_quat(q0)
    q1 = normalize_quat(q1)
    if np.dot(q0, q1) < 0:
        q1 = -q1
    rel = (_rot(q1) * _rot(q0).inv()).as_rotvec()[0]
    s = np.atleast_1d(np.asarray(s, float))
    out = Rotation.from_rotvec(s[:, None] * rel[None, :]) * _rot(q0)
    return normalize_quat(out.as_quat())
