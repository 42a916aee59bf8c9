"""The LiDAR's own information inside the degenerate subspace, and the wheel scale it teaches."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lili_odom.fusion import FusionConfig, FusionEstimator
from lili_odom.fusion.estimator import SubspaceMeasurement
from lili_odom.fusion.wheel_scale import WheelScaleConfig

AXIS_X = np.array([[1.0, 0, 0, 0, 0, 0]])


def step(x: float, y: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, y, 0.0]
    return T


def degenerate_x() -> SimpleNamespace:
    return SimpleNamespace(basis_scaled=AXIS_X, characteristic_length=10.0, ok=True)


def estimator(**lidar) -> FusionEstimator:
    cfg = FusionConfig(T_base_lidar=np.eye(4), T_base_imu=np.eye(4), use_imu=False)
    for k, v in lidar.items():
        setattr(cfg.lidar, k, v)
    return FusionEstimator(cfg)


def fused_x(information: float, **lidar) -> float:
    """One update: registration held at x = 0 along a degenerate x, wheels say 1.0, the LiDAR's
    point-to-plane refinement says 0.95 with ``information`` [1/m^2] along x."""
    est = estimator(**lidar)
    est.initialize(0.0)
    sub = SubspaceMeasurement(step(0.95, 0.3), information * AXIS_X.T @ AXIS_X, 10.0)
    out = est.update(1.0, step(0.0, 0.3), degenerate_x(), wheel_delta=step(1.0),
                     subspace=sub)
    assert out is not None and out.used_lidar and out.used_wheel
    assert out.pose[1, 3] == pytest.approx(0.3, abs=0.01)
    return float(out.pose[0, 3])


def test_a_weak_axis_keeps_the_lidars_information():
    assert fused_x(1e4) == pytest.approx(0.95, abs=0.015)


def test_without_lidar_information_the_wheels_carry_the_axis():
    assert fused_x(0.5) == pytest.approx(1.0, abs=0.005)  # below subspace_min_information
    assert fused_x(1e4, subspace_information=False) == pytest.approx(1.0, abs=0.005)


def test_subspace_information_is_capped_at_the_configured_lidar_information():
    # capped at 1 / 0.02^2: a claimed 1e8 weighs like 2500, so the wheels' anchor still counts
    assert fused_x(1e8) == pytest.approx(fused_x(2500.0), abs=1e-4)
    assert fused_x(1e8) > 0.951


def test_bad_subspace_measurement_is_rejected_not_raised():
    est = estimator()
    est.initialize(0.0)
    bad = SubspaceMeasurement(np.full((4, 4), np.nan), np.eye(6), 10.0)
    out = est.update(1.0, step(0.0), degenerate_x(), wheel_delta=step(1.0), subspace=bad)
    assert out is not None and out.pose[0, 3] == pytest.approx(1.0, abs=0.005)
    assert est.stats.n_rejected_lidar_information == 1


def drive_degenerate(information: float | None, metres: float, scale: float = 1.03,
                     config: WheelScaleConfig | None = None) -> FusionEstimator:
    """1 m/s along a degenerate x with long wheels; the registration is held at the wheels'
    prediction along x (as after solution remapping); the subspace refinement sees the truth."""
    cfg = FusionConfig(T_base_lidar=np.eye(4), T_base_imu=np.eye(4), use_imu=False,
                       wheel_scale=config or WheelScaleConfig())
    est = FusionEstimator(cfg)
    est.initialize(0.0)
    x, t = 0.0, 0.0
    for _ in range(int(round(metres / 0.1))):
        t += 0.1
        x += 0.1
        pred = est.wheel_prediction(t)
        held = step(pred[0, 3] if pred is not None else x)
        sub = (None if information is None
               else SubspaceMeasurement(step(x), information * AXIS_X.T @ AXIS_X, 10.0))
        assert est.update(t, held, degenerate_x(), wheel_delta=step(0.1 * scale),
                          subspace=sub) is not None
    return est


def test_wheel_scale_learns_along_a_degenerate_axis_the_lidar_still_holds():
    est = drive_degenerate(2500.0, 20.0)
    assert est.wheel_scale.scale == pytest.approx(1.03, rel=0.01)


def test_wheel_scale_does_not_learn_from_the_wheels_own_prediction():
    assert drive_degenerate(None, 20.0).wheel_scale.scale == 1.0
    # too weak along the direction of travel (sigma 10 cm > max_lidar_sigma 3 cm)
    assert drive_degenerate(100.0, 20.0).wheel_scale.scale == 1.0
    # the old behaviour (only fully constrained registrations) on request
    off = drive_degenerate(2500.0, 20.0, config=WheelScaleConfig(max_lidar_sigma=0.0))
    assert off.wheel_scale.scale == 1.0


def test_a_looser_limit_until_the_wheel_scale_is_established():
    # held to about 4.5 cm along the direction of travel: above the 3 cm limit, within 5 cm
    off = drive_degenerate(500.0, 20.0, config=WheelScaleConfig(max_lidar_sigma_start=0.0))
    assert off.wheel_scale.scale == 1.0
    start = drive_degenerate(500.0, 20.0)  # the default: 5 cm until established
    assert start.wheel_scale.established
    assert start.wheel_scale.scale == pytest.approx(1.03, rel=0.01)
    # once established the 3 cm limit applies again: the rest of the 20 m is not chained
    assert start.wheel_scale.lidar_m < 15.0


def test_registration_information_adds_the_planes_covariance_to_the_configured_one():
    """Planes far stronger than the configured sigmas leave those; a direction the planes
    hold weakly takes about the planes' own weight; one they do not hold keeps at most
    ``1 / MAX_PLANE_SIGMA^2``. The planes' scaled rotations are converted with the length."""
    from lili_odom.fusion.measurements import MAX_PLANE_SIGMA, registration_information

    configured = FusionConfig().lidar.information()
    length = 10.0
    strong = registration_information(configured, 1e9 * np.eye(6), length)
    np.testing.assert_allclose(strong, configured, rtol=1e-3)
    planes = np.diag([1e9, 400.0, 0.0, 1e9, 1e9, 1e9])  # y: a 5 cm sigma; z: nothing
    info = registration_information(configured, planes, length)
    np.testing.assert_allclose(info, info.T)
    sigma_y = np.sqrt(1.0 / configured[1, 1] + 1.0 / 400.0)
    assert info[1, 1] == pytest.approx(sigma_y**-2, rel=1e-6)
    assert info[2, 2] <= MAX_PLANE_SIGMA**-2
    assert info[2, 2] == pytest.approx(1.0 / (1.0 / configured[2, 2] + MAX_PLANE_SIGMA**2))
    # a rotation the planes hold with 400 [1/m^2] over L w: (0.05 / L) rad
    weak_roll = registration_information(configured, np.diag([1e9] * 3 + [400.0] + [1e9] * 2),
                                         length)
    sigma_roll = np.sqrt(1.0 / configured[3, 3] + (0.05 / length) ** 2)
    assert weak_roll[3, 3] == pytest.approx(sigma_roll**-2, rel=1e-6)
