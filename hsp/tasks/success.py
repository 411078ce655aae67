"""Success criteria of the paper (Section V-C) as pure functions of pose trajectories.

The same checker judges the scripted demonstrations and, later, the learned policies.
``poses`` are world poses ``(T, n, 7)`` of a task's objects over an episode.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from hsp.geometry import inverse, transform_points
from hsp.geometry.symmetry import symmetry_rotations
from hsp.tasks.registry import Task
from hsp.tasks.spec import PaintingSuccess, StackingSuccess, Symmetry, TireRemovalSuccess


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges ``[s, e)`` of the True runs of a boolean ``(T,)`` array."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def straight_stroke(points: np.ndarray, min_length: float, straightness: float) -> bool:
    """Whether some sub-path of ``points (L, 3)`` has chord ≥ ``min_length`` and
    chord / path length ≥ ``straightness``."""
    if len(points) < 2:
        return False
    path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    chord = np.linalg.norm(points[None, :, :] - points[:, None, :], axis=-1)
    along = path[None, :] - path[:, None]
    ok = (chord >= min_length) & (chord >= straightness * np.maximum(along, 1e-12))
    return bool(np.any(np.triu(ok, 1)))


def painting_progress(tip: np.ndarray, paint: np.ndarray, surface: np.ndarray, spec: PaintingSuccess) -> dict[str, bool]:
    """Sub-goals of painting, each after the one before: brush ``tip (T, 3)`` within
    ``source_radius`` of ``paint (T, 3)`` (``dipped``), later on the plane ``plane_height``
    above ``surface (T, 7)``, the canvas's surface frame (``above_canvas``), then a straight
    stroke of ≥ ``stroke_length`` without leaving the plane (``stroked``)."""
    out = {"dipped": False, "above_canvas": False, "stroked": False}
    dipped = np.flatnonzero(np.linalg.norm(tip - paint, axis=1) <= spec.source_radius)
    if dipped.size == 0:
        return out
    out["dipped"] = True
    local = transform_points(inverse(surface), tip)
    on_plane = np.abs(local[:, 2] - spec.plane_height) <= spec.plane_tolerance
    if spec.surface_half_extent is not None:
        hx, hy = spec.surface_half_extent
        on_plane &= (np.abs(local[:, 0]) <= hx) & (np.abs(local[:, 1]) <= hy)
    on_plane[: dipped[0] + 1] = False
    out["above_canvas"] = bool(on_plane.any())
    out["stroked"] = any(straight_stroke(local[s:e], spec.stroke_length, spec.stroke_straightness) for s, e in _runs(on_plane))
    return out


def painting_success(tip: np.ndarray, paint: np.ndarray, surface: np.ndarray, spec: PaintingSuccess) -> bool:
    """All three sub-goals of :func:`painting_progress`."""
    return all(painting_progress(tip, paint, surface, spec).values())


def stacking_errors(final: np.ndarray, base: int, blocks: list[int], pattern: np.ndarray, symmetry: Symmetry) -> np.ndarray:
    """Distance (m) of each block centre from its place in the pattern, ``(B,)``.

    ``final (n, 7)`` world poses; ``pattern (B, 3)`` places in the base block's frame. The
    base frame is taken up to its symmetry about z (one choice for all blocks).
    """
    R_base = Rotation.from_quat(final[base, 3:]).as_matrix()
    rel = (final[blocks, :3] - final[base, :3]) @ R_base  # (B, 3) in the base frame
    sym = symmetry_rotations(symmetry, resting=True)  # (K, 3, 3)
    rel_k = np.einsum("bi,kij->kbj", rel, sym)  # rel expressed in each symmetric frame
    err = np.linalg.norm(rel_k - pattern[None], axis=-1)  # (K, B)
    return err[np.argmin(err.max(axis=1))]


def turned_angle(q_xyzw: np.ndarray) -> np.ndarray:
    """Signed rotation (rad) about the object's own z axis since frame 0, unwrapped, ``(T,)``."""
    R = Rotation.from_quat(q_xyzw)
    rv = (R[0].inv() * R).as_rotvec()
    return np.unwrap(rv[:, 2])


