"""Viterbi scores from the trained networks (the E-step of EM, Algorithm 1).

π_h scores the pairs, log π(o+) + log π(o* | o+), and π_m the way-points in place of the
priors (π_m's mixture density of each candidate); π_l's term stays the prior's
straight-line step. π_h chooses only where a sub-task ends
(:class:`~hsp.policy.stepper.Stepper`), and so does π_m: their scores count at the
previous round's decision frames only; elsewhere π_h's are uniform (the transition's γ
keeps the pair) and the way-points' are the prior's (on another scale: π_m's density in
standardised units can exceed the prior's, which pulls way-points toward the previous
decisions; EM as Algorithm 1 is not finished). The memory and history inputs come from
the labels of the previous round: the history of a state depends on the path that
reached it, which a Viterbi recursion cannot carry, so the previous labels stand in for
it.
"""

from __future__ import annotations

import numpy as np
import torch

from hsp.geometry import relative
from hsp.labeling.label import EpisodeLabels
from hsp.labeling.priors import NEG, PriorConfig, PriorScores
from hsp.policy.features import decisions_before, episode_steps, moved_since, one_hot
from hsp.policy.networks import mixture_log_prob
from hsp.policy.train import Policy, batch, forward


class PolicyScores:
    """:class:`~hsp.labeling.viterbi.Scores` of one episode from a trained :class:`Policy`."""

    def __init__(self, world: np.ndarray, ok: np.ndarray, policy: Policy, labels: EpisodeLabels,
                 cfg: PriorConfig) -> None:
        self.prior = PriorScores(world, ok, cfg)
        self.H, self.P = self.prior.H, self.prior.P
        pairs, norm, net = self.prior.pairs, policy.norm, policy.net
        n = world.shape[1]
        steps = episode_steps(world, ok, labels.tool, labels.target, labels.waypoint_index, policy.classes, policy.n_classes,
                              policy.still_m, policy.settle_frames)
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
            pair_scores = log_tool[:, pairs[:, 0]] + log_target[:, pairs[:, 0], pairs[:, 1]]  # (H, P)
            self._unary = np.where(steps.decision[:, None], pair_scores, np.float32(-np.log(self.P)))
            self._decision = steps.decision
            flags = b["flags"][0]  # (H, n, FLAGS)
            i, j = torch.from_numpy(pairs[:, 0]), torch.from_numpy(pairs[:, 1])
            pair_classes = torch.cat([codes[i], codes[j]], -1).expand(self.H, -1, -1)
            pair_flags = torch.cat([flags[:, i], flags[:, j]], -1)
            d, prev, has = decisions_before(steps.decision)  # each pair as if chosen at the previous round's decisions
            same = has[:, None] & (steps.tool[prev, None] == pairs[:, 0]) & (steps.target[prev, None] == pairs[:, 1])
            came = moved_since(same, world[prev][:, pairs[:, 0], :3], world[d][:, pairs[:, 0], :3]).astype(np.float32)
            self._mixture = net.pi_m(pair_classes, norm("current", torch.from_numpy(rel)), pair_flags,
                                     norm("came_from", torch.from_numpy(came)),
                                     norm("waypoint", torch.from_numpy(rel)))  # (H, P, 2K) and (H, P, 2K, 7)
            self._candidates = norm("waypoint", torch.from_numpy(rel)).transpose(0, 1)  # (P, H, 7), standardised
        self._allowed = self.prior.candidates()

    def unary(self, t: int) -> np.ndarray:
        return self._unary[t]

    def jump(self, t: int) -> np.ndarray:
        """log π_m(w_k | …) of every candidate k ≥ t (its mixture density in standardised
        units), minus log(H − t) as in the prior; at frames where π_m is not asked (not a
        decision of the previous round) the prior's term."""
        if not self._decision[t]:
            return self.prior.jump(t)
        mixture = tuple(x[t][:, None] for x in self._mixture)  # (P, 1, K) and (P, 1, K, 7)
        with torch.no_grad():
            logp = mixture_log_prob(mixture, self._candidates[:, t:]).numpy()  # (P, H − t)
        return np.where(self._allowed[:, t:], logp - np.float32(np.log(self.H - t)), NEG).astype(np.float32)

    def motion(self, t: int) -> np.ndarray:
        return self.prior.motion(t)
