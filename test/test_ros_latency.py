"""The node's latency statistics (sweep end -> published odometry), without ROS."""
from __future__ import annotations

import math

import numpy as np
import pytest

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory
from lili_odom.config import NodeConfig
from lili_odom.pipeline.feeder import MessageFeeder
from lili_odom.pipeline.odometry import OdometryPipeline
from lili_odom.ros.health import HealthConfig, HealthMonitor
from lili_odom.ros.latency import LatencyStats

F = RosbagsFactory()


def test_percentiles_of_known_latencies():
    stats = LatencyStats(window=1000)
    assert stats.percentiles() is None
    assert stats.summary()["latency_p99_s"] is None
    for ms in np.random.default_rng(0).permutation(np.arange(1, 101)):  # 1..100 ms, shuffled
        stats.add(ms / 1000.0)
    p = stats.percentiles()
    assert p["p50"] == pytest.approx(0.0505)  # linear interpolation between 50 and 51 ms
    assert p["p99"] == pytest.approx(0.09901)
    assert p["max"] == pytest.approx(0.100)
    s = stats.summary()
    assert (s["latency_p50_s"], s["latency_p99_s"], s["latency_max_s"]) == (0.0505, 0.099, 0.1)
    assert s["latency_scans"] == s["latency_window_scans"] == 100


def test_window_rolls_and_run_figures_stay():
    stats = LatencyStats(window=10)
    stats.add(5.0)  # one slow scan early in the run
    for _ in range(20):
        stats.add(0.02)
    stats.add(float("nan"))
    stats.add(float("inf"))
    assert len(stats) == 10
    assert stats.percentiles() == {"p50": pytest.approx(0.02), "p99": pytest.approx(0.02),
                                   "max": pytest.approx(0.02)}
    s = stats.summary()
    assert s["latency_scans"] == 21 and s["latency_run_max_s"] == 5.0
    assert s["latency_invalid"] == 2
    with pytest.raises(ValueError):
        LatencyStats(window=0)


def test_negative_latency_is_kept():
    stats = LatencyStats()
    stats.add(-0.03)  # the node's clock behind the LiDAR's stamps
    assert stats.percentiles()["max"] == pytest.approx(-0.03)


def test_processing_status_reports_the_latency():
    monitor = HealthMonitor(HealthConfig())
    (status,) = [s for s in monitor.statuses() if s.name == "lili_odom: processing time"]
    assert "latency" not in status.message
    for k in range(200):
        monitor.on_processed(0.03, None)
        monitor.on_published(0.040 if k % 100 else 0.250)  # two slow scans in 200
    (status,) = [s for s in monitor.statuses() if s.name == "lili_odom: processing time"]
    assert "latency p50 40 / p99 " in status.message and "max 250 ms" in status.message
    assert float(status.values["latency_p50_s"]) == pytest.approx(0.040)
    assert float(status.values["latency_max_s"]) == pytest.approx(0.250)
    assert 0.040 < float(status.values["latency_p99_s"]) <= 0.250
    assert status.values["latency_window_scans"] == "200"


def _room(rng, n=3000):
    parts = []
    for axis, val in [(0, 10.0), (0, -10.0), (1, 6.0), (1, -6.0), (2, -1.5), (2, 2.5)]:
        q = rng.uniform([-10, -6, -1.5], [10, 6, 2.5], (n // 6, 3))
        q[:, axis] = val
        parts.append(q)
    return np.vstack(parts)


@pytest.mark.parametrize("times, sweep", [(np.linspace(0.0, 0.0987, 3000), 0.0987),
                                          (None, 0.1)])
def test_latency_reference_is_the_sweep_end_or_one_period_without_times(times, sweep):
    """What the node subtracts (the output's stamp) is header.stamp + the last point's time
    offset, or + pipeline.sweep_duration (one 10 Hz period) for a cloud without times."""
    cfg = NodeConfig()
    cfg.pipeline.method = "none"
    assert cfg.pipeline.sweep_duration == pytest.approx(0.1)
    feeder = MessageFeeder(OdometryPipeline(cfg.pipeline), cfg)
    cloud = M.pointcloud_xyz_msg(F, _room(np.random.default_rng(1)), 20.0, "os_lidar",
                                 times=times)
    (out,) = feeder.feed(cfg.lidar_topic, cloud)  # no IMU or wheels: processed at once
    assert out.stamp == pytest.approx(20.0 + sweep)
    stats = LatencyStats()
    published_at = 20.0 + 0.1 + 0.035  # node clock when the odometry went out
    stats.add(published_at - out.stamp)
    assert stats.percentiles()["p50"] == pytest.approx(0.135 - sweep)
    assert math.isfinite(stats.summary()["latency_run_max_s"])
