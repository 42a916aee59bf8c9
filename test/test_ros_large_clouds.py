"""Full-resolution clouds cross processes with the package's defaults.

A driver-like publisher (``python -m lili_odom.ros.cloud_check publish``: 128 x 1024 clouds in
the ouster-ros "original" layout, 6.3 MB each, best effort at 10 Hz) runs in a subprocess
with no DDS variables set, so it loads the package's Fast DDS profile as ``lili-odom play``
and ``lili_odom_node`` do; the node (fake pipeline, default subscription QoS) runs in-process.
At least 99 % of the clouds must reach the node, and the node's missing-scan count must
account for the ones that did not. (With Fast DDS's own defaults most of them are lost:
``benchmarks.dds_large_clouds`` measures both.) Isolated domain, localhost only.
"""
from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from _ros_fakes import FakeProvider, isolated_ros_env, wait_for  # noqa: E402
from lili_odom.ros.node import LiliOdomNode, parameters_from_mapping  # noqa: E402

COUNT = 100  # 10 s at 10 Hz


def test_128x1024_clouds_at_10hz_reach_the_node_with_the_defaults(monkeypatch):
    env = isolated_ros_env()
    for key in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE",
                "FASTDDS_BUILTIN_TRANSPORTS", "LILI_ODOM_DDS_PROFILE"):
        env.pop(key, None)
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(key, env[key])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = LiliOdomNode(context=ctx, provider=FakeProvider(),
                        parameter_overrides=parameters_from_mapping(
                            {"diagnostics_period": 0.0, "diagnostics_publish_period": 0.0,
                             # the fake pipeline does not parse; keep every scan for counting
                             "scan_queue_size": 1000}))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    try:
        pub = subprocess.run([sys.executable, "-m", "lili_odom.ros.cloud_check", "publish",
                              "--count", str(COUNT), "--rate", "10", "--height", "128",
                              "--width", "1024", "--qos", "sensor-data"],
                             env=env, capture_output=True, text=True, timeout=50)
        assert pub.returncode == 0, pub.stderr
        # a busy executor may still hold samples in the subscription's history: let it drain
        received = -1
        while node.counters["scans_received"] != received:
            received = node.counters["scans_received"]
            if received >= COUNT:
                break
            time.sleep(2.0)
        diag = node.diagnostics()
    finally:
        executor.shutdown(timeout_sec=2.0)
        spin.join(5.0)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    received = diag["scans_received"]
    assert received >= 0.99 * COUNT, {k: diag[k] for k in ("scans_received", "scans_missing",
                                                           "scans_processed", "scans_dropped")}
    # losses inside the run show up as missing scans (the first and last cannot)
    assert diag["scans_missing"] <= COUNT - received, diag
    assert diag["scans_dropped"] == 0, diag
