"""The three networks of the paper (Section III; sizes of Section V-C).

* π_h: g_t → FC(64)+ReLU; the history (previous pair, w_{t−1}) → LSTM(32); [z_t, LSTM,
  embedded g_t] → two hidden layers of 64 → log-softmax over the P (tool, target) pairs
  (one head over the pairs the labels can take, rather than separate tool and target heads:
  the target is never the end-effector or the tool itself).
* π_m: the pair's semantic labels, p_t[o+, o*], the LSTM state and g_t → two hidden
  layers of 64 → a diagonal Gaussian over the way-point w_t (7).
* π_l: the target in the tool's frame, w_t and the pair's labels → two hidden layers of 64
  → a diagonal Gaussian over the action a_t (6).

Inputs and outputs are standardised with statistics of the training data
(:class:`Normalisation`); log-likelihoods are in those standardised units.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

LOG_STD_RANGE = (-5.0, 2.0)
LOG_SQRT_2PI = 0.9189385332046727


def mlp(d_in: int, d_out: int, hidden: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(d_in, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, d_out))


def gaussian_log_prob(mean: torch.Tensor, log_std: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Diagonal Gaussian log-density, summed over the last axis."""
    z = (x - mean) * torch.exp(-log_std)
    return (-0.5 * z * z - log_std - LOG_SQRT_2PI).sum(-1)


@dataclass(frozen=True)
class Sizes:
    pairs: int
    classes: int
    hidden: int = 64
    memory: int = 32

    @property
    def z(self) -> int:
        return 7 * self.pairs


class Hierarchy(nn.Module):
    """π_h, π_m and π_l with the LSTM memory they share."""

    def __init__(self, sizes: Sizes) -> None:
        super().__init__()
        s = self.sizes = sizes
        self.progress = nn.Sequential(nn.Linear(7, s.hidden), nn.ReLU())
        self.memory = nn.LSTM(s.pairs + 7, s.memory, batch_first=True)
        self.high = mlp(s.z + s.memory + s.hidden, s.pairs, s.hidden)
        self.intermediate = mlp(2 * s.classes + 7 + s.memory + 7, 14, s.hidden)
        self.low = mlp(7 + 7 + 2 * s.classes, 12, s.hidden)

    def remember(self, history: torch.Tensor) -> torch.Tensor:
        """LSTM states over an episode batch ``(B, T, P + 7)`` → ``(B, T, memory)``."""
        return self.memory(history)[0]

    def pi_h(self, z: torch.Tensor, memory: torch.Tensor, progress: torch.Tensor) -> torch.Tensor:
        """log π_h over pairs ``(..., P)``."""
        return torch.log_softmax(self.high(torch.cat([z, memory, self.progress(progress)], -1)), -1)

    def pi_m(self, classes: torch.Tensor, current: torch.Tensor, memory: torch.Tensor,
             progress: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-σ of the way-point ``(..., 7)`` each."""
        out = self.intermediate(torch.cat([classes, current, memory, progress], -1))
        return out[..., :7], out[..., 7:].clamp(*LOG_STD_RANGE)

    def pi_l(self, target_in_tool: torch.Tensor, waypoint: torch.Tensor,
             classes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-σ of the action ``(..., 6)`` each."""
        out = self.low(torch.cat([target_in_tool, waypoint, classes], -1))
        return out[..., :6], out[..., 6:].clamp(*LOG_STD_RANGE)
