"""Success statistics of an evaluation: rates, Wilson intervals, spread across runs."""

from __future__ import annotations

import numpy as np


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval (95 % by default) of a binomial proportion; ``(0, 1)`` for ``n = 0``."""
    if n == 0:
        return 0.0, 1.0
    phat = successes / n
    centre = (phat + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(phat * (1 - phat) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    low = 0.0 if successes == 0 else max(0.0, centre - half)  # exact at the ends, not 1e-18
    high = 1.0 if successes == n else min(1.0, centre + half)
    return float(low), float(high)


def summarise(episodes: list[dict]) -> dict[str, float | int]:
    """Flat-key summary of per-episode records (``run``, ``success``, ``steps``, ``progress``)."""
    success = np.array([e["success"] for e in episodes], bool)
    runs = sorted({e["run"] for e in episodes})
    per_run = [success[[e["run"] == r for e in episodes]].mean() for r in runs]
    low, high = wilson_interval(int(success.sum()), len(success))
    out: dict[str, float | int] = {
        "episodes": len(episodes),
        "runs": len(runs),
        "success_rate": float(success.mean()),
        "success_rate_ci95_low": low,
        "success_rate_ci95_high": high,
        "success_rate_std": float(np.std(per_run)),
        "episode_length_mean": float(np.mean([e["steps"] for e in episodes])),
    }
    for goal in episodes[0]["progress"]:
        out[f"subgoal.{goal}"] = float(np.mean([e["progress"][goal] for e in episodes]))
    return out
