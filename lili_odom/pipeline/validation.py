"""Input checks of the pipeline's public API, run before any native (KISS-ICP, GTSAM) call.

:class:`~lili_odom.pipeline.odometry.OdometryPipeline` is a library API as well as the core of
the node: a caller may hand it arrays of any shape, dtype or value. Two kinds of bad input are
told apart:

* **malformed** input (a stamp that is not a number, points that are not ``(N, 3)`` numbers,
  per-point times that are not ``N`` numbers): :class:`PipelineInputError` (a ``ValueError``)
  with a one-line message; the pipeline's state is unchanged.
* **bad values** in well-formed input (non-finite points, non-finite or implausible per-point
  times): the scan is used as far as it is valid. Non-finite points are dropped with their
  times; a time field with a non-finite value or a span longer than ``max_sweep_s`` is
  ignored (no deskewing) and counted under ``scan_times_ignored``. A non-finite stamp is
  skipped by the pipeline (``skipped_bad_stamp``).

IMU and wheel samples are checked by their buffers (rejected and counted as
``imu_rejected`` / ``wheel_rejected``); :func:`check_stamp` only rejects stamps that are not
numbers at all.
"""
from __future__ import annotations

import math
from typing import Any, MutableMapping

import numpy as np

from lili_odom.geometry import nonfinite_rows
from lili_odom.pipeline.types import Scan

__all__ = ["PipelineInputError", "MAX_SWEEP_S", "check_stamp", "checked_scan"]

#: Longest plausible sweep [s]; per-point times spanning more are ignored.
MAX_SWEEP_S = 1.0


class PipelineInputError(ValueError):
    """Malformed input to the pipeline API (wrong type, shape or length)."""


def check_stamp(stamp: Any, what: str = "stamp") -> float:
    """``stamp`` as a float [s] (may be non-finite); PipelineInputError if not a real number."""
    if isinstance(stamp, (bool, np.bool_)) or isinstance(stamp, (str, bytes)):
        raise PipelineInputError(f"{what} must be a number of seconds, got {type(stamp).__name__}")
    try:
        return float(stamp)
    except (TypeError, ValueError, OverflowError):
        raise PipelineInputError(
            f"{what} must be a number of seconds, got {type(stamp).__name__}") from None


def _numeric_array(values: Any, what: str) -> np.ndarray:
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError, OverflowError):
        raise PipelineInputError(f"{what} is not an array of numbers") from None
    if arr.dtype.kind not in "biuf":
        raise PipelineInputError(f"{what} must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def checked_scan(scan: Any, counters: MutableMapping[str, int] | None = None,
                 max_sweep_s: float = MAX_SWEEP_S) -> Scan:
    """A copy of ``scan`` the pipeline can use safely (see module docstring).

    Args:
        scan: a :class:`Scan` (or an object with its attributes); points and times may be any
            array-like of real numbers.
        counters: incremented under ``scan_times_ignored`` when the times are dropped.
        max_sweep_s: longest plausible span of the per-point times [s].

    Returns:
        A new :class:`Scan`: stamp float, points ``(M, 3)`` float64 finite, times ``(M,)``
        float64 finite with a span in ``(0, max_sweep_s]`` or None.

    Raises:
        PipelineInputError: malformed scan.
    """
    for attr in ("stamp", "points"):
        if not hasattr(scan, attr):
            raise PipelineInputError(f"scan has no {attr!r}")
    stamp = check_stamp(scan.stamp, "scan stamp")
    points = _numeric_array(scan.points, "scan points")
    if points.size == 0:
        points = points.reshape(0, 3)
    if points.ndim != 2 or points.shape[1] != 3:
        raise PipelineInputError(f"scan points must have shape (N, 3), got {points.shape}")
    raw_times = getattr(scan, "times", None)
    times = None
    if raw_times is not None:
        times = _numeric_array(raw_times, "scan times")
        if times.ndim != 1 or times.shape[0] != points.shape[0]:
            raise PipelineInputError(f"scan times must have shape ({points.shape[0]},) like the "
                                     f"points, got {times.shape}")
    dropped = getattr(scan, "dropped", 0)
    try:
        dropped = int(dropped)
    except (TypeError, ValueError, OverflowError):
        raise PipelineInputError(f"scan dropped must be an integer, got {dropped!r}") from None
    frame_id = str(getattr(scan, "frame_id", "os_lidar"))

    bad = nonfinite_rows(points)
    if bad is not None:
        good = ~bad
        dropped += int(np.count_nonzero(bad))
        points = points[good]
        times = None if times is None else times[good]
    if times is not None and len(times):
        with np.errstate(invalid="ignore", over="ignore"):
            span = float(times.max() - times.min()) if np.isfinite(times).all() else math.nan
        if not 0.0 <= span <= max_sweep_s:
            if counters is not None:
                counters["scan_times_ignored"] = counters.get("scan_times_ignored", 0) + 1
            times = None
    return Scan(stamp=stamp, points=np.ascontiguousarray(points), times=times,
                frame_id=frame_id, dropped=dropped)
