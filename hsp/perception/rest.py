"""Objects at rest: a physical prior for the tracker.

An object that has stopped moving on its support (the table or another object; still in
the air, it is held) stands upright (one of its resting axes points straight up), stays
where it came to rest, and, on the table, touches it. ICP on a
few noisy points of a small or half-hidden object leaves its tilt and its slide along a
flat face loosely constrained; at rest neither can change, so the anchor (the running mean
of ICP's positions and headings since the object stopped) replaces them. An anchored object
is released when ICP finds it more than ``release_m`` away and either something not
anchored (the end-effector, an object moving or not yet at rest) touches it, or the depth
image sees through where it rests (it has gone: pushed by a hand the tracker has lost,
fallen from a tower). Otherwise the jump is ICP's, and the frame's measurement is ignored:
one frame's noise threw a base block 6 mm and 12° while the hand was 25 cm away, and the
block then put on the released, wandering base came to rest 6 mm off. Likewise a heading
more than ``turn_deg`` off is a turn only when something touches the object (or the object's
heading is looked for again, or ``edge_every`` frames in a row agree on it): a wrench's socket
3 cm beside a nut and 5 cm above it made ICP's heading jump 23°, and the socket, seated in the
nut's frame, then turned the nut by 25° of the plan's 48°.

Anchoring is also what lets the tracker hold an object that another one covers (a nut
under the socket): it is still where it came to rest, as long as the depth image does not
see through where it would be (:func:`~hsp.perception.evidence.seen_through`). A mounted object (a nut on its stud)
hidden under the end-effector, whose origin sits on its axis, turns with it: a socket
turning on a nut turns the nut. Held still instead, a hex nut turned by 57° under the socket
reads as unturned (its heading is seen modulo 60° once the socket lifts), and labels put the
turn relative to a nut that never turned. Its heading is looked for afresh once it is seen
again; any other object keeps the average it had (a base block half hidden while a block
was put beside it restarted on one look 4.4° off, and the next block landed 5.8 mm off).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from hsp.geometry import transform_points


CUBE_AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
UPRIGHT = np.array([[0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class RestConfig:
    still_m: float = 0.003
    """Radius (m) of the ball an object must stay in to count as still (tracking noise on
    a small nut reaches 2 mm)."""
    rest_frames: int = 10
    """Frames an object must stay still to be anchored (longer than a hand's pause with a
    held block, 0.1–0.5 s at 15 frames/s)."""
    release_m: float = 0.01
    """ICP's distance (m) from the anchor beyond which the object is moving again (a block
    covered by another can pull ICP 5 mm up off its bottom face)..."""
    release_xy_m: float = 0.005
    """... or its horizontal distance (a bucket the brush knocks)."""
    turn_deg: float = 20.0
    """A heading this far from the anchor's is a turn (a nut turned by the wrench), not noise,
    when something touches the object, when its heading is looked for again, or when
    ``edge_every`` frames in a row measure it (:meth:`RestState._refine`)."""
    average_frames: int = 30
    """Anchors average the last this many measurements or so (a running mean, then an EMA)."""
    edge_every: int = 15
    """A resting heading is looked for on the image edges when it starts and again every this
    many frames it is seen; the edges' headings are averaged, and ICP's no longer count (a
    nut's depth points fit best 2–5° off; one frame's edges sit 1–3° off, each way)."""
    refine_m: float = 0.003
    """Only measurements this close to the anchor's height refine it; horizontally, all that
    do not release it do."""
    max_tilt_deg: float = 30.0
    """An object tilted further from every resting axis when it stops is not resting on it
    (it leans on something); once anchored, ICP's tilt is noise."""
    table_contact_m: float = 0.01
    """A resting object whose lowest point is this close to the table, or to another object's
    surface under its centre (horizontally as close), stands on it; still elsewhere, it is held
    and not anchored."""
    touch_m: float = 0.03
    """Surfaces this close count as touching, for a release or a turn (the hand's tracked
    pose is 1–2 cm off at worst)."""
    max_seen_through: float = 0.2
    """Largest share of an anchored object's projected surface where depth readings lie
    behind it, for it to count as still there (hidden, or measured far by ICP's noise) rather
    than gone: a socket's wall hugs a nut within millimetres, so what is in front cannot be
    told from what is on it; at a spurious jump 0.00–0.05 are seen through."""


