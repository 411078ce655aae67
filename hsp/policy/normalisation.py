"""Per-feature standardisation, fitted on the training episodes and saved with the weights."""

from __future__ import annotations

import numpy as np
import torch

from hsp.policy.features import Steps

FIELDS = ("z", "progress", "current", "target_in_tool", "waypoint", "action")
MIN_STD = 1e-3


class Normalisation:
    """``(x − mean) / std`` per field of :class:`~hsp.policy.features.Steps`; a std under
    ``MIN_STD`` (a constant feature) is taken as ``MIN_STD``."""

    def __init__(self, stats: dict[str, torch.Tensor]) -> None:
        self.stats = stats

    @classmethod
    def fit(cls, episodes: list[Steps]) -> "Normalisation":
        stats = {}
        for name in FIELDS:
            x = np.concatenate([getattr(e, name) for e in episodes])
            stats[f"{name}.mean"] = torch.tensor(x.mean(0), dtype=torch.float32)
            stats[f"{name}.std"] = torch.tensor(np.maximum(x.std(0), MIN_STD), dtype=torch.float32)
        return cls(stats)

    def __call__(self, name: str, x: torch.Tensor) -> torch.Tensor:
        return (x - self.stats[f"{name}.mean"]) / self.stats[f"{name}.std"]

    def history(self, x: torch.Tensor) -> torch.Tensor:
        """The LSTM input: the pair one-hot as is, w_{t−1} standardised as a way-point."""
        P = x.shape[-1] - 7
        return torch.cat([x[..., :P], self("waypoint", x[..., P:])], -1)
