"""Online wheel distance scale: estimated where the LiDAR is fully constrained, applied inside
the degenerate subspace."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lili_odom.fusion import FusionConfig, FusionEstimator
from lili_odom.fusion.wheel_scale import WheelScaleConfig, WheelScaleEstimator


def step(x: float, y: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:2, 3] = x, y
    return T


def test_scale_is_one_until_enough_constrained_travel():
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=5.0))
    for _ in range(40):  # 4 m
        assert est.observe(step(0.105), step(0.1))
    assert est.scale == 1.0
    for _ in range(20):  # 6 m in all
        est.observe(step(0.105), step(0.1))
    assert est.scale == pytest.approx(1.05, rel=1e-3)
    np.testing.assert_allclose(est.correct(step(0.21))[:3, 3], [0.2, 0, 0], atol=1e-9)


def test_noisy_increments_average_out_and_slip_is_rejected():
    rng = np.random.default_rng(0)
    est = WheelScaleEstimator()
    for k in range(300):  # 30 m, 3 mm registration noise per increment
        lidar = step(0.1 + rng.normal(0, 0.003), rng.normal(0, 0.003))
        wheel = step(0.1 * 1.02)
        if k % 25 == 0:
            wheel = step(0.5)  # the wheels spin on a wet patch
            assert not est.observe(wheel, lidar)
            continue
        est.observe(wheel, lidar)
    assert est.rejected == 12 and est.scale == pytest.approx(1.02, abs=0.005)


def test_stationary_and_non_finite_increments_are_ignored_and_scale_is_clamped():
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=0.5, max_scale=1.1,
                                               slip_gate_ratio=1.0))
    assert not est.observe(step(0.0), step(0.0))
    assert not est.observe(step(np.nan), step(0.1))
    for _ in range(10):
        est.observe(step(0.15), step(0.1))
    assert est.scale == 1.1  # 1.5 clamped


def test_disabled_estimator_never_scales():
    est = WheelScaleEstimator(WheelScaleConfig(enabled=False))
    for _ in range(100):
        est.observe(step(0.11), step(0.1))
    assert est.scale == 1.0


def test_old_travel_fades_so_a_new_surface_is_followed():
    est = WheelScaleEstimator(WheelScaleConfig(window_m=20.0))
    for _ in range(300):
        est.observe(step(0.11), step(0.1))
    for _ in range(1000):  # 100 m on a surface where the wheels are right
        est.observe(step(0.1), step(0.1))
    assert est.scale == pytest.approx(1.0, abs=0.002)


def test_invalid_configuration_is_named():
    with pytest.raises(ValueError, match="fusion.wheel_scale.window_m"):
        FusionConfig(wheel_scale=WheelScaleConfig(window_m=0.0)).validate()


def test_fused_motion_inside_the_degenerate_direction_uses_the_calibrated_wheels():
    """5 % long wheels: calibrated on 10 m of constrained driving, then along a degenerate x
    the fused increments follow the true 0.5 m steps, not the wheels' 0.525 m."""
    est = FusionEstimator(FusionConfig(T_base_lidar=np.eye(4), T_base_imu=np.eye(4),
                                       use_imu=False))
    est.initialize(0.0)
    x, t = 0.0, 0.0
    for _ in range(20):  # constrained: the LiDAR sees the true position
        t += 0.5
        x += 0.5
        out = est.update(t, step(x), None, wheel_delta=step(0.525))
        assert out is not None and not out.used_wheel
    assert est.wheel_scale.scale == pytest.approx(1.05, rel=1e-3)
    deg = SimpleNamespace(basis_scaled=np.array([[1.0, 0, 0, 0, 0, 0]]),
                          characteristic_length=10.0, ok=True)
    x0 = out.pose[0, 3]
    for k in range(10):  # degenerate along x: the registration is stuck at x0
        t += 0.5
        out = est.update(t, step(x0), deg, wheel_delta=step(0.525))
        assert out is not None and out.used_wheel
    assert out.pose[0, 3] - x0 == pytest.approx(5.0, abs=0.05)  # uncalibrated: 5.25