def upright(q: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, float]:
    """Orientation ``q (4,)`` turned by the smallest rotation that points the nearest of the
    body ``axes (A, 3)`` straight up, and the tilt (deg) it removed."""
    R = Rotation.from_quat(q)
    up = R.apply(axes)  # (A, 3) in the world
    a = up[np.argmax(up[:, 2])]
    tilt = float(np.degrees(np.arccos(np.clip(a[2], -1.0, 1.0))))
    axis = np.cross(a, [0.0, 0.0, 1.0])
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return R.as_quat(), tilt
    return (Rotation.from_rotvec(axis / s * np.radians(tilt)) * R).as_quat(), tilt


def _heading_change(q: np.ndarray, q_anchor: np.ndarray, period: float) -> float | None:
    """Turn (rad) about the world's vertical from ``q_anchor`` to ``q``, both upright,
    wrapped to the symmetry ``period`` (0: continuous, no heading); None when a different
    body axis is up (a cube put down on another face)."""
    R = Rotation.from_quat(q).as_matrix() @ Rotation.from_quat(q_anchor).as_matrix().T
    if R[2, 2] < np.cos(np.pi / 4):
        return None
    if period == 0.0:
        return 0.0
    turn = np.arctan2(R[1, 0], R[0, 0])
    return float((turn + period / 2) % period - period / 2)


