"""Fusion estimator: degenerate-subspace remapping, IMU propagation, bounds, robustness."""
from __future__ import annotations

import math
import time
from types import SimpleNamespace

import gtsam
import numpy as np
import pytest

from lili_odom.fusion import FusionConfig, FusionEstimator, ImuBuffer, split_information
from lili_odom.fusion.config import LidarNoiseConfig
from lili_odom.fusion.imu import ImuNoiseConfig, gravity_alignment, integrate, make_preintegration_params
from lili_odom.fusion.subspace import scaled_lidar_to_base, sqrt_information
from lili_odom.fusion.wheel import wheel_information
from lili_odom.geometry import exp, log, scaling_matrix

G = 9.80665


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def pose(R: np.ndarray | None = None, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = t
    return T


def degeneracy(basis_scaled, length: float = 10.0) -> SimpleNamespace:
    return SimpleNamespace(basis_scaled=np.atleast_2d(np.asarray(basis_scaled, float)),
                           characteristic_length=length, ok=True)


def feed_imu(est: FusionEstimator, t0: float, t1: float, acc_imu, gyro_imu=(0, 0, 0),
             rate: float = 100.0) -> None:
    """Constant (or callable of t) IMU readings in the IMU frame at ``rate`` Hz over [t0, t1]."""
    n = int(round((t1 - t0) * rate))
    for k in range(n + 1):
        t = t0 + k / rate
        a = acc_imu(t) if callable(acc_imu) else acc_imu
        w = gyro_imu(t) if callable(gyro_imu) else gyro_imu
        est.add_imu(t, np.asarray(a, float), np.asarray(w, float))


def config(T_base_lidar=None, T_base_imu=None, **kw) -> FusionConfig:
    return FusionConfig(
        T_base_lidar=np.eye(4) if T_base_lidar is None else T_base_lidar,
        T_base_imu=np.eye(4) if T_base_imu is None else T_base_imu,
        **kw,
    )


# --------------------------------------------------------------------------------------------
# the key property: wheels inside the degenerate subspace, LiDAR outside


def test_wheel_inside_lidar_outside_translation_x_without_imu() -> None:
    est = FusionEstimator(config())
    est.initialize(0.0)
    lidar = pose(t=(0.0, 0.3, 0.0))  # "moved 0 along x, 0.3 along y"
    wheel = pose(t=(1.0, 0.0, 0.0))  # "moved 1.0 along x, 0 along y"
    out = est.update(1.0, lidar, degeneracy([1, 0, 0, 0, 0, 0]), wheel_delta=wheel)
    assert out is not None and out.used_lidar and out.used_wheel and not out.used_imu
    assert out.degenerate_dimension == 1
    np.testing.assert_allclose(out.pose[:3, 3], [1.0, 0.3, 0.0], atol=0.01)
    np.testing.assert_allclose(out.pose[:3, :3], np.eye(3), atol=1e-3)


def test_without_degeneracy_lidar_wins_and_no_wheel_factor() -> None:
    est = FusionEstimator(config())
    est.initialize(0.0)
    out = est.update(1.0, pose(t=(0.0, 0.3, 0.0)), None, wheel_delta=pose(t=(1.0, 0, 0)))
    assert out is not None and not out.used_wheel
    np.testing.assert_allclose(out.pose[:3, 3], [0.0, 0.3, 0.0], atol=0.01)


def _constant_velocity_run(est: FusionEstimator, v: np.ndarray, t1: float) -> None:
    """IMU readings of a robot moving with constant world velocity, level, IMU = base_link."""
    feed_imu(est, -1.0, t1 + 0.05, (0.0, 0.0, G))


def test_wheel_inside_lidar_outside_with_consistent_imu() -> None:
    v = np.array([1.0, 0.3, 0.0])
    est = FusionEstimator(config())
    _constant_velocity_run(est, v, 1.0)
    est.initialize(0.0, velocity=v)
    out = est.update(1.0, pose(t=(0.0, 0.3, 0.0)), degeneracy([1, 0, 0, 0, 0, 0]),
                     wheel_delta=pose(t=(1.0, 0.0, 0.0)))
    assert out.used_imu and out.used_wheel
    np.testing.assert_allclose(out.pose[:3, 3], [1.0, 0.3, 0.0], atol=0.01)
    np.testing.assert_allclose(out.velocity, v, atol=0.02)

    # without wheels the degenerate x comes from the IMU, never from the LiDAR's "0"
    est = FusionEstimator(config())
    _constant_velocity_run(est, v, 1.0)
    est.initialize(0.0, velocity=v)
    out = est.update(1.0, pose(t=(0.0, 0.3, 0.0)), degeneracy([1, 0, 0, 0, 0, 0]))
    assert out.used_imu and not out.used_wheel
    np.testing.assert_allclose(out.pose[:3, 3], [1.0, 0.3, 0.0], atol=0.01)


MOUNT = pose(rot_z(math.pi), (0.2, 0.1, 0.6))  # LiDAR yawed 180 deg, with a lever arm


def test_extrinsic_yaw_180_translation() -> None:
    est = FusionEstimator(config(T_base_lidar=MOUNT))
    est.initialize(0.0)
    # LiDAR +x is base -x: the same physical degenerate axis
    out = est.update(1.0, pose(t=(0.0, 0.3, 0.0)), degeneracy([1, 0, 0, 0, 0, 0]),
                     wheel_delta=pose(t=(1.0, 0.0, 0.0)))
    np.testing.assert_allclose(out.pose[:3, 3], [1.0, 0.3, 0.0], atol=0.01)


@pytest.mark.parametrize("wheel_restriction", ["marginalize", "weighted"])
@pytest.mark.parametrize("mount", [np.eye(4), MOUNT])
def test_coupled_rotation_translation_direction(mount: np.ndarray, wheel_restriction: str
                                                ) -> None:
    L = 8.0
    b = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 1.0])  # scaled: y translation + yaw (L * wz)
    b /= np.linalg.norm(b)
    # the split alone: the anchor re-centres the LiDAR factor on the wheel-remapped pose and
    # uses its information in that frame, which for this 14 deg, 0.5 m disagreement costs
    # 1-2 cm outside b (second order; per-scan disagreements are millimetres)
    cfg = config(T_base_lidar=mount, wheel_restriction=wheel_restriction,
                 lidar=LidarNoiseConfig(anchor_sigma=0.0))
    est = FusionEstimator(cfg)
    est.initialize(0.0)
    lidar = exp(np.array([0.5, -0.2, 0.0, 0.0, 0.0, 0.15]))
    wheel = exp(np.array([0.45, 0.3, 0.0, 0.0, 0.0, -0.1]))
    out = est.update(1.0, lidar, degeneracy(b, L), wheel_delta=wheel)
    assert out is not None and out.used_wheel
    delta = out.pose  # previous pose is identity
    M = scaled_lidar_to_base(mount, L)
    Minv = np.linalg.inv(M)
    s_lidar = Minv @ log(np.linalg.inv(lidar) @ delta)  # LiDAR factor error, scaled LiDAR coords
    s_wheel = Minv @ log(np.linalg.inv(wheel) @ delta)
    P = np.outer(b, b)
    # LiDAR satisfied outside the subspace, wheels inside it (residual << the 0.5 m conflict):
    # the wheel residual's component along b, orthogonal or weighted by the wheels' own
    # information (their least-squares fit along b)
    assert np.linalg.norm((np.eye(6) - P) @ s_lidar) < 2e-3
    W = np.eye(6)
    if wheel_restriction == "weighted":
        W = M.T @ wheel_information(wheel, cfg.wheel) @ M
    assert abs(b @ W @ s_wheel) / math.sqrt(b @ W @ b) < 2e-3
    # and the two measurements really disagreed along b
    assert abs(b @ (Minv @ log(np.linalg.inv(lidar) @ wheel))) > 0.3


