"""The three networks of the paper (Section III; sizes of Section V-C) and the retrieval head of L_ret.

* Memory: an LSTM(32) over the history input (labels of o+_{t−1}, o*_{t−1} and w_{t−1});
  its output M(h_t), g_t embedded by FC(64)+ReLU, e_t and the per-label done fractions
  form the context π_h reads.
* π_h: two softmax heads, tool and target (the paper's L_o+ and L_o*). Each scores every
  object with one MLP (two hidden layers of 64) from that object's features (semantic
  label, its height and tilt, the end-effector in its frame, history flags, tracked) and
  the context, so identical objects are interchangeable. The target head also reads the
  tool in the candidate's frame and the tool's label; the end-effector and the tool itself
  are never targets. 20 % of their hidden units are dropped in training (``dropout``): a
  few hundred decisions are otherwise fitted exactly by whatever features tell them apart.
  Of world poses (the objects', e_t) π_h reads only what does not
  change when the whole scene is moved or turned on the table (:func:`upright`): which
  object comes next does not depend on where the layout lies, and with x, y and heading
  the few training episodes were told apart by their layouts (stacking-2: held-out
  decisions fell from iteration 2,000 on, 0.82 → 0.73; closed loop 0.00 → 0.20).
* π_m: the pair's labels and history flags, p_t[o+, o*] and where the tool came from within
  the sub-task (its rise and horizontal distance since the decision before: the one part
  of h_t it reads, see below) → two hidden layers of 64 →
  a mixture of diagonal Gaussians over w_t (7), trained by its negative log-likelihood
  (L_w); the robot takes the mean of the heaviest component. ``modes`` components have
  their means in the target's frame (a place on the target: above it, on it) and as many
  at the tool's current pose plus an offset (a lift, a retreat: a way-point the target's
  frame puts wherever the tool happens to be). Not the paper's mean squared error:
  pseudo-labels give one decision two answers (an approach way-point above a block in
  some episodes, none in others), and a squared error's answer lies between them (closed
  loop: 3.7 cm above the block, between the labels' 0 and 8 cm, too high to grasp).
  Without the anchored components, a lift's way-point had to be copied from p_t through
  the hidden layers and came out centimetres off on held-out layouts. π_m reads the
  history through the flags and where the tool came from, not M(h_t), g_t or e_t: with
  them, the few decision frames it is trained on (~12 per episode) let it recognise the
  training episodes instead of the situation (held-out stacking-1 way-points within
  5 mm: 0.52 with M(h_t) and the done fractions, 0.77 without).
* π_l: the pair's labels, p_t[o+, o*], w_t and the remaining way from one to the other →
  two hidden layers of 64 → a diagonal Gaussian over a_t. Its mean is a per-axis fraction
  of the remaining way, between ``min_fraction`` and 1: the step always heads for w_t,
  vanishes there and never stalls short of it, so the low level is a stable controller in
  closed loop, whatever its small errors. (Without the floor, π_l learnt the demonstrator's
  slow starts as near-zero fractions and, closed loop, stopped 25 mm short of w_t.)
* Retrieval (L_ret): from M(h_t), the labels of o+_{t−1} and o*_{t−1} and w_{t−1}.

Inputs are standardised (:class:`~hsp.policy.normalisation.Normalisation`); π_l's action
is in physical units scaled per axis by the data's spread.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from torch import nn

from hsp.policy.features import CAME_FROM, FLAGS

if TYPE_CHECKING:
    from hsp.policy.normalisation import Normalisation

LOG_STD_RANGE = (-5.0, 2.0)
LOG_SQRT_2PI = 0.9189385332046727


def mlp(d_in: int, d_out: int, hidden: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d_in, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, d_out))


def upright(world: torch.Tensor) -> torch.Tensor:
    """What of world poses ``(..., 7)`` stays when the scene is moved or turned about the
    vertical: the height z and the cosine of the object's tilt (its z axis against the
    world's) ``(..., 2)``."""
    x, y = world[..., 3], world[..., 4]
    return torch.stack([world[..., 2], 1 - 2 * (x * x + y * y)], -1)


