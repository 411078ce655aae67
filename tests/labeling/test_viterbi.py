"""The factorised Viterbi equals brute force over every path on small random problems."""

import itertools

import numpy as np
import pytest

from hsp.labeling.viterbi import NEG, Transition, viterbi


class RandomScores:
    def __init__(self, H: int, P: int, rng: np.random.Generator) -> None:
        self.H, self.P = H, P
        self.U = rng.normal(size=(H, P))
        self.J = rng.normal(size=(H, P, H))
        self.M = rng.normal(size=(H, P, H))
        for t in range(H):
            self.J[t, :, :t] = NEG

    def unary(self, t):
        return self.U[t]

    def jump(self, t):
        return self.J[t, :, t:]

    def motion(self, t):
        return self.M[t, :, t:]


def path_score(s: RandomScores, tr: Transition, pairs, ks) -> float:
    stay_pair, switch_pair, keep_k, jump_k = tr.logs(s.P)
    total = np.log(1.0 / s.P) + jump_k + s.J[0, pairs[0], ks[0]]
    for t in range(s.H):
        p, k = pairs[t], ks[t]
        if k < t:
            return NEG
        total += s.U[t, p] + s.M[t, p, k]
        if t == 0:
            continue
        q, kq = pairs[t - 1], ks[t - 1]
        if p == q:
            options = [stay_pair + jump_k + s.J[t, p, k]]
            if k == kq:
                options.append(stay_pair + keep_k)
            total += max(options)
        else:
            total += switch_pair + jump_k + s.J[t, p, k]
    return total


def brute_force(s: RandomScores, tr: Transition):
    best, arg = NEG, None
    states_per_t = [[(p, k) for p in range(s.P) for k in range(t, s.H)] for t in range(s.H)]
    for seq in itertools.product(*states_per_t):
        pairs, ks = [p for p, _ in seq], [k for _, k in seq]
        sc = path_score(s, tr, pairs, ks)
        if sc > best:
            best, arg = sc, (pairs, ks)
    return best, arg


@pytest.mark.parametrize("seed", range(120))
def test_fast_viterbi_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    H, P = int(rng.integers(1, 6)), int(rng.integers(1, 4))
    s = RandomScores(H, P, rng)
    tr = Transition(gamma=float(rng.uniform(0.5, 0.99)), beta=float(rng.uniform(0.5, 0.99)))
    path = viterbi(s, tr)
    best, (pairs, ks) = brute_force(s, tr)
    assert path.score == pytest.approx(best, abs=1e-9)
    assert list(path.pair) == pairs and list(path.k) == ks
    assert path_score(s, tr, path.pair, path.k) == pytest.approx(path.score, abs=1e-9)
