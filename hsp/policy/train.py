"""Training π_h, π_m and π_l on labels (the M-step of Algorithm 1), with the loss of Section IV-C.

L = L_o+ + L_o* + L_w + L_action + L_mem + L_ret:

* L_o+, L_o*: cross-entropy of the labelled tool, and of the labelled target given the tool
  (of its equivalence set where the poses cannot tell the target from others,
  :mod:`~hsp.labeling.equivalence`: L_o* + L_w is then the set's joint likelihood, so the
  member whose frame explains the way-point best is learnt);
* L_w: −log π_m(w_t), a mixture of Gaussians in standardised units (not the paper's squared
  error: :mod:`~hsp.policy.networks` says why), with p_t[o+, o*] and w_t seen from the turns
  of a symmetric target that put the tool's position, and its heading, in one sector (a
  cube's four sides are one place, a grasp from above one heading: :func:`turned`);
* all three on the decision frames only (the paper sums L_o+ and L_o* over every frame),
  where a sub-task has ended and the next tool, target and way-point are chosen: a
  sub-task runs until its tool comes to rest (:class:`~hsp.policy.stepper.Stepper`), so
  these are the only frames where π_h and π_m are asked (elsewhere, repeating the
  previous choice would be all they learnt);
* L_action: −log π_l(a_t), the action in units of its spread in the data;
* L_mem: ‖M(h_t) − M(h_{t−1})‖₂ where the tool, target and way-point did not change (h_t
  then holds nothing that h_{t−1} did not: the last entry repeats the one before);
* L_ret: cross-entropy of the retrieved labels of o+_{t−1}, o*_{t−1} and the squared error of
  the retrieved w_{t−1} (standardised), from M(h_t).

Terms are means over the frames whose tool and target are tracked (L_action: whose step is
observed). Batches are whole episodes, drawn until they hold ``batch_steps`` frames, so the
LSTM reads every history from its start. Every ``checkpoint_every`` iterations the policy
is validated on the held-out episodes (:func:`validate`, running free among others), and
each level is kept from the checkpoint where it does best there (:func:`level_scores`);
π_m is fitted from several initialisations side by side, the best of them kept the same way.
"""

from __future__ import annotations

import copy
import json
import logging
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from rich.progress import track
from torch import nn
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from hsp.errors import HspError
from hsp.fileio import atomic_path
from hsp.geometry import rotation_angle_deg
from hsp.policy.features import (STEP_FIELDS, Steps, in_view, nearest_round_turn, nearest_symmetric, one_hot,
                                 sector_turns, seen_by_pi_m, turned_about_z, views)
from hsp.policy.networks import Hierarchy, Sizes, gaussian_log_prob, mixture_log_prob
from hsp.policy.normalisation import Normalisation
from hsp.policy.stepper import Stepper, pi_m_waypoint

log = logging.getLogger(__name__)

FORMAT = 8
"""Layout of saved models; older ones are refused with a clear message."""
WAYPOINT_HIT_M = 0.02
"""A way-point agrees with the label when within this (m)."""


@dataclass(frozen=True)
class TrainConfig:
    iterations: int = 8000
    """Gradient steps (paper: 20,000 at a constant 1e-4)."""
    batch_steps: int = 2048
    """Frames per batch (paper: 2,048)."""
    learning_rate: float = 3e-3
    """Adam's first step size (paper: 1e-4, constant), falling to zero along a cosine over the
    iterations: way-points must come out within millimetres (a block is placed within
    5 mm), which a constant step leaves to the batches' noise. At 1e-3 π_m underfit which
    of its components a decision takes (a hover or a place after a lift)."""
    hidden: int = 64
    memory: int = 32
    min_fraction: float = 0.05
    """π_l's mean step covers at least this fraction of the remaining way (per axis)."""
    modes: int = 4
    """Components of π_m's mixture over way-points in the target's frame, and as many at
    the tool's current pose. With two, painting's strokes ended at the centre of the
    strokes' spread (supervised, 50 held-out layouts: 0.26 → 0.46 with four)."""
    pi_m_restarts: int = 3
    """π_m is fitted from this many random initialisations side by side, and the one that
    does best on the held-out episodes is kept (:func:`train`; one without held-out episodes)."""
    dropout: float = 0.2
    """Dropout of π_h's hidden units in training: a few hundred decisions are fitted
    exactly by features that happen to tell them apart (a block's place beside another
    taken for "the target"); stacking-2, supervised, 50 held-out layouts: 0.70 → 0.94."""
    validation_every: int = 5
    """Every this-many-th episode (the 5th, 10th, …) is held out to validate; 0: none."""
    checkpoint_every: int = 1000
    """Iterations between validations on the held-out episodes; each level is kept from the
    checkpoint where it does best there (the last iterate when nothing is held out)."""
    still_m: float = 0.002
    """A tool moving less than this per frame relative to its target (translation plus
    0.05 m × angle) rests; tracking jitter is under 1 mm per frame. In the labels, the next
    sub-task is decided once the tool, having moved, has rested ``settle_frames`` frames
    (:func:`~hsp.policy.features.decisions`) ..."""
    arrive_m: float = 0.002
    """... and running, once the tool has been within this of its way-point, or stopped
    short of it, ``settle_frames`` frames in a row (:class:`~hsp.policy.stepper.Stepper`)."""
    settle_frames: int = 3
    axis_m: float = 0.01
    """Way-points within this of their target's z axis are on it (a place on top, a grasp,
    a lift: a hand's scatter there is 2-3 mm; a place beside a block is a block's width
    out): π_m learns them as seen from the tool, not turned to a side (:func:`turned`)."""


