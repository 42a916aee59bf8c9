"""Online calibration of the wheel odometry's distance scale from well-constrained LiDAR.

Inside a degenerate subspace the fused motion *is* the wheel motion, so a wheel scale error
becomes drift at the same rate: 1 % over a 200 m featureless tunnel is 2 m along its axis. Tyre
radius, load and surface change that scale by around a percent on a skid-steer robot, so it
cannot be trusted from the robot's description. Where the registration is not degenerate, the
LiDAR measures the same increments far better than the wheels; this module estimates

    s = (distance the wheels report) / (distance the LiDAR measured)

over the recent non-degenerate travel and divides the translation of every wheel increment
by it before the increment enters the graph.

Only increments that moved, that the LiDAR constrained fully (no degenerate direction), and
that agree with the LiDAR to within a slip gate are used; each counts with its distance and
older travel fades with ``window_m`` so a changed surface is followed. Until ``min_distance_m``
of such travel was seen, the scale is 1.

Frames and units: increments are 4x4 motions of base_link from the previous stamp, expressed
in base_link at the previous stamp [m]; the scale is dimensionless.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["WheelScaleConfig", "WheelScaleEstimator"]


@dataclass
class WheelScaleConfig:
    """Attributes:
        enabled: estimate and apply the wheel distance scale (False: scale 1).
        min_distance_m: LiDAR-constrained travel needed before the estimate is applied [m].
        window_m: travel over which old increments fade (exponential, per metre) [m].
        min_scale / max_scale: the estimate is clamped to this range.
        slip_gate_m / slip_gate_ratio: an increment whose wheel and LiDAR distances differ by
            more than ``slip_gate_m + slip_gate_ratio * distance`` is not used (slip, bad
            registration).
    """

    enabled: bool = True
    min_distance_m: float = 5.0
    window_m: float = 200.0
    min_scale: float = 0.8
    max_scale: float = 1.25
    slip_gate_m: float = 0.02
    slip_gate_ratio: float = 0.2

    def validate(self, prefix: str = "wheel_scale.") -> None:
        from lili_odom.errors import check_range

        check_range(prefix + "min_distance_m", self.min_distance_m, 0.0, 1e4, unit="m")
        check_range(prefix + "window_m", self.window_m, 0.0, 1e6, lo_open=True, unit="m")
        check_range(prefix + "min_scale", self.min_scale, 0.0, 1.0, lo_open=True)
        check_range(prefix + "max_scale", self.max_scale, 1.0, 100.0)
        check_range(prefix + "slip_gate_m", self.slip_gate_m, 0.0, 10.0, unit="m")
        check_range(prefix + "slip_gate_ratio", self.slip_gate_ratio, 0.0, 10.0)


class WheelScaleEstimator:
    """Running estimate of the wheel distance scale (see module docstring)."""

    def __init__(self, config: WheelScaleConfig | None = None) -> None:
        self.config = config or WheelScaleConfig()
        self.wheel_m = 0.0   # faded sum of wheel distances [m]
        self.lidar_m = 0.0   # faded sum of the LiDAR distances along the wheel direction [m]
        self.used = 0
        self.rejected = 0

    def observe(self, wheel_delta: np.ndarray, lidar_delta: np.ndarray) -> bool:
        """Add one increment pair; returns True when it was used.

        Args:
            wheel_delta: the *raw* wheel increment (4x4).
            lidar_delta: the fully constrained LiDAR increment over the same interval (4x4).
        """
        dw = np.asarray(wheel_delta, dtype=float)[:3, 3]
        dl = np.asarray(lidar_delta, dtype=float)[:3, 3]
        n = float(np.linalg.norm(dw))
        if not (np.all(np.isfinite(dw)) and np.all(np.isfinite(dl))) or n < 1e-3:
            return False
        along = float(dl @ (dw / n))  # LiDAR distance along the wheels' direction of travel
        cfg = self.config
        if abs(along - n) > cfg.slip_gate_m + cfg.slip_gate_ratio * n:
            self.rejected += 1
            return False
        fade = math.exp(-n / cfg.window_m)
        self.wheel_m = self.wheel_m * fade + n
        self.lidar_m = self.lidar_m * fade + along
        self.used += 1
        return True

    @property
    def scale(self) -> float:
        """Wheel distance per LiDAR distance (1 until enough travel was observed)."""
        cfg = self.config
        if not cfg.enabled or self.lidar_m < cfg.min_distance_m or self.lidar_m <= 0:
            return 1.0
        return float(np.clip(self.wheel_m / self.lidar_m, cfg.min_scale, cfg.max_scale))

    def correct(self, wheel_delta: np.ndarray) -> np.ndarray:
        """``wheel_delta`` with its translation divided by the scale (a new array)."""
        out = np.array(wheel_delta, dtype=float)
        out[:3, 3] /= self.scale
        return out