def test_split_information_properties() -> None:
    L = 5.0
    basis = np.array([[0.0, 0.6, 0.0, 0.0, 0.0, 0.8]])
    om_l = np.diag([2500.0] * 3 + [1e5] * 3)
    om_w = np.diag([1e4, 1e4, 100, 100, 100, 1e3])
    for mode in ("marginalize", "project"):
        sp = split_information(om_l, om_w, basis, L, MOUNT, mode=mode)
        assert np.linalg.eigvalsh(sp.lidar).min() > 0  # positive definite
        w = np.linalg.eigvalsh(sp.wheel)
        assert np.count_nonzero(w > 1e-9 * w.max()) == 1  # rank 1
        M = scaled_lidar_to_base(MOUNT, L)
        d_base = M @ basis[0]  # base-frame twist of the degenerate direction
        # the LiDAR quadratic form barely sees it, the wheel one only sees it
        q = d_base @ sp.lidar @ d_base
        assert q < 1e-5 * np.linalg.eigvalsh(sp.lidar).max()
        other = M @ np.array([1.0, 0, 0, 0, 0, 0])
        assert abs(other @ sp.wheel @ other) < 1e-9 * w.max()
    R = sqrt_information(sp.wheel)
    np.testing.assert_allclose(R.T @ R, sp.wheel, atol=1e-6 * w.max())


def test_weighted_wheel_restriction_measures_the_axis_with_what_the_wheels_measure() -> None:
    """A detected tunnel axis mixing pitch into the translation: the wheels measure the
    forward distance well and pitch badly. ``marginalize`` weakens them along the whole
    direction, ``project`` lets their (unmeasured) pitch move it, ``weighted`` does neither."""
    L = 10.0
    mount = np.eye(4)
    basis = np.array([[0.92, 0.0, 0.0, 0.0, 0.39, 0.0]])
    basis /= np.linalg.norm(basis)
    om_l = np.diag([2500.0] * 3 + [1e5] * 3)
    om_w = np.diag([1.0 / 0.008**2, 1e4, 1e4, 1.0 / 0.016**2, 1.0 / 0.016**2, 1e4])
    M = scaled_lidar_to_base(mount, L)
    u = M @ basis[0]  # base twist of the unit scaled direction
    pitch_only = np.array([0.0, 0.0, 0.0, 0.0, 0.01, 0.0])  # residual the wheels cannot see
    forward = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    sp = {mode: split_information(om_l, om_w, basis, L, mount, wheel_mode=mode).wheel
          for mode in ("marginalize", "project", "weighted")}
    # information along the axis: marginalize is weak (about (0.39 L 0.016)^-2), the others
    # keep the wheels' forward precision
    assert u @ sp["marginalize"] @ u < 0.02 * (u @ sp["project"] @ u)
    assert u @ sp["weighted"] @ u == pytest.approx(u @ sp["project"] @ u, rel=1e-9)
    # a 0.01 rad pitch disagreement costs the weighted factor no more than the 8 mm the
    # wheels' pitch noise is worth, but costs the projected one like a 4 cm slide
    cost = {m: float(pitch_only @ sp[m] @ pitch_only) for m in sp}
    assert cost["weighted"] < 0.6 * float(forward @ sp["weighted"] @ forward)
    assert cost["project"] > 10 * cost["weighted"]
    # a forward disagreement is penalised with the wheels' forward precision
    assert float(forward @ sp["weighted"] @ forward) == pytest.approx(
        0.01**2 / 0.008**2, rel=0.05)
    w = np.linalg.eigvalsh(sp["weighted"])
    assert np.count_nonzero(w > 1e-9 * w.max()) == 1  # one scalar measurement
    with pytest.raises(ValueError, match="wheel_restriction"):
        FusionConfig(wheel_restriction="oblique").validate()


