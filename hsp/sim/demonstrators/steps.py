"""What a scripted demonstrator says to do; the executor turns it into motion.

A ``Move`` is one way-point of the paper's sub-task model: the tool o+ should reach
``pose`` (its pose in the target o*'s frame, i.e. w_t) by the end of the segment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Move:
    tool: int
    target: int
    pose: np.ndarray
    """w: tool pose in the target frame at the end of the segment, ``(7,)``."""
    straight: bool = False
    """No bulge (a paint stroke, a final insertion)."""
    slow: float = 1.0
    """Duration multiplier (> 1 for careful, precise segments)."""


@dataclass(frozen=True)
class Grasp:
    obj: int


@dataclass(frozen=True)
class Release:
    pass


Step = Move | Grasp | Release
