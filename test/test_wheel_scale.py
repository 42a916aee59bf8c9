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


def drive(est: WheelScaleEstimator, n: int, wheel: float, lidar: float) -> None:
    for _ in range(n):
        est.observe(step(wheel), step(lidar))


def test_scale_is_one_until_enough_constrained_travel():
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=5.0, segment_m=2.0))
    drive(est, 40, 0.105, 0.1)  # 4 m: one segment of 2 m closed, a second one running
    assert est.used == 1 and est.scale == 1.0
    drive(est, 30, 0.105, 0.1)  # 7 m in all: three closed segments, 6 m of LiDAR travel
    assert est.used == 3 and est.scale == pytest.approx(1.05, rel=1e-3)
    np.testing.assert_allclose(est.correct(step(0.21))[:3, 3], [0.2, 0, 0], atol=1e-9)


def test_registration_noise_telescopes_instead_of_biasing():
    """3 cm of noise on every registration makes single increments useless (ratios from 0.5
    to 3); chained into segments the error is two endpoints over metres."""
    rng = np.random.default_rng(0)
    est = WheelScaleEstimator()
    err_prev = np.zeros(2)
    for _ in range(600):  # 60 m
        err = rng.normal(0, 0.03, 2)
        est.observe(step(0.1 * 1.02), step(0.1 + err[0] - err_prev[0], err[1] - err_prev[1]))
        err_prev = err
    assert est.rejected == 0 and est.scale == pytest.approx(1.02, abs=0.004)


def test_a_shortfall_while_accelerating_from_rest_stays_out_of_the_segments():
    """The registration loses 10 cm while the robot speeds up: segments start at steady
    speed, after it."""
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=2.0))
    for k in range(20):  # 0 -> 1 m/s, 10 Hz
        v = 0.005 * (k + 1)
        est.observe(step(v), step(v - 0.005))
    drive(est, 200, 0.1, 0.1)
    assert est.scale == pytest.approx(1.0, abs=1e-6)


def test_a_wheel_slip_rejects_its_segment_and_a_wrong_estimate_is_restarted():
    est = WheelScaleEstimator(WheelScaleConfig(segment_m=2.0, max_rejections=3))
    drive(est, 200, 0.102, 0.1)
    assert est.scale == pytest.approx(1.02, rel=1e-6)
    drive(est, 10, 0.102 * 1.35, 0.1)  # the wheels spin for a second on a wet patch
    drive(est, 30, 0.102, 0.1)
    assert est.rejected == 1 and est.scale == pytest.approx(1.02, rel=1e-6)
    # a new surface where the wheels run 10 % long: three segments in a row disagree,
    # the estimate restarts and follows
    drive(est, 300, 0.11, 0.1)
    assert est.restarts == 1 and est.scale == pytest.approx(1.10, rel=1e-6)


def test_a_slip_before_the_estimate_exists_does_not_carry_its_segment():
    """Five segments, the first with 20 cm of wheel slip (3.3 %) before there is an estimate
    to gate it: the plain mean comes out 0.7 % long, the Huber estimate about 0.4 %, and with
    the slip's piece cut out of its segment the scale is right."""
    def run(robust_ratio: float, slip_piece_ratio: float) -> WheelScaleEstimator:
        est = WheelScaleEstimator(WheelScaleConfig(robust_ratio=robust_ratio,
                                                   slip_piece_ratio=slip_piece_ratio))
        drive(est, 60, 0.1, 0.1)  # 1 s to a steady start, then the first segment
        drive(est, 10, 0.12, 0.1)  # one second of spinning wheels
        drive(est, 40, 0.1, 0.1)
        drive(est, 200, 0.1, 0.1)
        assert est.used == 5 and est.rejected == 0
        return est

    assert run(0.0, 0.0).scale == pytest.approx(1.0072, abs=2e-4)
    assert abs(run(0.015, 0.0).scale - 1.0) < 0.0045
    est = run(0.015, 0.08)
    assert est.slip_pieces >= 1 and abs(est.scale - 1.0) < 1e-3


def test_a_slip_in_the_only_segments_before_a_tunnel_is_cut_out():
    """Two segments before the chain breaks for good, the first with a 1 s, 35 % slip: the
    scale established from them is the true 1.02, not their mean (about 1.05)."""
    est = WheelScaleEstimator()
    drive(est, 15, 0.102, 0.1)  # steady start
    drive(est, 20, 0.102, 0.1)
    drive(est, 10, 0.102 * 1.35, 0.1)
    drive(est, 70, 0.102, 0.1)
    est.interrupt()  # into the tunnel
    assert est.used == 2 and est.slip_pieces >= 1
    assert est.scale == pytest.approx(1.02, abs=2e-3)
    plain = WheelScaleEstimator(WheelScaleConfig(slip_piece_ratio=0.0))
    drive(plain, 15, 0.102, 0.1)
    drive(plain, 20, 0.102, 0.1)
    drive(plain, 10, 0.102 * 1.35, 0.1)
    drive(plain, 70, 0.102, 0.1)
    plain.interrupt()
    assert plain.scale > 1.04


