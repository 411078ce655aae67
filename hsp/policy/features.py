"""What the three networks see and predict, per frame of one labelled episode (paper, Sections III, IV-C).

The observation z_t = (e_t, semantic labels, p_t) is laid out per object, so that π_h
scores every object with the same weights and identical objects (the four lug nuts) are
interchangeable whatever order the tracker numbered them in. The history h_t enters three
ways, each a function of the past tools, targets and way-points (o+_k, o*_k, w_k)_{k<t}:

* the LSTM reads, per frame, the semantic labels of o+_{t−1} and o*_{t−1} and w_{t−1}
  (labels rather than object indices, for the same interchangeability);
* per object, whether it was the previous tool, the previous target, and whether it was
  the target, or the tool, of a sub-task that has ended (:func:`history_flags`: a block
  already carried is told from one not yet touched);
* per semantic label, the fractions of its objects that were such targets and such tools
  (how many nuts are done).

Poses are ``[x, y, z, qx, qy, qz, qw]`` with canonical orientations of symmetric objects
(as the labels use). Everything here takes arrays and returns arrays; the closed-loop
runner builds the same features from its own choices.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from scipy.spatial.transform import Rotation

from hsp.geometry import compose, rotvec_delta, yaw_of
from hsp.labeling.priors import relative_poses

FLAGS = 4
"""Per-object history flags: previous tool, previous target, target of an ended sub-task,
tool of an ended sub-task."""


@dataclass
class Steps:
    """One episode of ``H`` frames with ``n`` objects and ``C`` semantic labels; float32
    arrays except the indices and masks."""

    world: np.ndarray
    """Every object's world pose ``(H, n, 7)``; object 0 is the end-effector, e_t."""
    ee_in_object: np.ndarray
    """p_t[0, j]: the end-effector in each object's frame ``(H, n, 7)``."""
    tool_in_object: np.ndarray
    """p_t[o+_t, j]: the labelled tool in each object's frame ``(H, n, 7)`` (π_h's target head)."""
    flags: np.ndarray
    """Per-object history flags ``(H, n, FLAGS)`` (:func:`history_flags`)."""
    done: np.ndarray
    """Per semantic label, the fractions of its objects that were targets, and tools, of
    ended sub-tasks ``(H, 2C)``."""
    history: np.ndarray
    """What the LSTM reads at t: labels of o+_{t−1} and o*_{t−1} (one-hot each) and w_{t−1} ``(H, 2C + 7)``."""
    progress: np.ndarray
    """g_t = p_t[o+_{t−1}, o*_{t−1}] − w_{t−1} ``(H, 7)`` (zero at t = 0)."""
    tracked: np.ndarray
    """Whether each object is tracked at t ``(H, n)`` bool."""
    tool: np.ndarray
    """o+_t ``(H,)`` int64."""
    target: np.ndarray
    """o*_t ``(H,)`` int64."""
    current: np.ndarray
    """p_t[o+_t, o*_t]: the tool in the target's frame ``(H, 7)``."""
    waypoint: np.ndarray
    """w_t ``(H, 7)``, in the target's frame."""
    equivalent: np.ndarray
    """The targets o*_t cannot be told apart from ``(H, n)`` bool, o*_t included
    (:mod:`~hsp.labeling.equivalence`)."""
    candidate_current: np.ndarray
    """p_t[o+_t, j] for every object j ``(H, n, 7)``: the tool seen from each candidate target."""
    candidate_waypoint: np.ndarray
    """p_k[o+_t, j] ``(H, n, 7)``: the way-point as each candidate target would put it."""
    came_from: np.ndarray
    """What π_m reads of the sub-task so far ``(H, CAME_FROM)`` (:func:`came_from`): where
    the tool was at the sub-task's decision before this one."""
    remaining: np.ndarray
    """The way from p_t[o+, o*] to w_t, translation and rotation vector in the target's frame ``(H, 6)``."""
    action: np.ndarray
    """a_t: the tool's step t → t+1 in the target's frame, same layout ``(H, 6)`` (zero at the end)."""
    labelled: np.ndarray
    """Frames whose tool and target are tracked ``(H,)`` bool: the only ones the losses use."""
    decision: np.ndarray
    """Decision frames ``(H,)`` bool (:func:`new_choices`): the only frames π_h and π_m are
    trained on, as a sub-task ends only where its tool comes to rest (:func:`decisions`,
    :class:`~hsp.policy.stepper.Stepper`)."""
    acted: np.ndarray
    """Frames whose step to t+1 is observed (both tracked at t and t+1) ``(H,)`` bool."""

    def __len__(self) -> int:
        return len(self.tool)


