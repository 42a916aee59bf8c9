"""Robustness to IMU, wheel and clock faults (issue #6), driven through ``OdometryPipeline``
``add_imu`` / ``add_wheel`` / ``process_scan``: the pipeline keeps producing finite poses,
resets on clock jumps backwards, never integrates over forward gaps, and runs without wheels
or without an IMU.

The pipeline tests call KISS-ICP and GTSAM, so they run in one subprocess
(``test_sensor_cases_in_subprocess``); in the parent process they are skipped.
"""
from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import closed_room
from scipy.spatial.transform import Rotation

from lili_odom.fusion.imu import ImuBuffer, StampJumpFilter
from lili_odom.fusion.wheel import WheelBuffer

INNER = os.environ.get("LILI_ODOM_ROBUSTNESS_INNER") == "1"
inner = pytest.mark.skipif(not INNER, reason="runs in test_sensor_cases_in_subprocess")

G = 9.80665
T0 = 500.0


# --------------------------------------------------------------------------------------------
# buffers alone (pure Python)


def test_single_future_stamp_does_not_wipe_the_imu_buffer():
    buf = ImuBuffer(buffer_seconds=30.0)
    acc, gyro = np.array([0, 0, G]), np.zeros(3)
    for k in range(100):
        assert buf.add(T0 + 0.01 * k, acc, gyro)
    assert not buf.add(T0 + 1000.0, acc, gyro)  # a corrupt stamp: held back
    for k in range(100, 200):
        assert buf.add(T0 + 0.01 * k, acc, gyro)
    assert len(buf) == 200 and buf.newest_time == pytest.approx(T0 + 1.99)
    assert buf.jumps.n_outliers == 1 and buf.n_held == 1


def test_confirmed_clock_jumps_are_followed():
    buf = ImuBuffer(buffer_seconds=30.0)
    acc, gyro = np.array([0, 0, G]), np.zeros(3)
    for k in range(100):
        buf.add(T0 + 0.01 * k, acc, gyro)
    # forward by 100 s (longer than the buffer): the third sample confirms it
    results = [buf.add(T0 + 100.0 + 0.01 * k, acc, gyro) for k in range(5)]
    assert results == [False, False, True, True, True]
    assert len(buf) == 5 and buf.oldest_time == pytest.approx(T0 + 100.0)
    # backwards by more than the buffer (a bag loop on a long bag)
    results = [buf.add(T0 - 50.0 + 0.01 * k, acc, gyro) for k in range(4)]
    assert results == [False, False, True, True]
    assert len(buf) == 4 and buf.newest_time == pytest.approx(T0 - 50.0 + 0.03)
    assert buf.jumps.n_jumps == 2


def test_imu_dropout_of_seconds_resumes_after_confirmation():
    buf = ImuBuffer()
    acc, gyro = np.array([0, 0, G]), np.zeros(3)
    for k in range(10):
        buf.add(T0 + 0.01 * k, acc, gyro)
    for k in range(10):
        buf.add(T0 + 3.0 + 0.01 * k, acc, gyro)
    assert len(buf) == 20 and buf.jumps.n_outliers == 0


def test_wheel_buffer_survives_a_future_stamp_and_nan_poses():
    buf = WheelBuffer()
    for k in range(50):
        T = np.eye(4)
        T[0, 3] = 0.01 * k
        assert buf.add(T0 + 0.02 * k, T)
    assert not buf.add(T0 + 5000.0, np.eye(4))
    bad = np.eye(4)
    bad[:3, :3] = np.nan
    assert not buf.add(T0 + 1.001, bad)
    bad = np.eye(4)
    bad[0, 3] = np.inf
    assert not buf.add(T0 + 1.002, bad)
    assert len(buf) == 50 and buf.delta(T0, T0 + 0.98)[0, 3] == pytest.approx(0.49)