# --------------------------------------------------------------------------------------------
# covariance honesty


def _straight_run(deg: bool, wheel: bool, n: int = 30) -> np.ndarray:
    """Constant 1 m/s along x, IMU consistent, LiDAR exact; returns the last pose covariance."""
    v = np.array([1.0, 0.0, 0.0])
    est = FusionEstimator(config())
    feed_imu(est, -1.0, 0.1 * n + 0.05, (0.0, 0.0, G))
    est.initialize(0.0, velocity=v)
    for i in range(1, n + 1):
        t = 0.1 * i
        out = est.update(t, pose(t=v * t), degeneracy([1, 0, 0, 0, 0, 0]) if deg else None,
                         wheel_delta=pose(t=v * 0.1) if wheel else None)
        np.testing.assert_allclose(out.pose[:3, 3], v * t, atol=1e-3)
    return out.covariance


def test_covariance_large_along_degenerate_direction() -> None:
    c_ok = _straight_run(deg=False, wheel=False)
    c_deg = _straight_run(deg=True, wheel=False)
    c_wheel = _straight_run(deg=True, wheel=True)
    sx_ok, sx_deg, sx_wheel = (math.sqrt(c[0, 0]) for c in (c_ok, c_deg, c_wheel))
    # degenerate and unconstrained by wheels: much larger than when the LiDAR sees x
    assert sx_deg > 5 * sx_ok
    # wheels bring it back down to wheel level (random walk of 30 increments of 1 cm sigma)
    assert sx_wheel < 0.5 * sx_deg
    assert 0.5 * math.sqrt(30) * 0.01 < sx_wheel < 1.5 * math.sqrt(30) * 0.01
    # the non-degenerate y direction is unaffected
    assert math.sqrt(c_deg[1, 1]) < 1.5 * math.sqrt(c_ok[1, 1])


# --------------------------------------------------------------------------------------------
# IMU propagation


def test_imu_constant_acceleration_matches_analytic() -> None:
    R0 = rot_z(0.7)
    p0 = np.array([1.0, -2.0, 0.5])
    v0 = np.array([0.5, 0.2, 0.0])
    a_w = np.array([0.4, -0.3, 0.1])
    T_base_imu = pose(rot_z(math.pi), (0.006, -0.012, 0.3))
    R_bi = T_base_imu[:3, :3]
    f_base = R0.T @ (a_w + np.array([0.0, 0.0, G]))  # specific force in base_link
    f_imu = R_bi.T @ f_base
    est = FusionEstimator(config(T_base_imu=T_base_imu))
    feed_imu(est, -0.5, 1.1, f_imu, rate=200.0)
    est.initialize(0.0, pose=pose(R0, p0), velocity=v0)
    for t in (0.05, 0.5, 1.0):
        T = est.predict(t)
        np.testing.assert_allclose(T[:3, 3], p0 + v0 * t + 0.5 * a_w * t * t, atol=1e-6)
        np.testing.assert_allclose(T[:3, :3], R0, atol=1e-9)
    times = np.array([1.0, 0.25, 0.6])
    Ts = est.predict_poses(times)
    for T, t in zip(Ts, times):
        np.testing.assert_allclose(T[:3, 3], p0 + v0 * t + 0.5 * a_w * t * t, atol=1e-6)
    # the graph path (IMU factor only, no LiDAR) reproduces the same motion
    out = est.update(1.0, None)
    assert out.used_imu and not out.used_lidar
    np.testing.assert_allclose(out.pose[:3, 3], p0 + v0 + 0.5 * a_w, atol=1e-3)
    np.testing.assert_allclose(out.velocity, v0 + a_w, atol=1e-3)


def test_imu_rotation_in_place_with_lever_arm() -> None:
    """Spinning about base_link z with the IMU off-axis: the centripetal term is compensated."""
    wz = 1.0
    r = np.array([0.3, 0.1, 0.2])  # IMU position in base_link
    T_base_imu = pose(rot_z(math.pi / 2), r)
    R_bi = T_base_imu[:3, :3]
    w_b = np.array([0.0, 0.0, wz])
    centripetal = np.cross(w_b, np.cross(w_b, r))
    f_imu = R_bi.T @ (centripetal + np.array([0.0, 0.0, G]))  # level robot, gravity along z
    est = FusionEstimator(config(T_base_imu=T_base_imu))
    feed_imu(est, 0.0, 1.1, f_imu, R_bi.T @ w_b, rate=400.0)
    est.initialize(0.0, pose=np.eye(4), velocity=np.zeros(3))
    T = est.predict(1.0)
    np.testing.assert_allclose(T[:3, :3], rot_z(wz), atol=1e-6)
    np.testing.assert_allclose(T[:3, 3], 0.0, atol=2e-3)


