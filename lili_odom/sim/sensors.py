"""Sensor and platform parameters of the simulated Clearpath Husky + Ouster OS1-128, in one place.

Every number is fixed here, before any method is compared, with where it comes from. Frames:
``base_link`` (Husky body, REP-103, origin on the centre line at axle-ish height), ``os_sensor``
(Ouster housing base), ``os_lidar`` (beam origin, yawed 180 deg from ``os_sensor``), ``os_imu``.
Units: SI (m, s, rad), noise densities per sqrt(Hz).

Sources (abbreviated in the comments below):

* [OS1] Ouster OS1 rev6 datasheet and the Ouster sensor user manual (beam layout, frames,
  ``lidar_to_sensor_transform`` / ``imu_to_sensor_transform`` defaults of the OS1).
* [ouster-ros] ouster-ros driver defaults (``timestamp_mode`` TIME_FROM_INTERNAL_OSC,
  ``point_type: original``, frame names ``os_sensor`` / ``os_lidar`` / ``os_imu``).
* [ICM] TDK InvenSense ICM-20948 datasheet (the IMU inside the OS1).
* [Husky] Clearpath ``husky_description`` URDF and ``husky_control`` control.yaml
  (wheel radius, track, wheelbase, ``wheel_separation_multiplier``, 50 Hz odom).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lili_odom.extrinsics import (HUSKY_BASE_TO_SENSOR, OS1_SENSOR_TO_IMU, OS1_SENSOR_TO_LIDAR,
                                  pose_from_xyz_rpy)

__all__ = [
    "LidarConfig",
    "ImuConfig",
    "WheelOdomConfig",
    "HuskyConfig",
    "Extrinsics",
    "SensorSuite",
    "default_sensors",
    "parse_resolution",
]


@dataclass
class LidarConfig:
    """Ouster OS1-128 in 1024x10 mode."""

    rows: int = 128                 # [OS1] 128 channels
    cols: int = 1024                # [OS1] lidar_mode 1024x10
    rate_hz: float = 10.0           # [OS1] 10 Hz rotation
    elevation_max_deg: float = 22.5  # [OS1] vertical FOV 45 deg, uniform beam spacing (+22.5..-22.5)
    elevation_min_deg: float = -22.5
    range_sigma: float = 0.03       # [OS1] range accuracy class ~ +-3 cm (Gaussian sigma here)
    min_range: float = 0.3          # [OS1] minimum range 0.3 m (closer: no return)
    max_range: float = 120.0        # [OS1] rev6: 120 m on an 80 % target
    max_range_reflectivity: float = 0.8  # reflectivity at which max_range holds ([OS1]: 45 m @ 10 %)
    dropout: float = 0.002          # random missing returns (dust, multi-path); assumption
    range_resolution_m: float = 0.001  # [OS1] range reported in mm

    @property
    def scan_period(self) -> float:
        return 1.0 / self.rate_hz

    def elevations(self) -> np.ndarray:
        """Beam elevation [rad] per ring; ring 0 is the top beam ([OS1] channel order)."""
        return np.deg2rad(np.linspace(self.elevation_max_deg, self.elevation_min_deg, self.rows))

    def azimuths(self) -> np.ndarray:
        """Azimuth [rad] of column j in ``os_lidar``: column 0 looks along +x, columns advance
        clockwise seen from above ([OS1] encoder angle 2*pi*(1 - j/cols))."""
        return 2.0 * np.pi * (1.0 - np.arange(self.cols) / self.cols)

    def column_times(self) -> np.ndarray:
        """Column timestamps [s] from the scan start: ``j * period / cols`` ([ouster-ros] ``t``)."""
        return np.arange(self.cols) * (self.scan_period / self.cols)


@dataclass
class ImuConfig:
    """ICM-20948 inside the OS1, published by ouster-ros at 100 Hz in ``os_imu``."""

    rate_hz: float = 100.0                  # [ouster-ros] IMU packets at 100 Hz
    gyro_noise_density: float = 2.618e-4    # [ICM] 0.015 dps/sqrt(Hz) -> rad/s/sqrt(Hz)
    accel_noise_density: float = 2.256e-3   # [ICM] 230 ug/sqrt(Hz) -> m/s^2/sqrt(Hz)
    gyro_bias_walk: float = 1.0e-5          # rad/s^2/sqrt(Hz): typical Allan-variance figure for
    accel_bias_walk: float = 1.0e-4         # m/s^3/sqrt(Hz): this MEMS class (not in [ICM])
    gyro_bias_sigma0: float = 3.5e-3        # rad/s (0.2 dps) turn-on bias left after calibration
    accel_bias_sigma0: float = 0.05         # m/s^2 (5 mg) turn-on bias left after calibration
    gravity: float = 9.80665                # m/s^2, standard gravity

    @property
    def gyro_sigma(self) -> float:
        """Discrete white-noise sigma per sample [rad/s]."""
        return self.gyro_noise_density * math.sqrt(self.rate_hz)

    @property
    def accel_sigma(self) -> float:
        """Discrete white-noise sigma per sample [m/s^2]."""
        return self.accel_noise_density * math.sqrt(self.rate_hz)


@dataclass
class HuskyConfig:
    """Clearpath Husky A200 geometry ([Husky] URDF)."""

    wheel_radius: float = 0.1651        # [Husky] 13 in wheels
    track: float = 0.555                # [Husky] wheel separation (left-right)
    wheelbase: float = 0.512            # [Husky] front-rear axle distance
    base_height: float = 0.1323         # base_link above the contact plane: wheel_radius - 0.0328
    separation_multiplier: float = 1.875  # [Husky] control.yaml skid-steer wheel_separation_multiplier


@dataclass
class WheelOdomConfig:
    """Husky diff-drive odometry on ``/platform/odom`` (50 Hz, ``odom`` -> ``base_link``)."""

    rate_hz: float = 50.0            # [Husky] diff_drive_controller publish_rate 50
    scale_sigma: float = 0.03        # per-run linear scale error (tyre radius / load), ~3 % 1-sigma
    scale_max: float = 0.05          # clipped to +-5 %
    yaw_scale_sigma: float = 0.05    # skid-steer yaw-rate scale error (effective track), 1-sigma
    v_sigma: float = 0.01            # m/s white noise on the forward speed
    w_sigma: float = 0.02            # rad/s white noise on the yaw rate
    slip_rate_hz: float = 1.0 / 40.0  # occasional slip events (Poisson), while moving
    slip_duration_range: tuple[float, float] = (0.3, 1.5)  # s
    slip_speed_gain_range: tuple[float, float] = (0.1, 0.35)  # measured speed over-reads by this
    slip_yaw_rate_sigma: float = 0.03  # rad/s spurious yaw rate during a slip (one side spins)
    # Fixed error profile (scenario data); the defaults keep the random model above.
    scale_error: float | None = None      # fixed speed scale error e_v (0.03 = over-reads 3 %)
    yaw_scale_error: float | None = None  # fixed yaw-rate scale error e_w
    slip_events: tuple[tuple[float, float, float], ...] | None = None  # (t [s], duration [s], gain)
    outages: tuple[tuple[float, float], ...] = ()  # [t0, t1) trial-time windows without messages


@dataclass
class Extrinsics:
    """Rigid transforms ``T_parent_child`` (4x4, maps child points into parent)."""

    # base_link -> os_sensor: OS1 on a 0.40 m mast on the Husky top plate, 0.10 m forward of
    # the centre (top plate at ~0.25 m above base_link). A plausible research mount.
    base_to_sensor: np.ndarray = field(default_factory=lambda: pose_from_xyz_rpy(HUSKY_BASE_TO_SENSOR))
    # os_sensor -> os_lidar: [OS1] lidar_to_sensor_transform, 180 deg yaw and 36.18 mm up
    sensor_to_lidar: np.ndarray = field(default_factory=lambda: pose_from_xyz_rpy(OS1_SENSOR_TO_LIDAR))
    # os_sensor -> os_imu: [OS1] imu_to_sensor_transform, (6.253, -11.775, 7.645) mm, no rotation
    sensor_to_imu: np.ndarray = field(default_factory=lambda: pose_from_xyz_rpy(OS1_SENSOR_TO_IMU))

    @property
    def base_to_lidar(self) -> np.ndarray:
        return self.base_to_sensor @ self.sensor_to_lidar

    @property
    def base_to_imu(self) -> np.ndarray:
        return self.base_to_sensor @ self.sensor_to_imu

    def as_dict(self) -> dict[str, np.ndarray]:
        """``{"base_link->os_sensor": T, "os_sensor->os_lidar": T, "os_sensor->os_imu": T}``."""
        return {
            "base_link->os_sensor": self.base_to_sensor.copy(),
            "os_sensor->os_lidar": self.sensor_to_lidar.copy(),
            "os_sensor->os_imu": self.sensor_to_imu.copy(),
        }


@dataclass
class SensorSuite:
    """Everything the simulator needs to know about the robot."""

    lidar: LidarConfig = field(default_factory=LidarConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    wheels: WheelOdomConfig = field(default_factory=WheelOdomConfig)
    husky: HuskyConfig = field(default_factory=HuskyConfig)
    extrinsics: Extrinsics = field(default_factory=Extrinsics)
    truth_rate_hz: float = 100.0   # /ground_truth/odom rate


def parse_resolution(text: str) -> tuple[int, int]:
    """``"128x1024"`` -> (rows, cols)."""
    try:
        rows, cols = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise ValueError(f"resolution must look like 128x1024, got {text!r}") from exc
    if rows < 1 or cols < 8:
        raise ValueError(f"bad resolution {text!r}")
    return rows, cols


def default_sensors(resolution: tuple[int, int] | str = (128, 1024)) -> SensorSuite:
    """The fixed sensor suite; ``resolution`` = (rows, cols) for reduced CI bags."""
    if isinstance(resolution, str):
        resolution = parse_resolution(resolution)
    suite = SensorSuite()
    suite.lidar.rows, suite.lidar.cols = resolution
    return suite
