"""Door ``api``: ``Scan``, ``ImuSample`` and ``WheelSample`` objects into ``OdometryPipeline``.

A case builds a fresh pipeline (``lili`` for one case in eight, ``none`` otherwise), feeds
three valid scans of a small box room moving at 0.5 m/s with IMU and wheel samples, then one
to three bad inputs (a scan, an IMU or a wheel sample with bad shapes, types, values or
stamps), then two valid scans. Expected: every call returns (an output, None for a skipped
scan, or a counted rejection) or raises ``PipelineInputError``; every output is finite; and
the last valid scan gives an output (the pipeline did not stop after the fault).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from lili_odom.fuzz.outcome import (CLEAN, NONFINITE, OTHER, STALLED, Outcome, all_finite,
                                    from_exception, one_line)

DT = 0.1  # scan period [s]
SPEED = 0.5  # forward speed of the room's observer [m/s]
F64_MAX = float(np.finfo(np.float64).max)


def room(rng: np.random.Generator, n_per_face: int = 150,
         half: tuple[float, float, float] = (6.0, 5.0, 3.0)) -> np.ndarray:
    """(6 n, 3) points on the faces of a box of half-extents ``half`` around the origin [m]
    (default 12 x 10 x 6 m)."""
    half = np.asarray(half, dtype=float)
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = rng.uniform(-1, 1, (n_per_face, 3)) * half
            p[:, axis] = sign * half[axis]
            faces.append(p)
    return np.vstack(faces)


def _pick(rng: np.random.Generator, options: list) -> Any:
    return options[int(rng.integers(len(options)))]


class _World:
    """Valid inputs of an observer moving along x through a fixed room."""

    def __init__(self, rng: np.random.Generator, t0: float = 100.0):
        self.points = room(rng)
        self.t0 = t0
        self.rng = rng

    def scan(self, k: int):
        from lili_odom.pipeline.types import Scan

        n = len(self.points)
        times = np.linspace(0.0, DT, n)
        shift = SPEED * (k * DT + times)[:, None] * np.array([1.0, 0.0, 0.0])
        return Scan(self.t0 + k * DT, self.points - shift, times)

    def imu(self, t: float):
        from lili_odom.pipeline.types import ImuSample

        return ImuSample(t, np.zeros(3), np.array([0.0, 0.0, 9.80665]))

    def wheel(self, t: float):
        from lili_odom.pipeline.types import WheelSample

        pose = np.eye(4)
        pose[0, 3] = SPEED * (t - self.t0)
        return WheelSample(t, np.array([SPEED, 0, 0, 0, 0, 0.0]), pose)

    def sensors_until(self, pipe, t_from: float, t_to: float) -> None:
        for t in np.arange(t_from, t_to, 0.01):
            pipe.add_imu(self.imu(float(t)))
            if int(round(t * 100)) % 2 == 0:
                pipe.add_wheel(self.wheel(float(t)))


# ----------------------------------------------------------------------------- bad inputs
_BAD_STAMPS = [np.nan, np.inf, -np.inf, F64_MAX, -F64_MAX, 1e308, -1.0, 0.0, "100.3", None,
               b"1", True, np.array([1.0, 2.0]), np.array(100.35), [100.35], 1 + 2j, object()]


def _bad_points(rng, good: np.ndarray) -> tuple[Any, str]:
    n = len(good)
    what = int(rng.integers(16))
    if what == 0:
        return good[:, :2], "points (N, 2)"
    if what == 1:
        return np.hstack([good, good[:, :1]]), "points (N, 4)"
    if what == 2:
        return good[0], "points (3,)"
    if what == 3:
        return good[:, :, None], "points (N, 3, 1)"
    if what == 4:
        return good.tolist(), "points as a list"
    if what == 5:
        return good.astype(str), "points as strings"
    if what == 6:
        return good.astype(object), "points object dtype"
    if what == 7:
        return good.astype(np.complex128), "points complex"
    if what == 8:
        return good.astype(np.int32), "points int32"
    if what == 9:
        return np.zeros((0, 3)), "no points"
    if what == 10:
        p = good.copy()
        p[rng.random(n) < _pick(rng, [0.01, 0.5, 1.0])] = _pick(rng, [np.nan, np.inf, -np.inf])
        return p, "non-finite points"
    if what == 11:
        p = good.copy()
        p[rng.random(n) < _pick(rng, [0.01, 0.5, 1.0])] = _pick(rng, [F64_MAX, 1e300, -1e308,
                                                                        1e19])
        return p, "huge points"
    if what == 12:
        return good.astype(np.float32), "points float32"
    if what == 13:
        return good[:1], "one point"
    if what == 14:
        return None, "points None"
    return good * _pick(rng, [1e-9, 1e6, 0.0]), "scaled points"


def _bad_times(rng, n: int, good: np.ndarray) -> tuple[Any, str]:
    if n < 2:
        return np.full(n, 1e308), "times 1e308 for fewer than 2 points"
    what = int(rng.integers(16))
    if what == 0:
        t = np.linspace(0, DT, n)
        t[0], t[-1] = -F64_MAX, F64_MAX
        return t, "times first -max, last +max"
    if what == 1:
        return np.where(np.arange(n) % 2 == 0, F64_MAX, -F64_MAX), "times alternating +-max"
    if what == 2:
        t = np.linspace(0, DT, n)
        t[0], t[-1] = -1e308, 1e308
        return t, "times first -1e308, last +1e308"
    if what == 3:
        return good.tolist(), "times as a list"
    if what == 4:
        return tuple(good), "times as a tuple"
    if what == 5:
        k = int(_pick(rng, [-1, 1, -n, n]))
        return (good[:k] if k < 0 else np.concatenate([good, good[:k]])), f"times length {n}{k:+d}"
    if what == 6:
        return good[:, None], "times (N, 1)"
    if what == 7:
        return good.astype(str), "times as strings"
    if what == 8:
        t = good.copy()
        t[rng.random(n) < 0.3] = _pick(rng, [np.nan, np.inf, -np.inf])
        return t, "non-finite times"
    if what == 9:
        return np.full(n, _pick(rng, [0.0, 0.05, 1e308, -5.0])), "constant times"
    if what == 10:
        return good * _pick(rng, [-1.0, 100.0, 1e9, 1e300]), "scaled times"
    if what == 11:
        return (good * 1e9).astype(np.int64), "times int64 nanoseconds"
    if what == 12:
        return good + _pick(rng, [1.7e9, -1.7e9, 1e18]), "offset times"
    if what == 13:
        return good.astype(np.complex64), "times complex"
    if what == 14:
        return rng.uniform(-1, 1, n) * F64_MAX, "times random over float64"
    return good[::-1].copy(), "times reversed"


def _bad_scan(rng, world: _World, k: int):
    from lili_odom.pipeline.types import Scan

    s = world.scan(k)
    parts = []
    points, times, stamp = s.points, s.times, s.stamp
    choices = int(rng.integers(1, 8))
    if choices & 1:
        points, text = _bad_points(rng, points)
        parts.append(text)
        if isinstance(points, np.ndarray) and points.ndim == 2 and points.shape[1] == 3:
            times = times[: len(points)] if len(points) <= len(times) else times
    if choices & 2 or not parts:
        n = len(points) if hasattr(points, "__len__") else 0
        times, text = _bad_times(rng, n, np.linspace(0, DT, n))
        parts.append(text)
    if choices & 4:
        stamp = _pick(rng, _BAD_STAMPS + [s.stamp - DT, s.stamp - 50.0, s.stamp + 1e6,
                                          s.stamp - 1e-3])
        parts.append(f"stamp {one_line(repr(stamp), 40)}")
    if rng.random() < 0.1:
        parts.append("dropped 'x'")
        return Scan(stamp, points, times, dropped="x"), ", ".join(parts)
    return Scan(stamp, points, times), ", ".join(parts)


def _bad_vector(rng) -> tuple[Any, str]:
    v = _pick(rng, [np.zeros(2), np.zeros(4), np.full(3, np.nan), np.full(3, np.inf),
                    np.full(3, 1e308), np.full(3, -F64_MAX), [0.0, 0.0, 9.8], "abc", None,
                    np.zeros((3, 3)), np.array(["a", "b", "c"]), np.full(3, 1e4),
                    np.zeros(3, np.complex128), 5.0])
    return v, one_line(repr(v), 40)


def _bad_imu(rng, world: _World, t: float):
    from lili_odom.pipeline.types import ImuSample

    s = world.imu(t)
    what = int(rng.integers(4))
    if what == 0:
        s.stamp = _pick(rng, _BAD_STAMPS + [t - 5.0, t + 100.0, t - 1e-4])
        return s, f"IMU stamp {one_line(repr(s.stamp), 40)}"
    v, text = _bad_vector(rng)
    if what == 1:
        s.angular_velocity = v
        return s, f"IMU gyro {text}"
    if what == 2:
        s.linear_acceleration = v
        return s, f"IMU acc {text}"
    s.linear_acceleration = np.full(3, _pick(rng, [16 * 9.80665, 1e3, -1e3]))
    s.angular_velocity = np.full(3, _pick(rng, [34.9, 100.0]))
    return s, "IMU saturated"


def _bad_wheel(rng, world: _World, t: float):
    from lili_odom.pipeline.types import WheelSample

    s = world.wheel(t)
    what = int(rng.integers(5))
    if what == 0:
        s.stamp = _pick(rng, _BAD_STAMPS + [t - 5.0, t + 100.0])
        return s, f"wheel stamp {one_line(repr(s.stamp), 40)}"
    if what == 1:
        s.pose = _pick(rng, [None, np.eye(3), np.full((4, 4), np.nan), np.zeros((4, 4)),
                             np.eye(4) * 2, "pose", np.eye(4).tolist(), np.eye(4)[:3]])
        return s, f"wheel pose {one_line(repr(s.pose), 40)}"
    if what == 2:
        pose = np.eye(4)
        pose[:3, 3] = _pick(rng, [1e308, 1e6, np.inf, -F64_MAX])
        return WheelSample(s.stamp, s.twist, pose), "wheel pose teleport"
    if what == 3:
        s.twist, text = _bad_vector(rng)
        return s, f"wheel twist {text}"
    s.twist_covariance = _pick(rng, [np.full((6, 6), np.nan), np.zeros(5), "cov", -np.eye(6)])
    return s, "wheel covariance bad"


# ----------------------------------------------------------------------------- one case
def run_case(rng: np.random.Generator) -> Outcome:
    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
    from lili_odom.pipeline.validation import PipelineInputError

    method = "lili" if rng.random() < 0.125 else "none"
    world = _World(rng)
    pipe = OdometryPipeline(PipelineConfig(method=method))
    outputs = []
    parts = [method]

    def good_scan(k: int) -> Any:
        world.sensors_until(pipe, world.t0 + (k - 1) * DT + 0.2, world.t0 + k * DT + 0.2)
        out = pipe.process_scan(world.scan(k))
        if out is not None:
            outputs.append(out)
        return out

    for k in range(3):
        good_scan(k)
    n_bad = int(rng.integers(1, 4))
    documented = None
    for j in range(n_bad):
        kind = int(rng.integers(3))
        t = world.t0 + (3 + j / n_bad) * DT
        if kind == 0:
            bad, text = _bad_scan(rng, world, 3)
            call = pipe.process_scan
        elif kind == 1:
            bad, text = _bad_imu(rng, world, t)
            call = pipe.add_imu
        else:
            bad, text = _bad_wheel(rng, world, t)
            call = pipe.add_wheel
        parts.append(text)
        try:
            out = call(bad)
        except Exception as exc:  # noqa: BLE001 - classified
            outcome = from_exception(exc, (PipelineInputError,), "; ".join(parts))
            if outcome.status == OTHER:
                return outcome
            documented = outcome
            continue
        if out is not None:
            outputs.append(out)
    case = "; ".join(parts)
    try:
        good_scan(4)
        last = good_scan(5)
    except Exception as exc:  # noqa: BLE001 - a valid scan must never raise
        outcome = from_exception(exc, (), case)
        outcome.detail = "valid scan after the fault: " + outcome.detail
        return outcome
    for out in outputs:
        if not all_finite(out.pose, out.twist, out.covariance, out.stamp):
            return Outcome(NONFINITE, "non-finite output", case)
    if last is None:
        return Outcome(STALLED, f"no output for the last valid scan; counters "
                                f"{dict(pipe.counters)}", case)
    if documented is not None:
        return documented
    return Outcome(CLEAN, f"{len(outputs)} outputs", case)