def test_gravity_alignment_at_start() -> None:
    roll, pitch = 0.05, -0.08
    R_wb = np.asarray(gtsam.Rot3.Ypr(0.0, pitch, roll).matrix())
    est = FusionEstimator(config())
    gyro_bias = np.array([0.002, -0.001, 0.003])
    feed_imu(est, -1.0, 0.0, R_wb.T @ np.array([0, 0, G]), gyro_bias)
    out = est.initialize(0.0)
    np.testing.assert_allclose(out.pose[:3, :3], R_wb, atol=1e-6)
    np.testing.assert_allclose(out.gyro_bias, gyro_bias, atol=1e-9)
    al = gravity_alignment(est.imu.samples(-1, 0), np.eye(3))
    assert al.stationary


def test_imu_buffer_robustness() -> None:
    buf = ImuBuffer()
    ts = np.arange(0.0, 1.0001, 0.01)
    rng = np.random.default_rng(3)
    order = rng.permutation(len(ts))
    for k in order:  # out of order
        assert buf.add(ts[k], [0.1 * ts[k], 0, G], [0, 0, 0])
    assert buf.n_out_of_order > 0
    assert not buf.add(ts[5], [0, 0, G], [0, 0, 0])  # duplicate
    assert not buf.add(0.5, [np.nan, 0, G], [0, 0, 0])
    assert not buf.add(np.inf, [0, 0, G], [0, 0, 0])
    assert (buf.n_duplicates, buf.n_nonfinite, len(buf)) == (1, 2, len(ts))
    params = make_preintegration_params(ImuNoiseConfig())
    pim = gtsam.PreintegratedCombinedMeasurements(params, gtsam.imuBias.ConstantBias())
    rep = integrate(buf, pim, 0.123, 0.871, 0.25, 0.05)  # interpolated ends
    assert rep.covered
    assert pim.deltaTij() == pytest.approx(0.871 - 0.123, abs=1e-12)
    # linearly varying acceleration is integrated exactly (trapezoid on linear signals)
    dv = np.asarray(pim.deltaVij())
    t0, t1 = 0.123, 0.871
    np.testing.assert_allclose(dv[0], 0.05 * (t1**2 - t0**2), rtol=1e-3)
    # a hole: delete samples in (0.3, 0.7) -> not covered
    gap = ImuBuffer()
    for t in ts[(ts < 0.3) | (ts > 0.7)]:
        gap.add(t, [0, 0, G], [0, 0, 0])
    pim2 = gtsam.PreintegratedCombinedMeasurements(params, gtsam.imuBias.ConstantBias())
    rep2 = integrate(gap, pim2, 0.2, 0.8, 0.25, 0.05)
    assert not rep2.covered and "gap" in rep2.reason and pim2.deltaTij() == 0.0


def test_no_imu_gap_falls_back_to_motion_model() -> None:
    est = FusionEstimator(config())
    feed_imu(est, -1.0, 0.3, (0.0, 0.0, G))
    feed_imu(est, 1.0, 2.05, (0.0, 0.0, G))  # IMU missing over (0.3, 1.0)
    est.initialize(0.0)
    out = est.update(0.2, pose(t=(0.02, 0, 0)))
    assert out.used_imu
    out = est.update(0.9, pose(t=(0.09, 0, 0)))
    assert out is not None and not out.used_imu
    assert est.stats.n_no_imu == 1
    out = est.update(1.5, pose(t=(0.15, 0, 0)))
    assert out is not None and out.used_imu
    np.testing.assert_allclose(out.pose[:3, 3], [0.15, 0, 0], atol=0.01)


# --------------------------------------------------------------------------------------------
# bounded graph, robustness


def test_graph_stays_bounded_and_time_flat() -> None:
    n, reset = 400, 40
    v = np.array([1.0, 0.0, 0.0])
    est = FusionEstimator(config(reset_every=reset))
    feed_imu(est, -1.0, 0.05, (0.0, 0.0, G))
    est.initialize(0.0, velocity=v)
    sizes, dts = [], []
    for i in range(1, n + 1):
        t = 0.1 * i
        feed_imu(est, t - 0.09, t + 0.0, (0.0, 0.0, G))
        t0 = time.perf_counter()
        out = est.update(t, pose(t=v * t), degeneracy([1, 0, 0, 0, 0, 0]) if i % 3 else None,
                         wheel_delta=pose(t=v * 0.1))
        dts.append(time.perf_counter() - t0)
        sizes.append(est.graph_size)
        assert out is not None
    assert est.stats.n_resets == n // reset
    assert max(sizes) <= 4 * reset + 4
    assert len(est.imu) < 300
    np.testing.assert_allclose(out.pose[:3, 3], v * 0.1 * n, atol=0.05)
    first, last = np.median(dts[:100]), np.median(dts[-100:])
    assert last < 3 * first + 1e-3