@dataclass
class Policy:
    """The trained hierarchy with what it needs to read new episodes."""

    net: Hierarchy
    norm: Normalisation
    objects: list[str]
    classes: np.ndarray
    """Semantic label index of each object ``(n,)``."""
    n_classes: int
    arrive_m: float = TrainConfig.arrive_m
    still_m: float = TrainConfig.still_m
    settle_frames: int = TrainConfig.settle_frames
    """A sub-task runs until its tool rests at its way-point: :class:`~hsp.policy.stepper.Stepper`."""
    folds: np.ndarray | None = None
    """Per object, its turns about z that leave it unchanged (0: any; None: none known):
    π_m sees each decision from turns of its target (:func:`turned`,
    :func:`~hsp.policy.stepper.pi_m_waypoint`)."""

    def object_folds(self) -> np.ndarray:
        """:attr:`folds`, or 1 (no turn but none) for every object when none is known."""
        return np.ones(len(self.classes), np.int64) if self.folds is None else np.asarray(self.folds)


def batch(episodes: list[Steps], idx: list[int]) -> dict[str, torch.Tensor]:
    """Episodes ``idx`` padded to one length, with a mask of real frames (``frame``)."""
    T = max(len(episodes[i]) for i in idx)
    out: dict[str, torch.Tensor] = {}
    for name in STEP_FIELDS:
        like = getattr(episodes[idx[0]], name)
        padded = np.zeros((len(idx), T, *like.shape[1:]), like.dtype)
        for row, i in enumerate(idx):
            a = getattr(episodes[i], name)
            padded[row, :len(a)] = a
        out[name] = torch.from_numpy(padded)
    out["frame"] = torch.arange(T)[None] < torch.tensor([len(episodes[i]) for i in idx])[:, None]
    return out


