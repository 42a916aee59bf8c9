"""The node over DDS, in-process with a fake pipeline (isolated domain, localhost only)."""
from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")
import rclpy.serialization  # noqa: E402

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from _ros_fakes import FakeProvider, isolated_ros_env, wait_for  # noqa: E402
from lili_odom import messages as M  # noqa: E402
from lili_odom.ros.factory import RclpyFactory, message_class  # noqa: E402
from lili_odom.ros.node import LiliOdomNode  # noqa: E402

F = RclpyFactory()
PointCloud2 = message_class("sensor_msgs/msg/PointCloud2")
Imu = message_class("sensor_msgs/msg/Imu")
Odometry = message_class("nav_msgs/msg/Odometry")
String = message_class("std_msgs/msg/String")
MarkerArray = message_class("visualization_msgs/msg/MarkerArray")
Path = message_class("nav_msgs/msg/Path")


class Harness:
    """A lili_odom node plus a tester node spinning in one background executor."""

    def __init__(self, monkeypatch, provider: FakeProvider, overrides=()):
        env = isolated_ros_env()
        for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
            monkeypatch.setenv(key, env[key])
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=int(env["ROS_DOMAIN_ID"]))
        self.node = LiliOdomNode(provider=provider, context=self.context,
                                 parameter_overrides=list(overrides))
        self.tester = rclpy.create_node("tester", context=self.context)
        reliable = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.received: dict[str, list] = {"odom": [], "basis": [], "markers": [], "map": [],
                                           "path": []}
        self.pub_cloud = self.tester.create_publisher(PointCloud2, "/ouster/points", reliable)
        self.pub_imu = self.tester.create_publisher(Imu, "/ouster/imu", reliable)
        sub = self.tester.create_subscription
        sub(Odometry, "/lili_odom/odometry", self.received["odom"].append, reliable)
        sub(String, "/lili_odom/degeneracy/basis", self.received["basis"].append, reliable)
        sub(MarkerArray, "/lili_odom/degeneracy", self.received["markers"].append, reliable)
        sub(PointCloud2, "/lili_odom/map", self.received["map"].append, latched)
        sub(Path, "/lili_odom/path", self.received["path"].append, reliable)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.tester)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        assert wait_for(lambda: self.pub_cloud.get_subscription_count() >= 1
                        and self.pub_imu.get_subscription_count() >= 1
                        and self.node.pub_odom.get_subscription_count() >= 1, 10.0), \
            "DDS discovery timed out"

    def cloud(self, stamp: float):
        return M.pointcloud_xyz_msg(F, np.random.default_rng(0).normal(size=(100, 3)) + 5.0,
                                    stamp, "os_lidar")

    def close(self):
        self.executor.shutdown(timeout_sec=2.0)
        self.thread.join(5.0)
        self.node.destroy_node()
        self.tester.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def harness_factory(monkeypatch):
    made = []

    def make(provider, overrides=()):
        h = Harness(monkeypatch, provider, overrides)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()


def test_one_odometry_per_scan(harness_factory):
    provider = FakeProvider()
    h = harness_factory(provider, [Parameter("odom_frame", value="test_odom"),
                                   Parameter("voxel", value=0.25),
                                   Parameter("path_period", value=0.0),
                                   Parameter("diagnostics_period", value=0.0)])
    assert provider.parameters["voxel"] == 0.25
    for i in range(5):
        h.pub_imu.publish(F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, 10.0 + 0.01 * i,
                                                                          "os_imu")))
    time.sleep(0.1)
    n = 6
    for k in range(n):
        h.pub_cloud.publish(h.cloud(10.0 + 0.1 * k))
        time.sleep(0.1)
    assert wait_for(lambda: len(h.received["odom"]) >= n, 10.0), h.node.diagnostics()
    time.sleep(0.2)
    odom = h.received["odom"]
    assert len(odom) == n
    assert [o.header.frame_id for o in odom] == ["test_odom"] * n
    assert [o.child_frame_id for o in odom] == ["base_link"] * n
    assert [round(o.pose.pose.position.x) for o in odom] == list(range(1, n + 1))
    assert [round(M.stamp_seconds(o.header), 6) for o in odom] == \
        [round(10.0 + 0.1 * k, 6) for k in range(n)]
    pipeline = provider.created[0]
    assert len(pipeline.imu) == 5 and pipeline.scans[0].points.shape == (100, 3)
    diag = h.node.diagnostics()
    assert diag["scans_processed"] == n and diag["scans_dropped"] == 0
    assert diag["pipeline.scans"] == n
    assert wait_for(lambda: len(h.received["basis"]) >= n and len(h.received["markers"]) >= n
                    and h.received["map"] and len(h.received["path"]) >= n, 5.0)
    basis = json.loads(h.received["basis"][-1].data)
    assert basis["dimension"] == 1 and basis["basis"][0]["translation"] == [1.0, 0.0, 0.0]
    assert h.received["map"][0].width == 2 and h.received["map"][0].header.frame_id == "test_odom"
    path = h.received["path"][-1].poses
    assert len(path) == n
    assert [round(q.pose.position.x) for q in path] == list(range(1, n + 1))
    assert [round(M.stamp_seconds(q.header), 6) for q in path] == \
        [round(10.0 + 0.1 * k, 6) for k in range(n)]
    assert {q.header.frame_id for q in path} == {"test_odom"}