@pytest.mark.parametrize("variable", [True, False])
def test_reset_preserves_covariance(variable: bool) -> None:
    est = FusionEstimator(config(reset_every=10, gravity_variable=variable))
    feed_imu(est, -1.0, 1.05, (0.0, 0.0, G))
    est.initialize(0.0)
    for i in range(1, 10):
        est.update(0.1 * i, np.eye(4), degeneracy([1, 0, 0, 0, 0, 0]))
    before = est._isam.marginalCovariance(gtsam.symbol_shorthand.X(9))
    out = est.update(1.0, np.eye(4), degeneracy([1, 0, 0, 0, 0, 0]))
    assert est.stats.n_resets == 1 and est.graph_size == 1
    after = est._pose_covariance(est._state.pose, 10)  # from the graph rebuilt at the reset
    np.testing.assert_allclose(np.diag(after), np.diag(est._state.cov_gtsam), rtol=1e-3)
    assert np.all(np.diag(out.covariance) > 0) and before.shape == (6, 6)


@pytest.mark.parametrize(
    "bad",
    [
        dict(T_icp=np.full((4, 4), np.nan)),
        dict(T_icp=np.eye(4) * 2.0),
        dict(T_icp="garbage"),
        dict(degeneracy=degeneracy([np.nan, 0, 0, 0, 0, 0])),
        dict(degeneracy=SimpleNamespace(basis_scaled=[[1, 0, 0, 0, 0, 0]],
                                        characteristic_length=np.inf)),
        dict(degeneracy=object()),
        dict(wheel_delta=np.full((4, 4), np.inf)),
        dict(lidar_information=np.full((6, 6), np.nan)),
        dict(wheel_info=np.full((6, 6), np.nan), wheel_delta=np.eye(4)),
    ],
)
def test_nonfinite_inputs_rejected_without_exceptions(bad: dict) -> None:
    est = FusionEstimator(config())
    feed_imu(est, -1.0, 0.55, (0.0, 0.0, G))
    est.add_imu(0.555, [np.nan, 0, 0], [0, 0, 0])
    est.initialize(0.0)
    kwargs = dict(T_icp=pose(t=(0.01, 0, 0)), degeneracy=None)
    kwargs.update(bad)
    T_icp = kwargs.pop("T_icp")
    deg = kwargs.pop("degeneracy")
    out = est.update(0.1, T_icp, deg, **kwargs)
    assert out is not None and np.all(np.isfinite(out.pose)) and np.all(np.isfinite(out.covariance))
    s = est.stats
    assert (s.n_rejected_lidar + s.n_rejected_basis + s.n_rejected_wheel
            + s.n_rejected_lidar_information) >= 1
    assert est.imu.n_nonfinite == 1
    # and the estimator keeps working afterwards
    assert est.update(0.2, pose(t=(0.0, 0, 0))) is not None


def test_bad_stamps_rejected() -> None:
    est = FusionEstimator(config())
    assert est.update(float("nan"), np.eye(4)) is None
    est.initialize(1.0)
    assert est.update(1.0, np.eye(4)) is None  # not after the previous stamp
    assert est.update(0.5, np.eye(4)) is None
    assert est.update(float("inf"), np.eye(4)) is None
    assert est.stats.n_rejected_stamp == 4
    assert not est.add_wheel(2.0, np.full((4, 4), np.nan))
    assert est.predict(float("nan")) is not None


def test_wheel_buffer_interpolation_and_rejection() -> None:
    from lili_odom.fusion import WheelBuffer

    buf = WheelBuffer()
    stamps = np.arange(0.0, 1.0001, 0.02)
    for k in np.random.default_rng(5).permutation(len(stamps)):  # out of order
        t = stamps[k]
        assert buf.add(t, pose(rot_z(0.5 * t), (t, 0.2 * t, 0.0)))
    assert buf.n_out_of_order > 0
    assert not buf.add(0.5, np.eye(4) * 3)
    assert not buf.add(0.5, pose(t=(0, 0, 0)))  # duplicate stamp
    d = buf.delta(0.111, 0.789)
    expect = np.linalg.inv(pose(rot_z(0.5 * 0.111), (0.111, 0.0222, 0))) @ pose(
        rot_z(0.5 * 0.789), (0.789, 0.2 * 0.789, 0))
    np.testing.assert_allclose(d, expect, atol=2e-4)
    assert buf.delta(0.5, 2.0) is None  # beyond the data