UPRIGHT = 2
"""Features of :func:`upright`."""


def gaussian_log_prob(mean: torch.Tensor, log_std: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Diagonal Gaussian log-density, summed over the last axis."""
    z = (x - mean) * torch.exp(-log_std)
    return (-0.5 * z * z - log_std - LOG_SQRT_2PI).sum(-1)


class ObjectScorer(nn.Module):
    """One logit per object from its features ``(..., n, F)`` and a shared context
    ``(..., D)``: an MLP on their concatenation, its first layer split so that the
    context's part is computed once per frame rather than once per object."""

    def __init__(self, d_object: int, d_context: int, hidden: int, dropout: float = 0.0) -> None:
        super().__init__()
        self.object_in = nn.Linear(d_object, hidden)
        self.context_in = nn.Linear(d_context, hidden, bias=False)
        self.rest = nn.Sequential(nn.ReLU(), nn.Dropout(dropout), nn.Linear(hidden, hidden), nn.ReLU(), nn.Dropout(dropout),
                                  nn.Linear(hidden, 1))

    def forward(self, objects: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        return self.rest(self.object_in(objects) + self.context_in(context).unsqueeze(-2))[..., 0]


@dataclass(frozen=True)
class Sizes:
    objects: int
    classes: int
    hidden: int = 64
    memory: int = 32
    min_fraction: float = 0.05
    """Least fraction of the remaining way that π_l's mean step covers."""
    modes: int = 2
    """Components of π_m's mixture in the target's frame, and as many at the tool's pose."""
    dropout: float = 0.0
    """Dropout of π_h's hidden units in training."""

    @property
    def object_features(self) -> int:
        """Label, upright pose, end-effector in the object's frame, flags, tracked."""
        return self.classes + UPRIGHT + 7 + FLAGS + 1

    @property
    def context(self) -> int:
        """e_t (upright), M(h_t), embedded g_t, done fractions (as targets, as tools)."""
        return UPRIGHT + self.memory + self.hidden + 2 * self.classes


class Hierarchy(nn.Module):
    """π_h (with the LSTM memory it reads), π_m and π_l."""

    def __init__(self, sizes: Sizes) -> None:
        super().__init__()
        s = self.sizes = sizes
        C = s.classes
        self.progress = nn.Sequential(nn.Linear(7, s.hidden), nn.ReLU())
        self.memory = nn.LSTM(2 * C + 7, s.memory, batch_first=True)
        self.tool_head = ObjectScorer(s.object_features, s.context, s.hidden, s.dropout)
        self.target_head = ObjectScorer(s.object_features + 7, C + s.context, s.hidden, s.dropout)
        self.intermediate = mlp(2 * C + 7 + 2 * FLAGS + CAME_FROM, 2 * s.modes * 15, s.hidden)
        self.low = mlp(2 * C + 7 + 7 + 6, 12, s.hidden)
        self.retrieve = nn.Linear(s.memory, 2 * C + 7)

    def levels(self) -> dict[str, list[nn.Module]]:
        """The modules of each level; none is shared (π_m and π_l read no memory), so each
        level's checkpoint can be chosen on its own."""
        return {"pi_h": [self.progress, self.memory, self.tool_head, self.target_head, self.retrieve],
                "pi_m": [self.intermediate], "pi_l": [self.low]}

    def remember(self, history: torch.Tensor, state: tuple[torch.Tensor, torch.Tensor] | None = None
                 ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
        """M(h_t) over a batch ``(B, T, 2C + 7)`` → ``(B, T, memory)``, and the LSTM state after it."""
        return self.memory(history, state)

    def context(self, ee: torch.Tensor, memory: torch.Tensor, progress: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
        return torch.cat([ee, memory, self.progress(progress), done], -1)

    def read(self, norm: "Normalisation", codes: torch.Tensor, world: torch.Tensor, ee_in_object: torch.Tensor,
             flags: torch.Tensor, tracked: torch.Tensor, progress: torch.Tensor, done: torch.Tensor,
             memory: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The per-object features ``(..., n, F)`` and the context ``(..., D)`` that π_h
        reads, from raw world poses ``(..., n, 7)`` (of which :func:`upright`), the
        end-effector in each object's frame, history flags ``(..., n, 3)``, tracked
        ``(..., n)`` bool, g_t, done fractions and M(h_t); ``codes`` are the objects'
        one-hot labels ``(n, C)``."""
        mean, std = norm.stats["world.mean"][2], norm.stats["world.std"][2]
        pose = upright(world)
        pose = torch.cat([(pose[..., :1] - mean) / std, pose[..., 1:]], -1)  # the cosine as it is
        context = self.context(pose[..., 0, :], memory, norm("progress", progress), done)
        objects = torch.cat([codes.expand(*world.shape[:-1], -1), pose, norm("ee_in_object", ee_in_object),
                             flags, tracked[..., None].float()], -1)
        return objects, context

    def pi_tool(self, objects: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        """log π_h(o+) over objects ``(..., n)`` from per-object features ``(..., n, F)``."""
        return torch.log_softmax(self.tool_head(objects, context), -1)

    def pi_target(self, objects: torch.Tensor, tool_in_object: torch.Tensor, tool_class: torch.Tensor,
                  context: torch.Tensor, tool: torch.Tensor) -> torch.Tensor:
        """log π_h(o* | o+) over objects ``(..., n)``; the end-effector and ``tool`` get −inf."""
        n = objects.shape[-2]
        logits = self.target_head(torch.cat([objects, tool_in_object], -1), torch.cat([tool_class, context], -1))
        index = torch.arange(n)
        barred = (index == 0) | (index == tool.unsqueeze(-1))
        return torch.log_softmax(logits.masked_fill(barred, float("-inf")), -1)

    def pi_m(self, classes: torch.Tensor, current: torch.Tensor, flags: torch.Tensor, came_from: torch.Tensor,
             anchor: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """π_m's mixture over w_t, standardised: log-weights ``(..., 2K)``, means and log-σ
        ``(..., 2K, 7)`` each; the last K means are offsets from ``anchor``, p_t[o+, o*] in
        w_t's standardised units. ``came_from``: where the tool was at the sub-task's decision
        before (:func:`~hsp.policy.features.came_from`), standardised."""
        out = self.intermediate(torch.cat([classes, current, flags, came_from], -1))
        out = out.unflatten(-1, (2 * self.sizes.modes, 15))
        anchored = (torch.arange(2 * self.sizes.modes) >= self.sizes.modes).float()[:, None]  # (2K, 1)
        mean = out[..., 1:8] + anchored * anchor.unsqueeze(-2)
        return torch.log_softmax(out[..., 0], -1), mean, out[..., 8:].clamp(*LOG_STD_RANGE)

    def pi_l(self, classes: torch.Tensor, current: torch.Tensor, waypoint: torch.Tensor, remaining: torch.Tensor,
             remaining_raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean (physical units, a fraction of ``remaining_raw`` per axis) and log-σ (in the
        action's scaled units) of a_t ``(..., 6)`` each; the other inputs are standardised."""
        out = self.low(torch.cat([classes, current, waypoint, remaining], -1))
        lo = self.sizes.min_fraction
        return (lo + (1 - lo) * torch.sigmoid(out[..., :6])) * remaining_raw, out[..., 6:].clamp(*LOG_STD_RANGE)


def mixture_log_prob(mixture: tuple[torch.Tensor, torch.Tensor, torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """log p(x) under π_m's mixture (log-weights ``(..., K)``, means and log-σ ``(..., K, 7)``)
    of points ``(..., 7)``."""
    log_weight, mean, log_std = mixture
    return torch.logsumexp(log_weight + gaussian_log_prob(mean, log_std, x.unsqueeze(-2)), -1)


def mixture_mode(mixture: tuple[torch.Tensor, torch.Tensor, torch.Tensor]) -> torch.Tensor:
    """The mean of the heaviest component ``(..., 7)``: the way-point the robot goes to."""
    log_weight, mean, _ = mixture
    return mean.gather(-2, log_weight.argmax(-1)[..., None, None].expand(*mean.shape[:-2], 1, mean.shape[-1]))[..., 0, :]