def test_honest_segments_scattered_by_registration_error_average_as_before():
    """Segments within the Huber threshold of each other give their distance-weighted mean."""
    est = WheelScaleEstimator(WheelScaleConfig(segment_m=2.0))
    for ratio in (1.01, 1.0, 1.02, 1.0, 1.01, 1.02):
        drive(est, 32, 0.1 * ratio, 0.1)
        est.interrupt()
    ratios = [s.ratio for s in est.segments]
    weights = [s.lidar * np.exp(-(est.travel - s.travel) / 200.0) for s in est.segments]
    assert len(ratios) == 6
    assert est.scale == pytest.approx(np.average(ratios, weights=weights), rel=1e-9)


def test_a_broken_chain_keeps_its_steady_part_and_short_pieces_are_dropped():
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=0.0, segment_m=5.0,
                                               min_segment_m=2.0))
    drive(est, 32, 0.105, 0.1)  # 3 m, then a degenerate scan
    est.interrupt()
    assert est.used == 1 and est.scale == pytest.approx(1.05, rel=1e-6)
    drive(est, 15, 0.12, 0.1)  # 1.2 m, too short
    est.interrupt()
    assert est.used == 1


def test_a_wheel_yaw_error_does_not_shorten_the_chord():
    """On an arc the wheels report 10 % too little turn; the chord is built with the LiDAR's
    orientation, so the distance scale is still the distance scale."""
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=1.0))
    yaw = 0.02
    for _ in range(300):
        lidar = step(0.1)
        lidar[:3, :3] = [[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]]
        wheel = step(0.101)
        wheel[:3, :3] = [[np.cos(0.9 * yaw), -np.sin(0.9 * yaw), 0],
                         [np.sin(0.9 * yaw), np.cos(0.9 * yaw), 0], [0, 0, 1]]
        est.observe(wheel, lidar)
    assert est.used >= 5 and est.scale == pytest.approx(1.01, abs=2e-3)


def test_stationary_and_non_finite_increments_are_ignored_and_scale_is_clamped():
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=0.5, max_scale=1.1,
                                               segment_m=1.0, min_segment_m=1.0))
    drive(est, 50, 0.0, 0.0)
    assert est.used == 0 and est.scale == 1.0
    assert not est.observe(step(np.nan), step(0.1))
    drive(est, 60, 0.105, 0.1)
    assert est.scale == pytest.approx(1.05, rel=1e-6)
    est = WheelScaleEstimator(WheelScaleConfig(min_distance_m=0.5, max_scale=1.1, min_scale=0.5,
                                               segment_m=1.0, min_segment_m=1.0))
    drive(est, 60, 0.108, 0.1)
    assert est.scale == pytest.approx(1.08, rel=1e-6)
    drive(est, 300, 0.112, 0.1)  # inside the slip gate, the estimate moves beyond the range
    assert est.rejected == 0 and est.scale == 1.1


def test_disabled_estimator_never_scales():
    est = WheelScaleEstimator(WheelScaleConfig(enabled=False))
    drive(est, 100, 0.11, 0.1)
    assert est.scale == 1.0


def test_old_travel_fades_so_a_new_surface_is_followed():
    est = WheelScaleEstimator(WheelScaleConfig(window_m=20.0, slip_gate_ratio=0.2))
    drive(est, 300, 0.11, 0.1)
    drive(est, 1000, 0.1, 0.1)  # 100 m on a surface where the wheels are right
    assert est.scale == pytest.approx(1.0, abs=0.002)


def test_invalid_configuration_is_named():
    with pytest.raises(ValueError, match="fusion.wheel_scale.window_m"):
        FusionConfig(wheel_scale=WheelScaleConfig(window_m=0.0)).validate()


def test_fused_motion_inside_the_degenerate_direction_uses_the_calibrated_wheels():
    """5 % long wheels: calibrated on 15 m of constrained driving, then along a degenerate x
    the fused increments follow the true 0.5 m steps, not the wheels' 0.525 m."""
    est = FusionEstimator(FusionConfig(T_base_lidar=np.eye(4), T_base_imu=np.eye(4),
                                       use_imu=False))
    est.initialize(0.0)
    x, t = 0.0, 0.0
    for _ in range(30):  # constrained: the LiDAR sees the true position
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


def test_chaining_says_whether_a_segment_is_open():
    est = WheelScaleEstimator(WheelScaleConfig(steady_scans=10))
    drive(est, 9, 0.1, 0.1)
    assert not est.chaining  # not yet steady for steady_scans increments
    drive(est, 1, 0.1, 0.1)
    assert est.chaining
    est.interrupt()
    assert not est.chaining