@pytest.mark.parametrize("seed", [1, 2])
def test_random_garbage_never_raises_and_recovers(seed: int) -> None:
    """Random stamps, IMU, wheel poses, LiDAR poses, bases and informations, some corrupt."""
    rng = np.random.default_rng(seed)
    est = FusionEstimator(config(T_base_lidar=MOUNT))
    feed_imu(est, -1.0, 0.0, (0.0, 0.0, G))
    est.initialize(0.0)
    bad = [np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0, 1e-300]
    t = 0.0
    for _ in range(200):
        t += rng.choice([0.1, 0.1, 0.1, -0.05, 0.0, 3.0])
        for j in range(10):
            acc = rng.normal(size=3) * rng.choice([1.0, 1e6, np.nan]) + [0, 0, G]
            est.add_imu(t - 0.1 + 0.01 * j + rng.normal() * 0.02, acc, rng.normal(size=3) * 0.1)
        est.add_wheel(t, exp(rng.normal(size=6) * rng.choice([0.1, 1e3])))
        T = exp(rng.normal(size=6) * rng.choice([0.1, 10.0, 1e4]))
        if rng.random() < 0.2:
            T[rng.integers(3), rng.integers(4)] = rng.choice(bad)
        basis = rng.normal(size=(rng.integers(0, 7), 6))
        if rng.random() < 0.1 and basis.size:
            basis[0, 0] = rng.choice(bad)
        deg = SimpleNamespace(basis_scaled=basis, characteristic_length=rng.choice(
            [10.0, 0.0, -1.0, np.nan, 1e-9, 1e9]))
        info = rng.normal(size=(6, 6)) * rng.choice([1.0, 1e12]) if rng.random() < 0.2 else None
        out = est.update(t, T, deg, lidar_information=info)
        if out is not None:
            assert np.all(np.isfinite(out.pose)) and np.all(np.isfinite(out.covariance))
        P = est.predict(t + 0.05)
        assert P is not None and np.all(np.isfinite(P))
    # sane data afterwards is fused again: every update succeeds, and the IMU is used again
    # once the garbage IMU samples (their stamps jittered up to ~0.15 s past t) are behind
    feed_imu(est, t, t + 1.0, (0.0, 0.0, G))
    ok = [est.update(t + 0.1 * k, est.last_output.pose) for k in range(1, 6)]
    assert all(o is not None for o in ok)
    assert all(o.used_imu for o in ok[2:])


@pytest.mark.parametrize("factor, variable", [("between", False), ("prior", False),
                                              ("prior", True), ("hybrid", True)])
def test_accelerometer_bias_recovered_while_driving_a_degenerate_axis(factor: str,
                                                                       variable: bool) -> None:
    """Level start, constant accelerometer bias, 1 m/s along x with x degenerate (wheels there):
    the LiDAR holds the other directions, so the bias must be found, not absorbed elsewhere.
    With the start's tilt a variable (``gravity_variable``), driving straight cannot tell the
    bias from the frame's tilt: what must be found is their sum, the reading they explain.
    (The variable needs an absolute LiDAR factor to tie the frames: with ``between`` alone the
    lateral velocity is left 1 cm/s off.)"""
    bias = np.array([-0.027, -0.081, 0.0])
    cfg = config(gravity_align=False, gravity_variable=variable)
    cfg.lidar.factor = factor
    est = FusionEstimator(cfg)
    feed_imu(est, -1.0, 0.0, (bias + [0, 0, G]).tolist())
    for k in range(-10, 1):
        est.add_wheel(0.1 * k, pose(t=(0.1 * k, 0, 0)))
    est.update(0.0, pose())
    out = None
    for k in range(1, 201):
        t = 0.1 * k
        feed_imu(est, t - 0.09, t, (bias + [0, 0, G]).tolist())
        est.add_wheel(t - 0.05, pose(t=(t - 0.05, 0, 0)))
        est.add_wheel(t, pose(t=(t, 0, 0)))
        out = est.update(t, pose(t=(t, 0, 0)), degeneracy([1, 0, 0, 0, 0, 0]))
        assert out is not None
    # the estimated body's specific force at rest under the gravity tilted by gravity_tilt
    R_tilt = exp(np.array([0, 0, 0, *out.gravity_tilt, 0]))[:3, :3]
    explained = out.accel_bias[:2] + (out.pose[:3, :3].T @ R_tilt @ [0.0, 0.0, G])[:2]
    assert np.allclose(explained, bias[:2], atol=0.01), (out.accel_bias, out.gravity_tilt)
    assert abs(out.velocity[1]) < 0.01 and abs(out.velocity[0] - 1.0) < 0.01, out.velocity
    assert abs(out.pose[0, 3] - 20.0) < 0.05 and abs(out.pose[1, 3]) < 0.01


def _turn_under_a_tilted_map(gain: float, delta: float = 0.01, n: int = 300,
                             **overrides) -> tuple:
    """Level robot turning in place at 0.3 rad/s, IMU exact; the registrations come from a map
    whose frame is tilted by ``delta`` [rad] about x (what an accelerometer bias taken for
    gravity at the start leaves). Returns (last output, mean |registration - fused| tilt of
    the last 50 updates [rad], the estimator)."""
    wz = 0.3
    overrides = {"gravity_variable": False, **overrides}
    cfg = config(gravity_align=False, gravity_tracking_gain=gain, **overrides)
    est = FusionEstimator(cfg)
    tilt = exp(np.array([0, 0, 0, delta, 0, 0]))
    feed_imu(est, -1.0, 0.0, (0.0, 0.0, G), (0.0, 0.0, wz))
    est.initialize(0.0, pose=tilt, velocity=np.zeros(3))
    diffs, out = [], None
    for k in range(1, n + 1):
        t = 0.1 * k
        feed_imu(est, t - 0.09, t, (0.0, 0.0, G), (0.0, 0.0, wz))
        meas = tilt @ pose(rot_z(wz * t))
        out = est.update(t, meas)
        assert out is not None
        diffs.append(np.linalg.norm(log(meas @ np.linalg.inv(out.pose))[3:5]))
    return out, float(np.mean(diffs[-50:])), est