def _mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of ``x`` over ``mask`` (entries outside it may be inf or nan)."""
    return torch.where(mask, x, 0.0).sum() / mask.sum().clamp(min=1)


def turned(b: dict[str, torch.Tensor], folds: np.ndarray, axis_m: float) -> dict[str, torch.Tensor]:
    """π_m's inputs p_t[o+, j] and labels p_k[o+, j] of batch ``b`` seen, for each candidate
    target j (``folds`` per object), as π_m is asked at run time
    (:func:`~hsp.policy.features.seen_by_pi_m`, :func:`~hsp.policy.stepper.pi_m_waypoint`):
    positions from the turn of j that puts the tool's position in one sector, orientations
    from the turn that puts its heading there; as ``turned_candidate_current`` and
    ``turned_candidate_waypoint`` beside the rest of ``b``.

    On a round target, a label is first taken at the turn of the target nearest the tool's
    present pose (:func:`~hsp.policy.features.nearest_round_turn`): a hand dips a brush
    into a round bucket at a heading it draws at random, which nothing observed tells and
    a robot need not copy; a turn of a nut 10 cm from a round wheel's axis is kept.

    A label's position farther than ``axis_m`` from j's axis is then taken at its own turn
    into that sector: a cube's four sides are one place, and which of them the demonstrator
    used depends on how the cube's frame was chosen, which nothing observed tells; learnt
    so, the place is the side the tool comes from (a mixture fitted to all four put its
    mean in their middle). A position on the axis is left where the tool's view puts it:
    folding its millimetre scatter into one sector moved its mean 2-3 mm off the axis. The
    heading of a grasp is the hand's own rounded to the cube's symmetry: seen from the turn
    that puts the hand's heading within ±45°, it is one answer, 0° (seen with the position,
    a staircase of what π_m reads, learnt 15-40° off; the fingers missed the faces and the
    block slipped). Last, a label's orientation is taken at the turn of the tool's own
    symmetry nearest the tool's present one (a hand's fingers at 0° and at 180° are one
    grasp)."""
    real = (b["frame"] & b["decision"]).numpy()  # π_m learns at decisions; padding has no poses to turn
    raw = b["candidate_current"].numpy()[real].astype(np.float64)
    current, turns = seen_by_pi_m(raw, folds)  # (D, n, 7)
    waypoint = nearest_round_turn(b["candidate_waypoint"].numpy()[real].astype(np.float64), raw, folds == 0)
    waypoint = in_view(waypoint, turns)
    off_axis = np.linalg.norm(waypoint[..., :2], axis=-1) > axis_m
    waypoint[..., :3] = turned_about_z(waypoint, np.where(off_axis, sector_turns(waypoint, folds), 0.0))[..., :3]
    waypoint = nearest_symmetric(waypoint, current, folds[b["tool"].numpy()[real]][:, None])

    def put(x: torch.Tensor, value: np.ndarray) -> torch.Tensor:
        out = x.numpy().copy()
        out[real] = value
        return torch.from_numpy(out)

    return b | {"turned_candidate_current": put(b["candidate_current"], current),
                "turned_candidate_waypoint": put(b["candidate_waypoint"], waypoint)}


def forward(policy: Policy, b: dict[str, torch.Tensor], at: tuple[torch.Tensor, ...] | None = None
            ) -> dict[str, torch.Tensor]:
    """Every output of the hierarchy on a batch with its labelled history (teacher forcing):
    M(h_t), π_l and the retrieval at every frame ``(B, T, …)``; π_h's inputs and heads at
    frames ``at`` only ``(D, …)`` (every frame when None): π_h is trained and asked where a
    sub-task ends, a few frames in a hundred, and its heads cost most of a step."""
    net, norm = policy.net, policy.norm
    codes = torch.from_numpy(one_hot(np.asarray(policy.classes), policy.n_classes))  # (n, C)
    memory, _ = net.remember(norm.history(b["history"]))
    pick = (lambda x: x) if at is None else (lambda x: x[at])  # noqa: E731
    objects, context = net.read(norm, codes, *map(pick, (b["world"], b["ee_in_object"], b["flags"], b["tracked"],
                                                          b["progress"], b["done"], memory)))
    chosen = pick(b["tool"])
    log_tool = net.pi_tool(objects, context)
    log_target = net.pi_target(objects, norm("tool_in_object", pick(b["tool_in_object"])), codes[chosen], context, chosen)
    tool, target = b["tool"], b["target"]
    pair_classes = torch.cat([codes[tool], codes[target]], -1)
    current = norm("current", b["current"])
    action, log_std = net.pi_l(pair_classes, current, norm("waypoint", b["waypoint"]), norm("remaining", b["remaining"]),
                               b["remaining"])
    return {"memory": memory, "objects": objects, "context": context, "log_tool": log_tool, "log_target": log_target,
            "action": action, "action_log_std": log_std, "retrieved": net.retrieve(memory)}


def candidate_mixtures(policy: Policy, b: dict[str, torch.Tensor], at: tuple[torch.Tensor, ...]
                       ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """π_m's mixture over w_t (standardised) for every object j as the target, from
    p_t[o+, j] and the pair's flags, at frames ``at`` (indices into the batch's frames):
    log-weights ``(D, n, 2K)``, means and log-σ ``(D, n, 2K, 7)``. Uses the batch's turned
    poses where it has them (:func:`turned`). π_m is asked at decisions only, so it is
    computed there, not in :func:`forward`."""
    net, norm = policy.net, policy.norm
    codes = torch.from_numpy(one_hot(np.asarray(policy.classes), policy.n_classes))  # (n, C)
    current = b.get("turned_candidate_current", b["candidate_current"])[at]  # (D, n, 7)
    tool, flags = b["tool"][at], b["flags"][at]  # (D,), (D, n, FLAGS)
    D, n = current.shape[:2]
    pair_classes = torch.cat([codes[tool][:, None].expand(D, n, -1), codes.expand(D, n, -1)], -1)
    tool_flags = flags.gather(1, tool[:, None, None].expand(D, 1, flags.shape[-1])).expand(D, n, -1)
    came_from = norm("came_from", b["came_from"][at])[:, None].expand(D, n, -1)
    return net.pi_m(pair_classes, norm("current", current), torch.cat([tool_flags, flags], -1), came_from,
                    norm("waypoint", current))


def candidate_log_probs(policy: Policy, b: dict[str, torch.Tensor], at: tuple[torch.Tensor, ...]
                        ) -> torch.Tensor:
    """log π_m(p_k[o+, j] | o+, j, p_t[o+, j], flags) for every object j as the target, at
    frames ``at``: ``(D, n)`` (:func:`candidate_mixtures`)."""
    waypoint = b.get("turned_candidate_waypoint", b["candidate_waypoint"])[at]
    return mixture_log_prob(candidate_mixtures(policy, b, at), policy.norm("waypoint", waypoint))


@contextmanager
def pi_m_of(net: Hierarchy, module: nn.Module) -> Iterator[None]:
    """``net`` with ``module`` (shaped as ``net.intermediate``) as its π_m for the duration."""
    kept = net.intermediate
    net.intermediate = module
    try:
        yield
    finally:
        net.intermediate = kept


def losses(policy: Policy, b: dict[str, torch.Tensor], restarts: Sequence[nn.Module] = ()) -> dict[str, torch.Tensor]:
    """The six terms of L on one batch (means over the frames that count). Where the
    target is one of an equivalence set S (targets the poses cannot tell apart), L_o* is
    −log Σ_{j∈S} π(j | o+) and L_o* + L_w is −log Σ_{j∈S} π(j | o+) π_m(p_k[o+, j] | j):
    the member whose frame explains the way-point best takes the set's probability. With
    ``restarts`` (other π_m modules), their L_w summed is a seventh term, with π_h held
    fixed in it (π_h learns from the π_m it runs with)."""
    norm, C = policy.norm, policy.n_classes
    labelled = b["labelled"] & b["frame"]
    decided = labelled & b["decision"]
    at = decided.nonzero(as_tuple=True)
    out = forward(policy, b, at)
    acted = b["acted"] & b["frame"]
    tool_nll = -out["log_tool"].gather(-1, b["tool"][at][:, None])[:, 0]
    scale = norm.stats["action.std"]
    a_nll = -gaussian_log_prob(out["action"] / scale, out["action_log_std"], b["action"] / scale)
    # L_mem: M(h_t) keeps still while the history gains nothing new, i.e. while (o+, o*, w)
    # of the frame before is that of the frame before it (the LSTM's input repeats)
    same = torch.zeros_like(labelled)
    same[:, 1:] = (b["history"][:, 1:] == b["history"][:, :-1]).all(-1) & labelled[:, 1:] & labelled[:, :-1]
    drift = torch.zeros(same.shape)
    drift[:, 1:] = (out["memory"][:, 1:] - out["memory"][:, :-1]).norm(dim=-1)
    # L_ret: from M(h_t), the previous step's tool and target labels and w_{t−1} (the LSTM's last input)
    previous = b["history"]
    r = out["retrieved"]
    has_past = torch.zeros_like(labelled)
    has_past[:, 1:] = labelled[:, :-1] & b["frame"][:, 1:]
    ret = (-(torch.log_softmax(r[..., :C], -1) * previous[..., :C]).sum(-1)
           - (torch.log_softmax(r[..., C:2 * C], -1) * previous[..., C:2 * C]).sum(-1)
           + ((r[..., 2 * C:] - norm("waypoint", previous[..., 2 * C:])) ** 2).mean(-1))
    members = b["equivalent"][at]  # (D, n)
    log_target = out["log_target"]
    set_mass = torch.logsumexp(log_target.masked_fill(~members, float("-inf")), -1)
    joint = _set_joint(policy, b, at, log_target, members)
    D = max(len(members), 1)
    out = {"tool": tool_nll.sum() / D, "target": -set_mass.sum() / D, "waypoint": -(joint - set_mass).sum() / D,
           "action": _mean(a_nll, acted), "memory": _mean(drift, same), "retrieval": _mean(ret, has_past)}
    if restarts:
        fixed, fixed_mass = log_target.detach(), set_mass.detach()
        extra = torch.zeros(())
        for module in restarts:
            with pi_m_of(policy.net, module):
                extra = extra - (_set_joint(policy, b, at, fixed, members) - fixed_mass).sum()
        out["waypoint_restarts"] = extra / D
    return out


def _set_joint(policy: Policy, b: dict[str, torch.Tensor], at: tuple[torch.Tensor, ...], log_target: torch.Tensor,
               members: torch.Tensor) -> torch.Tensor:
    """log Σ_{j∈S} π(j | o+) π_m(p_k[o+, j] | j) at the decisions ``at`` ``(D,)``."""
    return torch.logsumexp((log_target + candidate_log_probs(policy, b, at)).masked_fill(~members, float("-inf")), -1)


def split(n_episodes: int, every: int) -> tuple[list[int], list[int]]:
    """Training and validation episode indices: every ``every``-th episode validates
    (none when ``every`` is 0 or fewer than two episodes would train)."""
    held = [i for i in range(n_episodes) if every > 0 and i % every == every - 1]
    if n_episodes - len(held) < 2:
        held = []
    return [i for i in range(n_episodes) if i not in held], held


def free_run(policy: Policy, episodes: list[Steps]) -> dict[str, np.ndarray]:
    """The hierarchy stepped over recorded episodes on its own history (never the labels):
    per frame, its tool, target and way-point, padded to the longest episode ``(E, T)``.
    It chooses where the recording's sub-tasks end (``Steps.decision``): the demonstrator
    moves the tool there, not the policy, so the stepper's own rule (the tool at rest at
    the policy's way-point) would read every pause of the demonstrator as a new decision."""
    T = max(len(e) for e in episodes)
    pad = lambda x: np.concatenate([x, np.repeat(x[-1:], T - len(x), 0)])  # noqa: E731
    world = np.stack([pad(e.world.astype(np.float64)) for e in episodes])
    tracked = np.stack([pad(e.tracked) for e in episodes])
    ended = np.stack([np.pad(e.decision, (0, T - len(e))) for e in episodes])
    stepper = Stepper(policy, len(episodes))
    tool = np.zeros((len(episodes), T), np.int64)
    target = np.zeros_like(tool)
    waypoint = np.zeros((len(episodes), T, 7), np.float32)
    for t in range(T):
        c = stepper.step(world[:, t], tracked[:, t], ended=ended[:, t])
        tool[:, t], target[:, t], waypoint[:, t] = c.tool, c.target, c.waypoint
    return {"tool": tool, "target": target, "waypoint": waypoint}


