"""The measurements of one fusion update, checked before they reach the factor graph.

* :func:`lidar_measurement`: the scan-to-map registration (pose of ``base_link`` in the
  odometry frame), the detected degenerate subspace (scaled LiDAR body twists ``(v, L w)``,
  characteristic length L [m]) and the registration's ``(v, w)`` information in the LiDAR
  body frame.
* :func:`wheel_increment`: the wheel motion of ``base_link`` between two stamps, in
  ``base_link`` at the earlier stamp, with its distance corrected by the online wheel scale
  and its ``(v, w)`` information in ``base_link``.

Whatever is invalid (non-finite, not rigid, physically implausible) is dropped, counted in
:class:`lili_odom.fusion.estimator.FusionStats` and explained in the update's notes; the
update goes on without it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from lili_odom.fusion.config import FusionConfig
from lili_odom.fusion.subspace import snap_basis
from lili_odom.fusion.wheel import WheelBuffer, wheel_information
from lili_odom.fusion.wheel_scale import WheelScaleEstimator
from lili_odom.geometry import orthonormalize, scaling_matrix

if TYPE_CHECKING:
    from lili_odom.fusion.estimator import FusionStats

__all__ = ["LidarMeasurement", "WheelIncrement", "as_pose", "finite", "lidar_measurement",
           "plausible", "registration_information", "wheel_increment"]

#: Largest standard deviation [m, scaled twists] the plane fits' covariance contributes to
#: :func:`registration_information` along a direction they hold less (or not at all).
MAX_PLANE_SIGMA = 1.0


def finite(*arrays: Any) -> bool:
    """True when every array (or number) converts to floats and all are finite."""
    try:
        return all(np.all(np.isfinite(np.asarray(a, dtype=float))) for a in arrays)
    except (TypeError, ValueError):
        return False


def as_pose(T: Any) -> np.ndarray | None:
    """A valid 4x4 rigid transform or None (non-finite, wrong shape, far from SO(3))."""
    try:
        T = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return None
    if np.abs(T[:3, 3]).max() > 1e7:  # beyond any odometry frame; would overflow later
        return None
    R = T[:3, :3]
    with np.errstate(over="ignore", invalid="ignore"):
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-3) or np.linalg.det(R) < 0.5:
            return None
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-6):
        return None
    return orthonormalize(T)


def plausible(delta: np.ndarray, dt: float, cfg: FusionConfig) -> bool:
    """True when the increment (4x4) is physically possible within ``dt`` seconds
    (``max_speed`` / ``max_rate`` plus the gate margins)."""
    trans = float(np.linalg.norm(delta[:3, 3]))
    cos_angle = 0.5 * (float(np.trace(delta[:3, :3])) - 1.0)
    angle = math.acos(min(1.0, max(-1.0, cos_angle)))
    return (trans <= cfg.max_speed * dt + cfg.gate_margin_translation
            and angle <= cfg.max_rate * dt + cfg.gate_margin_rotation)


@dataclass
class LidarMeasurement:
    """The registration as the fusion uses it.

    Attributes:
        pose: 4x4 pose of base_link in the odometry frame, or None (no LiDAR factor).
        basis: (k, 6) degenerate directions, scaled LiDAR body twists; (0, 6) when nothing
            is degenerate or there is no pose.
        length: characteristic length L [m] of the scaling.
        information: 6x6 ``(v, w)`` information in the LiDAR body frame.
    """

    pose: np.ndarray | None
    basis: np.ndarray
    length: float
    information: np.ndarray


def registration_information(configured: np.ndarray, planes: np.ndarray,
                             length: float) -> np.ndarray:
    """The registration's ``(v, w)`` information in the LiDAR body frame (6x6) from the
    configured one and the scan's point-to-plane information: their covariances add.

    ``configured``: 6x6 ``(v, w)`` information (``FusionConfig.lidar.information``), the
    floor of the registration's error however well the scene holds it. ``planes``: 6x6
    debiased point-to-plane information of the registration [1/m^2] over the scaled LiDAR
    body twists ``(v, L w)`` with characteristic length ``length`` L [m]; a direction it holds
    with less than ``1 / MAX_PLANE_SIGMA^2`` counts with that much. Where the planes hold
    every direction far better than the configured sigmas the result is about
    ``configured``; where they hold one weakly (sparse open ground) it is about the planes'
    own, so the fusion weighs the IMU against the registration by what the scene holds.
    """
    w, V = np.linalg.eigh(0.5 * (planes + planes.T))
    variances = 1.0 / np.maximum(w, MAX_PLANE_SIGMA**-2)
    unscale = scaling_matrix(1.0 / length)  # scaled (v, L w) -> plain (v, w)
    plane_cov = unscale @ (V * variances) @ V.T @ unscale
    cov = np.linalg.inv(configured) + plane_cov
    info = np.linalg.inv(cov)
    return 0.5 * (info + info.T)


def lidar_measurement(T_icp: Any, degeneracy: Any, lidar_information: Any, T_prev: np.ndarray,
                      dt: float, cfg: FusionConfig, stats: FusionStats,
                      notes: list[str]) -> LidarMeasurement:
    """Check the registration ``T_icp``, the detector result ``degeneracy`` (``basis_scaled``,
    ``characteristic_length``, ``ok``) and the optional ``lidar_information`` against the
    previous fused pose ``T_prev`` (4x4) and the interval ``dt`` [s]."""
    T_meas = as_pose(T_icp) if T_icp is not None else None
    if T_icp is not None and T_meas is None:
        stats.n_rejected_lidar += 1
        notes.append("LiDAR pose rejected (non-finite or not rigid)")
    basis = np.zeros((0, 6))
    length = cfg.lidar.default_length
    if T_meas is not None and degeneracy is not None and getattr(degeneracy, "ok", True):
        try:
            basis = np.asarray(degeneracy.basis_scaled, dtype=float).reshape(-1, 6)
            length = float(degeneracy.characteristic_length)
        except (AttributeError, TypeError, ValueError):
            basis, length = np.full((1, 6), np.nan), math.nan
        if not (finite(basis) and math.isfinite(length) and 1e-3 <= length <= 1e6):
            stats.n_rejected_basis += 1
            notes.append("degeneracy basis rejected (non-finite or absurd length); "
                         "LiDAR factor dropped")
            T_meas = None
            basis = np.zeros((0, 6))
            length = cfg.lidar.default_length
        else:
            basis = snap_basis(basis, cfg.lidar.basis_snap)
    omega = cfg.lidar.information()
    if lidar_information is not None:
        cand = np.asarray(lidar_information, dtype=float)
        if (cand.shape == (6, 6) and finite(cand)
                and np.linalg.eigvalsh(0.5 * (cand + cand.T)).min()
                >= -1e-9 * max(np.abs(cand).max(), 1.0)):
            omega = 0.5 * (cand + cand.T)
        else:
            stats.n_rejected_lidar_information += 1
            notes.append("LiDAR information rejected; using the configured one")
    if T_meas is not None and not plausible(np.linalg.inv(T_prev) @ T_meas, dt, cfg):
        stats.n_rejected_lidar += 1
        notes.append("LiDAR pose rejected (implausible jump from the previous fused pose)")
        T_meas = None
        basis = np.zeros((0, 6))
    return LidarMeasurement(T_meas, basis, length, omega)


@dataclass
class WheelIncrement:
    """The wheel increment as the fusion uses it (all None: no wheel data for the interval).

    Attributes:
        raw: 4x4 motion of base_link as the wheels report it, in base_link at the earlier
            stamp.
        corrected: the same with its translation divided by the online wheel scale.
        information: 6x6 ``(v, w)`` information of ``corrected`` in base_link.
    """

    raw: np.ndarray | None = None
    corrected: np.ndarray | None = None
    information: np.ndarray | None = None


def wheel_increment(t0: float, t1: float, wheel_delta: Any, wheel_info: Any,
                    wheels: WheelBuffer, scale: WheelScaleEstimator, cfg: FusionConfig,
                    stats: FusionStats, notes: list[str]) -> WheelIncrement:
    """The increment from ``t0`` to ``t1`` [s]: ``wheel_delta`` (4x4) when given, else from the
    wheel buffer; its information ``wheel_info`` (6x6) when given and valid, else
    ``cfg.wheel``'s."""
    if wheel_delta is not None:
        delta = as_pose(wheel_delta)
        if delta is None:
            stats.n_rejected_wheel += 1
            notes.append("wheel increment rejected")
    else:
        delta = wheels.delta(t0, t1)
        if delta is not None:
            delta = as_pose(delta)
    if delta is not None and not plausible(delta, t1 - t0, cfg):
        stats.n_rejected_wheel += 1
        notes.append("wheel increment rejected (implausible)")
        delta = None
    if delta is None:
        return WheelIncrement()
    corrected = scale.correct(delta)
    omega = wheel_information(corrected, cfg.wheel)
    if wheel_info is not None:
        cand = np.asarray(wheel_info, dtype=float)
        if cand.shape == (6, 6) and finite(cand):
            omega = 0.5 * (cand + cand.T)
        else:
            stats.n_rejected_wheel += 1
            notes.append("wheel information rejected; using the configured one")
    return WheelIncrement(delta, corrected, omega)
