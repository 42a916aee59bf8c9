"""IMU model: specific force and angular rate of ``os_imu`` from the true trajectory, plus noise.

Outputs are in ``os_imu`` (the OS1's ICM-20948): ``gyro`` [rad/s] = true body angular rate +
bias + white noise; ``accel`` [m/s^2] = specific force ``R_world_imu^T (a_world - g_world)``
(so +9.81 on z at rest, level) + bias + white noise. Biases start from a small turn-on offset and
random-walk (``ImuConfig``). Kinematics come from central differences of the analytic
trajectory of the ``os_imu`` origin (lever arm included). No orientation is produced.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lili_odom.sim.sensors import ImuConfig
from lili_odom.sim.trajectory import Trajectory

__all__ = ["ImuData", "simulate_imu", "true_imu", "turn_on_biases"]


@dataclass
class ImuData:
    """``t`` (N,) trial time [s]; ``gyro``, ``accel`` (N, 3) in os_imu; true biases (N, 3)."""

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray


def true_imu(traj: Trajectory, t: np.ndarray, T_base_imu: np.ndarray, gravity: float = 9.80665) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free (angular rate, specific force) of the ``os_imu`` frame at times ``t``."""
    k = traj.kinematics(t, T_base_imu)
    g = np.array([0.0, 0.0, -gravity])
    f_world = k.acceleration - g
    f_body = np.einsum("nji,nj->ni", k.rotation, f_world)
    return k.omega, f_body


def _imu_rng(seed: int) -> np.random.Generator:
    return np.random.default_rng([seed, 7101])


def _draw_turn_on(rng: np.random.Generator, cfg: ImuConfig) -> tuple[np.ndarray, np.ndarray]:
    bg0 = rng.normal(0.0, cfg.gyro_bias_sigma0, 3)
    ba0 = rng.normal(0.0, cfg.accel_bias_sigma0, 3)
    return bg0, ba0


def turn_on_biases(cfg: ImuConfig, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(gyro [rad/s], accelerometer [m/s^2]) turn-on biases, ``os_imu`` frame, that
    :func:`simulate_imu` starts its random walks from for ``seed``."""
    return _draw_turn_on(_imu_rng(seed), cfg)


def simulate_imu(traj: Trajectory, T_base_imu: np.ndarray, cfg: ImuConfig, seed: int,
                 t_end: float | None = None) -> ImuData:
    """IMU samples at ``cfg.rate_hz`` from t = 0 to ``t_end`` (default: trajectory end).

    The whole trial is always generated from t = 0 so that a piece (``--start``) sees the same
    samples and bias history as the full run."""
    t_end = traj.duration if t_end is None else t_end
    dt = 1.0 / cfg.rate_hz
    t = np.arange(0.0, t_end + 1e-9, dt)
    n = len(t)
    rng = _imu_rng(seed)
    w, f = true_imu(traj, t, T_base_imu, cfg.gravity)
    bg0, ba0 = _draw_turn_on(rng, cfg)
    bg = bg0 + np.cumsum(rng.normal(0.0, cfg.gyro_bias_walk * np.sqrt(dt), (n, 3)), 0)
    ba = ba0 + np.cumsum(rng.normal(0.0, cfg.accel_bias_walk * np.sqrt(dt), (n, 3)), 0)
    gyro = w + bg + rng.normal(0.0, cfg.gyro_sigma, (n, 3))
    accel = f + ba + rng.normal(0.0, cfg.accel_sigma, (n, 3))
    return ImuData(t=t, gyro=gyro, accel=accel, gyro_bias=bg, accel_bias=ba)
