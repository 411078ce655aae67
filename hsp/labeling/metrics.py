"""Pseudo-labels against the demonstrator's own annotation (evaluation only)."""

from __future__ import annotations

import numpy as np


def boundaries(tool: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Frames where the (tool, target) pair changes, ``(B,)``."""
    return np.flatnonzero((np.diff(tool) != 0) | (np.diff(target) != 0)) + 1


def boundary_errors(pred: np.ndarray, truth: np.ndarray, H: int) -> np.ndarray:
    """For each true boundary, frames to the nearest predicted one (H when there is none)."""
    if truth.size == 0:
        return np.zeros(0)
    if pred.size == 0:
        return np.full(truth.size, float(H))
    return np.abs(truth[:, None] - pred[None, :]).min(axis=1).astype(float)


def label_metrics(pred: list[dict[str, np.ndarray]], truth: list[dict[str, np.ndarray]]) -> dict[str, float | None]:
    """Frame accuracies, median boundary error (frames) and median way-point error (mm,
    over frames whose tool and target are right; ``None`` when there are none, as JSON
    has no NaN). Each item has tool, target, waypoint; a prediction's ``equivalent`` (its
    target's equivalence set per frame, ``(H, n)``) adds the target accuracy modulo
    equivalence: right when the true target is in the set."""
    tool_ok, target_ok, set_ok, b_err, w_err = [], [], [], [], []
    for p, g in zip(pred, truth):
        tool_ok.append(p["tool"] == g["tool"])
        target_ok.append(p["target"] == g["target"])
        if "equivalent" in p:
            set_ok.append(np.take_along_axis(p["equivalent"], g["target"][:, None], 1)[:, 0])
        b_err.append(boundary_errors(boundaries(p["tool"], p["target"]), boundaries(g["tool"], g["target"]), len(g["tool"])))
        both = tool_ok[-1] & target_ok[-1]
        w_err.append(np.linalg.norm(p["waypoint"][both, :3] - g["waypoint"][both, :3], axis=1) * 1000.0)
    cat = np.concatenate
    b, w = cat(b_err), cat(w_err)
    return {
        "tool_accuracy": float(np.mean(cat(tool_ok))),
        "target_accuracy": float(np.mean(cat(target_ok))),
        **({"target_accuracy_equivalent": float(np.mean(cat(set_ok)))} if set_ok else {}),
        "boundary_error_frames_median": float(np.median(b)) if b.size else 0.0,
        "waypoint_error_mm_median": float(np.median(w)) if w.size else None,
    }
