"""The live node, driven over DDS by ``lili-odom play``, gives the offline runner's trajectory.

One odometry message per scan of the committed CI bag, and the same poses as
``lili-odom run`` on that bag (subprocesses; isolated domain, localhost only).
"""
from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402

from _ros_fakes import isolated_ros_env, wait_for  # noqa: E402
from lili_odom import messages as M  # noqa: E402
from lili_odom.ros.factory import message_class  # noqa: E402
from lili_odom.ros.node import LiliOdomNode, parameters_from_mapping  # noqa: E402
from lili_odom.ros.provider import OdometryPipelineProvider  # noqa: E402

BAG = Path(__file__).resolve().parents[1] / "bags" / "tunnel_entrance_32x256"
METHOD = "none"  # the detectors are covered elsewhere; this checks the plumbing end to end


def _start_runner(tmp_path) -> tuple[subprocess.Popen, Path]:
    """``lili-odom run`` on the bag in a subprocess (it runs while the node replays)."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "lili_odom.cli", "run", str(BAG), "--method",
                             METHOD, "--out", str(out), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return proc, out / "estimate.tum"


def _runner_trajectory(proc: subprocess.Popen, estimate: Path) -> np.ndarray:
    try:
        _, stderr = proc.communicate(timeout=600)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    return np.loadtxt(estimate)


def test_node_over_dds_matches_offline_runner(tmp_path, monkeypatch):
    runner, estimate = _start_runner(tmp_path)
    env = isolated_ros_env()
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(key, env[key])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = LiliOdomNode(context=ctx, provider=OdometryPipelineProvider(),
                        parameter_overrides=parameters_from_mapping(
                            {"pipeline.method": METHOD, "diagnostics_period": 0.0,
                                 # play is a reliable publisher: a lossless replay, with a
                                 # queue for the whole bag, so a loaded machine drops nothing
                                 "reliable_inputs": True, "scan_queue_size": 1000,
                                 "scan_subscription_depth": 1000}))
    listener = rclpy.create_node("listener", context=ctx)
    got: list = []
    listener.create_subscription(message_class("nav_msgs/msg/Odometry"), "/lili_odom/odometry",
                                 got.append, QoSProfile(depth=1000,
                                                        reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    executor.add_node(listener)
    spin = threading.Thread(target=executor.spin, daemon=True)
    spin.start()
    try:
        play = subprocess.run([sys.executable, "-m", "lili_odom.cli", "play", str(BAG),
                               "--rate", "1.0", "--delay", "20.0", "--qos-depth", "1000"],
                              env=env, capture_output=True, text=True, timeout=120)
        assert play.returncode == 0, play.stderr
        expected = _runner_trajectory(runner, estimate)
        wait_for(lambda: len(got) >= len(expected), 120.0)
        time.sleep(0.5)
        diag = node.diagnostics()
    finally:
        runner.kill()  # nothing after a normal exit; a runner left by a failure stops
        executor.shutdown(timeout_sec=2.0)
        spin.join(5.0)
        node.destroy_node()
        listener.destroy_node()
        rclpy.try_shutdown(context=ctx)

    assert diag["scans_dropped"] == 0 and diag["scan_errors"] == 0, diag
    assert diag["scans_received"] == len(expected), diag  # every scan of the bag arrived
    assert len(got) == len(expected), diag  # one odometry per scan
    stamps = np.array([M.stamp_seconds(o.header) for o in got])
    np.testing.assert_allclose(stamps, expected[:, 0], atol=1e-6)
    xyz = np.array([[o.pose.pose.position.x, o.pose.pose.position.y, o.pose.pose.position.z]
                    for o in got])
    err = np.linalg.norm(xyz - expected[:, 1:4], axis=1)
    assert err.max() < 1e-3, f"node vs runner: max position difference {err.max():.2e} m"
    q = np.array([[o.pose.pose.orientation.x, o.pose.pose.orientation.y,
                   o.pose.pose.orientation.z, o.pose.pose.orientation.w] for o in got])
    dots = np.abs(np.sum(q * expected[:, 4:8], axis=1))
    assert np.degrees(2 * np.arccos(np.clip(dots, -1, 1))).max() < 0.05
