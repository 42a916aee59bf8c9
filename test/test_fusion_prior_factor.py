"""The absolute LiDAR factor (``fusion.lidar.factor = "prior"``): basis snapping, the
degenerate anchor (and the directions it takes from the wheels) and the covariance reported
along the anchored subspace."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom.fusion import FusionConfig, FusionEstimator
from lili_odom.fusion.config import LidarNoiseConfig
from lili_odom.fusion.estimator import SubspaceMeasurement
from lili_odom.fusion.subspace import (
    degenerate_anchor,
    orthonormal_rows,
    planar_directions,
    scaled_lidar_to_base,
    snap_basis,
)
from lili_odom.geometry import exp, log
from test_fusion import MOUNT, G, config, degeneracy, feed_imu, pose


def test_snap_basis_zeroes_small_components_and_keeps_rows_orthonormal() -> None:
    b = np.array([[1.0, 0.03, -0.02, 0.0, 0.0, 0.05], [0.0, 0.04, 1.0, 0.5, 0.0, 0.0]])
    out = snap_basis(b, 0.1)
    np.testing.assert_allclose(out @ out.T, np.eye(2), atol=1e-12)
    # the span is that of the snapped rows: (1, 0, ...) and (0, 0, 1, 0.5, 0, 0)
    expected = orthonormal_rows(np.array([[1.0, 0, 0, 0, 0, 0], [0, 0, 1.0, 0.5, 0, 0]]))
    np.testing.assert_allclose(out.T @ out, expected.T @ expected, atol=1e-12)
    np.testing.assert_array_equal(snap_basis(b, 0.0), b)
    assert snap_basis(np.zeros((0, 6)), 0.1).shape == (0, 6)


@pytest.mark.parametrize("mount", [np.eye(4), MOUNT])
def test_anchor_takes_degenerate_components_from_the_reference(mount: np.ndarray) -> None:
    L = 8.0
    basis = np.array([[1.0, 0.0, 0.0, 0.0, 0.0, 0.3]])
    basis /= np.linalg.norm(basis)
    T_meas = exp(np.array([0.4, -0.1, 0.02, 0.01, 0.0, 0.05]))
    T_ref = exp(np.array([0.9, 0.2, 0.0, 0.0, 0.01, -0.08]))
    target, omega = degenerate_anchor(T_meas, T_ref, basis, L, mount, sigma=0.05)
    Minv = np.linalg.inv(scaled_lidar_to_base(mount, L))
    P = basis.T @ basis
    # inside the subspace the target agrees with the reference, outside with the measurement
    assert np.linalg.norm(P @ Minv @ log(np.linalg.inv(target) @ T_ref)) < 1e-6
    assert np.linalg.norm((np.eye(6) - P) @ Minv @ log(np.linalg.inv(T_meas) @ target)) < 1e-6
    # the information is rank 1 along the subspace with the requested sigma
    s = scaled_lidar_to_base(mount, L) @ basis[0]  # base twist of the unit scaled direction
    assert s @ omega @ s == pytest.approx(1.0 / 0.05**2, rel=1e-9)
    assert np.linalg.matrix_rank(omega, tol=1e-6 * np.abs(omega).max()) == 1
    # the reference's own uncertainty along the subspace weakens the anchor
    _, weaker = degenerate_anchor(T_meas, T_ref, basis, L, mount, sigma=0.05,
                                  reference_covariance=np.eye(6) * 0.01)
    assert s @ weaker @ s < 0.5 * (s @ omega @ s)


@pytest.mark.parametrize("mount", [np.eye(4), MOUNT])
def test_anchor_weighted_by_the_reference_ignores_a_tilt_it_does_not_measure(
        mount: np.ndarray) -> None:
    """The wheel prediction knows the distance but not the roll; a detected axis carrying
    some roll must take the distance from it, not trade it against the roll disagreement."""
    L = 14.0
    basis = np.array([[0.95, 0.0, 0.0, 0.3, 0.0, 0.0]])  # scaled LiDAR twist: x with some roll
    basis /= np.linalg.norm(basis)
    axis = (scaled_lidar_to_base(mount, L) @ basis[0])[:3]  # base direction of its translation
    axis /= np.linalg.norm(axis)
    T_meas = np.eye(4)
    T_ref = exp(np.r_[0.09 * axis, 0.0, 0.0, 0.0]) @ exp(np.array([0, 0, 0, 0.02, 0, 0]))
    wheel_info = np.diag([1 / 0.008**2] * 3 + [1 / 0.016**2] * 2 + [1 / 0.002**2])
    plain, _ = degenerate_anchor(T_meas, T_ref, basis, L, mount, sigma=0.05)
    weighted, omega = degenerate_anchor(T_meas, T_ref, basis, L, mount, sigma=0.05,
                                        reference_information=wheel_info)
    # unweighted, 0.02 rad of roll (0.28 m scaled) moves the target along the axis as much
    assert abs(plain[:3, 3] @ axis - 0.09) > 0.05
    # weighted, the target moves the wheels' 9 cm along the axis (up to the roll it implies)
    assert weighted[:3, 3] @ axis == pytest.approx(0.09, abs=0.005)
    assert np.linalg.matrix_rank(omega, tol=1e-6 * np.abs(omega).max()) == 1


#: a detected roll about an axis beside and below the sensor (a corridor's floor edge), as a
#: scaled LiDAR twist: mostly roll, with a little lateral and vertical translation
ROLL_ABOUT_EDGE = np.array([0.0, 0.07, 0.1, 0.99, 0.0, 0.0]) / np.linalg.norm([0.07, 0.1, 0.99])


@pytest.mark.parametrize("length", [3.0, 10.0, 30.0])
def test_planar_directions_keep_travel_and_yaw_and_drop_a_roll_about_a_floor_edge(
        length: float) -> None:
    mount = pose(t=(0.2, 0.0, 0.6))
    travel, yaw = [1.0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 1.0]
    kept = planar_directions(np.vstack([travel, ROLL_ABOUT_EDGE]), length, mount, 0.5)
    np.testing.assert_allclose(np.abs(kept), [travel], atol=1e-9)
    assert planar_directions(ROLL_ABOUT_EDGE, length, mount, 0.5).shape == (0, 6)
    # a yaw about the sensor is a yaw of base_link with a lateral swing of the mount's lever
    kept = planar_directions(np.vstack([yaw, ROLL_ABOUT_EDGE]), length, mount, 0.5)
    np.testing.assert_allclose(np.abs(kept), [yaw], atol=1e-9)
    # height and pitch are not planar motion; 0 keeps everything
    assert planar_directions(np.array([[0, 0, 1.0, 0, 0, 0], [0, 0, 0, 0, 1.0, 0]]), length,
                             mount, 0.5).shape == (0, 6)
    assert len(planar_directions(np.vstack([travel, ROLL_ABOUT_EDGE]), length, mount,
                                 0.0)) == 2
    # a non-finite characteristic length gives every direction back
    assert len(planar_directions(np.vstack([travel, ROLL_ABOUT_EDGE]), np.nan, mount,
                                 0.5)) == 2


@pytest.mark.parametrize("with_subspace", [False, True])
def test_a_roll_the_wheels_do_not_measure_is_held_at_the_registration(
        with_subspace: bool) -> None:
    """Wheels that drift sideways by 1 cm per 10 cm, a registration exactly on the truth and a
    detected roll about a corridor's floor edge: anchored at the wheel prediction, the roll's
    lateral part moves the pose towards the wheels; held at the registration, it does not."""
    v = np.array([1.0, 0.0, 0.0])
    lateral = {}
    for share in (0.0, 0.5):
        est = FusionEstimator(config(lidar=LidarNoiseConfig(
            anchor_min_planar_share=share)))
        n = 40
        feed_imu(est, -1.0, 0.1 * n + 0.05, (0.0, 0.0, G))
        est.initialize(0.0, velocity=v)
        for i in range(1, n + 1):
            truth = pose(t=v * 0.1 * i)
            sub = (SubspaceMeasurement(truth, 300.0 * np.outer(ROLL_ABOUT_EDGE, ROLL_ABOUT_EDGE),
                                       10.0) if with_subspace else None)
            out = est.update(0.1 * i, truth, degeneracy(ROLL_ABOUT_EDGE),
                             wheel_delta=pose(t=(0.1, 0.01, 0.0)), subspace=sub)
        lateral[share] = np.linalg.norm(out.pose[1:3, 3])
        assert out.pose[0, 3] == pytest.approx(4.0, abs=0.01)
    assert lateral[0.0] > 0.02
    assert lateral[0.5] < 0.01


def test_prior_factor_reports_the_wheel_random_walk_along_the_axis() -> None:
    v = np.array([1.0, 0.0, 0.0])
    est = FusionEstimator(config(lidar=LidarNoiseConfig(factor="prior")))
    n = 30
    feed_imu(est, -1.0, 0.1 * n + 0.05, (0.0, 0.0, G))
    est.initialize(0.0, velocity=v)
    for i in range(1, n + 1):
        out = est.update(0.1 * i, pose(t=v * 0.1 * i), degeneracy([1, 0, 0, 0, 0, 0]),
                         wheel_delta=pose(t=v * 0.1))
        np.testing.assert_allclose(out.pose[:3, 3], v * 0.1 * i, atol=1e-3)
    sx, sy = np.sqrt(out.covariance[0, 0]), np.sqrt(out.covariance[1, 1])
    # 30 wheel increments of 1 cm sigma: ~5.5 cm, not the anchor's 2 cm
    assert 0.5 * np.sqrt(30) * 0.01 < sx < 1.5 * np.sqrt(30) * 0.01 and sx > 3 * sy


def test_invalid_factor_is_rejected() -> None:
    with pytest.raises(ValueError, match="lidar.factor"):
        LidarNoiseConfig(factor="absolute").validate()
    with pytest.raises(ValueError, match="anchor_sigma"):
        LidarNoiseConfig(anchor_sigma=-1.0).validate()
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="anchor_min_planar_share"):
            LidarNoiseConfig(anchor_min_planar_share=bad).validate()
    FusionConfig(lidar=LidarNoiseConfig(factor="prior")).validate()


def test_hybrid_factor_is_absolute_in_translation_and_relative_in_tilt() -> None:
    """A local map tilted 1 deg against gravity and 5 cm to the side (every registration
    carries both): the absolute factor pins the pitch to the map's; the hybrid factor measures
    roll and pitch only relative to the previous fused pose, which the IMU's gravity also
    holds, so it follows the map's tilt less. Across the axis both follow the map."""
    v = np.array([1.0, 0.0, 0.0])
    tilt = np.radians(1.0)
    R_map = exp(np.array([0.0, 0.0, 0.0, 0.0, tilt, 0.0]))[:3, :3]
    offset = np.array([0.0, 0.05, 0.0])
    pitch = {}
    for factor in ("prior", "hybrid"):
        est = FusionEstimator(config(lidar=LidarNoiseConfig(factor=factor, anchor_sigma=0.0)))
        n = 50
        feed_imu(est, -1.0, 0.1 * n + 0.05, (0.0, 0.0, G))  # level, constant velocity
        est.initialize(0.0, velocity=v)
        for i in range(1, n + 1):
            out = est.update(0.1 * i, pose(R=R_map, t=v * 0.1 * i + offset),
                             degeneracy([1, 0, 0, 0, 0, 0]), wheel_delta=pose(t=v * 0.1))
        pitch[factor] = log(out.pose)[4]
        assert out.pose[1, 3] == pytest.approx(0.05, abs=0.01)
        assert out.pose[0, 3] == pytest.approx(5.0, abs=0.05)  # the wheels along the axis
    assert pitch["prior"] > 0.9 * tilt
    assert pitch["hybrid"] < pitch["prior"] - 0.2 * tilt
