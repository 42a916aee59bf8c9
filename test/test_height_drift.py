"""The height-drift study's arithmetic (benchmarks/studies/height_drift.py)."""
import numpy as np

from benchmarks.studies.height_drift import height_error, largest_jump, true_accel_bias


def pose(z: float) -> np.ndarray:
    T = np.eye(4)
    T[2, 3] = z
    return T


def test_height_error_is_taken_from_each_first_pose():
    stamps = np.array([10.0, 11.0, 12.0])
    est = np.stack([pose(5.0), pose(5.1), pose(5.3)])
    truth_t = np.array([9.0, 13.0])
    truth = np.stack([pose(0.0), pose(0.4)])  # 0.1 m/s up
    t, dz = height_error(stamps, est, truth_t, truth)
    assert np.allclose(t, [0.0, 1.0, 2.0])
    assert np.allclose(dz, [0.0, 0.0, 0.1])


def test_largest_jump_finds_the_biggest_change_within_the_window():
    t = np.arange(0.0, 20.0, 0.5)
    dz = np.where(t < 12.0, -0.01 * t, -0.12 + 0.3)  # a slow descent, then a 0.3 m step
    change, when = largest_jump(t, dz, window=3.0)
    assert abs(change - 0.3) < 0.01 and 12.0 <= when <= 15.0


def test_the_true_bias_is_the_simulators_draw(monkeypatch):
    """The study's bias is the one :func:`simulate_imu` starts its accelerometer with (its
    first sample adds one step of the random walk, about 1e-5 m/s^2)."""
    from types import SimpleNamespace

    import lili_odom.sim.imu as sim_imu
    from lili_odom.sim.sensors import ImuConfig

    monkeypatch.setattr(sim_imu, "true_imu",
                        lambda traj, t, X, g: (np.zeros((len(t), 3)), np.zeros((len(t), 3))))
    for seed in (1, 21):
        imu = sim_imu.simulate_imu(SimpleNamespace(duration=0.05), np.eye(4), ImuConfig(), seed)
        assert np.allclose(imu.accel_bias[0], true_accel_bias(seed), atol=1e-4)
    assert not np.allclose(true_accel_bias(1), true_accel_bias(21), atol=1e-3)
