"""MessageFeeder: topic dispatch, /tf_static chains and scan/IMU/wheel synchronisation."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory
from lili_odom.config import NodeConfig
from lili_odom.pipeline.feeder import MessageFeeder, chain_transform
from lili_odom.pipeline.odometry import OdometryPipeline

F = RosbagsFactory()


def _T(t=(0.0, 0.0, 0.0), yaw=0.0) -> np.ndarray:
    T = np.eye(4)
    c, s_ = np.cos(yaw), np.sin(yaw)
    T[:3, :3] = [[c, -s_, 0], [s_, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


def test_chain_transform_composes_chain_both_directions():
    tfs = {("base_link", "os_sensor"): _T((0.1, 0, 0.65)),
           ("os_sensor", "os_lidar"): _T((0, 0, 0.036), np.pi),
           ("os_sensor", "os_imu"): _T((0.006, -0.012, 0.008))}
    T = chain_transform(tfs, "base_link", "os_lidar")
    np.testing.assert_allclose(T, tfs[("base_link", "os_sensor")] @ tfs[("os_sensor", "os_lidar")])
    back = chain_transform(tfs, "os_lidar", "os_imu")
    np.testing.assert_allclose(T @ back, chain_transform(tfs, "base_link", "os_imu"), atol=1e-12)
    assert chain_transform(tfs, "base_link", "camera") is None
    np.testing.assert_allclose(chain_transform({}, "a", "a"), np.eye(4))


def _room(rng, n=3000):
    parts = []
    for axis, val in [(0, 10.0), (0, -10.0), (1, 6.0), (1, -6.0), (2, -1.5), (2, 2.5)]:
        q = rng.uniform([-10, -6, -1.5], [10, 6, 2.5], (n // 6, 3))
        q[:, axis] = val
        parts.append(q)
    return np.vstack(parts)


def _imu(t):
    return F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, t, "os_imu"),
                 linear_acceleration=F.new("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=9.80665))


def _wheel(t):
    return F.new("nav_msgs/msg/Odometry", header=M.header_msg(F, t, "odom"),
                 child_frame_id="base_link", pose=F.new(
                     "geometry_msgs/msg/PoseWithCovariance", pose=M.pose_msg(F, np.eye(4))))


def _cloud(rng, t):
    pts = _room(rng)
    return M.pointcloud_xyz_msg(F, pts, t, "os_lidar", times=np.linspace(0.0, 0.099, len(pts)))


@pytest.fixture
def feeder():
    cfg = NodeConfig()
    cfg.pipeline.method = "none"
    return MessageFeeder(OdometryPipeline(cfg.pipeline), cfg)


def test_scan_waits_for_the_imu_and_wheels_covering_its_sweep(feeder):
    rng = np.random.default_rng(0)
    c = feeder.config
    for k in range(50):  # 0.5 s of IMU and wheels before the first scan
        feeder.feed(c.imu_topic, _imu(9.5 + 0.01 * k))
        if k % 2 == 0:
            feeder.feed(c.wheel_topic, _wheel(9.5 + 0.01 * k))
    assert feeder.feed(c.lidar_topic, _cloud(rng, 10.0)) == []
    assert feeder.pending == 1
    assert feeder.feed(c.imu_topic, _imu(10.05)) == []  # sweep ends at 10.099
    assert feeder.feed(c.imu_topic, _imu(10.10)) == []  # IMU covered, wheels not yet
    out = feeder.feed(c.wheel_topic, _wheel(10.10))
    assert len(out) == 1 and out[0].stamp == pytest.approx(10.099)
    assert feeder.pending == 0 and feeder.processed == 1
    # the second scan: IMU and wheels keep coming, so it waits for both as well
    assert feeder.feed(c.lidar_topic, _cloud(rng, 10.1)) == []
    assert feeder.feed(c.wheel_topic, _wheel(10.2)) == []
    out = feeder.feed(c.imu_topic, _imu(10.2))
    assert len(out) == 1 and out[0].details["used_imu"]
    stats = feeder.pipeline.estimator.stats
    assert stats.n_no_imu == 0 and stats.n_no_wheel == 0  # both covered every interval


def test_silent_stream_releases_scans_after_the_wait(feeder):
    rng = np.random.default_rng(1)
    c = feeder.config
    wait = c.pipeline.sensor_wait_s
    for k in range(30):
        feeder.feed(c.imu_topic, _imu(9.8 + 0.01 * k))
    feeder.feed(c.wheel_topic, _wheel(10.05))  # wheels alive but then silent
    assert feeder.feed(c.lidar_topic, _cloud(rng, 10.0)) == []
    assert feeder.feed(c.imu_topic, _imu(10.2)) == []  # wheels still lag: wait
    out = feeder.feed(c.imu_topic, _imu(10.099 + wait + 0.001))
    assert len(out) == 1  # the wheel stream stalled for longer than sensor_wait_s


def test_scans_without_any_imu_or_wheels_are_processed_at_once(feeder):
    rng = np.random.default_rng(2)
    c = feeder.config
    assert len(feeder.feed(c.lidar_topic, _cloud(rng, 5.0))) == 1
    assert len(feeder.feed(c.lidar_topic, _cloud(rng, 5.1))) == 1


def test_pending_scans_are_bounded_and_flushed(feeder):
    rng = np.random.default_rng(3)
    c = feeder.config
    limit = c.pipeline.max_pending_scans
    feeder.feed(c.imu_topic, _imu(20.0))
    outs = []
    for k in range(limit + 2):  # the IMU stream is alive (20.0 >= end - wait) but never covers
        feeder.config.pipeline.sensor_wait_s = 10.0
        outs += feeder.feed(c.lidar_topic, _cloud(rng, 20.0 + 0.01 * k))
    assert feeder.pending == limit and len(outs) == 2
    outs += feeder.flush()
    assert feeder.pending == 0 and len(outs) == limit + 2
    assert [o.stamp for o in outs] == sorted(o.stamp for o in outs)


def test_bad_messages_are_counted_not_raised(feeder):
    c = feeder.config
    assert feeder.feed(c.imu_topic, object()) == []
    broken = F.new("sensor_msgs/msg/PointCloud2", header=M.header_msg(F, 1.0, "os_lidar"))
    assert feeder.feed(c.lidar_topic, broken) == []
    counters = feeder.pipeline.counters
    assert counters["bad_message" + c.imu_topic.replace("/", "_")] == 1
    assert counters["bad_clouds"] == 1


def test_a_cloud_parsed_ahead_is_fed_as_the_message_would_be():
    rng = np.random.default_rng(4)
    cfg = NodeConfig()
    cfg.pipeline.method = "none"
    direct = MessageFeeder(OdometryPipeline(cfg.pipeline), cfg)
    ahead = MessageFeeder(OdometryPipeline(cfg.pipeline), cfg)
    clouds = [_cloud(rng, 5.0 + 0.1 * k) for k in range(3)]
    parsed = [ahead.parse_ahead(m) for m in clouds]  # before any is fed, as a reading thread
    outs_direct = [o for m in clouds for o in direct.feed(cfg.lidar_topic, m)]
    outs_ahead = [o for p in parsed for o in ahead.feed(cfg.lidar_topic, p)]
    assert len(outs_direct) == len(outs_ahead) == 3
    for a, b in zip(outs_direct, outs_ahead):  # KISS-ICP's threaded sums: the last bits only
        assert a.stamp == b.stamp and np.allclose(a.pose, b.pose, atol=1e-6)
    # a malformed cloud is counted as a bad cloud, a non-message as a bad message, as when fed
    broken = F.new("sensor_msgs/msg/PointCloud2", header=M.header_msg(F, 1.0, "os_lidar"))
    assert ahead.feed(cfg.lidar_topic, ahead.parse_ahead(broken)) == []
    assert ahead.feed(cfg.lidar_topic, ahead.parse_ahead(object())) == []
    counters = ahead.pipeline.counters
    assert counters["bad_clouds"] == 1
    assert counters["bad_message" + cfg.lidar_topic.replace("/", "_")] == 1


def test_point_stride_parses_every_nth_point_without_counting_the_rest_as_dropped():
    rng = np.random.default_rng(5)
    msg = _cloud(rng, 5.0)
    scans = {}
    for stride in (1, 3):
        cfg = NodeConfig()
        cfg.pipeline.method = "none"
        cfg.pipeline.scan_matcher.point_stride = stride
        scans[stride] = MessageFeeder(OdometryPipeline(cfg.pipeline), cfg).parse_ahead(
            msg).result()
    full, strided = scans[1], scans[3]
    assert len(full.points) > 300 and strided.dropped == full.dropped == 0
    np.testing.assert_array_equal(strided.points, full.points[::3])
    np.testing.assert_array_equal(strided.times, full.times[::3])
