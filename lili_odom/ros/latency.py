"""Latency of the node's odometry: from the end of a scan's sweep to its published odometry.

The latency of one scan [s] is the node clock at the moment its ``~/odometry`` message is
published minus the end of its sweep, ``header.stamp`` + the sweep duration. The pipeline
stamps each output with exactly that end (:attr:`lili_odom.pipeline.types.OdometryOutput.stamp`,
the scan's reference time): ``header.stamp`` + the time offset of the sweep's last point (the
largest per-point time), or
``header.stamp`` + ``pipeline.sweep_duration`` (default 0.1 s, one period of a 10 Hz LiDAR)
when the cloud has no usable per-point times. The node subtracts that stamp.

The node clock is ROS time: the system clock, or ``/clock`` with ``use_sim_time`` (then the
latency is only as fine as the ``/clock`` rate). A latency therefore includes the transport of
the cloud to the node, waiting for the IMU/wheel samples that cover the sweep, queueing and
processing; a clock offset between the LiDAR's stamps and the node's clock adds to it.

:class:`LatencyStats` keeps the latencies of the last ``window`` scans (p50 / p99 / max) and
the count and maximum over the whole run. Pure Python, no rclpy.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

__all__ = ["DEFAULT_WINDOW", "LatencyStats"]

#: Scans in the rolling window (100 s at 10 Hz).
DEFAULT_WINDOW = 1000


class LatencyStats:
    """Latencies [s] of published odometry.

    ``add`` records one scan's latency (non-finite values are counted in ``invalid`` and
    otherwise ignored; negative ones are kept: they reveal a clock offset). Percentiles are
    over the last ``window`` scans (numpy's linear interpolation); ``count`` and ``run_max``
    cover the whole run.
    """

    def __init__(self, window: int = DEFAULT_WINDOW) -> None:
        if window < 1:
            raise ValueError(f"window must be at least 1 scan, got {window}")
        self._recent: deque[float] = deque(maxlen=int(window))
        self.count = 0
        self.invalid = 0
        self.run_max = -math.inf

    def add(self, seconds: float) -> None:
        value = float(seconds)
        if not math.isfinite(value):
            self.invalid += 1
            return
        self._recent.append(value)
        self.count += 1
        self.run_max = max(self.run_max, value)

    def __len__(self) -> int:
        """Latencies in the window."""
        return len(self._recent)

    def percentiles(self) -> dict[str, float] | None:
        """``{"p50", "p99", "max"}`` [s] over the window; None before the first scan."""
        if not self._recent:
            return None
        values = np.fromiter(self._recent, dtype=float, count=len(self._recent))
        p50, p99 = np.percentile(values, [50.0, 99.0])
        return {"p50": float(p50), "p99": float(p99), "max": float(values.max())}

    def summary(self, digits: int = 4) -> dict[str, Any]:
        """The node's summary keys: ``latency_p50_s``, ``latency_p99_s``, ``latency_max_s``
        (window, None before the first scan), ``latency_window_scans``, ``latency_scans``
        (whole run), ``latency_run_max_s`` and ``latency_invalid``; seconds rounded to
        ``digits``."""
        p = self.percentiles() or {}

        def r(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else round(x, digits)

        return {"latency_p50_s": r(p.get("p50")), "latency_p99_s": r(p.get("p99")),
                "latency_max_s": r(p.get("max")), "latency_window_scans": len(self._recent),
                "latency_scans": self.count, "latency_run_max_s": r(self.run_max),
                "latency_invalid": self.invalid}
