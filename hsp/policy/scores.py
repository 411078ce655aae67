"""Viterbi scores from the trained networks (the E-step of EM, Algorithm 1).

π_h scores the pairs, log π(o+) + log π(o* | o+), and π_m the way-points in place of the
priors; π_l's term stays the prior's straight-line step. π_m is trained by squared error
in standardised units, which is the log-density of a unit Gaussian there. The memory and
history inputs come from the labels of the previous round: the history of a state depends
on the path that reached it, which a Viterbi recursion cannot carry, so the previous
labels stand in for it.
"""

from __future__ import annotations

import numpy as np
import torch

from hsp.geometry import relative
from hsp.labeling.label import EpisodeLabels
from hsp.labeling.priors import NEG, PriorConfig, PriorScores
from hsp.policy.features import episode_steps, one_hot
from hsp.policy.networks import LOG_SQRT_2PI
from hsp.policy.train import Policy, batch, forward


class PolicyScores:
    """:class:`~hsp.labeling.viterbi.Scores` of one episode from a trained :class:`Policy`."""

    def __init__(self, world: np.ndarray, ok: np.ndarray, policy: Policy, labels: EpisodeLabels,
                 cfg: PriorConfig) -> None:
        self.prior = PriorScores(world, ok, cfg)
        self.H, self.P = self.prior.H, self.prior.P
        pairs, norm, net = self.prior.pairs, policy.norm, policy.net
        n = world.shape[1]
        steps = episode_steps(world, ok, labels.tool, labels.target, labels.waypoint_index, policy.classes, policy.n_classes)
        b = batch([steps], [0])
        codes = torch.from_numpy(one_hot(np.asarray(policy.classes), policy.n_classes))
        rel = self.prior.rel.astype(np.float32)  # (H, P, 7): p_t[i, j]
        with torch.no_grad():
            out = forward(policy, b)
            objects, context = out["objects"][0], out["context"][0]
            log_tool = out["log_tool"][0].numpy()  # (H, n)
            log_target = np.zeros((self.H, n, n), np.float32)
            for i in range(n):  # π_h(o* | o+ = i)
                tool = torch.full((self.H,), i)
                tool_in = torch.from_numpy(relative(world[:, i:i + 1].repeat(n, 1), world).astype(np.float32))
                log_target[:, i] = net.pi_target(objects, norm("tool_in_object", tool_in), codes[tool], context, tool).numpy()
            self._unary = log_tool[:, pairs[:, 0]] + log_target[:, pairs[:, 0], pairs[:, 1]]  # (H, P)
            flags = b["flags"][0]  # (H, n, 3)
            i, j = torch.from_numpy(pairs[:, 0]), torch.from_numpy(pairs[:, 1])
            pair_classes = torch.cat([codes[i], codes[j]], -1).expand(self.H, -1, -1)
            pair_flags = torch.cat([flags[:, i], flags[:, j]], -1)
            mean = net.pi_m(pair_classes, norm("current", torch.from_numpy(rel)), pair_flags,
                            context[:, None].expand(-1, self.P, -1))
            self._mean = mean.numpy()  # (H, P, 7), standardised
            self._candidates = norm("waypoint", torch.from_numpy(rel)).numpy().transpose(1, 0, 2)  # (P, H, 7)
        self._allowed = self.prior.candidates()

    def unary(self, t: int) -> np.ndarray:
        return self._unary[t]

    def jump(self, t: int) -> np.ndarray:
        """log π_m(w_k | …) of every candidate k ≥ t (unit Gaussian in standardised units),
        minus log(H − t) as in the prior."""
        z = self._candidates[:, t:] - self._mean[t][:, None]
        logp = -0.5 * np.einsum("phd,phd->ph", z, z) - 7 * LOG_SQRT_2PI
        return np.where(self._allowed[:, t:], logp - np.float32(np.log(self.H - t)), NEG).astype(np.float32)

    def motion(self, t: int) -> np.ndarray:
        return self.prior.motion(t)
