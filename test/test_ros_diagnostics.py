"""The node's /diagnostics, missing-scan count and ~/save_map over DDS (in-process, fake
pipeline, isolated domain, localhost only)."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402

from _ros_fakes import FakeProvider, wait_for  # noqa: E402
from test_ros_node import harness_factory  # noqa: E402,F401  (fixture)
from lili_odom.io.cloud_files import load_points  # noqa: E402
from lili_odom.ros.factory import message_class  # noqa: E402

DiagnosticArray = message_class("diagnostic_msgs/msg/DiagnosticArray")
Trigger = message_class("std_srvs/srv/Trigger")


def test_diagnostics_report_missing_scans_and_save_map_writes_the_map(harness_factory,
                                                                      tmp_path):
    target = tmp_path / "maps" / "site.ply"
    h = harness_factory(FakeProvider(), [Parameter("diagnostics_period", value=0.0),
                                         Parameter("diagnostics_publish_period", value=0.2),
                                         Parameter("map_accumulate_period_s", value=0.0),
                                         Parameter("map_save_path", value=str(target))])
    arrays: list = []
    h.tester.create_subscription(DiagnosticArray, "/diagnostics", arrays.append,
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    # 10 Hz stamps with scans 4 and 5 and 9 lost upstream: 3 missing
    stamps = [50.0 + 0.1 * k for k in range(12) if k not in (4, 5, 9)]
    for t in stamps:
        h.pub_cloud.publish(h.cloud(t))
        time.sleep(0.05)
    assert wait_for(lambda: h.node.diagnostics()["scans_processed"] == len(stamps), 10.0), \
        h.node.diagnostics()
    assert h.node.diagnostics()["scans_missing"] == 3

    def latest_status(name):
        for arr in reversed(arrays):
            for s in arr.status:
                if s.name == name:
                    return s
        return None

    name = "lili_odom: scans dropped and missing"
    assert wait_for(lambda: latest_status(name) is not None
                    and any(kv.key == "scans_missing" and kv.value == "3"
                            for kv in latest_status(name).values), 5.0)
    loss = latest_status(name)
    assert loss.level in (b"\x01", b"\x02") and "missing" in loss.message  # 3 of 12: >= 1 %
    names = {s.name for s in arrays[-1].status}
    assert {"lili_odom: lidar input", "lili_odom: imu input", "lili_odom: degeneracy",
            "lili_odom: processing time", "lili_odom: wheel scale", "lili_odom: fusion"} <= names
    degeneracy = latest_status("lili_odom: degeneracy")
    assert degeneracy.level == b"\x01" and "dimension 1" in degeneracy.message  # fake: 1-D
    assert all(s.hardware_id == "/lili_odom" for s in arrays[-1].status)

    client = h.tester.create_client(Trigger, "/lili_odom/save_map")
    assert client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(Trigger.Request())
    assert wait_for(future.done, 10.0)
    answer = future.result()
    assert answer.success, answer.message
    assert Path(answer.message) == target.resolve() and target.is_file()
    np.testing.assert_allclose(np.sort(load_points(target), axis=0),
                               [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])  # the fake's map

    h.node.p["map_save_path"] = str(tmp_path / "map.xyz")  # a bad name answers, not crashes
    future = client.call_async(Trigger.Request())
    assert wait_for(future.done, 10.0)
    assert not future.result().success and "pcd or .ply" in future.result().message


def test_node_measures_the_latency_of_its_odometry(harness_factory):
    """Clouds stamped with the node's own clock, a pipeline taking 50 ms: the latency in the
    node's summary and in /diagnostics is the processing plus the transport."""
    h = harness_factory(FakeProvider(delay=0.05),
                        [Parameter("diagnostics_period", value=0.0),
                         Parameter("diagnostics_publish_period", value=0.2)])
    arrays: list = []
    h.tester.create_subscription(DiagnosticArray, "/diagnostics", arrays.append,
                                 QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
    n = 8
    for _ in range(n):
        # the fake stamps its output with the header stamp: that is the sweep end here
        h.pub_cloud.publish(h.cloud(h.node.get_clock().now().nanoseconds * 1e-9))
        time.sleep(0.1)
    assert wait_for(lambda: h.node.diagnostics()["latency_scans"] == n, 10.0), \
        h.node.diagnostics()
    d = h.node.diagnostics()
    assert 0.05 <= d["latency_p50_s"] <= d["latency_p99_s"] <= d["latency_max_s"] < 2.0
    assert d["latency_run_max_s"] == d["latency_max_s"] and d["latency_invalid"] == 0

    def processing_status():
        for arr in reversed(arrays):
            for s in arr.status:
                if s.name == "lili_odom: processing time":
                    return s
        return None

    assert wait_for(lambda: processing_status() is not None and any(
        kv.key == "latency_window_scans" and kv.value == str(n)
        for kv in processing_status().values), 5.0)
    values = {kv.key: kv.value for kv in processing_status().values}
    assert float(values["latency_p99_s"]) == pytest.approx(d["latency_p99_s"], abs=1e-4)
    assert "latency p50" in processing_status().message
