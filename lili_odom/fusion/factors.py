"""GTSAM factors of one fusion update (keys ``X(i)``, ``V(i)``, ``B(i)`` of state i).

All informations are 6x6 in ``(v, w)`` order (translation [m], rotation [rad]) in the body
frame of ``base_link``; GTSAM's ``Pose3`` tangent is ``(w, v)``, so matrices are permuted at
this boundary (:func:`to_gtsam_matrix`). GTSAM's ``BetweenFactorPose3`` error is
``Logmap(Z^-1 X(i-1)^-1 X(i))``, a twist in the body frame of ``X(i)``.

* :func:`add_lidar_factors`: the registration as a ``prior``, a ``between`` or a ``hybrid``
  (prior in translation and yaw, between in roll and pitch) factor.
* :func:`add_subspace_factor`: the LiDAR's own measurement inside the degenerate subspace.
* :func:`add_wheel_factor`: the wheel increment, with its information restricted to the
  degenerate subspace.
* :func:`add_motion_model_factors`: what replaces the IMU factor on an interval without IMU.

With ``frame`` (the key of the odometry frame's pose in the gravity frame,
``FusionConfig.gravity_variable``) the poses ``X(i)`` are in the gravity frame and an absolute
factor at a pose ``T`` of the odometry frame is a ``BetweenFactorPose3(frame, X(i), T)``
(error ``Logmap(T^-1 F^-1 X(i))``, the prior's error on the pose in the odometry frame);
without it a ``PriorFactorPose3(X(i), T)``. Relative factors are the same in both frames.
"""
from __future__ import annotations

import math
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from lili_odom.fusion.config import FusionConfig
from lili_odom.fusion.subspace import restrict_information, sqrt_information
from lili_odom.geometry import orthonormalize

__all__ = ["absolute_factor", "add_cruise_factor", "add_lidar_factors",
           "add_motion_model_factors", "add_subspace_factor", "add_wheel_factor",
           "from_gtsam_matrix", "noise_from_information", "robust_kernel", "to_gtsam_matrix"]

# base_link roll and pitch (rows of the (v, w) identity) and the other four directions
TILT = np.eye(6)[[3, 4]]
NOT_TILT = np.eye(6)[[0, 1, 2, 5]]

# (v, w) <-> (w, v) permutation for 6x6 matrices.
_SWAP = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])


def to_gtsam_matrix(m: np.ndarray) -> np.ndarray:
    """6x6 matrix in ``(v, w)`` order -> GTSAM's ``(w, v)`` order (and back: it is its own
    inverse)."""
    return _SWAP @ m @ _SWAP


from_gtsam_matrix = to_gtsam_matrix


def noise_from_information(omega_vw: np.ndarray) -> gtsam.noiseModel.Base:
    """GTSAM Gaussian noise model from a PSD information in (v, w) order.

    ``Gaussian.Information`` runs an LLT that silently yields NaNs on a singular matrix, so the
    square root is built from an eigendecomposition and made upper triangular by QR.
    """
    R = sqrt_information(to_gtsam_matrix(omega_vw))
    R = np.linalg.qr(R, mode="r")
    return gtsam.noiseModel.Gaussian.SqrtInformation(np.asarray(R), False)


def robust_kernel(name: str, threshold: float) -> Any:
    """GTSAM M-estimator ``name`` (``none`` | ``huber`` | ``cauchy``) at a whitened threshold."""
    if name == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(threshold)
    if name == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(threshold)
    return None


def _robust(noise: gtsam.noiseModel.Base, kernel: Any) -> gtsam.noiseModel.Base:
    return noise if kernel is None else gtsam.noiseModel.Robust.Create(kernel, noise)


def absolute_factor(key: int, pose: np.ndarray, noise: gtsam.noiseModel.Base,
                    frame: int | None = None) -> gtsam.NonlinearFactor:
    """A factor on the pose ``key`` at ``pose`` (4x4, odometry frame): a prior, or with
    ``frame`` a between factor from the odometry frame's pose in the gravity frame."""
    if frame is None:
        return gtsam.PriorFactorPose3(key, gtsam.Pose3(pose), noise)
    return gtsam.BetweenFactorPose3(frame, key, gtsam.Pose3(pose), noise)