def test_gravity_tracking_follows_the_map_frame_through_a_turn() -> None:
    """Without tracking the IMU pulls the estimate off the map's tilt once the turn separates
    bias from tilt; with it, gravity is rotated into the map's frame and the two agree."""
    out0, diff0, _ = _turn_under_a_tilted_map(0.0)
    out1, diff1, _ = _turn_under_a_tilted_map(0.02)
    np.testing.assert_allclose(out0.gravity_tilt, 0.0)
    assert diff0 > 0.002, diff0
    assert diff1 < 0.5 * diff0, (diff1, diff0)
    np.testing.assert_allclose(out1.gravity_tilt, [0.01, 0.0], atol=0.003)


def test_gravity_variable_takes_the_map_frames_tilt_with_the_bias() -> None:
    """As a graph variable, the tilt between the map's frame and gravity is estimated with
    the accelerometer bias: at rest the two share the reading, the turn tells them apart,
    and the estimate agrees with the tilted map without a gain."""
    _, diff0, _ = _turn_under_a_tilted_map(0.0)
    out, diff, _ = _turn_under_a_tilted_map(0.0, gravity_variable=True)
    assert diff0 > 0.005 and diff < 1e-4, (diff, diff0)
    np.testing.assert_allclose(out.gravity_tilt, [0.01, 0.0], atol=0.002)
    np.testing.assert_allclose(out.accel_bias, 0.0, atol=0.2 * G * 0.01)


def test_gravity_variable_reports_the_covariance_in_the_odometry_frame() -> None:
    """Far from the origin a tilt of the gravity frame moves the graph's poses by its lever
    (the distance times the tilt), not the odometry frame's: the reported covariance is the
    odometry frame's, as without the variable."""
    covs = []
    for variable in (False, True):
        est = FusionEstimator(config(gravity_align=False, gravity_variable=variable,
                                     gravity_tracking_gain=0.0))
        feed_imu(est, -1.0, 0.0, (0.0, 0.0, G))
        est.initialize(0.0, pose=np.eye(4), velocity=np.array([2.0, 0.0, 0.0]),
                       velocity_sigma=0.01)
        for k in range(1, 151):  # 30 m along x at 2 m/s
            t = 0.1 * k
            feed_imu(est, t - 0.09, t, (0.0, 0.0, G))
            out = est.update(t, pose(t=(2.0 * t, 0.0, 0.0)))
            assert out is not None
        covs.append(out.covariance)
        np.testing.assert_allclose(out.pose[:3, 3], [30.0, 0.0, 0.0], atol=1e-3)
    lever = (30.0 * est.config.gravity_variable_sigma) ** 2  # what the graph frame's z has
    assert covs[1][2, 2] < 0.01 * lever, (covs[1][2, 2], lever)
    np.testing.assert_allclose(np.diag(covs[1]), np.diag(covs[0]), rtol=0.5)


def test_gravity_variable_survives_graph_resets_and_recovery() -> None:
    """The frame variable is carried through the periodic reset (joint marginal with the
    newest state) and through a rebuild after a solver failure."""
    out, diff, est = _turn_under_a_tilted_map(0.0, n=120, gravity_variable=True, reset_every=7)
    assert est.stats.n_resets >= 15 and est.stats.n_reset_fallbacks == 0, est.stats
    assert diff < 0.002, diff
    np.testing.assert_allclose(out.gravity_tilt, [0.01, 0.0], atol=0.003)
    est = FusionEstimator(config(gravity_align=False, gravity_variable=True))
    feed_imu(est, -1.0, 0.0, (0.0, 0.0, G))
    est.initialize(0.0, pose=np.eye(4), velocity=np.zeros(3))
    est.gravity_tilt = np.array([0.004, -0.002])  # the next initialize's prior mean
    np.testing.assert_allclose(est.initialize(0.0, pose=np.eye(4)).gravity_tilt,
                               [0.004, -0.002], atol=1e-9)
    prev = est._state
    est._recover(prev)
    feed_imu(est, 0.01, 0.1, (0.0, 0.0, G))
    out = est.update(0.1, np.eye(4))
    assert out is not None
    np.testing.assert_allclose(out.gravity_tilt, [0.004, -0.002], atol=1e-4)


def test_gravity_tracking_is_bounded_and_gated() -> None:
    cfg = config(gravity_align=False, gravity_tracking_gain=1.0, gravity_tracking_max=0.004,
                 gravity_variable=False)
    est = FusionEstimator(cfg)
    feed_imu(est, -1.0, 0.0, (0.0, 0.0, G))
    est.initialize(0.0, pose=np.eye(4), velocity=np.zeros(3))
    for k in range(1, 20):
        feed_imu(est, 0.1 * k - 0.09, 0.1 * k, (0.0, 0.0, G))
        out = est.update(0.1 * k, exp(np.array([0, 0, 0, 0.03, 0, 0])))
    assert 0.0 < np.linalg.norm(out.gravity_tilt) <= 0.004 + 1e-12
    assert out.gravity_tilt[0] > 0.0
    before = out.gravity_tilt.copy()
    feed_imu(est, 1.91, 2.0, (0.0, 0.0, G))
    out = est.update(2.0, exp(np.array([0, 0, 0, -0.2, 0, 0])))  # beyond the 0.05 rad gate
    np.testing.assert_allclose(out.gravity_tilt, before)
    assert est.initialize(2.1).gravity_tilt.tolist() == [0.0, 0.0]  # a new frame: along -z