def tire_removal_progress(tip: np.ndarray, sockets: np.ndarray, bolt_turn: np.ndarray, centre: np.ndarray,
                          spec: TireRemovalSuccess) -> tuple[list[bool], bool]:
    """Which bolts were turned ≥ ``min_rotation_deg`` counter-clockwise while the tool
    point was within ``tolerance`` of their socket, and whether, after all of them, the tool
    point reached the wheel centre.

    ``tip (T, 3)``, ``sockets (T, B, 3)``, ``bolt_turn (T, B)`` rad, ``centre (T, 3)``.
    """
    need = np.radians(spec.min_rotation_deg)
    done_at: list[int | None] = []
    for b in range(sockets.shape[1]):
        near = np.linalg.norm(tip - sockets[:, b], axis=1) <= spec.tolerance
        done = None
        for s, e in _runs(near):
            a = bolt_turn[s:e, b]
            rise = a - np.minimum.accumulate(a)
            hit = np.flatnonzero(rise >= need - 1e-9)
            if hit.size:
                done = s + int(hit[0])
                break
        done_at.append(done)
    turned = [d is not None for d in done_at]
    if not all(turned):
        return turned, False
    at_centre = np.linalg.norm(tip - centre, axis=1) <= spec.tolerance
    return turned, bool(np.any(at_centre[max(d for d in done_at if d is not None) + 1 :]))


def tire_removal_success(tip: np.ndarray, sockets: np.ndarray, bolt_turn: np.ndarray, centre: np.ndarray,
                         spec: TireRemovalSuccess) -> bool:
    """Every bolt turned, then the wheel centre reached (:func:`tire_removal_progress`)."""
    turned, centre_reached = tire_removal_progress(tip, sockets, bolt_turn, centre, spec)
    return all(turned) and centre_reached


def progress(task: Task, poses: np.ndarray, held: int = 0) -> dict[str, bool]:
    """Every sub-goal of the task's criterion on world poses ``(T, n, 7)``: ``dipped``,
    ``above_canvas``, ``stroked`` (painting); ``placed.<block>`` (stacking: judged on the
    last frame, and a block still held by the gripper, object ``held`` > 0, is not placed);
    ``turned.<bolt>`` and ``centre_reached`` (tire removal). The task succeeds when all hold."""
    s = task.spec.success
    kp = lambda name, point: transform_points(poses[:, task.index(name)], task.keypoint(name, point))  # noqa: E731
    if isinstance(s, PaintingSuccess):
        surface = poses[:, task.index(s.surface)].copy()
        surface[:, :3] = kp(s.surface, s.surface_point)
        return painting_progress(kp(s.tool, s.tool_point), kp(s.source, s.source_point), surface, s)
    if isinstance(s, StackingSuccess):
        blocks = [task.index(b) for b in s.pattern]
        base = task.index(s.base)
        err = stacking_errors(poses[-1], base, blocks, np.array(list(s.pattern.values())), task.objects[base].symmetry)
        return {f"placed.{name}": bool(e <= s.tolerance) and i != held for name, i, e in zip(s.pattern, blocks, err)}
    if isinstance(s, TireRemovalSuccess):
        bolts = [task.index(b) for b in s.bolts]
        sockets = np.stack([kp(b, s.bolt_point) for b in s.bolts], axis=1)
        turn = np.stack([turned_angle(poses[:, i, 3:]) for i in bolts], axis=1)
        turned, centre = tire_removal_progress(kp(s.tool, s.tool_point), sockets, turn, kp(s.wheel, s.wheel_point), s)
        return {f"turned.{b}": t for b, t in zip(s.bolts, turned)} | {"centre_reached": centre}
    raise TypeError(f"unknown success kind {type(s).__name__}")


def is_success(task: Task, poses: np.ndarray) -> bool:
    """Apply the task's criterion to world poses ``(T, n, 7)``: every sub-goal of :func:`progress`."""
    return all(progress(task, poses).values())
