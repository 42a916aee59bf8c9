"""Per-stage timing statistics of odometry runs, and picking the median of repeated runs."""
from __future__ import annotations

from typing import Any, Iterable

import numpy as np

__all__ = ["stage_stats", "median_run"]


def stage_stats(per_scan: dict[str, list[float]], stages: Iterable[str],
                measured: Iterable[str] | None = None) -> dict[str, dict[str, float] | None]:
    """Per stage, from per-scan times [s]: ``{"mean_ms", "p95_ms", "max_ms"}``; None for a
    stage without times or not in ``measured`` (default: every stage)."""
    measured = set(stages if measured is None else measured)
    out: dict[str, dict[str, float] | None] = {}
    for k in stages:
        v = np.asarray(per_scan.get(k, []), dtype=float) * 1e3
        if k not in measured or not len(v):
            out[k] = None
            continue
        out[k] = {"mean_ms": float(np.mean(v)), "p95_ms": float(np.percentile(v, 95)),
                  "max_ms": float(np.max(v))}
    return out


def median_run(runs: list[dict[str, Any]], key: str = "scans_per_s") -> dict[str, Any]:
    """The run with the median ``key`` (the upper one of an even count), with every run's
    value in ``repeats_<key>`` (in run order)."""
    chosen = sorted(runs, key=lambda r: r[key])[len(runs) // 2]
    return {**chosen, f"repeats_{key}": [r[key] for r in runs]}