def test_a_cloud_that_does_not_decode_is_counted_and_the_next_is_processed(harness_factory):
    provider = FakeProvider()
    h = harness_factory(provider, [Parameter("diagnostics_period", value=0.0)])
    good = h.cloud(30.0)
    raw = rclpy.serialization.serialize_message(good)
    h.pub_cloud.publish(raw[:40])  # a CDR header and a cut-off PointCloud2
    assert wait_for(lambda: h.node.counters["undecodable_clouds"] == 1, 5.0), h.node.diagnostics()
    h.pub_cloud.publish(raw)  # serialised bytes and message objects arrive alike
    h.pub_cloud.publish(h.cloud(30.1))
    assert wait_for(lambda: len(h.received["odom"]) == 2, 10.0), h.node.diagnostics()
    diag = h.node.diagnostics()
    assert diag["scans_received"] == 3 and diag["undecodable_clouds"] == 1
    assert diag["scans_processed"] == 2 and diag["scan_errors"] == 0
    scans = provider.created[0].scans
    assert [s.stamp for s in scans] == pytest.approx([30.0, 30.1])
    assert scans[0].points.shape == (100, 3)
    np.testing.assert_allclose(scans[0].points, M.scan_from_msg(good).points)

    class Unreadable:  # an encoding rosbags does not read: rclpy decodes the cloud
        def deserialize_cdr(self, raw, typename):
            raise ValueError("unsupported encapsulation")

    h.node._decode.typestore = Unreadable()
    h.pub_cloud.publish(h.cloud(30.2))
    assert wait_for(lambda: len(h.received["odom"]) == 3, 10.0), h.node.diagnostics()
    assert h.node.diagnostics()["undecodable_clouds"] == 1
    assert provider.created[0].scans[-1].stamp == pytest.approx(30.2)


def test_slow_pipeline_drops_older_pending_scans(harness_factory):
    provider = FakeProvider(delay=0.3)
    h = harness_factory(provider, [Parameter("diagnostics_period", value=0.0)])
    n = 6
    for k in range(n):
        h.pub_cloud.publish(h.cloud(20.0 + 0.1 * k))
        time.sleep(0.03)
    assert wait_for(lambda: h.node.counters["scans_received"] == n, 5.0)
    assert wait_for(lambda: h.node.diagnostics()["scans_processed"]
                    + h.node.diagnostics()["scans_dropped"] == n, 5.0), h.node.diagnostics()
    diag = h.node.diagnostics()
    assert diag["scans_dropped"] >= 2
    pipeline = provider.created[0]
    assert pipeline.scans[-1].stamp == pytest.approx(20.0 + 0.1 * (n - 1))  # newest processed
    assert wait_for(lambda: len(h.received["odom"]) == diag["scans_processed"], 5.0)


def _room(rng, n=6000):
    """Points on the walls, floor and ceiling of a 20 x 12 x 4 m room around the sensor."""
    parts = []
    for axis, val in [(0, 10.0), (0, -10.0), (1, 6.0), (1, -6.0), (2, -1.5), (2, 2.5)]:
        q = rng.uniform([-10, -6, -1.5], [10, 6, 2.5], (n // 6, 3))
        q[:, axis] = val
        parts.append(q)
    return np.vstack(parts)


def test_real_pipeline_publishes_odometry(harness_factory):
    from lili_odom.ros.provider import OdometryPipelineProvider

    h = harness_factory(OdometryPipelineProvider(),
                        [Parameter("diagnostics_period", value=0.0),
                         Parameter("pipeline.method", value="zhang")])
    rng = np.random.default_rng(3)
    t0 = 100.0
    imu_i = 0

    def imu_until(t_end):
        nonlocal imu_i
        while t0 - 0.5 + 0.01 * imu_i <= t_end:
            t = t0 - 0.5 + 0.01 * imu_i
            h.pub_imu.publish(F.new(
                "sensor_msgs/msg/Imu", header=M.header_msg(F, t, "os_imu"),
                linear_acceleration=F.new("geometry_msgs/msg/Vector3", z=9.80665)))
            imu_i += 1

    n = 3
    for k in range(n):
        stamp = t0 + 0.1 * k
        imu_until(stamp + 0.1)
        time.sleep(0.05)
        # per-point times: the pipeline at this commit aborts (Sophus, NaN) on clouds without
        cloud = _room(rng)
        h.pub_cloud.publish(M.pointcloud_xyz_msg(F, cloud, stamp, "os_lidar",
                                                 times=np.linspace(0.0, 0.0999, len(cloud))))
        assert wait_for(lambda: len(h.received["odom"]) >= k + 1, 20.0), h.node.diagnostics()
    odom = h.received["odom"]
    assert len(odom) == n and odom[0].header.frame_id == "lili_odom"
    for o in odom:  # a static sensor in a closed room stays near the origin
        p = o.pose.pose.position
        assert np.linalg.norm([p.x, p.y, p.z]) < 0.5
    diag = h.node.diagnostics()
    assert diag["scan_errors"] == 0 and diag["pipeline.processed"] == n
    assert wait_for(lambda: len(h.received["basis"]) >= n, 5.0)
    assert json.loads(h.received["basis"][-1].data)["method"] == "zhang"
