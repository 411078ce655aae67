"""Human-like Cartesian motion: minimum-jerk segments, curved paths and tremor.

Flash and Hogan (1985): a person's point-to-point reach follows the minimum-jerk profile
s(τ) = 10τ³ − 15τ⁴ + 6τ⁵. A sideways/upward bulge that vanishes at both ends makes the
path curved; an 8–12 Hz sum of sinusoids adds physiological tremor.
"""

from __future__ import annotations

import numpy as np

from hsp.geometry import slerp


def minimum_jerk(tau: np.ndarray) -> np.ndarray:
    """Progress s ∈ [0, 1] at normalised times ``tau`` (clipped to [0, 1])."""
    t = np.clip(tau, 0.0, 1.0)
    return t**3 * (10.0 - 15.0 * t + 6.0 * t * t)


def segment_poses(start: np.ndarray, goal: np.ndarray, tau: np.ndarray, bulge: np.ndarray) -> np.ndarray:
    """Poses ``(K, 7)`` along a minimum-jerk segment from ``start`` to ``goal`` (7,) at
    normalised times ``tau (K,)``; ``bulge (3,)`` is the path's largest offset (mid-way)."""
    s = minimum_jerk(tau)
    pos = start[:3] + s[:, None] * (goal[:3] - start[:3]) + np.sin(np.pi * s)[:, None] * bulge[None, :]
    return np.concatenate([pos, slerp(start[3:], goal[3:], s)], axis=1)


class Tremor:
    """Band-limited positional tremor (m) as a function of time (s); seeded."""

    def __init__(self, amplitude: float, rng: np.random.Generator, components: int = 4) -> None:
        self.freq = rng.uniform(8.0, 12.0, size=(components, 3))
        self.phase = rng.uniform(0, 2 * np.pi, size=(components, 3))
        self.amp = amplitude / np.sqrt(components) * rng.uniform(0.5, 1.0, size=(components, 3))

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Offsets ``(K, 3)`` at times ``t (K,)``."""
        t = np.atleast_1d(t)[:, None, None]
        return np.sum(self.amp * np.sin(2 * np.pi * self.freq * t + self.phase), axis=1)