def one_hot(index: np.ndarray, n: int) -> np.ndarray:
    out = np.zeros(index.shape + (n,), np.float32)
    np.put_along_axis(out, index[..., None], 1.0, axis=-1)
    return out


ARM_M = 0.05
"""A turn by θ counts as the arc ``ARM_M``·θ, about an object's radius, where a rotation
and a translation are compared."""


def remaining_way(current: np.ndarray, waypoint: np.ndarray) -> np.ndarray:
    """The step ``(..., 6)`` that takes pose ``current`` to ``waypoint`` (both in the target's
    frame): translation difference and rotation vector of R_w R_cur⁻¹, as actions are."""
    return rotvec_delta(current, waypoint)


def way_length(step: np.ndarray) -> np.ndarray:
    """Length ``(...)`` of steps ``(..., 6)``: the translation's, plus ``ARM_M`` times the angle."""
    return np.linalg.norm(step[..., :3], axis=-1) + ARM_M * np.linalg.norm(step[..., 3:], axis=-1)


def history_flags(tool: np.ndarray, target: np.ndarray, n: int) -> np.ndarray:
    """Per frame t and object j, from the tools and targets before t ``(H,)`` each: j was
    o+_{t−1}; j was o*_{t−1}; j was the target of a sub-task (a run of one pair) that
    ended before t; j was the tool of one (an object carried or used; the end-effector, the
    tool of most sub-tasks, is not flagged). ``(H, n, FLAGS)`` float32, zero at t = 0."""
    H = len(tool)
    out = np.zeros((H, n, FLAGS), np.float32)
    if H < 2:
        return out
    t = np.arange(1, H)
    out[t, tool[:-1], 0] = 1.0
    out[t, target[:-1], 1] = 1.0
    switch = np.flatnonzero((tool[1:] != tool[:-1]) | (target[1:] != target[:-1])) + 1  # pair at s differs from s−1
    switch = switch[switch + 1 < H]  # the history shows the new pair from t = s + 1 on
    ended = np.zeros((H, n, 2), np.float32)
    ended[switch + 1, target[switch - 1], 0] = 1.0
    ended[switch + 1, tool[switch - 1], 1] = 1.0
    ended[:, 0, 1] = 0.0
    out[:, :, 2:] = np.maximum.accumulate(ended, axis=0)
    return out


CAME_FROM = 3
"""π_m's reading of the sub-task so far: whether it has a decision before this one, and the
tool's rise and horizontal distance since then."""


def moved_since(same: np.ndarray, before: np.ndarray, now: np.ndarray) -> np.ndarray:
    """``(..., CAME_FROM)`` from whether the pair is the one chosen at the decision before
    ``(...)`` and the tool's world positions then and now ``(..., 3)``: that flag, the
    height it has come down by and the horizontal distance it has come (zeros without
    one). Neither changes when the scene is moved or turned on the table."""
    d = np.where(np.asarray(same)[..., None], np.asarray(before) - np.asarray(now), 0.0)
    return np.concatenate([np.asarray(same, np.float32)[..., None], d[..., 2:], np.linalg.norm(d[..., :2], axis=-1,
                                                                                               keepdims=True)], -1)