def test_jump_filter_discards_inconsistent_held_samples():
    f = StampJumpFilter(max_forward_s=1.0, max_backward_s=30.0, confirm=3)
    assert f.offer(10.0, None, 9.99)[0] == "fits"
    assert f.offer(100.0, None, 10.0)[0] == "held"
    assert f.offer(500.0, None, 10.0)[0] == "held"  # not consistent with 100: restart holding
    assert f.offer(10.01, None, 10.0)[0] == "fits"
    assert f.n_outliers == 2 and f.held == []


def test_nan_in_wheel_quaternion_is_rejected_not_read_as_identity():
    from types import SimpleNamespace as NS

    from lili_odom.messages import wheel_from_msg

    v = NS(x=0.0, y=0.0, z=0.0)
    msg = NS(header=NS(stamp=NS(sec=1, nanosec=0)),
             pose=NS(pose=NS(position=NS(x=1.0, y=0.0, z=0.0),
                             orientation=NS(x=0.0, y=0.0, z=float("nan"), w=1.0))),
             twist=NS(twist=NS(linear=v, angular=v), covariance=[0.0] * 36))
    sample = wheel_from_msg(msg)
    assert not np.all(np.isfinite(sample.pose))
    assert not WheelBuffer().add(sample.stamp, sample.pose)


# --------------------------------------------------------------------------------------------
# through the pipeline (subprocess)


def test_sensor_cases_in_subprocess():
    env = dict(os.environ, LILI_ODOM_ROBUSTNESS_INNER="1")
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", "inner",
         str(Path(__file__))], capture_output=True, text=True, timeout=600, env=env,
        cwd=Path(__file__).resolve().parents[1])
    if proc.returncode != 0 or " passed" not in proc.stdout:
        pytest.fail(f"inner tests failed (exit {proc.returncode}):\n{proc.stdout[-8000:]}\n"
                    f"{proc.stderr[-3000:]}", pytrace=False)


def room(seed: int = 0, n_per_face: int = 600) -> np.ndarray:
    """Points on the six faces of a 24 x 12 x 6 m room around the sensor (LiDAR frame)."""
    return closed_room(seed, n_per_face, half=(12.0, 6.0, 3.0))


