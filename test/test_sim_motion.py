"""Trajectory, IMU and wheel-odometry models of the simulator against the true motion."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lili_odom.sim.imu import simulate_imu, true_imu
from lili_odom.sim.sensors import default_sensors
from lili_odom.sim.trajectory import Trajectory
from lili_odom.sim.wheels import simulate_wheel_odom
from lili_odom.sim.world import load_world

G = np.array([0.0, 0.0, -9.80665])


@pytest.fixture(scope="module")
def tunnel():
    return load_world("tunnel")


@pytest.fixture(scope="module")
def traj1(tunnel):
    return Trajectory(tunnel, tunnel.trials[1], seed=0)


def test_trials_have_the_specified_lengths_and_stay_in_the_tunnel(tunnel, traj1):
    traj2 = Trajectory(tunnel, tunnel.trials[2], seed=0)
    for traj, length in ((traj1, 260.0), (traj2, 430.0)):
        t = np.arange(0.0, traj.duration, 0.05)
        p = traj.pose(t)[:, :3, 3]
        travelled = np.sum(np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1))
        assert abs(travelled - length) < 3.0
        inside = p[:, 0] > 1.0
        s = np.linspace(0, tunnel.tube_length, 5001)
        cxy, _ = traj.line.frame(s)
        dist = np.min(np.linalg.norm(p[inside, None, :2] - cxy[None, ::5], axis=2), axis=1)
        assert np.max(dist) < 2.0  # Husky (0.67 m wide) stays well inside the 6 m tunnel
    assert "turn" in traj2.phase_kinds(np.arange(0, traj2.duration, 0.5))


def test_speed_profile_is_husky_like_and_not_constant_velocity(traj1):
    t = np.arange(0.0, traj1.duration, 0.02)
    k = traj1.kinematics(t)
    speed = np.linalg.norm(k.velocity, axis=1)
    assert speed.max() < 1.25
    assert np.linalg.norm(k.acceleration, axis=1).max() < 0.6
    moving = speed > 0.05
    assert np.percentile(speed[moving], 10) < 0.7 and np.percentile(speed[moving], 90) > 0.9
    # full stops of a few seconds inside the tunnel
    stopped = (speed < 1e-3) & (k.position[:, 0] > 5.0) & (t < traj1.duration - 3)
    runs = np.diff(np.r_[0, stopped.astype(int), 0])
    lengths = (np.where(runs == -1)[0] - np.where(runs == 1)[0]) * 0.02
    assert np.sum(lengths >= 2.5) >= 2
    # floor bumps: some z, roll and pitch motion
    assert np.ptp(k.position[:, 2]) > 0.02
    assert np.abs(k.omega[:, 0]).max() > 0.005 and np.abs(k.omega[:, 1]).max() > 0.005
    # a constant-velocity guess held through a few seconds (a degenerate stretch) is off by metres
    horizon = 5.0
    n = int(round(horizon / 0.02))
    pred = k.position[:-n] + horizon * k.velocity[:-n]
    err = np.linalg.norm(pred - k.position[n:], axis=1)
    assert err.max() > 1.0 and np.mean(err > 0.3) > 0.1


def _integrate(t, R0, v0, p0, gyro, accel):
    R, v, p = R0.copy(), v0.copy(), p0.copy()
    dt = np.diff(t)
    for i in range(len(dt)):
        a0 = R @ accel[i] + G
        R1 = R @ Rotation.from_rotvec(0.5 * (gyro[i] + gyro[i + 1]) * dt[i]).as_matrix()
        a1 = R1 @ accel[i + 1] + G
        a = 0.5 * (a0 + a1)
        p = p + v * dt[i] + 0.5 * a * dt[i] ** 2
        v = v + a * dt[i]
        R = R1
    return R, v, p


def test_imu_integrates_to_the_true_motion(traj1):
    S = default_sensors()
    X = S.extrinsics.base_to_imu
    t = np.arange(40.0, 46.0 + 1e-9, 0.01)
    k = traj1.kinematics(t, X)
    assert np.linalg.norm(k.velocity[0]) > 0.3
    # noise-free model: exact up to integration error
    w, f = true_imu(traj1, t, X)
    R, v, p = _integrate(t, k.rotation[0], k.velocity[0], k.position[0], w, f)
    assert np.linalg.norm(p - k.position[-1]) < 0.01
    assert np.linalg.norm(v - k.velocity[-1]) < 0.005
    # simulated IMU, true biases removed: within the white-noise level
    imu = simulate_imu(traj1, X, S.imu, seed=4, t_end=47.0)
    sel = (imu.t >= 40.0 - 1e-9) & (imu.t <= 46.0 + 1e-9)
    assert np.allclose(imu.t[sel], t)
    R, v, p = _integrate(t, k.rotation[0], k.velocity[0], k.position[0],
                         imu.gyro[sel] - imu.gyro_bias[sel], imu.accel[sel] - imu.accel_bias[sel])
    assert np.linalg.norm(p - k.position[-1]) < 0.15
    rot_err = Rotation.from_matrix(R.T @ k.rotation[-1]).magnitude()
    assert rot_err < 5 * S.imu.gyro_noise_density * np.sqrt(6.0) + 1e-4
    # residuals have the configured white-noise level
    res = imu.gyro[sel] - imu.gyro_bias[sel] - w
    assert 0.7 < res.std() / S.imu.gyro_sigma < 1.3
    res = imu.accel[sel] - imu.accel_bias[sel] - f
    assert 0.7 < res.std() / S.imu.accel_sigma < 1.3


def test_imu_at_rest_measures_gravity(traj1):
    S = default_sensors()
    w, f = true_imu(traj1, np.array([0.5, 1.0]), S.extrinsics.base_to_imu)
    assert np.allclose(np.linalg.norm(f, axis=1), 9.80665, atol=1e-4)
    assert f[0, 2] > 9.7 and np.allclose(w, 0.0, atol=1e-6)


def test_wheel_odometry_within_the_configured_scale_error(traj1):
    S = default_sensors()
    t_end = 150.0
    for seed in (0, 1, 2):
        wo = simulate_wheel_odom(traj1, S.wheels, seed=seed, t_end=t_end)
        dt = 1.0 / S.wheels.rate_hz
        dist_odom = np.sum(np.hypot(np.diff(wo.x), np.diff(wo.y)))
        p = traj1.pose(wo.t)[:, :3, 3]
        dist_true = np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1))
        slip = np.sum(np.abs(wo.v_true[wo.slipping]) * S.wheels.slip_speed_gain_range[1]) * dt
        ratio = dist_odom / dist_true
        assert abs(ratio - 1.0) <= S.wheels.scale_max + slip / dist_true + 0.01
        assert abs(ratio - wo.scale) <= slip / dist_true + 0.01
        # planar end point: off by the scale and the heading drift, not more
        T0 = traj1.pose(0.0)[0]
        end_true = (np.linalg.inv(T0) @ traj1.pose(wo.t[-1])[0])[:2, 3]
        end_odom = np.array([wo.x[-1], wo.y[-1]])
        assert np.linalg.norm(end_odom - end_true) < 0.15 * dist_true


def test_sensor_models_are_deterministic_per_seed(traj1):
    S = default_sensors()
    a = simulate_imu(traj1, S.extrinsics.base_to_imu, S.imu, seed=5, t_end=20.0)
    b = simulate_imu(traj1, S.extrinsics.base_to_imu, S.imu, seed=5, t_end=20.0)
    c = simulate_imu(traj1, S.extrinsics.base_to_imu, S.imu, seed=6, t_end=20.0)
    assert np.array_equal(a.accel, b.accel) and not np.array_equal(a.accel, c.accel)
    w1 = simulate_wheel_odom(traj1, S.wheels, seed=5, t_end=20.0)
    w2 = simulate_wheel_odom(traj1, S.wheels, seed=5, t_end=20.0)
    assert np.array_equal(w1.x, w2.x)
    world = load_world("tunnel")
    t = np.linspace(0, 100, 777)
    assert np.array_equal(Trajectory(world, world.trials[1], seed=3).pose(t), Trajectory(world, world.trials[1], seed=3).pose(t))
    assert not np.allclose(Trajectory(world, world.trials[1], seed=4).pose(t), Trajectory(world, world.trials[1], seed=3).pose(t))


@pytest.mark.parametrize("name", ["tunnel", "corridor", "open_field", "orchard"])
def test_every_shipped_trial_is_a_valid_husky_motion(name):
    world = load_world(name)
    for trial, plan in world.trials.items():
        traj = Trajectory(world, plan, seed=1)
        t = np.arange(0.0, traj.duration, 0.05)
        k = traj.kinematics(t)
        assert np.all(np.isfinite(k.position)) and np.all(np.isfinite(k.omega))
        speed = np.linalg.norm(k.velocity, axis=1)
        assert speed.max() <= plan.speed_range[1] * 1.05 + 1e-6, (name, trial)
        assert np.linalg.norm(k.acceleration, axis=1).max() < 1.6 * plan.max_accel, (name, trial)
        assert speed[0] < 1e-6 and speed[-1] < 1e-6  # starts and ends at rest
        # no side slip: body velocity is along base_link x
        v_body = np.einsum("nji,nj->ni", k.rotation, k.velocity)
        assert np.abs(v_body[:, 1]).max() < 0.02
