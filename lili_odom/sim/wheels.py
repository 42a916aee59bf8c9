"""Husky wheel odometry model (``/platform/odom``): diff-drive twist with errors, integrated
planar pose, as the Husky's diff_drive_controller does.

Truth: forward speed ``v`` = x component of the base_link velocity in base_link, yaw rate ``w`` =
z component of the body angular rate. Measured: ``v (1 + e_v) + slip + noise`` and
``w (1 + e_w) + noise (+ spurious rate while slipping)``, with per-run scale errors ``e_v``,
``e_w`` (drawn per seed, or fixed by ``WheelOdomConfig.scale_error`` / ``yaw_scale_error``).
Slips are Poisson events, or the fixed ``slip_events``. The pose in ``odom`` (x, y [m], yaw [rad])
is integrated from the measured twist (midpoint rule), starting at the identity at t = 0; z, roll,
pitch are zero (planar). During an ``outages`` window the controller keeps integrating but no
message is published (``published`` is False), as when the driver's messages are lost.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lili_odom.sim.sensors import WheelOdomConfig
from lili_odom.sim.trajectory import Trajectory

__all__ = ["WheelOdomData", "simulate_wheel_odom"]


@dataclass
class WheelOdomData:
    """Samples at times ``t`` (N,): measured ``v`` [m/s], ``w`` [rad/s] in base_link, integrated
    ``x``, ``y``, ``yaw`` in ``odom``; ``v_true``, ``w_true``; per-run ``scale`` (1 + e_v) and
    ``yaw_scale`` (1 + e_w); ``slipping`` (N,) bool; ``published`` (N,) bool (False inside an
    outage window)."""

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v_true: np.ndarray
    w_true: np.ndarray
    scale: float
    yaw_scale: float
    slipping: np.ndarray
    published: np.ndarray


def simulate_wheel_odom(traj: Trajectory, cfg: WheelOdomConfig, seed: int,
                        t_end: float | None = None) -> WheelOdomData:
    """Wheel odometry at ``cfg.rate_hz`` from t = 0 to ``t_end`` (default: trajectory end)."""
    t_end = traj.duration if t_end is None else t_end
    dt = 1.0 / cfg.rate_hz
    t = np.arange(0.0, t_end + 1e-9, dt)
    n = len(t)
    rng = np.random.default_rng([seed, 7201])
    k = traj.kinematics(t)
    v_body = np.einsum("nji,nj->ni", k.rotation, k.velocity)
    v_true = v_body[:, 0]
    w_true = k.omega[:, 2]
    e_v = float(np.clip(rng.normal(0.0, cfg.scale_sigma), -cfg.scale_max, cfg.scale_max))
    e_w = float(np.clip(rng.normal(0.0, cfg.yaw_scale_sigma), -2 * cfg.yaw_scale_sigma, 2 * cfg.yaw_scale_sigma))
    if cfg.scale_error is not None:
        e_v = float(cfg.scale_error)
    if cfg.yaw_scale_error is not None:
        e_w = float(cfg.yaw_scale_error)
    # slip events (Poisson in time, or the fixed list), effective only while driving
    slipping = np.zeros(n, bool)
    gain = np.zeros(n)
    spurious = np.zeros(n)
    if cfg.slip_events is not None:
        for t_ev, dur, g in cfg.slip_events:
            m = (t >= t_ev) & (t < t_ev + dur)
            slipping |= m
            gain[m] = g
            spurious[m] = rng.normal(0.0, cfg.slip_yaw_rate_sigma)
    t_ev = 0.0
    while cfg.slip_events is None and cfg.slip_rate_hz > 0:
        t_ev += rng.exponential(1.0 / cfg.slip_rate_hz)
        if t_ev > t_end:
            break
        dur = rng.uniform(*cfg.slip_duration_range)
        m = (t >= t_ev) & (t < t_ev + dur)
        slipping |= m
        gain[m] = rng.uniform(*cfg.slip_speed_gain_range)
        spurious[m] = rng.normal(0.0, cfg.slip_yaw_rate_sigma)
    moving = np.abs(v_true) > 0.05
    slipping &= moving
    gain *= slipping
    spurious *= slipping
    v = v_true * (1.0 + e_v) * (1.0 + gain) + rng.normal(0.0, cfg.v_sigma, n) * moving
    w = w_true * (1.0 + e_w) + spurious + rng.normal(0.0, cfg.w_sigma, n) * (moving | (np.abs(w_true) > 0.02))
    # integrate (midpoint), as the controller does each update
    yaw = np.r_[0.0, np.cumsum(w[:-1] * dt)]
    ym = yaw[:-1] + 0.5 * w[:-1] * dt
    x = np.r_[0.0, np.cumsum(v[:-1] * np.cos(ym) * dt)]
    y = np.r_[0.0, np.cumsum(v[:-1] * np.sin(ym) * dt)]
    published = np.ones(n, bool)
    for t0, t1 in cfg.outages:
        published &= ~((t >= t0) & (t < t1))
    return WheelOdomData(t=t, v=v, w=w, x=x, y=y, yaw=yaw, v_true=v_true, w_true=w_true,
                         scale=1.0 + e_v, yaw_scale=1.0 + e_w, slipping=slipping, published=published)
