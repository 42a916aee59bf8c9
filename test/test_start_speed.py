"""The speed of a start while driving from the first two sweeps
(:mod:`lili_odom.pipeline.start_speed`) and its use by the pipeline without wheels."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom.pipeline.scan_matcher import ScanMatcher
from lili_odom.pipeline.start_speed import StartSpeedConfig, forward_speed
from lili_odom.pipeline.start_sweeps import StartSweep
from test_start_sweeps import SWEEP, _drive, _room

T_BASE_LIDAR = np.eye(4)


def _box(rng: np.random.Generator, ends: bool = True) -> np.ndarray:
    """Points on a 24 x 8 x 6 m box around the origin; without its two x-facing ``ends`` a
    tube along x."""
    room = _room(rng)
    if not ends:
        room = room[np.abs(np.abs(room[:, 0]) - 12.0) > 1e-9]
    return room


def _sweep(scene: np.ndarray, k: int, speed: float, start: float = -6.0) -> StartSweep:
    """Sweep ``k`` of a LiDAR driving along its x axis at ``speed`` [m/s] through ``scene``."""
    t = np.linspace(0.0, SWEEP, len(scene))
    x = start + speed * (SWEEP * k + t)
    t_first = 100.0 + SWEEP * k
    return StartSweep(scene - x[:, None] * [1.0, 0.0, 0.0], t, np.eye(4), np.eye(4), t_first,
                      t_first + SWEEP)


def _speed(scene: np.ndarray, speed: float, **config):
    cfg = StartSpeedConfig(**config)
    return forward_speed(_sweep(scene, 0, speed), _sweep(scene, 1, speed), ScanMatcher(),
                         T_BASE_LIDAR, np.zeros(3), cfg)


@pytest.mark.parametrize("speed", [2.0, -1.2, 0.0])
def test_the_speed_that_fits_two_sweeps_best_is_found(speed):
    found = _speed(_box(np.random.default_rng(1)), speed)
    assert found.speed is not None, found.rise
    assert found.speed == pytest.approx(speed, abs=0.1)
    assert found.rise >= StartSpeedConfig().min_rise
    assert min(found.costs, key=found.costs.get) == pytest.approx(found.speed)


def test_a_tube_fits_every_speed_alike_and_gives_none():
    found = _speed(_box(np.random.default_rng(2), ends=False), 2.0)
    assert found.speed is None
    assert found.rise < StartSpeedConfig().min_rise
    assert len(found.costs) > 20  # the coarse pass, then the fine one


def test_bad_input_gives_none_instead_of_raising():
    scene = _box(np.random.default_rng(3))
    first, second = _sweep(scene, 0, 1.0), _sweep(scene, 1, 1.0)
    cfg = StartSpeedConfig()
    assert forward_speed(first, second, ScanMatcher(), T_BASE_LIDAR,
                         np.array([np.nan, 0.0, 0.0]), cfg).speed is None
    assert forward_speed(second, first, ScanMatcher(), T_BASE_LIDAR, np.zeros(3),
                         cfg).speed is None  # out of order


def test_config_ranges_are_checked():
    StartSpeedConfig().validate()
    for bad in ({"fine_step": 0.5}, {"max_speed": 0.0}, {"velocity_sigma": -1.0},
                {"min_rise": float("nan")}, {"min_speed": 5.0}):
        with pytest.raises(ValueError):
            StartSpeedConfig(**bad).validate()


def test_the_pipeline_restarts_at_the_found_speed_without_wheels():
    """No wheels, a steady IMU: the speed comes from the first two sweeps, the fusion starts
    again from the first scan with it, and the estimate stays within centimetres."""
    counters: dict = {}
    errors, rebuilt = _drive(redeskew=True, start_speed=True, counters=counters)
    assert counters.get("start_speed_found") == 1 and rebuilt >= 1
    assert errors.max() < 0.03, errors


def test_a_start_at_rest_is_kept_as_it_was():
    counters: dict = {}
    errors, _ = _drive(redeskew=True, start_speed=True, speed=0.0, scans=3, counters=counters)
    assert counters.get("start_speed_slow") == 1 and not counters.get("start_speed_found")
    assert errors.max() < 0.01, errors


def test_the_pipeline_keeps_the_loose_start_where_no_speed_fits(caplog):
    import logging

    tube = _box(np.random.default_rng(4), ends=False)
    counters: dict = {}
    with caplog.at_level(logging.INFO, logger="lili_odom.pipeline.odometry"):
        _drive(redeskew=True, start_speed=True, room=tube, scans=3, counters=counters)
    assert "start speed not found" in caplog.text
    assert counters.get("start_speed_unknown") == 1 and not counters.get("start_speed_found")


def test_a_known_start_velocity_is_not_searched(caplog):
    """A start velocity whose prior is tighter than ``unknown_sigma`` (wheels) is kept."""
    import logging

    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
    from lili_odom.pipeline.types import ImuSample, Scan

    cfg = PipelineConfig()
    cfg.detection_schedule.background = False
    cfg.fusion.prior_sigma_velocity_moving = 0.3  # below unknown_sigma 0.5
    p = OdometryPipeline(cfg)
    scene = _box(np.random.default_rng(5))
    t_imu = 99.0
    for k in range(2):
        while t_imu <= 100.0 + SWEEP * (k + 1):
            p.add_imu(ImuSample(t_imu, np.zeros(3), np.array([0.0, 0.0, 9.81])))
            t_imu += 0.01
        s = _sweep(scene, k, 2.0)
        with caplog.at_level(logging.INFO, logger="lili_odom.pipeline.odometry"):
            assert p.process_scan(Scan(s.t_first, s.points, s.times - 0.0)) is not None
    assert "start speed" not in caplog.text and "started while driving" not in caplog.text
    p.close()


def test_the_estimator_takes_the_start_velocity_sigma():
    from lili_odom.fusion.config import FusionConfig
    from lili_odom.fusion.estimator import FusionEstimator

    est = FusionEstimator(FusionConfig())
    est.initialize(10.0, velocity=np.array([2.0, 0.0, 0.0]), velocity_sigma=0.2)
    assert est.velocity_sigma() == pytest.approx(0.2, rel=1e-3)
    with pytest.raises(ValueError):
        FusionEstimator(FusionConfig()).initialize(10.0, velocity=np.zeros(3), velocity_sigma=0.0)
