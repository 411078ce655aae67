"""Viterbi scores from the trained networks (the E-step of EM, Algorithm 1).

π_h scores the pairs and π_m the way-points in place of the priors; π_l's term stays the
prior's straight-line step (scoring every candidate way-point with the network would be
P·H² forward passes an episode). The memory and progress inputs come from the labels of
the previous round: the history of a state depends on the path that reached it, which a
Viterbi recursion cannot carry, so the previous labels stand in for it.
"""

from __future__ import annotations

import numpy as np
import torch

from hsp.labeling.label import EpisodeLabels
from hsp.labeling.priors import NEG, PriorConfig, PriorScores, pair_indices
from hsp.policy.features import class_codes, memory_inputs
from hsp.policy.networks import LOG_SQRT_2PI
from hsp.policy.train import Policy


class PolicyScores:
    """:class:`~hsp.labeling.viterbi.Scores` of one episode from a trained :class:`Policy`."""

    def __init__(self, world: np.ndarray, ok: np.ndarray, policy: Policy, labels: EpisodeLabels,
                 cfg: PriorConfig) -> None:
        self.prior = PriorScores(world, ok, cfg)
        self.H, self.P = self.prior.H, self.prior.P
        pairs, norm, net = self.prior.pairs, policy.norm, policy.net
        rel = self.prior.rel.astype(np.float32)  # (H, P, 7)
        pair = pair_indices(pairs, labels.tool, labels.target)
        history, progress = memory_inputs(rel, pair, labels.waypoint.astype(np.float32))
        with torch.no_grad():
            g = norm("progress", torch.from_numpy(progress))
            memory = net.remember(norm.history(torch.from_numpy(history))[None])[0]
            z = norm("z", torch.from_numpy(rel.reshape(self.H, -1)))
            self._unary = net.pi_h(z, memory, g).numpy()  # (H, P)
            codes = torch.from_numpy(class_codes(policy.classes, policy.n_classes, pairs))  # (P, 2C)
            current = norm("current", torch.from_numpy(rel))
            H, P = self.H, self.P
            mean, log_std = net.pi_m(codes.expand(H, P, -1), current, memory[:, None].expand(H, P, -1),
                                     g[:, None].expand(H, P, -1))
            self._mean, self._inv_std = mean.numpy(), torch.exp(-log_std).numpy()  # (H, P, 7)
            self._log_norm = (-log_std.sum(-1) - 7 * LOG_SQRT_2PI).numpy()  # (H, P)
            self._candidates = norm("waypoint", torch.from_numpy(rel)).numpy().transpose(1, 0, 2)  # (P, H, 7)
        self._allowed = self.prior.candidates()

    def unary(self, t: int) -> np.ndarray:
        return self._unary[t]

    def jump(self, t: int) -> np.ndarray:
        """log π_m(w_k | …) of every candidate k ≥ t, minus log(H − t) as in the prior."""
        z = (self._candidates[:, t:] - self._mean[t][:, None]) * self._inv_std[t][:, None]
        logp = self._log_norm[t][:, None] - 0.5 * np.einsum("phd,phd->ph", z, z)
        return np.where(self._allowed[:, t:], logp - np.float32(np.log(self.H - t)), NEG).astype(np.float32)

    def motion(self, t: int) -> np.ndarray:
        return self.prior.motion(t)

