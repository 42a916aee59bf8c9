"""Wheel odometry: noise model of one increment and a pose buffer.

Frames and units: the wheel odometry (Husky ``/platform/odom``) gives the pose of ``base_link``
in its own ``odom`` frame [m, rad]. Only *relative* motions are used: the increment between two
stamps, expressed in ``base_link`` at the earlier stamp, ``T(t0)^-1 T(t1)``. Information
matrices are 6x6 in our twist order ``(v, w)`` in ``base_link`` at the later stamp (the tangent
space of GTSAM's ``BetweenFactorPose3`` error, reordered).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from lili_odom.geometry import exp, is_valid_pose, log, orthonormalize

__all__ = ["WheelNoiseConfig", "WheelBuffer", "wheel_information"]


@dataclass
class WheelNoiseConfig:
    """Per-increment wheel odometry noise of a skid-steer Husky (1-sigma).

    Each sigma is ``floor + per_metre * distance (+ per_rad * |yaw change|)`` for the increment.
    Skid-steer yaw from wheels is poor (slip while turning) and wheel odometry is planar, so
    vertical motion, roll and pitch get loose sigmas.

    Attributes:
        forward_floor: [m] along base_link x.
        forward_per_metre: [m/m] slip/scale error per metre travelled.
        lateral_floor: [m] along base_link y.
        lateral_per_metre: [m/m] side slip per metre travelled.
        vertical_floor: [m] along base_link z.
        vertical_per_metre: [m/m].
        yaw_floor: [rad].
        yaw_per_rad: [rad/rad] of the measured yaw change.
        yaw_per_metre: [rad/m].
        tilt_floor: [rad] roll and pitch.
        tilt_per_metre: [rad/m] roll and pitch.
        max_interpolation_gap_s: wheel samples farther apart than this [s] are not
            interpolated between (the increment is then unavailable).
        max_extrapolation_s: how far [s] beyond the newest sample a query may be answered by
            holding the last pose.
        buffer_seconds: history kept [s].
    """

    forward_floor: float = 0.005
    forward_per_metre: float = 0.05
    lateral_floor: float = 0.005
    lateral_per_metre: float = 0.05
    vertical_floor: float = 0.02
    vertical_per_metre: float = 0.2
    yaw_floor: float = 0.002
    yaw_per_rad: float = 0.3
    yaw_per_metre: float = 0.02
    tilt_floor: float = 0.01
    tilt_per_metre: float = 0.1
    max_interpolation_gap_s: float = 0.5
    max_extrapolation_s: float = 0.05
    buffer_seconds: float = 30.0

    def validate(self, prefix: str = "wheel.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")``."""
        from lili_odom.errors import check_range

        for name in ("forward_floor", "lateral_floor", "vertical_floor", "yaw_floor",
                     "tilt_floor"):  # a zero sigma would be an infinite information
            check_range(prefix + name, getattr(self, name), 0.0, 1e3, lo_open=True)
        for name in ("forward_per_metre", "lateral_per_metre", "vertical_per_metre",
                     "yaw_per_rad", "yaw_per_metre", "tilt_per_metre"):
            check_range(prefix + name, getattr(self, name), 0.0, 1e3)
        check_range(prefix + "max_interpolation_gap_s", self.max_interpolation_gap_s, 0.0,
                    60.0, lo_open=True, unit="s")
        check_range(prefix + "max_extrapolation_s", self.max_extrapolation_s, 0.0, 1.0, unit="s")
        check_range(prefix + "buffer_seconds", self.buffer_seconds, 1.0, 3600.0, unit="s")


def wheel_information(delta: np.ndarray, cfg: WheelNoiseConfig) -> np.ndarray:
    """6x6 information ``(v, w)`` of one wheel increment ``delta`` (4x4, base_link)."""
    xi = log(delta)
    dist = float(np.linalg.norm(xi[:3]))
    dyaw = abs(float(xi[5]))
    sig = np.array([
        cfg.forward_floor + cfg.forward_per_metre * dist,
        cfg.lateral_floor + cfg.lateral_per_metre * dist,
        cfg.vertical_floor + cfg.vertical_per_metre * dist,
        cfg.tilt_floor + cfg.tilt_per_metre * dist,
        cfg.tilt_floor + cfg.tilt_per_metre * dist,
        cfg.yaw_floor + cfg.yaw_per_rad * dyaw + cfg.yaw_per_metre * dist,
    ])
    return np.diag(1.0 / sig**2)


