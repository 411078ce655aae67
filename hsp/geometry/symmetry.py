"""Rotations that map a symmetric object onto itself (the ``symmetry`` of a task object)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

Z_FOLDS = {"none": 1, "z_2fold": 2, "z_4fold": 4, "z_6fold": 6}
CONTINUOUS_STEPS = 360
"""Sampling of a continuous symmetry about z where a finite set is needed."""


def symmetry_axis(symmetry: str) -> np.ndarray | None:
    """The body axis ``(3,)`` a turn about which leaves the object (nearly) unchanged: x for
    a half turn about x (a round handle), z for a symmetry about z; None for none and for a
    cube (three such axes, each a quarter turn: a look-alike, not a drift)."""
    if symmetry == "x_2fold":
        return np.array([1.0, 0.0, 0.0])
    if symmetry == "z_continuous" or (symmetry in Z_FOLDS and symmetry != "none"):
        return np.array([0.0, 0.0, 1.0])
    return None


def without_twist(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Rotations ``q (N, 4)`` with their turn about the body ``axis (3,)`` taken out: the
    swing s of the swing-twist decomposition q = s · t, t a turn about ``axis``."""
    q = np.asarray(q, np.float64)
    t = np.concatenate([(q[:, :3] @ axis)[:, None] * axis, q[:, 3:]], axis=1)
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.where(norm > 1e-12, t / np.maximum(norm, 1e-12), [0.0, 0.0, 0.0, 1.0])  # a half turn about a normal: no twist
    return (Rotation.from_quat(q) * Rotation.from_quat(t).inv()).as_quat()


def z_rotations(k: int) -> np.ndarray:
    """The ``k`` rotations about z by multiples of 2π/k, ``(k, 3, 3)``."""
    return Rotation.from_euler("z", (np.arange(k) * 2 * np.pi / k)[:, None]).as_matrix()


def z_folds(symmetry: str) -> int:
    """How many turns about the body z axis leave the object unchanged: 0 for a continuous
    symmetry, 4 for a cube standing on a face, 1 for none (or a half turn about x)."""
    return {"z_continuous": 0, "cube": 4, **Z_FOLDS}.get(symmetry, 1)


def symmetry_rotations(symmetry: str, resting: bool = False) -> np.ndarray:
    """Rotations ``(K, 3, 3)`` that leave the object unchanged.

    ``resting``: only those about z that keep an object resting on its base (a cube keeps
    4 of its 24; a continuous symmetry is sampled every degree). Otherwise the full finite
    group (24 for a cube); a continuous symmetry has none and raises.
    """
    if symmetry in Z_FOLDS:
        return z_rotations(Z_FOLDS[symmetry])
    if symmetry == "x_2fold":  # a half turn about x turns a resting object upside down
        return np.eye(3)[None] if resting else np.stack([np.eye(3), Rotation.from_rotvec([np.pi, 0, 0]).as_matrix()])
    if symmetry == "cube":
        return z_rotations(4) if resting else Rotation.create_group("O").as_matrix()
    if symmetry == "z_continuous" and resting:
        return z_rotations(CONTINUOUS_STEPS)
    raise ValueError(f"{symmetry!r} has no finite set of symmetry rotations")


def canonical_orientations(q: np.ndarray, symmetry: str) -> np.ndarray:
    """Orientations ``(H, 4)`` of one object over an episode replaced by a symmetric
    equivalent, so that a symmetric object's frame means the same in every recording: for
    ``z_continuous`` the turn about the body z axis is removed in every frame (its heading
    cannot be seen); for a finite group, the equivalent closest to the world axes at the
    first frame is kept for the whole episode (no jumps where two are equally close)."""
    R = Rotation.from_quat(q).as_matrix()
    if symmetry == "z_continuous":  # argmax over θ of trace(R·Rz(θ)), in closed form
        theta = np.arctan2(R[:, 0, 1] - R[:, 1, 0], R[:, 0, 0] + R[:, 1, 1])
        return (Rotation.from_matrix(R) * Rotation.from_euler("z", theta[:, None])).as_quat()
    if symmetry == "none" or len(q) == 0:
        return q
    S = symmetry_rotations(symmetry)
    m = int(np.argmax(np.einsum("ij,mji->m", R[0], S)))  # trace(R_0 · S_m)
    return (Rotation.from_matrix(R) * Rotation.from_matrix(S[m])).as_quat()


def nearest_equivalent(q: np.ndarray, symmetry: str, reference: np.ndarray) -> np.ndarray:
    """Orientations ``q (N, 4)`` each replaced by its symmetric equivalent nearest
    ``reference (N, 4)`` (for ``z_continuous``: the heading removed, as it cannot be seen).
    Fed its own last output as the reference, it follows an object through a tracker's
    switch between look-alike frames (a covered cube re-found resting on another face)."""
    if symmetry == "none" or len(q) == 0:
        return q
    if symmetry == "z_continuous":
        return canonical_orientations(q, symmetry)
    R, S = Rotation.from_quat(q).as_matrix(), symmetry_rotations(symmetry)
    m = np.argmax(np.einsum("nji,njk,mki->nm", Rotation.from_quat(reference).as_matrix(), R, S), axis=1)
    return (Rotation.from_matrix(R) * Rotation.from_matrix(S[m])).as_quat()
