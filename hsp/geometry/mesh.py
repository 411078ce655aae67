"""Reading the vertices of the OBJ object models (their extents size layouts and tools)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from hsp.errors import HspError


@lru_cache(maxsize=64)
def obj_vertices(path: Path) -> np.ndarray:
    """Vertex positions ``(V, 3)`` of an OBJ file, in its object frame (m)."""
    path = Path(path)
    if not path.is_file():
        raise HspError(f"{path}: mesh file is missing")
    rows = [line.split()[1:4] for line in path.read_text().splitlines() if line.startswith("v ")]
    if not rows:
        raise HspError(f"{path}: no vertices in mesh")
    try:
        return np.array(rows, dtype=float)
    except ValueError:
        raise HspError(f"{path}: malformed vertex line in mesh") from None