class WheelBuffer:
    """Time-ordered wheel odometry poses with SE(3) interpolation.

    ``add`` rejects non-finite or invalid poses and duplicates (counters), keeps the buffer
    sorted when messages arrive out of order, and holds back poses whose stamp jumps away
    from the buffer's timeline until the jump is confirmed (a single corrupt stamp far in the
    future would otherwise prune every other pose; see
    :class:`lili_odom.fusion.imu.StampJumpFilter`).
    """

    def __init__(self, cfg: WheelNoiseConfig | None = None, max_stamp_jump_s: float = 1.0
                 ) -> None:
        from lili_odom.fusion.imu import StampJumpFilter

        self.cfg = cfg or WheelNoiseConfig()
        self._t: list[float] = []
        self._T: list[np.ndarray] = []
        self.jumps = StampJumpFilter(max_stamp_jump_s, self.cfg.buffer_seconds)
        self.n_added = 0
        self.n_invalid = 0
        self.n_duplicates = 0
        self.n_out_of_order = 0
        self.n_held = 0

    def __len__(self) -> int:
        return len(self._t)

    @property
    def newest_time(self) -> float | None:
        return self._t[-1] if self._t else None

    def add(self, t: float, T_odom_base: np.ndarray) -> bool:
        """Insert the wheel pose of base_link at ``t`` [s]; False when rejected."""
        try:
            t = float(t)
            T = np.asarray(T_odom_base, dtype=np.float64)
        except (TypeError, ValueError):
            self.n_invalid += 1
            return False
        if not math.isfinite(t) or not is_valid_pose(T, tol=1e-4):
            self.n_invalid += 1
            return False
        T = orthonormalize(T)
        verdict, released = self.jumps.offer(t, T, self.newest_time)
        if verdict == "held":
            self.n_held += 1
            return False
        if verdict == "backward":
            self._t.clear()
            self._T.clear()
        if released:
            for tr, Tr in released:
                self._insert(tr, Tr)
            return True
        return self._insert(t, T)

    def _insert(self, t: float, T: np.ndarray) -> bool:
        i = bisect.bisect_left(self._t, t)
        if (i < len(self._t) and abs(self._t[i] - t) < 1e-6) or (
            i > 0 and abs(self._t[i - 1] - t) < 1e-6
        ):
            self.n_duplicates += 1
            return False
        if i < len(self._t):
            self.n_out_of_order += 1
        self._t.insert(i, t)
        self._T.insert(i, T)
        self.n_added += 1
        horizon = self._t[-1] - self.cfg.buffer_seconds
        k = bisect.bisect_left(self._t, horizon) - 1
        if k > 0:
            del self._t[:k]
            del self._T[:k]
        return True

    def samples(self, t0: float, t1: float) -> list[tuple[float, np.ndarray]]:
        """``(t, T_odom_base)`` pairs with t0 <= t <= t1 (sorted)."""
        a = bisect.bisect_left(self._t, t0)
        b = bisect.bisect_right(self._t, t1)
        return list(zip(self._t[a:b], self._T[a:b]))

    def pose_at(self, t: float) -> np.ndarray | None:
        """Wheel pose at ``t`` (interpolated on SE(3)); None when not covered."""
        if not self._t or not math.isfinite(t):
            return None
        i = bisect.bisect_left(self._t, t)
        if i < len(self._t) and abs(self._t[i] - t) < 1e-9:
            return self._T[i]
        if i == 0:
            return self._T[0] if self._t[0] - t <= self.cfg.max_extrapolation_s else None
        if i == len(self._t):
            return self._T[-1] if t - self._t[-1] <= self.cfg.max_extrapolation_s else None
        ta, tb = self._t[i - 1], self._t[i]
        if tb - ta > self.cfg.max_interpolation_gap_s:
            return None
        w = (t - ta) / (tb - ta)
        Ta = self._T[i - 1]
        return Ta @ exp(w * log(np.linalg.inv(Ta) @ self._T[i]))

    def delta(self, t0: float, t1: float) -> np.ndarray | None:
        """Motion of base_link from ``t0`` to ``t1``, in base_link at ``t0``; None if unknown."""
        a = self.pose_at(t0)
        b = self.pose_at(t1)
        if a is None or b is None:
            return None
        return np.linalg.inv(a) @ b