def _label_turns(policy: Policy, label: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every turn of way-points ``label`` ``(..., 7)`` by the symmetry of ``target`` ``(...)``
    ``(..., S, 7)``, and which of them are the target's ``(..., S)``."""
    angle, valid = views(policy.object_folds()[target])
    return turned_about_z(np.repeat(label[..., None, :].astype(np.float64), angle.shape[-1], -2), angle), valid


def waypoint_distance(policy: Policy, w: np.ndarray, label: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Distance (m) of way-points ``w`` from the nearest turn of ``label`` (both ``(..., 7)``)
    by the symmetry of ``target`` ``(...)``: the same place on a symmetric target."""
    members, valid = _label_turns(policy, label, target)
    return np.where(valid, np.linalg.norm(members[..., :3] - w[..., None, :3], axis=-1), np.inf).min(-1)


def waypoint_turn(policy: Policy, w: np.ndarray, label: np.ndarray, tool: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Angle (degrees) between the orientations of way-points ``w`` and ``label`` (both
    ``(..., 7)``), the least over the turns of ``target`` ``(...)`` and of ``tool``
    ``(...)`` that leave them unchanged: the same grasp or place of symmetric objects."""
    members, valid = _label_turns(policy, label, target)
    w = np.broadcast_to(w[..., None, :].astype(np.float64), members.shape)
    members = nearest_symmetric(members, w, policy.object_folds()[tool][..., None])
    return np.where(valid, rotation_angle_deg(members[..., 3:], w[..., 3:]), np.inf).min(-1)


def validate(policy: Policy, episodes: list[Steps]) -> dict[str, float]:
    """On ``episodes`` (a target counts as right when it is in the label's equivalence set,
    the way-point then compared with the label's in its frame): π_h's pair accuracy running free over the labelled frames, beside
    repeating the previous label (``copy_previous``); at the labelled decision frames after
    the first, π_h's accuracy with the labelled history (teacher forcing), beside keeping the
    pair (``decision_copy_previous``); the median distance (mm) of π_m's way-point from the
    label, free (over all frames) and teacher-forced (at decisions, and how often it is within
    ``WAYPOINT_HIT_M``: the right component, ``waypoint_hit_teacher_forced``); how often the pair is
    right with its way-point within ``WAYPOINT_HIT_M``, running free over all frames
    (``free_subtask_accuracy``) and at the decisions (``decision_subtask_accuracy``: what
    the robot is asked); and the median distance (mm) of π_l's mean step from the observed
    one. The networks are asked in evaluation mode (no dropout)."""
    was_training = policy.net.training
    policy.net.eval()
    try:
        return _validate(policy, episodes)
    finally:
        policy.net.train(was_training)


def _validate(policy: Policy, episodes: list[Steps]) -> dict[str, float]:
    b = batch(episodes, list(range(len(episodes))))
    first = np.zeros(b["frame"].shape, bool)
    first[:, 0] = True
    decided = _judged_decisions(b)
    at = torch.from_numpy(decided).nonzero(as_tuple=True)
    with torch.no_grad():
        out = forward(policy, b, at)
    _, tf_w_err, tf_w_turn = _pi_m_teacher_forced(policy, b, decided)
    labelled = (b["labelled"] & b["frame"]).numpy()
    acted = (b["acted"] & b["frame"]).numpy()
    tool, target = b["tool"].numpy(), b["target"].numpy()
    members = b["equivalent"].numpy()
    member = lambda j: np.take_along_axis(members, j[..., None], -1)[..., 0]  # noqa: E731
    tf_tool = out["log_tool"].argmax(-1).numpy()  # at the decisions
    tf_target = out["log_target"].argmax(-1).numpy()  # given the labelled tool
    tf_right = (tf_tool == tool[decided]) & np.take_along_axis(members[decided], tf_target[:, None], -1)[:, 0]
    free = free_run(policy, episodes)
    free_pair = (free["tool"] == tool) & member(free["target"])
    free_label = np.take_along_axis(b["candidate_waypoint"].numpy(), free["target"][..., None, None], 2)[:, :, 0]
    free_w_err = np.full(labelled.shape, np.inf)
    free_w_err[labelled] = waypoint_distance(policy, free["waypoint"][labelled], free_label[labelled],
                                             free["target"][labelled])
    copy = np.zeros_like(labelled)
    copy[:, 1:] = (tool[:, 1:] == tool[:, :-1]) & (target[:, 1:] == target[:, :-1])
    a_err = np.linalg.norm((out["action"].numpy() - b["action"].numpy())[..., :3], axis=-1)
    return _pi_m_figures(tf_w_err, tf_w_turn) | {
        "pair_accuracy_free": float(free_pair[labelled].mean()),
        "pair_accuracy_copy_previous": float(copy[labelled & ~first].mean()),
        "decision_accuracy_teacher_forced": float(tf_right.mean()),
        "decision_copy_previous": float(copy[decided].mean()),
        "decision_subtask_accuracy": float((tf_right & (tf_w_err <= WAYPOINT_HIT_M)).mean()),
        "free_subtask_accuracy": float((free_pair & (free_w_err <= WAYPOINT_HIT_M))[labelled].mean()),
        "waypoint_error_mm_free": _mm(free_w_err[labelled & free_pair]),
        "action_error_mm": _mm(a_err[acted]),
    }


def _judged_decisions(b: dict[str, torch.Tensor]) -> np.ndarray:
    """The labelled decisions of batch ``b`` that validation judges: all but each episode's first."""
    decided = (b["labelled"] & b["frame"] & b["decision"]).numpy()
    decided[:, 0] = False
    return decided


def _mm(x: np.ndarray) -> float:
    return float(1000 * np.median(x)) if x.size else float("nan")


def _pi_m_teacher_forced(policy: Policy, b: dict[str, torch.Tensor], decided: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """π_m's way-points at the labelled decisions ``decided`` of batch ``b`` (in their
    order), their distance (m) from the labels and their turn (degrees) from them."""
    at = torch.from_numpy(decided).nonzero(as_tuple=True)
    tool, target = b["tool"][at].numpy(), b["target"][at].numpy()
    with torch.no_grad():
        w = pi_m_waypoint(policy, tool, target, b["candidate_current"][at].numpy()[np.arange(len(target)), target],
                          b["flags"][at].numpy(), b["came_from"][at].numpy())
    label = b["waypoint"].numpy()[decided]
    return w, waypoint_distance(policy, w, label, target), waypoint_turn(policy, w, label, tool, target)


def _pi_m_figures(error: np.ndarray, turn: np.ndarray) -> dict[str, float]:
    return {"waypoint_error_mm_teacher_forced": _mm(error),
            "waypoint_hit_teacher_forced": float((error <= WAYPOINT_HIT_M).mean()) if error.size else float("nan"),
            "waypoint_turn_deg_teacher_forced": float(np.median(turn)) if turn.size else float("nan")}


def pi_m_figures(policy: Policy, episodes: list[Steps]) -> dict[str, float]:
    """The teacher-forced π_m figures of :func:`validate` alone, on ``episodes``."""
    b = batch(episodes, list(range(len(episodes))))
    return _pi_m_figures(*_pi_m_teacher_forced(policy, b, _judged_decisions(b))[1:])


def level_scores(figures: dict[str, float]) -> dict[str, tuple[float, ...]]:
    """How good each level is on held-out episodes, higher better (NaN, nothing to judge,
    is the worst): π_h by its decisions with the labelled history, then running free; π_m
    at the decisions by how often its way-point is within ``WAYPOINT_HIT_M`` of the label
    (the right component: a median does not see a few wrong ones), then the median distance
    and turn; π_l by its steps' distance from the observed."""
    f = figures
    scores = {"pi_h": (f["decision_accuracy_teacher_forced"], f["pair_accuracy_free"]),
              "pi_m": (f["waypoint_hit_teacher_forced"], -f["waypoint_error_mm_teacher_forced"],
                       -f["waypoint_turn_deg_teacher_forced"]),
              "pi_l": (-f["action_error_mm"],)}
    return {level: tuple(float(np.nan_to_num(x, nan=-np.inf)) for x in score) for level, score in scores.items()}


def train(episodes: list[Steps], objects: list[str], classes: np.ndarray, n_classes: int, cfg: TrainConfig,
          seed: int, held_out: list[Steps] | None = None, folds: np.ndarray | None = None
          ) -> tuple[Policy, dict[str, float]]:
    """π_h, π_m, π_l fitted to labelled ``episodes``; with ``held_out`` episodes, each
    level is taken from the checkpoint where it does best on them (:func:`level_scores`),
    π_m also from the best of ``cfg.pi_m_restarts`` initialisations: a mixture fitted from
    one start can settle with a broad component carrying a decision it never learnt to place
    (a block put down 5-10 cm from its place). With
    ``folds`` (each object's turns about z that leave it unchanged), π_m learns every
    decision seen from the turns of its target that put the tool's position and heading
    in one sector (:func:`turned`). Returns
    the policy and a report: the last losses, and where checkpoints were chosen, each
    level's iteration and the validation figures of the policy returned."""
    if not episodes:
        raise HspError("no labelled episodes to train on")
    if cfg.iterations < 1 or cfg.batch_steps < 1 or cfg.checkpoint_every < 1:
        raise HspError(f"train: iterations, batch_steps and checkpoint_every must be ≥ 1, got {cfg.iterations}, "
                       f"{cfg.batch_steps}, {cfg.checkpoint_every}")
    if not 0.0 <= cfg.dropout < 1.0:
        raise HspError(f"train: dropout must be in [0, 1), got {cfg.dropout}")
    if cfg.pi_m_restarts < 1:
        raise HspError(f"train: pi_m_restarts must be ≥ 1, got {cfg.pi_m_restarts}")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = Hierarchy(Sizes(len(objects), n_classes, cfg.hidden, cfg.memory, cfg.min_fraction, cfg.modes, cfg.dropout))
    policy = Policy(net, Normalisation.fit(episodes), objects, np.asarray(classes), n_classes, cfg.arrive_m,
                    cfg.still_m, cfg.settle_frames, None if folds is None else np.asarray(folds))
    restarts = [_reinitialised(net.intermediate) for _ in range(cfg.pi_m_restarts - 1)] if held_out else []
    opt = torch.optim.Adam([*net.parameters(), *(p for m in restarts for p in m.parameters())], lr=cfg.learning_rate)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.iterations)
    lengths = np.array([len(e) for e in episodes])
    report: dict[str, float] = {}
    best: dict[str, tuple[tuple[float, ...], int, list[dict], int]] = {}  # score, iteration, states, restart
    for it in track(range(1, cfg.iterations + 1), description="train π_h, π_m, π_l"):
        order = rng.permutation(len(episodes))
        take = int(np.searchsorted(np.cumsum(lengths[order]), cfg.batch_steps)) + 1
        b = batch(episodes, list(order[:take]))
        parts = losses(policy, b if folds is None else turned(b, np.asarray(folds), cfg.axis_m), restarts)
        loss = sum(parts.values())
        opt.zero_grad()
        loss.backward()
        opt.step()
        schedule.step()
        report = {f"loss_{k}": v.item() for k, v in parts.items()} | {"final_loss": loss.item()}
        if held_out and (it % cfg.checkpoint_every == 0 or it == cfg.iterations):
            figures = validate(policy, held_out)
            others = []
            for module in restarts:
                with pi_m_of(net, module):
                    others.append(figures | pi_m_figures(policy, held_out))
            log.info("iteration %d: held out, π_h's decisions right %.3f (running free, pair %.3f); π_m's way-points "
                     "%.1f mm, %.1f° off, right %s; π_l's steps %.1f mm off", it,
                     figures["decision_accuracy_teacher_forced"], figures["pair_accuracy_free"],
                     figures["waypoint_error_mm_teacher_forced"], figures["waypoint_turn_deg_teacher_forced"],
                     " | ".join(f"{f['waypoint_hit_teacher_forced']:.3f}" for f in [figures, *others]),
                     figures["action_error_mm"])
            candidates = [(level, score, net.levels()[level], 0) for level, score in level_scores(figures).items()]
            candidates += [("pi_m", level_scores(f)["pi_m"], [m], r) for r, (f, m) in enumerate(zip(others, restarts), 1)]
            for level, score, modules, r in candidates:
                if level not in best or score >= best[level][0]:  # among equals, the later (further trained)
                    best[level] = (score, it, [copy.deepcopy(m.state_dict()) for m in modules], r)
    if best:
        for level, (_, kept, states, _) in best.items():
            for module, state in zip(net.levels()[level], states):
                module.load_state_dict(state)
            report[f"checkpoint_iteration_{level}"] = kept
        report["checkpoint_restart_pi_m"] = best["pi_m"][3]
        report |= {f"validation_{k}": v for k, v in validate(policy, held_out).items()}
    net.eval()
    return policy, report


def _reinitialised(module: nn.Module) -> nn.Module:
    """A copy of ``module`` with freshly drawn weights."""
    out = copy.deepcopy(module)
    for layer in out.modules():
        if isinstance(layer, nn.Linear):
            layer.reset_parameters()
    return out


def save(policy: Policy, cfg: TrainConfig, out_dir: Path) -> None:
    """Weights and normalisation (safetensors) and ``config.json``; the directory is
    swapped in whole, so a reader never sees half a model or one from two runs."""
    with atomic_path(Path(out_dir)) as tmp:
        tmp.mkdir()
        tensors = {f"net.{k}": v.contiguous() for k, v in policy.net.state_dict().items()}
        tensors |= {f"norm.{k}": v for k, v in policy.norm.stats.items()}
        save_file(tensors, tmp / "model.safetensors")
        config = {"format": FORMAT, "train": asdict(cfg), "sizes": asdict(policy.net.sizes), "objects": policy.objects,
                  "classes": policy.classes.tolist(), "n_classes": policy.n_classes, "arrive_m": policy.arrive_m, "still_m": policy.still_m,
                  "settle_frames": policy.settle_frames,
                  "folds": None if policy.folds is None else np.asarray(policy.folds).tolist()}
        (tmp / "config.json").write_text(json.dumps(config, indent=2) + "\n")


def load(model_dir: Path) -> Policy:
    """A policy written by :func:`save`; a one-line error naming the directory when it is
    not one, is damaged or was written in another layout."""
    model_dir = Path(model_dir)
    if not (model_dir / "config.json").is_file() or not (model_dir / "model.safetensors").is_file():
        raise HspError(f"{model_dir}: not a trained policy (needs config.json and model.safetensors; run `hsp train`)")
    try:
        config = json.loads((model_dir / "config.json").read_text())
        if config.get("format") != FORMAT:
            raise ValueError(f"model format {config.get('format', 1)}, this hsp reads {FORMAT}")
        tensors = load_file(model_dir / "model.safetensors")
        net = Hierarchy(Sizes(**config["sizes"]))
        net.load_state_dict({k[4:]: v for k, v in tensors.items() if k.startswith("net.")})
        norm = Normalisation({k[5:]: v for k, v in tensors.items() if k.startswith("norm.")})
        return Policy(net.eval(), norm, config["objects"], np.array(config["classes"]), config["n_classes"],
                      config["arrive_m"], config["still_m"], config["settle_frames"],
                      None if config.get("folds") is None else np.asarray(config["folds"]))
    except (SafetensorError, ValueError, KeyError, TypeError, RuntimeError, OSError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise HspError(f"{model_dir}: not a trained policy of this hsp version (retrain with `hsp train`): {first}") from None