def corridor(seed: int, n: int = 4000) -> np.ndarray:
    """Walls y = +-2, floor z = -1, ceiling z = 2, 60 m long in x: x translation unobservable."""
    rng = np.random.default_rng(seed)
    faces = []
    for ax, v in ((1, -2.0), (1, 2.0), (2, -1.0), (2, 2.0)):
        p = rng.uniform(-1, 1, (n // 4, 3)) * [30.0, 2.0, 1.5] + [0, 0, 0.5]
        p[:, ax] = v
        faces.append(p)
    return np.vstack(faces)


class Sim:
    """A robot standing still in a room: IMU at 100 Hz, wheels at 50 Hz, scans at 10 Hz.

    ``imu(t)`` / ``wheel(t)`` return the sample to add at ``t`` (None = no message); each scan
    is stamped at its sweep start with per-point times over [0, 0.1) s.
    """

    def __init__(self, method: str = "none", cloud=room, **config):
        from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig

        self.pipe = OdometryPipeline(PipelineConfig(method=method, **config))
        self.cloud = cloud
        self.outputs = []

    @staticmethod
    def still_imu(t, R=np.eye(3)):
        return R.T @ np.array([0.0, 0.0, G]), np.zeros(3)

    def run(self, t_start: float, seconds: float, imu=None, wheel=None, scans=True,
            imu_on=True, wheel_on=True):
        from lili_odom.pipeline.types import ImuSample, Scan, WheelSample

        imu = imu or (lambda t: self.still_imu(t))
        wheel = wheel or (lambda t: np.eye(4))
        outs = []
        for k in range(int(round(seconds * 100))):
            t = t_start + 0.01 * k
            if imu_on:
                s = imu(t)
                if s is not None:
                    self.pipe.add_imu(ImuSample(t, s[1], s[0]))
            if wheel_on and k % 2 == 0:
                T = wheel(t)
                if T is not None:
                    self.pipe.add_wheel(WheelSample(t, np.zeros(6), T))
            # the scan stamped at t - 0.1 is complete (its IMU/wheel data are in) at t
            if scans and k % 10 == 0 and k >= 10:
                pts = self.cloud(k)
                out = self.pipe.process_scan(Scan(t - 0.1, pts, np.linspace(0, 0.099, len(pts))))
                outs.append(out)
                if out is not None:
                    assert np.all(np.isfinite(out.pose)) and np.all(np.isfinite(out.covariance))
        self.outputs += outs
        return outs


def _ok(outs):
    return [o for o in outs if o is not None]


def _max_offset(outs):
    return max(float(np.linalg.norm(o.pose[:3, 3])) for o in _ok(outs))


@inner
def test_inner_baseline_still_robot_stays_put():
    sim = Sim()
    outs = sim.run(T0, 3.0)
    assert len(_ok(outs)) == len(outs) and _max_offset(outs) < 0.1
    assert all(o.details["used_imu"] for o in _ok(outs)[1:])


@inner
def test_inner_imu_gap_of_seconds_falls_back_then_recovers():
    sim = Sim()
    sim.run(T0, 2.0)
    gap = sim.run(T0 + 2.0, 3.0, imu_on=False)
    after = sim.run(T0 + 5.0, 2.0)
    assert len(_ok(gap)) == len(gap) and _max_offset(gap + after) < 0.1
    assert not any(o.details["used_imu"] for o in _ok(gap)[1:])
    assert all(o.details["used_imu"] for o in _ok(after)[3:])
    assert any("no IMU" in w for o in _ok(gap) for w in o.warnings)


@inner
@pytest.mark.parametrize("fault", ["duplicates", "out_of_order", "backwards", "future_glitch",
                                   "past_glitch", "nan", "saturated",
                                   "clipped_at_range"])
def test_inner_imu_faults_keep_poses_finite_and_put(fault):
    from lili_odom.pipeline.types import ImuSample

    sim = Sim()
    sim.run(T0, 1.5)
    rng = np.random.default_rng(0)
    acc0, gyro0 = Sim.still_imu(0)

    def imu(t):
        k = int(round((t - T0) * 100))
        if fault == "duplicates":
            sim.pipe.add_imu(ImuSample(t, gyro0, acc0))  # the same message twice
        elif fault == "out_of_order" and k % 7 == 0:
            sim.pipe.add_imu(ImuSample(t + 0.03, gyro0, acc0))  # early, then its neighbours
        elif fault == "backwards" and k % 5 == 0:
            sim.pipe.add_imu(ImuSample(t - 0.5 - rng.uniform(0, 0.4), gyro0, acc0))
        elif fault == "future_glitch" and k % 50 == 0:
            sim.pipe.add_imu(ImuSample(t + 1e4, gyro0, acc0))
        elif fault == "past_glitch" and k % 50 == 0:
            sim.pipe.add_imu(ImuSample(t - 1e4, gyro0, acc0))
        elif fault == "nan" and k % 3 == 0:
            return np.array([np.nan, 0, G]), np.array([0, np.inf, 0])
        elif fault == "saturated" and k % 4 == 0:
            return np.array([1e6, -1e6, 1e9]), np.array([1e3, 0, 0])
        elif fault == "clipped_at_range" and 200 <= k < 210:
            return np.array([156.9, -156.9, 156.9]), np.array([34.9, 34.9, -34.9])
        return acc0, gyro0

    outs = sim.run(T0 + 1.5, 3.0, imu=imu)
    assert len(_ok(outs)) >= len(outs) - 1, dict(sim.pipe.counters)
    # 0.15 m: with the LiDAR kernel at 3 sigma (was 1) the rejected-stamp cases drift 0.12 m
    # over these 3 s (under 0.1 m before); still bounded, a pose that runs away fails here
    assert _max_offset(outs) < (1.0 if fault == "clipped_at_range" else 0.15), fault
    tail = _ok(outs)[-5:]
    assert all(o.details["used_imu"] for o in tail), (fault, [o.warnings for o in tail])
    if fault in ("nan", "saturated", "future_glitch", "past_glitch"):
        assert sim.pipe.counters["imu_rejected"] > 0


@inner
def test_inner_without_imu_the_motion_model_carries_the_robot():
    def moving(k):  # the room slides backwards: the robot drives +x at 0.5 m/s
        return room(k) - [0.5 * (k - 10) * 0.01, 0.0, 0.0]

    sim = Sim(cloud=moving)
    outs = sim.run(T0, 4.0, imu_on=False, wheel_on=False)
    ok = _ok(outs)
    assert len(ok) == len(outs)
    assert all(not o.details["used_imu"] and not o.details["used_wheel"] for o in ok)
    # the distance travelled matches 0.5 m/s (the synthetic sweeps carry no motion of their
    # own while the pipeline deskews them with the predicted one, hence the loose bound)
    travelled = np.linalg.norm(ok[-1].pose[:3, 3] - ok[0].pose[:3, 3])
    assert travelled == pytest.approx(0.5 * (ok[-1].stamp - ok[0].stamp), abs=0.3)


@inner
@pytest.mark.parametrize("fault", ["missing", "stalled_while_lidar_moves", "nan", "huge_slip",
                                   "future_glitch", "backwards"])
def test_inner_wheel_faults(fault):
    from lili_odom.pipeline.types import WheelSample

    sim = Sim()
    sim.run(T0, 1.0)

    def wheel(t):
        k = int(round((t - T0) * 100))
        T = np.eye(4)
        if fault == "missing":
            return None
        if fault == "nan" and k % 4 == 0:
            T[:3, :3] = np.nan
        if fault == "huge_slip" and k >= 200:
            T[0, 3] = 50.0 + 10.0 * (k - 200)  # wheels spin freely: 1000 m/s
        if fault == "future_glitch" and k % 40 == 0:
            sim.pipe.add_wheel(WheelSample(t + 1e5, np.zeros(6), np.eye(4)))
        if fault == "backwards" and k % 6 == 0:
            sim.pipe.add_wheel(WheelSample(t - 0.7, np.zeros(6), np.eye(4)))
        return T

    outs = sim.run(T0 + 1.0, 3.0, wheel=wheel)
    assert len(_ok(outs)) == len(outs), dict(sim.pipe.counters)
    assert _max_offset(outs) < 0.1, (fault, [o.pose[:3, 3] for o in _ok(outs)])
    if fault == "nan":
        assert sim.pipe.counters["wheel_rejected"] > 0


def _corridor_run(wheels: bool):
    sim = Sim(method="zhang", cloud=lambda k: corridor(k))
    outs = _ok(sim.run(T0, 3.0, wheel_on=wheels))
    degenerate = [o for o in outs if o.degeneracy is not None and o.degeneracy.dimension > 0]
    return outs, degenerate


@inner
def test_inner_without_wheels_degenerate_direction_has_a_large_covariance():
    with_w, deg_w = _corridor_run(True)
    without, deg = _corridor_run(False)
    assert len(deg) >= len(without) // 2 and len(deg_w) >= len(with_w) // 2
    sx = np.sqrt(without[-1].covariance[0, 0])
    sy = np.sqrt(without[-1].covariance[1, 1])
    assert sx > 2.0 * np.sqrt(with_w[-1].covariance[0, 0]) and sx > 2.0 * sy
    # the robot stands still: the IMU alone keeps the unobservable x within about its sigma
    assert all(np.linalg.norm(o.pose[:3, 3]) < max(0.3, 2 * sx) for o in without)


@inner
def test_inner_without_wheels_degenerate_scans_carry_a_warning():
    outs, degenerate = _corridor_run(False)
    assert degenerate
    assert all(any("wheel" in w for w in o.warnings) for o in degenerate[1:])


@inner
def test_inner_clock_jump_backwards_resets_cleanly(caplog):
    sim = Sim()
    sim.run(T0, 3.0)
    with caplog.at_level(logging.WARNING):
        looped = sim.run(T0, 3.0)  # bag loop: the same stamps again
    assert sim.pipe.counters["resets"] == 1 and sim.pipe.counters["clock_jumps_back"] == 1
    assert "clock jumped back" in caplog.text
    ok = _ok(looped)
    assert len(ok) == len(looped) and _max_offset(looped) < 2.0
    assert any("reset" in w for w in ok[0].warnings)


@inner
def test_inner_after_a_bag_loop_the_robot_stays_put():
    sim = Sim()
    sim.run(T0, 3.0)
    looped = sim.run(T0, 3.0)
    # 0.17 m without the kernel (the first state after the reset lacks its IMU window, see
    # the next xfail test); 0.5 m with it
    assert _max_offset(looped) < 0.3


@inner
def test_inner_after_a_bag_loop_the_pipeline_equals_a_fresh_one():
    R = Rotation.from_euler("xy", [0.1, -0.05]).as_matrix()  # robot parked on a slope
    imu = lambda t: Sim.still_imu(t, R)  # noqa: E731
    fresh = Sim()
    want = _ok(fresh.run(T0, 2.0, imu=imu))
    looped = Sim()
    looped.run(T0, 2.0, imu=imu)
    got = _ok(looped.run(T0, 2.0, imu=imu))
    assert looped.pipe.counters["resets"] == 1
    np.testing.assert_allclose(got[0].pose[:3, :3], want[0].pose[:3, :3], atol=1e-3)


@inner
def test_inner_clock_jump_forwards_does_not_integrate_over_the_gap():
    sim = Sim()
    sim.run(T0, 2.0)
    # the IMU keeps talking during the 20 s gap, with garbage (a fall would read like this)
    sim.run(T0 + 2.0, 20.0, imu=lambda t: (np.array([30.0, 0.0, G]), np.array([0.0, 0.0, 2.0])),
            scans=False, wheel_on=False)
    after = sim.run(T0 + 22.0, 2.0)
    assert sim.pipe.counters["forward_gaps"] == 1 and sim.pipe.counters["resets"] == 0
    ok = _ok(after)
    assert len(ok) >= len(after) - 1 and _max_offset(after) < 0.1
    assert Rotation.from_matrix(ok[-1].pose[:3, :3]).magnitude() < 0.01


@inner
def test_inner_clock_jump_forwards_without_other_sensors_in_between():
    sim = Sim()
    sim.run(T0, 2.0)
    old = sim.pipe.estimator
    after = sim.run(T0 + 100.0, 2.0)  # everything jumps by 98 s (e.g. a paused bag)
    ok = _ok(after)
    assert sim.pipe.counters["forward_gaps"] == 1 and sim.pipe.counters["resets"] == 0
    assert len(ok) >= len(after) - 1 and _max_offset(after) < 0.1
    assert all(o.details["used_imu"] for o in ok[3:])
    # the map is kept, so is the frame's tilt (the graph variable, on by default): the new
    # estimator starts from the old one's estimate, where a reset would start from zero
    assert sim.pipe.estimator is not old and np.linalg.norm(old.gravity_tilt) > 1e-4
    np.testing.assert_allclose(after[0].details["gravity_tilt"], old.gravity_tilt, atol=1e-9)


@inner
def test_inner_clock_jump_keeps_the_tracked_gravity():
    """The same with gravity tracking's gain instead of the variable."""
    from lili_odom.fusion.config import FusionConfig

    sim = Sim(fusion=FusionConfig(gravity_variable=False))
    sim.run(T0, 2.0)
    sim.pipe.estimator.gravity_tilt = [1e-3, -2e-3]  # as gravity tracking may have left it
    sim.run(T0 + 100.0, 2.0)
    assert sim.pipe.counters["forward_gaps"] == 1
    # tracking then moves it by a few microradians in 2 s; a reset would put it back to zero
    np.testing.assert_allclose(sim.pipe.estimator.gravity_tilt, [1e-3, -2e-3], atol=1e-4)


@inner
def test_inner_first_scan_after_a_forward_gap_is_not_lost():
    sim = Sim()
    sim.run(T0, 2.0)
    after = sim.run(T0 + 100.0, 1.0)
    assert after[0] is not None and sim.pipe.counters["fusion_rejected"] == 0
