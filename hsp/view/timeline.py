"""A label timeline of one episode as a PNG: tool and target per frame as coloured bands,
the pseudo-labels above the demonstrator's annotation, way-point switches marked, and
each object's tracking status underneath."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hsp.dataset.features import TrackStatus
from hsp.fileio import atomic_path

STATUS_RGB = {TrackStatus.OK: (0.31, 0.78, 0.24), TrackStatus.SUSPECT: (1.0, 0.7, 0.0), TrackStatus.LOST: (0.9, 0.16, 0.16)}


def bands(values: np.ndarray) -> list[tuple[int, int, int]]:
    """Runs of equal values as ``(start, end, value)``, end exclusive, covering every frame."""
    values = np.asarray(values)
    if values.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [len(values)]])
    return [(int(s), int(e), int(values[s])) for s, e in zip(starts, ends)]


def object_colours(n: int) -> np.ndarray:
    """One distinct RGB colour per object index ``(n, 3)`` in [0, 1]; tab10 without its green
    and red, which mean ok and lost in the status rows."""
    from matplotlib import colormaps

    picks = np.array([0, 1, 4, 5, 6, 7, 8, 9])
    return np.asarray(colormaps["tab10"](picks[np.arange(n) % len(picks)]))[:, :3]


def write_timeline(path: Path, objects: list[str], labels: dict[str, np.ndarray], status: np.ndarray,
                   truth: dict[str, np.ndarray] | None = None, fps: float = 15.0, title: str = "") -> Path:
    """Draw the timeline. ``labels`` and ``truth`` hold ``tool``, ``target`` (object index per
    frame) and ``waypoint_index``; ``status (T, n)``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    colours = object_colours(len(objects))
    rows: list[tuple[str, np.ndarray]] = [("tool", labels["tool"]), ("target", labels["target"])]
    if truth is not None:
        rows += [("true tool", truth["tool"]), ("true target", truth["target"])]
    T, n = status.shape
    fig, ax = plt.subplots(figsize=(12, 0.45 * (len(rows) + n) + 1.2), dpi=100)
    y = 0
    ticks = []
    for name, values in rows:
        for s, e, v in bands(values):
            ax.broken_barh([(s, e - s)], (y, 0.8), facecolors=[colours[v]])
        ticks.append((y + 0.4, name))
        y += 1
    for k, lab in ((0, labels), (1, truth)):
        if lab is None:
            continue
        switches = np.flatnonzero(np.diff(lab["waypoint_index"])) + 1
        ax.vlines(switches, k * 2, k * 2 + 1.8, colors="black", linewidth=0.6)
    y += 0.3
    for i in range(n):
        for s, e, v in bands(status[:, i]):
            ax.broken_barh([(s, e - s)], (y, 0.8), facecolors=[STATUS_RGB[TrackStatus(v)]])
        ticks.append((y + 0.4, f"{objects[i]} status"))
        y += 1
    ax.set_yticks([t for t, _ in ticks], [name for _, name in ticks])
    ax.set_ylim(y, -0.2)
    ax.set_xlim(0, T)
    ax.set_xlabel(f"frame ({fps:g} per second); black ticks: way-point switches")
    handles = [Patch(color=colours[i], label=o) for i, o in enumerate(objects)]
    handles += [Patch(color=c, label=s.name.lower()) for s, c in STATUS_RGB.items()]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)
