"""Viterbi over states (pair p = (tool, target), way-point index k), factorised.

Algorithm 1 of the paper compares every state at t with every state at t−1: O(n⁴H³). The
transitions here are stay-or-switch, so the best predecessor splits into three cases that
successors share:

* A, keep pair and way-point:  F_{t−1}(p, k) + log γ + log β                 (needs k ≥ t)
* B, keep pair, new way-point:  max_k' F_{t−1}(p, k') + log γ + log(1−β) + J_t(p, k)
* C, switch pair:               max_{p'≠p, k'} F_{t−1}(p', k') + log((1−γ)/(P−1)) + log(1−β) + J_t(p, k)

``max_k'`` is one reduction per pair and ``max_{p'≠p}`` the top two pairs, so a step costs
O(P·H) and the whole recursion O(P·H²) = O(n²H²), with exactly the argmax of the full
recursion (tested against brute force). J_t(p, k) is the log-weight of jumping to
way-point k (π_m), U_t(p) the pair's unary log-score (π_h) and M_t(p, k) the observed
motion's log-likelihood (π_l); all come from a :class:`Scores` provider, the priors or the
trained networks (EM).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

NEG = -np.inf


class Scores(Protocol):
    """Log-scores of one episode with ``H`` frames and ``P`` (tool, target) pairs."""

    H: int
    P: int

    def unary(self, t: int) -> np.ndarray:
        """U_t: (P,) log π_h of each pair at frame t (tool evidence, target prior)."""

    def jump(self, t: int) -> np.ndarray:
        """J_t: (P, H − t) log-weight of choosing way-point k = t, …, H−1 at frame t."""

    def motion(self, t: int) -> np.ndarray:
        """M_t: (P, H − t) log π_l of the motion from t to t+1 aiming at way-point k ≥ t."""


@dataclass(frozen=True)
class Transition:
    """Stay-or-switch constants: γ (keep the pair), β (keep the way-point)."""

    gamma: float = 0.95
    beta: float = 0.95

    def logs(self, P: int) -> tuple[float, float, float, float]:
        stay_pair = np.log(self.gamma)
        switch_pair = np.log((1 - self.gamma) / max(P - 1, 1)) if P > 1 else NEG
        return float(stay_pair), float(switch_pair), float(np.log(self.beta)), float(np.log1p(-self.beta))


@dataclass
class Path:
    pair: np.ndarray
    """(H,) pair index per frame."""
    k: np.ndarray
    """(H,) way-point frame index per frame (k ≥ t)."""
    score: float


def viterbi(scores: Scores, transition: Transition) -> Path:
    """The most likely (pair, way-point) sequence; backpointers take H·P·H bytes."""
    H, P = scores.H, scores.P
    stay_pair, switch_pair, keep_k, jump_k = transition.logs(P)
    code = np.zeros((H, P, H), np.int8)  # 0: A keep both, 1: B new way-point, 2: C switch pair
    best_k = np.zeros((H, P), np.int32)  # argmax_k' F_{t-1}(p, k')
    best_p = np.zeros((H, 2), np.int32)  # top-2 pairs of max_k' F_{t-1}

    # F holds F_t(p, k) for k = t, …, H−1 only (way-points are never in the past).
    F = float(np.log(1.0 / P) + jump_k) + scores.jump(0) + scores.unary(0)[:, None] + scores.motion(0)
    rows = np.arange(P)
    for t in range(1, H):
        bk = F.argmax(axis=1)
        G = F[rows, bk]
        best_k[t] = bk + (t - 1)
        order = np.argsort(-G, kind="stable")[:2] if P > 1 else np.array([0, 0])
        best_p[t] = order
        other = np.where(rows == order[0], G[order[1]] if P > 1 else NEG, G[order[0]])
        J = scores.jump(t)
        A = F[:, 1:] + (stay_pair + keep_k)
        B = (G + stay_pair + jump_k)[:, None] + J
        C = (other + switch_pair + jump_k)[:, None] + J
        # argmax over (A, B, C) with the first maximum winning ties, as np.argmax does
        choice = np.where(B >= C, np.int8(1), np.int8(2))
        best = np.maximum(B, C)
        keep = A >= best
        choice[keep] = 0
        F = np.where(keep, A, best) + scores.unary(t)[:, None] + scores.motion(t)
        code[t, :, t:] = choice
    p, k = np.unravel_index(int(np.argmax(F)), F.shape)
    score = float(F[p, k])
    k += H - 1  # F's columns are k = H−1, … at the last frame
    pairs, ks = np.empty(H, np.int64), np.empty(H, np.int64)
    for t in range(H - 1, -1, -1):
        pairs[t], ks[t] = p, k
        if t == 0:
            break
        c = code[t, p, k]
        if c == 1:
            k = best_k[t, p]
        elif c == 2:
            p = best_p[t, 0] if best_p[t, 0] != p else best_p[t, 1]
            k = best_k[t, p]
    return Path(pairs, ks, score)
