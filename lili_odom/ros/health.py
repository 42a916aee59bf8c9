"""The node's health: missing-scan detection, input rates and the ``/diagnostics`` statuses.

Pure Python (no rclpy): the node feeds a :class:`HealthMonitor` from its callbacks and worker
and publishes what :meth:`HealthMonitor.statuses` returns as a
``diagnostic_msgs/DiagnosticArray``. One :class:`Status` per concern, named
``lili_odom: <concern>``, with a level (:data:`OK`, :data:`WARN`, :data:`ERROR`, the
``diagnostic_msgs/DiagnosticStatus`` values), a one-line message and key/value pairs.

Concerns: ``lidar input``, ``imu input``, ``wheel input`` (rates over the last ``window_s`` of
wall time against the expected rates), ``scans dropped and missing`` (the node's queue drops;
scans missing from gaps in the header stamps, i.e. lost before they reached the node),
``processing time`` (per scan, against the LiDAR period; the mean per pipeline stage over the
last 50 scans, ``stage_<name>_ms``; the latency from a scan's sweep end to its published
odometry, :mod:`lili_odom.ros.latency`), ``degeneracy`` (dimension and
directions of the last scan), ``wheel scale`` (the online estimate) and ``fusion`` (failures
counted by the pipeline, scans without output).
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from lili_odom.ros.latency import DEFAULT_WINDOW, LatencyStats

__all__ = ["OK", "WARN", "ERROR", "STALE", "Status", "HealthConfig", "StampGapCounter",
           "RateMeter", "HealthMonitor", "describe_direction"]

OK, WARN, ERROR, STALE = 0, 1, 2, 3  # diagnostic_msgs/DiagnosticStatus levels
PREFIX = "lili_odom: "


@dataclass
class Status:
    """One ``diagnostic_msgs/DiagnosticStatus``: ``name``, ``level``, ``message``, ``values``."""

    name: str
    level: int
    message: str
    values: dict[str, str] = field(default_factory=dict)


@dataclass
class HealthConfig:
    """Expected input rates [Hz] (0: input not expected, silence is OK) and thresholds.

    Attributes:
        lidar_hz / imu_hz / wheel_hz: expected rates (default 10, 100, 50: OS1 and Husky).
        window_s: rate and loss window [s of wall time] (default 5).
        rate_warn: a rate below this fraction of the expected one warns (default 0.8).
        loss_warn / loss_error: fraction of scans dropped or missing in the window that warns /
            errors (default 0.01 / 0.2).
        silence_error_s: no scan for this long after scans arrived is an error [s] (default 2).
        max_wheel_scale_error: an estimate farther than this from 1 warns (default 0.1).
        latency_window: scans over which the latency percentiles are taken (default 1000).
    """

    lidar_hz: float = 10.0
    imu_hz: float = 100.0
    wheel_hz: float = 50.0
    window_s: float = 5.0
    rate_warn: float = 0.8
    loss_warn: float = 0.01
    loss_error: float = 0.2
    silence_error_s: float = 2.0
    max_wheel_scale_error: float = 0.1
    latency_window: int = DEFAULT_WINDOW


class StampGapCounter:
    """Counts scans missing from the gaps between consecutive header stamps.

    A gap of ``g`` seconds with the LiDAR period ``p`` misses ``round(g / p) - 1`` scans when
    ``g > 1.5 p``. Gaps longer than ``max_gap_s`` (a paused sensor, a restarted bag) and stamps
    going back are not counted as missing scans but as ``gaps``. The period is the expected
    one (``period_s``).
    """

    def __init__(self, period_s: float, max_gap_s: float = 2.0) -> None:
        self.period = float(period_s)
        self.max_gap = float(max_gap_s)
        self.missing = 0
        self.gaps = 0
        self._last: float | None = None

    def update(self, stamp: float) -> int:
        """Record a scan stamp [s]; returns the scans missing before it (0 when none)."""
        last, self._last = self._last, float(stamp)
        if last is None or not self.period > 0 or not math.isfinite(stamp):
            return 0
        gap = stamp - last
        if gap <= 0 or gap > self.max_gap:
            if gap > self.max_gap or gap < -0.5 * self.period:
                self.gaps += 1
            return 0
        if gap <= 1.5 * self.period:
            return 0
        n = max(0, int(round(gap / self.period)) - 1)
        self.missing += n
        return n


class RateMeter:
    """Events per second over the last ``window_s`` seconds of a monotonic clock."""

    def __init__(self, window_s: float = 5.0, clock: Callable[[], float] = time.monotonic
                 ) -> None:
        self.window = float(window_s)
        self.clock = clock
        self._times: deque[float] = deque()
        self.total = 0
        self.last: float | None = None

    def tick(self, n: int = 1) -> None:
        now = self.clock()
        for _ in range(n):
            self._times.append(now)
        self.total += n
        self.last = now
        self._trim(now)

    def _trim(self, now: float) -> None:
        while self._times and self._times[0] < now - self.window:
            self._times.popleft()

    def count(self) -> int:
        self._trim(self.clock())
        return len(self._times)

    def rate(self, elapsed: float | None = None) -> float:
        """Events per second in the window (or in ``elapsed`` s when shorter, at start-up)."""
        span = self.window if elapsed is None else max(1e-3, min(self.window, elapsed))
        return self.count() / span


def describe_direction(twist: Sequence[float]) -> str:
    """A unit twist ``(v, w)`` in base_link as ``translation (x, y, z)`` or
    ``rotation about (x, y, z)``, whichever part dominates, components rounded to 2 digits."""
    t = np.asarray(twist, dtype=float).reshape(6)
    v, w = t[:3], t[3:]
    kind, vec = ("translation", v) if np.linalg.norm(v) >= np.linalg.norm(w) else \
        ("rotation about", w)
    n = np.linalg.norm(vec)
    vec = vec / n if n > 0 else vec
    return f"{kind} ({vec[0]:+.2f}, {vec[1]:+.2f}, {vec[2]:+.2f})"


def _fmt(x: float, digits: int = 3) -> str:
    return f"{x:.{digits}f}" if math.isfinite(x) else "nan"


class HealthMonitor:
    """Collects what the node observes and turns it into :class:`Status` entries.

    Thread safety: the ``on_*`` methods are called from the node's callbacks and worker; the
    counters they touch are plain integers and deques (atomic enough under the GIL for
    monitoring; a status may be one event stale).
    """

    FAILURE_COUNTERS = ("icp_failures", "detector_failures", "remap_failures",
                        "fusion_rejected")

    def __init__(self, config: HealthConfig | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config or HealthConfig()
        c = self.config
        self.clock = clock
        self.started = clock()
        self.lidar = RateMeter(c.window_s, clock)
        self.imu = RateMeter(c.window_s, clock)
        self.wheel = RateMeter(c.window_s, clock)
        self.missing_meter = RateMeter(c.window_s, clock)
        self.dropped_meter = RateMeter(c.window_s, clock)
        self.gaps = StampGapCounter(1.0 / c.lidar_hz if c.lidar_hz > 0 else 0.0)
        self._proc: deque[float] = deque(maxlen=50)
        self._stages: deque[Mapping[str, float]] = deque(maxlen=50)
        self.latency = LatencyStats(c.latency_window)
        self.last_output: Any = None
        self._failures_seen: dict[str, int] = {}
        self._failure_meter = RateMeter(c.window_s, clock)
        self.scans_without_output = 0

    # -- observations --------------------------------------------------------------------

    def on_scan(self, stamp: float) -> int:
        """A cloud reached the node; returns the scans found missing before it."""
        self.lidar.tick()
        missing = self.gaps.update(stamp)
        if missing:
            self.missing_meter.tick(missing)
        return missing

    def on_imu(self) -> None:
        self.imu.tick()

    def on_wheel(self) -> None:
        self.wheel.tick()

    def on_dropped(self, n: int = 1) -> None:
        self.dropped_meter.tick(n)

    def on_processed(self, seconds: float, output: Any | None) -> None:
        """One scan went through the pipeline in ``seconds``; ``output`` None: no output."""
        self._proc.append(float(seconds))
        if output is None:
            self.scans_without_output += 1
        else:
            self.last_output = output
            timings = getattr(output, "timings", None)
            if isinstance(timings, Mapping) and timings:
                self._stages.append(dict(timings))

    def on_published(self, latency_s: float) -> None:
        """A scan's odometry was published ``latency_s`` [s] after its sweep ended."""
        self.latency.add(latency_s)

    def on_pipeline_counters(self, counters: Mapping[str, int]) -> None:
        """Pipeline counters (``OdometryPipeline.counters``): failures since the last call
        count into the fusion status's window."""
        new = 0
        for name in self.FAILURE_COUNTERS:
            value = int(counters.get(name, 0))
            new += max(0, value - self._failures_seen.get(name, 0))
            self._failures_seen[name] = value
        if new:
            self._failure_meter.tick(new)

    def stage_means(self) -> dict[str, float]:
        """Mean time [s] per pipeline stage (``OdometryOutput.timings``: predict, deskew, icp,
        detector, ..., total) over the last 50 scans with an output; empty before the first."""
        names: dict[str, list[float]] = {}
        for timings in list(self._stages):  # a copy: the worker thread appends meanwhile
            for k, v in timings.items():
                if isinstance(v, (int, float)) and math.isfinite(v):
                    names.setdefault(k, []).append(float(v))
        return {k: float(np.mean(v)) for k, v in names.items()}

    # -- statuses ------------------------------------------------------------------------

    def statuses(self, counters: Mapping[str, Any] | None = None) -> list[Status]:
        """Every concern's status now; ``counters``: the node's diagnostics dict."""
        counters = dict(counters or {})
        return [self._lidar_status(), self._input_status("imu input", self.imu,
                                                         self.config.imu_hz, "IMU"),
                self._input_status("wheel input", self.wheel, self.config.wheel_hz, "wheel"),
                self._loss_status(counters), self._processing_status(),
                self._degeneracy_status(), self._wheel_scale_status(),
                self._fusion_status(counters)]

    def _elapsed(self) -> float:
        return self.clock() - self.started

    def _lidar_status(self) -> Status:
        c = self.config
        rate = self.lidar.rate(self._elapsed())
        values = {"rate_hz": _fmt(rate, 2), "expected_hz": _fmt(c.lidar_hz, 1),
                  "received": str(self.lidar.total)}
        name = PREFIX + "lidar input"
        if self.lidar.last is None:
            return Status(name, WARN, "no scans received yet", values)
        silent = self.clock() - self.lidar.last
        values["seconds_since_last"] = _fmt(silent, 2)
        if silent > c.silence_error_s:
            return Status(name, ERROR, f"no scan for {silent:.1f} s", values)
        if c.lidar_hz > 0 and self._elapsed() > c.window_s and rate < c.rate_warn * c.lidar_hz:
            return Status(name, WARN, f"{rate:.1f} Hz, expected {c.lidar_hz:g} Hz", values)
        return Status(name, OK, f"{rate:.1f} Hz", values)

    def _input_status(self, concern: str, meter: RateMeter, expected: float,
                      label: str) -> Status:
        c = self.config
        rate = meter.rate(self._elapsed())
        values = {"rate_hz": _fmt(rate, 1), "expected_hz": _fmt(expected, 1),
                  "received": str(meter.total)}
        name = PREFIX + concern
        if expected <= 0:
            return Status(name, OK, f"{rate:.1f} Hz (not expected)", values)
        if meter.last is None:
            return Status(name, WARN, f"no {label} messages received", values)
        if self._elapsed() > c.window_s and rate < c.rate_warn * expected:
            return Status(name, WARN, f"{rate:.1f} Hz, expected {expected:g} Hz", values)
        return Status(name, OK, f"{rate:.1f} Hz", values)

    def _loss_status(self, counters: Mapping[str, Any]) -> Status:
        c = self.config
        missing_w, dropped_w, arrived_w = (self.missing_meter.count(), self.dropped_meter.count(),
                                           self.lidar.count())
        expected_w = arrived_w + missing_w
        lost_fraction = (missing_w + dropped_w) / expected_w if expected_w else 0.0
        values = {"scans_missing": str(self.gaps.missing),
                  "scans_dropped": str(counters.get("scans_dropped", 0)),
                  "missing_in_window": str(missing_w), "dropped_in_window": str(dropped_w),
                  "lost_fraction_in_window": _fmt(lost_fraction, 3),
                  "stamp_gaps": str(self.gaps.gaps)}
        name = PREFIX + "scans dropped and missing"
        what = []
        if missing_w:
            what.append(f"{missing_w} missing (lost before the node: check the publisher's "
                        "DDS profile, docs/ros.md)")
        if dropped_w:
            what.append(f"{dropped_w} dropped (processing slower than the LiDAR)")
        text = f"{100 * lost_fraction:.1f} % of scans lost in {c.window_s:g} s: " + "; ".join(what)
        if lost_fraction >= c.loss_error:
            return Status(name, ERROR, text, values)
        if lost_fraction >= c.loss_warn:
            return Status(name, WARN, text, values)
        return Status(name, OK, f"none lost in {c.window_s:g} s (missing "
                      f"{self.gaps.missing}, dropped {values['scans_dropped']} in total)", values)

    def _processing_status(self) -> Status:
        c = self.config
        name = PREFIX + "processing time"
        if not self._proc:
            return Status(name, OK, "no scan processed yet", {})
        times = np.asarray(self._proc)
        mean, worst = float(times.mean()), float(times.max())
        period = 1.0 / c.lidar_hz if c.lidar_hz > 0 else math.inf
        values = {"mean_s": _fmt(mean, 4), "max_s": _fmt(worst, 4),
                  "period_s": _fmt(period, 3), "scans": str(len(times))}
        text = f"mean {1000 * mean:.0f} ms, max {1000 * worst:.0f} ms per scan"
        stages = self.stage_means()
        values.update({f"stage_{k}_ms": _fmt(1000 * v, 1) for k, v in stages.items()})
        slowest = sorted((k for k in stages if k != "total"), key=stages.get, reverse=True)[:2]
        if slowest:
            text += " (most in " + ", ".join(f"{k} {1000 * stages[k]:.0f} ms"
                                             for k in slowest) + ")"
        lat = self.latency.percentiles()
        if lat is not None:
            values.update({"latency_p50_s": _fmt(lat["p50"], 4),
                           "latency_p99_s": _fmt(lat["p99"], 4),
                           "latency_max_s": _fmt(lat["max"], 4),
                           "latency_window_scans": str(len(self.latency))})
            text += (f"; latency p50 {1000 * lat['p50']:.0f} / p99 {1000 * lat['p99']:.0f} / "
                     f"max {1000 * lat['max']:.0f} ms")
        if mean > 1.5 * period:
            return Status(name, ERROR, text + f" (period {1000 * period:.0f} ms)", values)
        if mean > 0.8 * period:
            return Status(name, WARN, text + f" (period {1000 * period:.0f} ms)", values)
        return Status(name, OK, text, values)

    def _degeneracy_status(self) -> Status:
        name = PREFIX + "degeneracy"
        out = self.last_output
        if out is None:
            return Status(name, OK, "no odometry yet", {})
        basis = np.asarray(getattr(out, "degenerate_basis", np.zeros((0, 6))),
                           dtype=float).reshape(-1, 6)
        dims = len(basis)
        directions = [describe_direction(b) for b in basis]
        weak = np.asarray(getattr(out, "weak_basis", np.zeros((0, 6))),
                          dtype=float).reshape(-1, 6)
        values = {"dimension": str(dims), "stamp": _fmt(float(out.stamp), 3),
                  "weakly_constrained": str(len(weak))}
        for i, d in enumerate(directions):
            values[f"direction_{i}"] = d
        for i, b in enumerate(weak):
            values[f"weak_direction_{i}"] = describe_direction(b)
        if getattr(out, "degeneracy", None) is None:
            values["detector"] = "none or skipped"
        if dims == 0 and len(weak):
            return Status(name, OK, f"constrained (dimension 0; {len(weak)} weakly "
                          "constrained, held by the LiDAR)", values)
        if dims == 0:
            return Status(name, OK, "constrained (dimension 0)", values)
        return Status(name, WARN, f"degenerate, dimension {dims}: " + "; ".join(directions),
                      values)

    def _wheel_scale_status(self) -> Status:
        c = self.config
        name = PREFIX + "wheel scale"
        out = self.last_output
        scale = None if out is None else (getattr(out, "details", {}) or {}).get("wheel_scale")
        if scale is None:
            return Status(name, OK, "no estimate yet", {})
        scale = float(scale)
        values = {"scale": _fmt(scale, 4)}
        if not math.isfinite(scale):
            return Status(name, ERROR, "estimate is not finite", values)
        if abs(scale - 1.0) > c.max_wheel_scale_error:
            return Status(name, WARN, f"{scale:.3f} (wheels off by {100 * (scale - 1):+.1f} %: "
                          "check tyre pressure / wheel radius)", values)
        return Status(name, OK, f"{scale:.3f}", values)

    def _fusion_status(self, counters: Mapping[str, Any]) -> Status:
        name = PREFIX + "fusion"
        recent = self._failure_meter.count()
        errors = int(counters.get("scan_errors", 0))
        values = {"failures_in_window": str(recent), "scan_errors": str(errors),
                  "scans_no_output": str(self.scans_without_output)}
        for k, v in counters.items():
            short = k.removeprefix("pipeline.")
            if k.startswith("pipeline.") and short in self.FAILURE_COUNTERS + ("resets",):
                values[short] = str(v)
        out = self.last_output
        if out is not None:
            details = getattr(out, "details", {}) or {}
            values["used_imu"] = str(bool(details.get("used_imu", False))).lower()
            values["used_wheel"] = str(bool(details.get("used_wheel", False))).lower()
            warnings = list(getattr(out, "warnings", []) or [])
            if warnings:
                values["last_warning"] = str(warnings[-1])
        processed = len(self._proc)
        if processed and self.last_output is None:
            return Status(name, ERROR, f"{processed} scans processed, none gave odometry",
                          values)
        if recent:
            return Status(name, WARN, f"{recent} registration/fusion failures in "
                          f"{self.config.window_s:g} s", values)
        if self.last_output is None:
            return Status(name, OK, "waiting for data", values)
        return Status(name, OK, "healthy", values)
