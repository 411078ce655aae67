"""Per-feature standardisation, fitted on the training episodes and saved with the weights."""

from __future__ import annotations

import numpy as np
import torch

from hsp.policy.features import Steps

FIELDS = ("world", "ee_in_object", "tool_in_object", "progress", "current", "waypoint", "came_from", "remaining",
          "action")
"""Standardised fields of :class:`~hsp.policy.features.Steps`; per-object ones are pooled over
objects (identical objects share their statistics)."""
MIN_STD = 1e-3


class Normalisation:
    """``(x − mean) / std`` per field; a std under ``MIN_STD`` (a constant feature) is taken
    as ``MIN_STD``. The action is only scaled (``action.std``): π_l's mean is a fraction of
    the remaining way, in physical units."""

    def __init__(self, stats: dict[str, torch.Tensor]) -> None:
        self.stats = stats

    @classmethod
    def fit(cls, episodes: list[Steps]) -> "Normalisation":
        stats = {}
        for name in FIELDS:
            x = np.concatenate([getattr(e, name).reshape(-1, getattr(e, name).shape[-1]) for e in episodes])
            stats[f"{name}.mean"] = torch.tensor(x.mean(0), dtype=torch.float32)
            stats[f"{name}.std"] = torch.tensor(np.maximum(x.std(0), MIN_STD), dtype=torch.float32)
        return cls(stats)

    def __call__(self, name: str, x: torch.Tensor) -> torch.Tensor:
        return (x - self.stats[f"{name}.mean"]) / self.stats[f"{name}.std"]

    def unscale(self, name: str, x: torch.Tensor) -> torch.Tensor:
        """The inverse of :meth:`__call__`."""
        return x * self.stats[f"{name}.std"] + self.stats[f"{name}.mean"]

    def history(self, x: torch.Tensor) -> torch.Tensor:
        """The LSTM input: the labels one-hot as they are, w_{t−1} standardised as a way-point."""
        return torch.cat([x[..., :-7], self("waypoint", x[..., -7:])], -1)