def came_from(world: np.ndarray, tracked: np.ndarray, tool: np.ndarray, target: np.ndarray,
              decision: np.ndarray) -> np.ndarray:
    """Per frame ``(H, CAME_FROM)``, for π_m, which reads no memory: where the tool of the
    frame's sub-task was at the decision before the one that began its present way-point,
    if that decision chose the same pair (:func:`moved_since`). A brush arrives on the
    plane above the canvas twice, at the start of its stroke and at its end, in the same
    pose: come down from above, it strokes; come along the plane, it lifts (the paper's
    π_m reads h_t for this). ``world`` ``(H, n, 7)``, ``tracked`` ``(H, n)``, the labels
    ``(H,)`` and the decision frames ``(H,)`` bool."""
    d, prev, has = decisions_before(decision)
    same = has & (tool[prev] == tool[d]) & (target[prev] == target[d]) & tracked[prev, tool[d]] & tracked[d, tool[d]]
    return moved_since(same, world[prev, tool[d], :3], world[d, tool[d], :3]).astype(np.float32)


def decisions_before(decision: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame of decision frames ``decision`` ``(H,)`` bool (the first is one): the
    decision that began its way-point, the decision before that, and whether there is one
    ``(H,)`` each."""
    at = np.flatnonzero(decision)
    seg = np.searchsorted(at, np.arange(len(decision)), side="right") - 1
    return at[np.maximum(seg, 0)], at[np.maximum(seg - 1, 0)], seg >= 1


def done_fractions(flags: np.ndarray, classes: np.ndarray, n_classes: int) -> np.ndarray:
    """Per frame and semantic label, the fractions of its objects flagged as targets, then
    as tools, of ended sub-tasks ``(..., 2C)`` from flags ``(..., n, FLAGS)``."""
    members = one_hot(classes, n_classes)  # (n, C)
    share = members / np.maximum(members.sum(0), 1.0)
    return np.concatenate([flags[..., 2] @ share, flags[..., 3] @ share], -1).astype(np.float32)


def memory_input(tool: np.ndarray, target: np.ndarray, waypoint: np.ndarray, classes: np.ndarray,
                 n_classes: int) -> np.ndarray:
    """The LSTM's input at every frame ``(H, 2C + 7)``: labels of the previous tool and
    target, one-hot each, and w_{t−1}; zero at t = 0."""
    H = len(tool)
    out = np.zeros((H, 2 * n_classes + 7), np.float32)
    if H > 1:
        out[1:, :n_classes] = one_hot(classes[tool[:-1]], n_classes)
        out[1:, n_classes:2 * n_classes] = one_hot(classes[target[:-1]], n_classes)
        out[1:, 2 * n_classes:] = waypoint[:-1]
    return out


def new_choices(tool: np.ndarray, target: np.ndarray, waypoint_index: np.ndarray) -> np.ndarray:
    """Frames ``(H,)`` bool where a tool, target and way-point are chosen: the first, and
    every frame whose tool, target or way-point frame k differs from the frame before."""
    out = np.ones(len(tool), bool)
    out[1:] = (tool[1:] != tool[:-1]) | (target[1:] != target[:-1]) | (waypoint_index[1:] != waypoint_index[:-1])
    return out


def decisions(rel: np.ndarray, tool: np.ndarray, target: np.ndarray, waypoint_index: np.ndarray, still_m: float,
              settle_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Labels ``(H,)`` each as a robot acts on them: a sub-task ends where its tool, having
    moved, comes to rest, and the next one is chosen once it has rested ``settle_frames``
    frames, as the :class:`~hsp.policy.stepper.Stepper` decides running (it also ends a
    sub-task where the tool stops short of its way-point, which a demonstrator's rest at
    the labelled way-point is; a segment without such a rest keeps its switch). So the frames
    a demonstrator rested beyond that before moving on go to the next sub-task (tool, target
    and way-point frame k); the frames whose step is the rest are marked ``waiting``.

    Labels put a pause with the motion it ends; a robot that only switched where the
    demonstrator did would wait for a switch that nothing in its observation announces (the
    next motion is what the switch causes). A frame is still when the tool's pose relative
    to the target moved less than ``still_m`` (:func:`way_length`) since the frame before.
    ``rel`` is p_t[i, j] ``(H, n, n, 7)``. Returns, per frame, the frame whose labels it
    takes (``source``), and ``waiting`` (bool)."""
    H = len(tool)
    t = np.arange(H)
    moving = way_length(remaining_way(rel[np.maximum(t - 1, 0), tool, target], rel[t, tool, target])) >= still_m
    source = t.copy()
    waiting = np.zeros(H, bool)
    starts = np.append(np.flatnonzero(new_choices(tool, target, waypoint_index)), H)
    for s0, s in zip(starts[:-2], starts[1:-1]):
        moved = np.flatnonzero(moving[s0 + 1:s])
        if not moved.size:
            continue
        last = s0 + 1 + moved[-1]  # the frame the tool arrived: it moved from last − 1, rests from here
        decide = last + settle_frames
        if last + 1 < s:
            waiting[last:s] = True  # their steps t → t + 1 are the rest
        if decide < s:
            source[decide:s] = s
    return source, waiting


def episode_steps(world: np.ndarray, tracked: np.ndarray, tool: np.ndarray, target: np.ndarray,
                  waypoint_index: np.ndarray, classes: np.ndarray, n_classes: int, still_m: float | None = None,
                  settle_frames: int = 3, equivalent: np.ndarray | None = None) -> Steps:
    """:class:`Steps` of one episode from canonical world poses ``(H, n, 7)``, whether each
    object is tracked ``(H, n)`` and its labels: tool, target and way-point frame k per frame
    ``(H,)`` each (w_t = p_k[o+_t, o*_t]) and the target's equivalence set ``(H, n)`` (only
    the target when not given). With ``still_m``, the labels are first turned into the
    robot's decisions (:func:`decisions`, with ``settle_frames``); the steps of the frames
    spent resting do not count as actions."""
    H, n = world.shape[:2]
    t = np.arange(H)
    rel = relative_poses(world)  # (H, n, n, 7): p_t[i, j]
    if equivalent is None:
        equivalent = np.arange(n) == target[:, None]
    waiting = np.zeros(H, bool)
    if still_m is not None:
        source, waiting = decisions(rel, tool, target, waypoint_index, still_m, settle_frames)
        tool, target, waypoint_index, equivalent = tool[source], target[source], waypoint_index[source], equivalent[source]
    current = rel[t, tool, target]
    waypoint = rel[waypoint_index, tool, target]
    equivalent = (equivalent & tracked & tracked[waypoint_index]) | (np.arange(n) == target[:, None])
    # p_t[o+, j] and p_k[o+, j] for every j of the set; the target's own elsewhere (a lost
    # object's pose is no number to compute with)
    candidate_current = np.where(equivalent[..., None], rel[t, tool], current[:, None])  # (H, n, 7)
    candidate_waypoint = np.where(equivalent[..., None], rel[waypoint_index, tool], waypoint[:, None])
    flags = history_flags(tool, target, n)
    progress = np.zeros((H, 7))
    if H > 1:
        progress[1:] = rel[t[1:], tool[:-1], target[:-1]] - waypoint[:-1]
    action = np.zeros((H, 6))
    labelled = tracked[t, tool] & tracked[t, target]
    acted = np.zeros(H, bool)
    if H > 1:  # the same pair's relative pose one frame on, as the low level would have to command it
        action[:-1] = rotvec_delta(current[:-1], rel[t[1:], tool[:-1], target[:-1]])
        acted[:-1] = labelled[:-1] & tracked[t[1:], tool[:-1]] & tracked[t[1:], target[:-1]] & ~waiting[:-1]
    f32 = np.float32
    decision = new_choices(tool, target, waypoint_index)
    return Steps(
        world=world.astype(f32), ee_in_object=rel[:, 0].astype(f32), tool_in_object=rel[t, tool].astype(f32),
        flags=flags, done=done_fractions(flags, classes, n_classes),
        history=memory_input(tool, target, waypoint, classes, n_classes), progress=progress.astype(f32),
        tracked=tracked.astype(bool), tool=tool.astype(np.int64), target=target.astype(np.int64),
        current=current.astype(f32), waypoint=waypoint.astype(f32), equivalent=equivalent.astype(bool),
        candidate_current=candidate_current.astype(f32), candidate_waypoint=candidate_waypoint.astype(f32),
        came_from=came_from(world, tracked, tool, target, decision),
        remaining=remaining_way(current, waypoint).astype(f32), action=action.astype(f32), labelled=labelled,
        decision=decision, acted=acted)


def turned_about_z(poses: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Poses in a target's frame ``(..., 7)`` as seen from the target turned by ``angle``
    ``(...)`` about its own z axis: for a turn in its symmetry, the same scene."""
    turn = np.zeros(np.shape(angle) + (7,))
    turn[..., 3:] = Rotation.from_euler("z", np.reshape(angle, (-1, 1))).as_quat().reshape(turn.shape[:-1] + (4,))
    return compose(turn, poses)


CONTINUOUS_VIEWS = 8
"""A way-point on a target with a continuous symmetry is compared with its turns by this
many steps of a revolution."""


def _into_sector(angle: np.ndarray, folds: np.ndarray) -> np.ndarray:
    """The turn (rad), among those that leave a target unchanged (``folds`` per entry,
    broadcast against ``angle``; 0: any turn), that brings ``angle`` within ±π/folds of
    zero (a continuous symmetry: onto it)."""
    k = np.broadcast_to(np.asarray(folds), np.shape(angle))
    step = 2 * np.pi / np.maximum(k, 1)
    return np.where(k == 0, -angle, np.where(k == 1, 0.0, -np.round(angle / step) * step))


def sector_turns(poses: np.ndarray, folds: np.ndarray) -> np.ndarray:
    """The turn (rad) about a target's z axis, among those that leave it unchanged
    (``folds`` per entry, broadcast against ``poses``' leading axes; 0: any turn), that
    brings the position of ``poses`` ``(..., 7)`` in its frame into the canonical sector:
    within ±π/folds of the x axis (a continuous symmetry: onto it)."""
    return _into_sector(np.arctan2(poses[..., 1], poses[..., 0]), folds)


def heading_turns(poses: np.ndarray, folds: np.ndarray) -> np.ndarray:
    """As :func:`sector_turns`, for the heading of ``poses`` rather than their position: the
    turn of a target that makes a tool's heading in its frame canonical. A hand above a
    cube, fingers at 30°, is the hand at 120° (a quarter turn of the cube): seen from the
    turn that brings its heading within ±45°, every grasp from above is the same."""
    return _into_sector(yaw_of(poses[..., 3:]), folds)


def seen_by_pi_m(poses: np.ndarray, folds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tool poses in their targets' frames ``(..., 7)`` as π_m reads them and answers: the
    position from the turn of the target that brings it into the canonical sector
    (:func:`sector_turns`: a place beside a cube is one side, the side the tool comes
    from), the orientation from the turn that makes the tool's heading canonical
    (:func:`heading_turns`: a grasp from above is one heading). Returns the view and the
    two turns ``(..., 2)``; :func:`in_view` with the turns negated turns an answer back."""
    turns = np.stack([sector_turns(poses, folds), heading_turns(poses, folds)], -1)
    return in_view(poses, turns), turns


def in_view(poses: np.ndarray, turns: np.ndarray) -> np.ndarray:
    """Poses ``(..., 7)`` in a target's frame with their position turned about its z axis by
    ``turns[..., 0]`` and their orientation by ``turns[..., 1]`` (both turns leave the
    target unchanged, so each part stays what it was)."""
    position = turned_about_z(poses, turns[..., 0])[..., :3]
    return np.concatenate([position, turned_about_z(poses, turns[..., 1])[..., 3:]], -1)


def nearest_symmetric(poses: np.ndarray, reference: np.ndarray, folds: np.ndarray) -> np.ndarray:
    """``poses`` ``(..., 7)`` of an object turned about its own z axis by the turn that
    leaves it unchanged (``folds`` per entry; 0: any) and brings its orientation nearest
    to ``reference``'s ``(..., 7)``: the same pose, reached from ``reference`` by the
    least rotation (a cube put down after a quarter turn in the hand is the same cube),
    its quaternion of the reference's sign."""
    shape = poses.shape
    p, r = poses.reshape(-1, 7), reference.reshape(-1, 7)
    folds = np.broadcast_to(np.asarray(folds), shape[:-1]).reshape(-1)
    out = p.copy()
    ok = (np.linalg.norm(p[:, 3:], axis=1) > 0) & (np.linalg.norm(r[:, 3:], axis=1) > 0)  # a lost pose: as it is
    if ok.any():
        R = Rotation.from_quat(p[ok, 3:])
        D = Rotation.from_quat(r[ok, 3:]).inv().as_matrix() @ R.as_matrix()  # R_ref⁻¹ R: what remains to turn
        best = np.arctan2(D[:, 0, 1] - D[:, 1, 0], D[:, 0, 0] + D[:, 1, 1])  # the turn about z undoing most of it
        turn = -_into_sector(best, folds[ok])  # the allowed turn nearest it
        q = (R * Rotation.from_euler("z", turn[:, None])).as_quat()
        out[ok, 3:] = q * np.where(np.sum(q * r[ok, 3:], -1) < 0, -1.0, 1.0)[:, None]  # the reference's sign
    return out.reshape(shape)


ROUND_TURNS = 360
"""Turns about a round target's axis compared by :func:`nearest_round_turn` (1° apart)."""


def nearest_round_turn(poses: np.ndarray, reference: np.ndarray, round_: np.ndarray) -> np.ndarray:
    """``poses`` ``(..., 7)`` in a round target's frame (``round_`` ``(...)``: a continuous
    symmetry about its z axis; others are left as they are), turned about that axis to the
    member of their orbit nearest ``reference`` ``(..., 7)``, at the length of
    :func:`way_length`: the arc the position sweeps plus ``ARM_M`` times the angle between
    the orientations. A tool dipped into a round bucket at any heading is one dip: on the
    axis, the turn is the one that leaves the orientation nearest the tool's; a place
    farther than ``ARM_M`` from the axis is kept (the turn would move it more than it
    saves: a nut turned on a round wheel stays turned)."""
    phi = 2 * np.pi * np.arange(ROUND_TURNS) / ROUND_TURNS  # (S,)
    ok = np.asarray(round_) & (np.linalg.norm(poses[..., 3:], axis=-1) > 0) \
        & (np.linalg.norm(reference[..., 3:], axis=-1) > 0)  # a lost pose is left as it is
    quat = lambda q: Rotation.from_quat(np.where(ok[..., None], q, [0.0, 0.0, 0.0, 1.0]).reshape(-1, 4))  # noqa: E731
    M = (quat(poses[..., 3:]) * quat(reference[..., 3:]).inv()).as_matrix().reshape(poses.shape[:-1] + (3, 3))
    # tr(R_z(φ) R_w R_ref⁻¹) for every φ, then the angle between R_z(φ) R_w and R_ref
    trace = np.cos(phi) * (M[..., 0, 0] + M[..., 1, 1])[..., None] \
        + np.sin(phi) * (M[..., 0, 1] - M[..., 1, 0])[..., None] + M[..., 2, 2][..., None]
    angle = np.arccos(np.clip((trace - 1) / 2, -1.0, 1.0))
    radius = np.linalg.norm(poses[..., :2], axis=-1)[..., None]
    cost = 2 * radius * np.abs(np.sin(phi / 2)) + ARM_M * angle  # (..., S)
    out = turned_about_z(poses, np.where(ok, phi[np.argmin(cost, -1)], 0.0))
    flip = ok & (np.sum(out[..., 3:] * reference[..., 3:], -1) < 0)  # the reference's sign
    out[..., 3:] *= np.where(flip, -1.0, 1.0)[..., None]
    return np.where(ok[..., None], out, poses)


def views(folds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every turn (rad) that leaves each target unchanged (``folds`` ``(...)``; a continuous
    symmetry every 360°/:data:`CONTINUOUS_VIEWS`) ``(..., S)``, the first none, and whether
    each is one of that target's ``(..., S)``."""
    k = np.where(np.asarray(folds) == 0, CONTINUOUS_VIEWS, np.maximum(folds, 1))
    S = int(k.max(initial=1))
    valid = np.arange(S) < k[..., None]
    return np.where(valid, 2 * np.pi * np.arange(S) / k[..., None], 0.0), valid


STEP_FIELDS = tuple(f.name for f in fields(Steps))

