"""The first sweeps of a new map deskewed again once the motion is known
(:mod:`lili_odom.pipeline.start_sweeps`), and a start while moving end to end."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom import geometry
from lili_odom.pipeline.start_sweeps import StartSweep, StartSweeps

SWEEP = 0.1


def _sweep(k: int, speed: float, motion_speed: float, times: bool = True) -> StartSweep:
    """Sweep ``k`` of a LiDAR driving along its x axis at ``speed`` [m/s], deskewed as if it
    drove at ``motion_speed``."""
    t_last = 100.0 + SWEEP * (k + 1)
    pose = np.eye(4)
    pose[0, 3] = speed * SWEEP * k
    motion = np.eye(4)
    motion[0, 3] = motion_speed * SWEEP
    t = np.linspace(0.0, SWEEP, 50) if times else np.zeros(0)
    return StartSweep(np.zeros((50, 3)), t, motion, pose, t_last - SWEEP, t_last)


def _twist(speed: float = 0.0, yaw_rate: float = 0.0) -> np.ndarray:
    return np.array([speed, 0.0, 0.0, 0.0, 0.0, yaw_rate])


def test_a_start_at_rest_leaves_the_map_alone():
    s = StartSweeps()
    assert s.add(_sweep(0, 0.0, 0.0), True, _twist()) is None
    assert s.add(_sweep(1, 0.0, 0.0), False, _twist(0.02)) is None  # 2 mm per sweep
    assert s.add(_sweep(2, 2.0, 0.0), False, _twist(2.0)) is None  # only the first two count


def test_a_start_while_moving_gives_each_sweep_the_fused_motion():
    s = StartSweeps()
    assert s.add(_sweep(0, 2.5, 0.0), True, _twist()) is None
    redo = s.add(_sweep(1, 2.5, 0.0), False, _twist(2.5))
    assert redo is not None and len(redo) == 2
    for r in redo:
        np.testing.assert_allclose(r.motion[:3, 3], [0.25, 0.0, 0.0], atol=1e-9)
        np.testing.assert_allclose(r.motion[:3, :3], np.eye(3), atol=1e-9)
    np.testing.assert_allclose(redo[1].pose[0, 3], 0.25)  # inserted where it was
    assert s.add(_sweep(2, 2.5, 0.0), False, _twist(2.5)) is None  # done until a new map
    assert s.add(_sweep(0, 2.5, 0.0), True, _twist()) is None  # a new map starts again
    assert s.add(_sweep(1, 2.5, 0.0), False, _twist(2.5)) is not None


def test_only_the_sweeps_deskewed_wrongly_get_a_new_motion():
    """Wheels that report the speed at the start deskew the second sweep right: it keeps
    its motion exactly; the first (deskewed with none) gets the fused one."""
    s = StartSweeps()
    s.add(_sweep(0, 2.0, 0.0), True, _twist())
    second = _sweep(1, 2.0, 1.99)
    redo = s.add(second, False, _twist(2.0))
    assert redo is not None
    np.testing.assert_allclose(redo[0].motion[0, 3], 0.2)
    assert redo[1] is second


def test_a_turn_on_the_spot_is_a_motion_too():
    s = StartSweeps()
    s.add(_sweep(0, 0.0, 0.0), True, _twist())
    redo = s.add(_sweep(1, 0.0, 0.0), False, _twist(yaw_rate=0.5))  # 5 cm at 10 m per sweep
    assert redo is not None
    np.testing.assert_allclose(geometry.log(redo[0].motion), [0, 0, 0, 0, 0, 0.05], atol=1e-9)
    s.add(_sweep(0, 0.0, 0.0), True, _twist())
    assert s.add(_sweep(1, 0.0, 0.0), False, _twist(yaw_rate=0.005)) is None  # 0.5 mm


def test_a_gap_or_a_bad_twist_rebuilds_nothing():
    s = StartSweeps(max_gap_s=0.5)
    s.add(_sweep(0, 2.0, 0.0), True, _twist())
    assert s.add(_sweep(9, 2.0, 0.0), False, _twist(2.0)) is None  # 0.9 s after the first
    s.add(_sweep(0, 2.0, 0.0), True, _twist())
    assert s.add(_sweep(1, 2.0, 0.0), False, _twist(np.nan)) is None
    with pytest.raises(ValueError):
        StartSweeps(count=1)


def test_sweeps_without_times_are_kept_as_they_were():
    s = StartSweeps()
    first = _sweep(0, 2.5, 0.0, times=False)
    s.add(first, True, _twist())
    redo = s.add(_sweep(1, 2.5, 0.0), False, _twist(2.5))
    assert redo is not None and redo[0] is first
    s.add(_sweep(0, 2.5, 0.0, times=False), True, _twist())
    assert s.add(_sweep(1, 2.5, 0.0, times=False), False, _twist(2.5)) is None


def _room(rng: np.random.Generator) -> np.ndarray:
    half = np.array([12.0, 4.0, 3.0])
    pts = []
    for ax in range(3):
        for side in (-1, 1):
            p = rng.uniform(-1, 1, (4000, 3)) * half
            p[:, ax] = side * half[ax]
            pts.append(p)
    room = np.vstack(pts)
    return room[rng.permutation(len(room))]


def _drive(redeskew: bool, speed: float = 2.5, scans: int = 12, start_speed: bool = False,
           room: np.ndarray | None = None, counters: dict | None = None
           ) -> tuple[np.ndarray, int]:
    """A LiDAR driving through a box room at ``speed`` from before its first sweep, with a
    steady IMU (constant speed looks like rest to it) and no wheels: the position error of
    every scan [m] and how often the map was rebuilt (``start_speed``: the speed searched
    from the first two sweeps, :mod:`lili_odom.pipeline.start_speed`)."""
    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
    from lili_odom.pipeline.types import ImuSample, Scan

    room = _room(np.random.default_rng(0)) if room is None else room
    t = np.linspace(0.0, SWEEP, len(room))
    cfg = PipelineConfig(redeskew_start=redeskew)
    cfg.start_speed.enabled = start_speed
    cfg.detection_schedule.background = False
    p = OdometryPipeline(cfg)
    T_bl = p.T_base_lidar
    errors = []
    t_imu = 99.0
    for k in range(scans):
        while t_imu <= 100.0 + SWEEP * (k + 1):
            p.add_imu(ImuSample(t_imu, np.zeros(3), np.array([0.0, 0.0, 9.81])))
            t_imu += 0.01
        x = -8.0 + speed * (SWEEP * k + t)  # os_lidar's x, per point time
        lidar = room - x[:, None] * [1.0, 0.0, 0.0]
        out = p.process_scan(Scan(100.0 + SWEEP * k, lidar, t.copy()))
        assert out is not None
        true_lidar = np.eye(4)
        true_lidar[0, 3] = speed * SWEEP * k  # LiDAR motion since the first sweep's end
        est_lidar = np.linalg.inv(T_bl) @ out.pose @ T_bl
        errors.append(np.linalg.norm(est_lidar[:3, 3] - true_lidar[:3, 3]))
    if counters is not None:
        counters.update(p.counters)
    return np.array(errors), p.counters["start_map_rebuilt"]


def test_a_start_while_moving_is_not_left_half_a_sweep_behind():
    """Without the rebuild the sweeps smeared at the start pull every later, correctly
    deskewed one about half a sweep's travel (12 cm) off, and more while the fusion
    converges; with it the error stays at a few millimetres."""
    errors, rebuilt = _drive(redeskew=True)
    assert rebuilt == 1
    assert errors.max() < 0.03, errors
    before, rebuilt = _drive(redeskew=False)
    assert rebuilt == 0
    assert before[2:].max() > 0.1, before


def test_a_speed_within_its_uncertainty_counts_as_none():
    """Without wheels, a robot at rest in a degenerate place has a fused speed after two
    sweeps that a sliding registration made: not significant, so not deskewed with."""
    s = StartSweeps(significance=3.0)
    s.add(_sweep(0, 0.0, 0.0), True, _twist())
    assert s.due
    assert s.add(_sweep(1, 0.0, 0.0), False, _twist(0.5), speed_sigma=0.4) is None
    assert not s.due
    s.add(_sweep(0, 0.0, 0.0), True, _twist())
    assert s.add(_sweep(1, 0.0, 0.0), False, _twist(0.5), speed_sigma=None) is None
    s.add(_sweep(0, 0.0, 0.0), True, _twist())
    redo = s.add(_sweep(1, 0.0, 0.0), False, _twist(0.5, yaw_rate=0.5), speed_sigma=0.4)
    assert redo is not None  # the turn (from the gyro) still counts, the speed does not
    np.testing.assert_allclose(geometry.log(redo[0].motion), [0, 0, 0, 0, 0, 0.05], atol=1e-9)
    s.add(_sweep(0, 2.5, 0.0), True, _twist())
    assert s.add(_sweep(1, 2.5, 0.0), False, _twist(2.5), speed_sigma=0.4) is not None