def test_velocity_sigma_is_the_velocity_marginal_and_shrinks_with_measurements() -> None:
    """A steady IMU alone does not make the start's zero velocity certain (it cannot tell
    rest from driving at constant speed): the prior stays loose without wheels at rest, and
    the LiDAR's positions then pin the velocity down."""
    est = FusionEstimator(config())
    assert est.velocity_sigma() is None
    feed_imu(est, -0.5, 0.3, (0.0, 0.0, G))
    est.initialize(0.0)
    loose = est.velocity_sigma()
    assert loose == pytest.approx(est.config.prior_sigma_velocity_moving, rel=1e-6)
    for k, t in enumerate((0.1, 0.2, 0.3), start=1):
        assert est.update(t, pose(t=(0.25 * k, 0.0, 0.0))) is not None
    assert est.velocity_sigma() < 0.5 * loose
    assert est.last_output.velocity[0] > 1.5  # 2.5 m/s measured, not held at zero
    with_wheels = FusionEstimator(config())
    feed_imu(with_wheels, -0.5, 0.0, (0.0, 0.0, G))
    for t in (-0.3, -0.2, -0.1, 0.0):
        with_wheels.add_wheel(t, pose())  # the wheels report rest as well
    with_wheels.initialize(0.0)
    assert with_wheels.velocity_sigma() == pytest.approx(
        with_wheels.config.prior_sigma_velocity, rel=1e-6)


def _cruise_along_a_degenerate_axis(cruise_sigma: float, wheels: bool) -> FusionOutput:
    """1 m/s along x for 20 s with x degenerate, an unknown accelerometer bias along x, and
    the wheels reporting the true motion or absent."""
    bias = np.array([0.05, 0.0, 0.0])
    est = FusionEstimator(config(gravity_align=False, cruise_sigma=cruise_sigma))
    feed_imu(est, -1.0, 0.0, (bias + [0, 0, G]).tolist())
    est.initialize(0.0, velocity=np.array([1.0, 0.0, 0.0]))
    out = None
    for k in range(1, 201):
        t = 0.1 * k
        feed_imu(est, t - 0.09, t, (bias + [0, 0, G]).tolist())
        if wheels:
            est.add_wheel(t - 0.1, pose(t=(t - 0.1, 0, 0)))
            est.add_wheel(t, pose(t=(t, 0, 0)))
        out = est.update(t, pose(t=(0.0, 0, 0)), degeneracy([1, 0, 0, 0, 0, 0]))
        assert out is not None
    return out


def test_cruise_factor_holds_the_velocity_along_an_unmeasured_axis() -> None:
    """Without wheels the biased accelerometer alone runs the degenerate axis away
    (0.05 m/s^2 over 20 s: metres); the cruise factor keeps the robot's steady speed, so the
    bias is being found and the end is within decimetres."""
    free = _cruise_along_a_degenerate_axis(0.0, wheels=False)
    held = _cruise_along_a_degenerate_axis(0.1, wheels=False)
    assert abs(free.pose[0, 3] - 20.0) > 2.0, free.pose[:3, 3]
    assert abs(held.pose[0, 3] - 20.0) < 0.3, held.pose[:3, 3]
    assert abs(held.velocity[0] - 1.0) < 0.03, held.velocity
    assert held.accel_bias[0] > 0.02 > abs(free.accel_bias[0]), (held.accel_bias,
                                                                 free.accel_bias)


def test_cruise_factor_only_without_wheel_data() -> None:
    """With wheel data on every interval the factor is not added: the estimate is the same
    with and without it."""
    off = _cruise_along_a_degenerate_axis(0.0, wheels=True)
    on = _cruise_along_a_degenerate_axis(0.1, wheels=True)
    np.testing.assert_allclose(on.pose, off.pose, atol=1e-9)
    np.testing.assert_allclose(on.velocity, off.velocity, atol=1e-9)


def test_cruise_factor_leaves_a_start_to_the_imu() -> None:
    """Accelerating at 0.5 m/s^2 from rest along a degenerate axis without wheels, with an
    unbiased IMU: the start is beyond ``cruise_max_accel``, so the factor does not hold the
    velocity at rest: the estimate is the one without the factor (without the gate the
    start would be taken for an accelerometer bias and the robot held at rest)."""
    def run(sigma: float, max_accel: float) -> FusionOutput:
        est = FusionEstimator(config(gravity_align=False, cruise_sigma=sigma,
                                     cruise_max_accel=max_accel))
        feed_imu(est, -1.0, 4.05, (0.5, 0.0, G))
        est.initialize(0.0)
        out = None
        for k in range(1, 41):
            out = est.update(0.1 * k, pose(), degeneracy([1, 0, 0, 0, 0, 0]))
        return out

    free, gated, held = run(0.0, 0.1), run(0.1, 0.1), run(0.1, 1e3)
    assert free.velocity[0] > 1.8, free.velocity
    np.testing.assert_allclose(gated.velocity, free.velocity, atol=1e-9)
    np.testing.assert_allclose(gated.pose, free.pose, atol=1e-9)
    assert held.velocity[0] < 0.5 and held.accel_bias[0] > 0.2, (held.velocity,
                                                                 held.accel_bias)