@dataclass
class RestState:
    """Per object: its resting axes (``None``: never rests, as the end-effector), how long it
    has been still, and its anchor (position and upright orientation) while at rest."""

    axes: list[np.ndarray | None]
    lowest: list[np.ndarray]
    """Model surface samples, to find the lowest point of an upright pose and what touches it."""
    periods: list[float]
    """Symmetry period (rad) of each object's heading about its up axis; 0 for none at all."""
    cfg: RestConfig = field(default_factory=RestConfig)
    mounted: list[bool] = field(default_factory=list)
    """Objects on a revolute joint about their own z (a lug nut on its stud): they turn, but
    never tilt, so they stay upright even while ICP moves them; none when empty."""

    def __post_init__(self) -> None:
        n = len(self.axes)
        self.mounted = list(self.mounted) or [False] * n
        self.still = np.zeros(n, int)
        self.anchored = np.zeros(n, bool)
        self.anchor = np.zeros((n, 7))
        self.still_at = np.zeros((n, 3))
        self._count = np.zeros(n, int)  # measurements in the position average
        self._turns = np.zeros(n, int)  # and in the heading average, restarted after a mounted object's hidden spell
        self.edged = np.zeros(n, int)
        """Edge headings averaged in each anchor's heading (then ICP's no longer count), 0 at its start."""
        self._seen = np.zeros(n, int)  # frames seen since anchored
        self._off = np.zeros(n, int)  # frames in a row whose heading is more than turn_deg off, untouched
        self._ee: np.ndarray | None = None  # the end-effector's pose at the last frame
        self._top = np.array([float(np.max(x[:, 2])) if len(x) else 0.0 for x in self.lowest])
        self.fresh = np.zeros(n, bool)
        """Anchors whose heading has just started (anchored, turned, a mounted one seen again
        after a hidden spell) and that have not been :meth:`settle`-d on a better estimate since."""

    def start(self, poses: np.ndarray, found: np.ndarray) -> None:
        """Anchor the objects found at the start that can rest (the layout rests them)."""
        self.still_at = poses[:, :3].copy()
        for i in np.flatnonzero(found):
            axes = self.axes[i]
            if axes is not None:
                self._anchor(i, poses[i, :3], upright(poses[i, 3:], axes)[0])

    def _anchor(self, i: int, x: np.ndarray, q_up: np.ndarray) -> None:
        self.anchored[i], self._count[i], self._turns[i], self.edged[i], self.fresh[i] = True, 1, 1, 0, True
        self._seen[i] = self._off[i] = 0
        self.anchor[i] = np.concatenate([x, q_up])

    def settle(self, i: int, pose: np.ndarray) -> np.ndarray:
        """Average a better estimate than ICP's of anchor ``i``'s horizontal position and heading
        (:mod:`hsp.perception.edges`) into it: the first replaces ICP's, weighted as a full
        average; later ones are averaged with it. The settled pose."""
        a = self.anchor[i]
        turn = _heading_change(pose[3:], a[3:], self.periods[i]) if self.edged[i] else None
        if turn is None:
            a[:2], a[3:], self.edged[i] = pose[:2], pose[3:], 1
        else:
            self.edged[i] = min(self.edged[i] + 1, self.cfg.average_frames)
            a[:2] += (pose[:2] - a[:2]) / self.edged[i]
            a[3:] = (Rotation.from_rotvec([0.0, 0.0, turn / self.edged[i]]) * Rotation.from_quat(a[3:])).as_quat()
        self._count[i], self._turns[i], self.fresh[i] = self.cfg.average_frames, self.cfg.average_frames, False
        return self._settled(i)

    def _settled(self, i: int) -> np.ndarray:
        """The anchored pose, on the table when its lowest point is near it."""
        out = self.anchor[i].copy()
        low = out[2] + float(np.min(Rotation.from_quat(out[3:]).apply(self.lowest[i])[:, 2]))
        if abs(low) < self.cfg.table_contact_m:
            out[2] -= low
        return out

    def _refine(self, i: int, poses: np.ndarray, q_up: np.ndarray) -> bool:
        """Average object ``i``'s measurement in ``poses (n, 7)`` into its anchor; False when it
        shows the object moving. A heading more than ``turn_deg`` off is a turn (a new heading)
        when something touches the object, when its heading is being looked for again (a
        mounted object after a hidden spell), or when ``edge_every`` frames in a row say so
        (the anchor's heading was wrong); otherwise that measurement's heading is ICP's noise
        and ignored (its position still counts)."""
        a, pose = self.anchor[i], poses[i]
        if np.linalg.norm(pose[:3] - a[:3]) > self.cfg.release_m or np.linalg.norm(pose[:2] - a[:2]) > self.cfg.release_xy_m:
            return False
        turn = _heading_change(q_up, a[3:], self.periods[i])
        self._count[i] = min(self._count[i] + 1, self.cfg.average_frames)
        step = (pose[:3] - a[:3]) / self._count[i]
        if abs(pose[2] - a[2]) > self.cfg.refine_m:
            step[2] = 0.0  # pulled up by a block put on top of it
        a[:3] += step
        if turn is None or abs(turn) > np.radians(self.cfg.turn_deg):
            self._off[i] += 1
            if self._turns[i] == 0 or self._off[i] >= self.cfg.edge_every or self._touched(i, poses):
                a[3:], self._turns[i], self.edged[i], self.fresh[i], self._off[i] = q_up, 1, 0, True, 0  # turned
            return True
        self._off[i] = 0
        self._seen[i] += 1
        self.fresh[i] |= (self._turns[i] == 0) | (self._seen[i] % self.cfg.edge_every == 0)  # seen again, or due
        self._turns[i] = min(self._turns[i] + 1, self.cfg.average_frames)
        if not self.edged[i]:
            a[3:] = (Rotation.from_rotvec([0.0, 0.0, turn / self._turns[i]]) * Rotation.from_quat(a[3:])).as_quat()
        return True

    def apply(self, poses: np.ndarray, measured: np.ndarray,
              seen_through: Callable[[int, np.ndarray], float] | None = None) -> np.ndarray:
        """One frame: the tracked ``poses (n, 7)`` with anchored objects settled;
        ``measured (n,)`` says which objects ICP saw this frame; ``seen_through(i, pose)`` is
        the frame's share of object ``i``'s surface at ``pose`` that the depth sees past (none:
        never gone). Anchors are refined by the mean of the measurements near them and
        released when one is far and the object is touched or gone."""
        out = poses.copy()
        for i, axes in enumerate(self.axes):
            if axes is None:
                continue
            q_up, tilt = upright(poses[i, 3:], axes)
            if self.mounted[i]:
                out[i, 3:] = q_up  # released or not, a mounted object only turns about its axis
            far = self.anchored[i] and measured[i] and not self._refine(i, poses, q_up)  # else refined by it
            if far and (self._touched(i, poses) or self._gone(i, seen_through)):
                self.anchored[i], self.fresh[i], self.still[i], self.still_at[i] = False, False, 0, poses[i, :3]
                continue
            if self.anchored[i]:
                if not measured[i] and self.mounted[i]:  # hidden, maybe turned in place (a nut under the socket)
                    self._turns[i], self.edged[i] = 0, 0  # heading to find again
                    if self._on_axis(i, poses[0]):
                        self._turn_with_end_effector(i, poses[0])
                out[i] = self._settled(i)
                continue
            if not measured[i] or np.linalg.norm(poses[i, :3] - self.still_at[i]) > self.cfg.still_m:
                self.still[i], self.still_at[i] = 0, poses[i, :3]
            self.still[i] += measured[i]
            rests = self.still[i] >= self.cfg.rest_frames and tilt <= self.cfg.max_tilt_deg
            if rests and self._supported(i, poses, q_up):
                self._anchor(i, poses[i, :3], q_up)
                out[i] = self._settled(i)
        self._ee = poses[0].copy()
        return out

    def _touched(self, i: int, poses: np.ndarray) -> bool:
        """Whether something not anchored (the end-effector, an object moving or not yet at
        rest) at ``poses (n, 7)`` comes within ``touch_m`` of anchored object ``i``'s resting surface."""
        here = transform_points(self._settled(i), self.lowest[i])
        return any(np.isfinite(cKDTree(transform_points(poses[j], self.lowest[j])).query(
            here, distance_upper_bound=self.cfg.touch_m)[0]).any() for j in np.flatnonzero(~self.anchored) if j != i)

    def _supported(self, i: int, poses: np.ndarray, q_up: np.ndarray) -> bool:
        """Whether object ``i``, upright at its tracked position in ``poses (n, 7)``, stands on
        something: its lowest point within ``table_contact_m`` of the table, or of the surface
        of an object that can rest (not the end-effector) under its centre; a mounted object
        always does. One still elsewhere (in the air, beside a block) is held, not at rest."""
        if self.mounted[i]:
            return True
        points = transform_points(np.concatenate([poses[i, :3], q_up]), self.lowest[i])
        low, centre = points[:, 2].min(), points[:, :2].mean(axis=0)
        if low < self.cfg.table_contact_m:
            return True
        others = [transform_points(poses[j], self.lowest[j])
                  for j, axes in enumerate(self.axes) if j != i and axes is not None]
        if not others:
            return False
        below = np.concatenate(others)
        return bool(((np.linalg.norm(below[:, :2] - centre, axis=1) < self.cfg.table_contact_m)
                     & (np.abs(below[:, 2] - low) < self.cfg.table_contact_m)).any())

    def _gone(self, i: int, seen_through: Callable[[int, np.ndarray], float] | None) -> bool:
        """Whether the frame sees through where anchored object ``i`` rests."""
        return seen_through is not None and seen_through(i, self._settled(i)) > self.cfg.max_seen_through

    def _on_axis(self, i: int, ee: np.ndarray) -> bool:
        """Whether the end-effector's origin sits on anchored object ``i``'s vertical axis
        (within ``release_xy_m``), no higher than ``release_m`` above its top."""
        offset = ee[:3] - self.anchor[i, :3]
        return bool(np.linalg.norm(offset[:2]) <= self.cfg.release_xy_m
                    and 0.0 <= offset[2] <= self._top[i] + self.cfg.release_m)

    def _turn_with_end_effector(self, i: int, ee: np.ndarray) -> None:
        """Turn anchor ``i`` about the vertical by the end-effector's turn since the last frame
        (none when it tipped by more than 45° in one frame: no turn about the vertical)."""
        turn = None if self._ee is None else _heading_change(ee[3:], self._ee[3:], 2 * np.pi)
        if turn is not None:
            self.anchor[i, 3:] = (Rotation.from_rotvec([0.0, 0.0, turn]) * Rotation.from_quat(self.anchor[i, 3:])).as_quat()
