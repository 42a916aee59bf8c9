"""The simulated IMU and the estimator's IMU model agree: GTSAM preintegration of the simulated
samples (true bias removed) from the true state reproduces the true motion."""
from __future__ import annotations

import gtsam
import numpy as np
import pytest

from lili_odom.fusion.imu import ImuNoiseConfig, make_preintegration_params
from lili_odom.sim.generator import SimRequest, Simulation
from lili_odom.sim.imu import simulate_imu


@pytest.fixture(scope="module")
def trial1():
    sim = Simulation(SimRequest(trial=1, resolution=(8, 64)))
    T_base_imu = sim.sensors.extrinsics.base_to_imu
    return sim.trajectory, T_base_imu, simulate_imu(sim.trajectory, T_base_imu,
                                                    sim.sensors.imu, seed=0)


@pytest.mark.parametrize("t0", [5.0, 48.0, 100.0, 150.0, 220.0])
def test_preintegrated_simulated_imu_follows_the_truth(trial1, t0: float) -> None:
    traj, T_base_imu, imu = trial1
    # the IMU frame as the body: conventions only (gravity, specific force, frames, bias).
    # With base_link as the body (body_P_sensor, 0.66 m below the IMU) GTSAM's lever-arm
    # correction has no angular-acceleration term, worth ~1.5 cm per second on the bumpy floor
    # (``integrate`` adds it: the test after this one).
    params = make_preintegration_params(ImuNoiseConfig(gravity=9.80665))
    i0, i1 = np.searchsorted(imu.t, [t0, t0 + 1.0])
    k0, k1 = (traj.kinematics(np.array([imu.t[i]]), T_base_imu) for i in (i0, i1))
    bias = gtsam.imuBias.ConstantBias(imu.accel_bias[i0], imu.gyro_bias[i0])
    pim = gtsam.PreintegratedCombinedMeasurements(params, bias)
    for j in range(i0, i1):
        pim.integrateMeasurement(imu.accel[j], imu.gyro[j], imu.t[j + 1] - imu.t[j])
    nav = pim.predict(gtsam.NavState(gtsam.Rot3(k0.rotation[0]), k0.position[0],
                                     k0.velocity[0]), bias)
    assert np.linalg.norm(nav.position() - k1.position[0]) < 0.005
    assert np.linalg.norm(nav.velocity() - k1.velocity[0]) < 0.005
    # and the motion was real: the robot moved (or turned) in that second
    assert np.linalg.norm(k1.position[0] - k0.position[0]) > 0.05 or t0 < 10.0


def _base_prediction(traj, T_base_imu, imu, t0: float, lever_arm) -> tuple[np.ndarray, np.ndarray]:
    """(predicted, true) base_link position 1 s after ``t0``, preintegrating the simulated
    samples (true bias) with base_link as the body through ``integrate``."""
    from lili_odom.fusion.imu import ImuBuffer, integrate

    params = make_preintegration_params(ImuNoiseConfig(gravity=9.80665), T_base_imu)
    i0, i1 = np.searchsorted(imu.t, [t0, t0 + 1.0])
    buf = ImuBuffer(buffer_seconds=5.0)
    for j in range(i0, i1 + 1):
        buf.add(imu.t[j], imu.accel[j] - imu.accel_bias[i0], imu.gyro[j] - imu.gyro_bias[i0])
    k0, k1 = (traj.kinematics(np.array([imu.t[i]]), np.eye(4)) for i in (i0, i1))
    pim = gtsam.PreintegratedCombinedMeasurements(params, gtsam.imuBias.ConstantBias())
    assert integrate(buf, pim, imu.t[i0], imu.t[i1], 0.1, 0.0, lever_arm).covered
    nav = pim.predict(gtsam.NavState(gtsam.Rot3(k0.rotation[0]), k0.position[0],
                                     k0.velocity[0]), gtsam.imuBias.ConstantBias())
    return nav.position(), k1.position[0]


def test_the_lever_arm_euler_term_is_removed_with_base_link_as_the_body(trial1) -> None:
    from lili_odom.fusion.imu import lever_arm_in_imu

    traj, T_base_imu, imu = trial1
    lever = lever_arm_in_imu(T_base_imu)
    assert lever is not None and np.linalg.norm(lever) > 0.5  # the OS1 on its mast
    errors = {True: [], False: []}
    for t0 in (48.0, 100.0, 150.0, 220.0):
        for compensate in (True, False):
            pred, true = _base_prediction(traj, T_base_imu, imu, t0,
                                          lever if compensate else None)
            errors[compensate].append(float(np.linalg.norm(pred - true)))
    assert max(errors[True]) < 0.005
    # without it the bumpy floor's rocking leaves centimetres in a second
    assert max(errors[False]) > 2 * max(errors[True]) and max(errors[False]) > 0.005


def test_lever_arm_in_imu_and_euler_correction() -> None:
    from lili_odom.fusion.imu import euler_correction, lever_arm_in_imu

    assert lever_arm_in_imu(None) is None and lever_arm_in_imu(np.eye(4)) is None
    T = np.eye(4)
    T[:3, :3] = gtsam.Rot3.Yaw(np.pi / 2).matrix()
    T[:3, 3] = [0.1, 0.0, 0.6]
    r = lever_arm_in_imu(T)
    assert np.allclose(T[:3, :3] @ r, T[:3, 3])  # the same offset, in the IMU frame
    # a roll acceleration of 2 rad/s^2 about the IMU's x axis with the IMU 0.6 m up: 1.2 m/s^2
    # sideways (along -y of the IMU frame)
    up = np.array([0.0, 0.0, 0.6])
    corr = euler_correction(np.zeros(3), np.array([0.02, 0.0, 0.0]), 0.01, up)
    assert np.allclose(corr, [0.0, -1.2, 0.0])
    # a constant rate (any bias) adds nothing
    assert np.allclose(euler_correction(np.ones(3), np.ones(3), 0.01, up), 0.0)
