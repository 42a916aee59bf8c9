"""``lili-odom play``: a tiny bag published over DDS (subprocess, isolated domain)."""
from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402

from _ros_fakes import isolated_ros_env  # noqa: E402
from lili_odom import messages as M  # noqa: E402
from lili_odom.bagio.factory import RosbagsFactory  # noqa: E402
from lili_odom.ros.factory import message_class  # noqa: E402

F = RosbagsFactory()
N_IMU, N_ODOM = 30, 10


def _tiny_bag(path):
    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    imu = w.add_connection("/ouster/imu", "sensor_msgs/msg/Imu", typestore=F.typestore)
    odom = w.add_connection("/platform/odom", "nav_msgs/msg/Odometry", typestore=F.typestore)
    tf = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=F.typestore)
    t0 = 50.0
    w.write(tf, int(t0 * 1e9), F.serialize(M.tf_message(F, [(t0, "base_link", "os_sensor",
                                                              np.eye(4))])))
    for i in range(N_IMU):
        t = t0 + 0.01 * i
        msg = F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, t, "os_imu"),
                    angular_velocity=F.new("geometry_msgs/msg/Vector3", z=float(i)))
        w.write(imu, int(t * 1e9), F.serialize(msg))
    for i in range(N_ODOM):
        t = t0 + 0.03 * i + 0.001
        msg = F.new("nav_msgs/msg/Odometry", header=M.header_msg(F, t, "odom"),
                    child_frame_id="base_link")
        w.write(odom, int(t * 1e9), F.serialize(msg))
    w.close()
    return path


def _play(bag, env, *extra, timeout=30.0):
    cmd = [sys.executable, "-m", "lili_odom.cli", "play", str(bag), *extra]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)


def test_play_publishes_every_message_with_clock(tmp_path, monkeypatch):
    bag = _tiny_bag(tmp_path / "tiny")
    env = isolated_ros_env()
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(key, env[key])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("play_listener", context=ctx)
    got = {"imu": [], "odom": [], "clock": []}
    qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(message_class("sensor_msgs/msg/Imu"), "/ouster/imu",
                             got["imu"].append, qos)
    node.create_subscription(message_class("nav_msgs/msg/Odometry"), "/platform/odom",
                             got["odom"].append, qos)
    node.create_subscription(message_class("rosgraph_msgs/msg/Clock"), "/clock",
                             got["clock"].append, qos)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "lili_odom.cli", "play", str(bag), "--rate", "2",
             "--delay", "15.0", "--clock-hz", "200"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
            if proc.poll() is not None and len(got["imu"]) >= N_IMU and \
                    len(got["odom"]) >= N_ODOM:
                break
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        if proc.poll() is None:
            proc.kill()
        _, err = proc.communicate(timeout=10)
    finally:
        executor.shutdown(timeout_sec=2.0)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0, err
    assert len(got["imu"]) == N_IMU and len(got["odom"]) == N_ODOM, (err, [m.angular_velocity.z for m in got["imu"]], len(got["odom"]))
    assert [m.angular_velocity.z for m in got["imu"]] == [float(i) for i in range(N_IMU)]
    assert got["clock"], "no /clock received"
    clock = [M.stamp_seconds(c.clock) for c in got["clock"]]
    assert clock == sorted(clock) and 49.99 <= clock[0] and clock[-1] <= 50.5
    if "tf2_msgs" not in sys.modules:
        try:
            import tf2_msgs  # noqa: F401
        except ImportError:
            assert "skipping /tf_static" in err


def test_play_bad_bag_is_one_line_error(tmp_path):
    bag = _tiny_bag(tmp_path / "tiny")
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(next(bag.glob("*.mcap")).read_bytes()[:500])
    env = isolated_ros_env()
    for path in (cut, tmp_path / "missing"):
        res = _play(path, env)
        assert res.returncode == 2
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("lili-odom play: error:"), res.stderr
    res = _play(bag, env, "--topics", "/nope")
    assert res.returncode == 2 and "/nope" in res.stderr


def test_play_sensor_data_qos_publishes_best_effort_like_a_driver(tmp_path, monkeypatch):
    bag = _tiny_bag(tmp_path / "tiny")
    env = isolated_ros_env()
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(key, env[key])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("play_listener", context=ctx)
    got: list = []
    node.create_subscription(message_class("sensor_msgs/msg/Imu"), "/ouster/imu", got.append,
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    reliabilities = set()
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "lili_odom.cli", "play", str(bag), "--rate", "1",
             "--delay", "15.0", "--clock-hz", "0", "--topics", "/ouster/imu",
             "--qos", "sensor-data"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and proc.poll() is None:
            executor.spin_once(timeout_sec=0.05)
            for info in node.get_publishers_info_by_topic("/ouster/imu"):
                reliabilities.add(info.qos_profile.reliability)
        _, err = proc.communicate(timeout=10)
    finally:
        executor.shutdown(timeout_sec=2.0)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0, err
    assert reliabilities == {ReliabilityPolicy.BEST_EFFORT}, reliabilities
    assert len(got) >= N_IMU - 1, len(got)  # best effort on loopback: (nearly) all arrive


def test_play_restamp_puts_the_stamps_on_the_system_clock(tmp_path, monkeypatch):
    bag = _tiny_bag(tmp_path / "tiny")
    env = isolated_ros_env()
    for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
        monkeypatch.setenv(key, env[key])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(env["ROS_DOMAIN_ID"]))
    node = rclpy.create_node("play_listener", context=ctx)
    got: list = []  # (stamp [s], system clock at reception [s])
    node.create_subscription(message_class("sensor_msgs/msg/Imu"), "/ouster/imu",
                             lambda m: got.append((M.stamp_seconds(m.header), time.time())),
                             QoSProfile(depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "lili_odom.cli", "play", str(bag), "--rate", "1",
             "--delay", "15.0", "--clock-hz", "0", "--topics", "/ouster/imu", "--restamp",
             "--qos", "sensor-data"],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and proc.poll() is None:
            executor.spin_once(timeout_sec=0.05)
        _, err = proc.communicate(timeout=10)
    finally:
        executor.shutdown(timeout_sec=2.0)
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    assert proc.returncode == 0, err
    assert len(got) >= N_IMU - 1, err  # best effort on loopback: (nearly) all arrive
    stamps = np.array([s for s, _ in got])
    spacing = np.diff(stamps) / 0.01
    np.testing.assert_allclose(spacing, np.round(spacing), atol=1e-4)  # 10 ms grid kept
    lag = np.array([r for _, r in got]) - stamps  # reception after the (new) stamp
    assert np.all(lag > -0.05) and np.median(lag) < 1.0, lag