def add_lidar_factors(graph: gtsam.NonlinearFactorGraph, i: int, form: str,
                      T_prev: np.ndarray, T_meas: np.ndarray, target: np.ndarray,
                      information: np.ndarray, kernel: Any, frame: int | None = None) -> None:
    """The registration's factor(s) on ``X(i)``.

    ``form`` ``"prior"``: a ``PriorFactorPose3`` at ``target`` (the registration, its
    degenerate components possibly replaced by the wheel prediction); ``"between"``: a
    ``BetweenFactorPose3`` from ``X(i-1)`` with ``Z = T_prev^-1 T_meas``; ``"hybrid"``: the prior
    with ``information`` restricted to translation and yaw, the between factor with it
    restricted to roll and pitch. ``T_prev``: previous fused pose, ``T_meas``: registration
    (4x4, base_link in the odometry frame); ``kernel``: M-estimator or None; ``frame``: key
    of the odometry frame in the gravity frame, or None (:func:`absolute_factor`).
    """
    if form == "prior":
        noise = _robust(noise_from_information(information), kernel)
        graph.add(absolute_factor(X(i), target, noise, frame))
    elif form == "hybrid":
        Z = orthonormalize(np.linalg.inv(T_prev) @ T_meas)
        absolute = _robust(noise_from_information(
            restrict_information(information, NOT_TILT, TILT)), kernel)
        graph.add(absolute_factor(X(i), target, absolute, frame))
        relative = _robust(noise_from_information(
            restrict_information(information, TILT, NOT_TILT)), kernel)
        graph.add(gtsam.BetweenFactorPose3(X(i - 1), X(i), gtsam.Pose3(Z), relative))
    else:
        Z = orthonormalize(np.linalg.inv(T_prev) @ T_meas)
        noise = _robust(noise_from_information(information), kernel)
        graph.add(gtsam.BetweenFactorPose3(X(i - 1), X(i), gtsam.Pose3(Z), noise))


def add_subspace_factor(graph: gtsam.NonlinearFactorGraph, i: int, pose: np.ndarray,
                        information: np.ndarray, kernel: Any, frame: int | None = None) -> None:
    """An absolute factor (:func:`absolute_factor`) on ``X(i)`` at the subspace-refined
    registration ``pose`` (4x4) with its base_link ``(v, w)`` ``information``."""
    noise = _robust(noise_from_information(information), kernel)
    graph.add(absolute_factor(X(i), pose, noise, frame))


def add_wheel_factor(graph: gtsam.NonlinearFactorGraph, i: int, delta: np.ndarray,
                     information: np.ndarray) -> None:
    """A ``BetweenFactorPose3`` ``X(i-1) -> X(i)`` at the wheel increment ``delta`` (4x4)."""
    graph.add(gtsam.BetweenFactorPose3(X(i - 1), X(i), gtsam.Pose3(delta),
                                       noise_from_information(information)))


def add_cruise_factor(graph: gtsam.NonlinearFactorGraph, i: int, sigma: float,
                      kernel: Any) -> None:
    """A factor holding the velocity constant from ``V(i-1)`` to ``V(i)`` (odometry frame)
    with standard deviation ``sigma`` [m/s] per axis; ``kernel``: M-estimator or None."""
    noise = _robust(gtsam.noiseModel.Isotropic.Sigma(3, max(sigma, 1e-9)), kernel)
    graph.add(gtsam.BetweenFactorPoint3(V(i - 1), V(i), np.zeros(3), noise))


def add_motion_model_factors(graph: gtsam.NonlinearFactorGraph, i: int, motion: np.ndarray,
                             information: np.ndarray | None, velocity: np.ndarray, dt: float,
                             cfg: FusionConfig) -> None:
    """What replaces the IMU factor on an interval of ``dt`` [s] without IMU: a
    ``BetweenFactorPose3`` at the constant-twist ``motion`` (4x4) when ``information`` is given
    (already restricted to the LiDAR-blind directions), a loose prior (``no_imu_sigma_velocity``)
    on ``V(i)`` at ``velocity`` [m/s, odometry frame] and the bias random walk."""
    if information is not None:
        graph.add(gtsam.BetweenFactorPose3(X(i - 1), X(i), gtsam.Pose3(motion),
                                           noise_from_information(information)))
    graph.add(gtsam.PriorFactorVector(
        V(i), velocity, gtsam.noiseModel.Isotropic.Sigma(3, cfg.no_imu_sigma_velocity)))
    rw = np.array([cfg.imu.accel_bias_random_walk] * 3 + [cfg.imu.gyro_bias_random_walk] * 3)
    graph.add(gtsam.BetweenFactorConstantBias(
        B(i - 1), B(i), gtsam.imuBias.ConstantBias(),
        gtsam.noiseModel.Diagonal.Sigmas(np.maximum(rw * math.sqrt(dt), 1e-9))))
