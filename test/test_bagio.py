"""Bag reading in header-stamp order, reader errors, output bags and TUM files (no DDS)."""
from __future__ import annotations

import re

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory
from lili_odom.bagio.reader import BagReader
from lili_odom.bagio.tum import format_tum_line, read_tum, write_tum
from lili_odom.bagio.writer import OutputBagWriter, thin_poses
from lili_odom.errors import UserError
from lili_odom.pipeline.types import OdometryOutput

F = RosbagsFactory()


def _imu(stamp: float):
    return F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, stamp, "os_imu"))


def _cloud(stamp: float):
    return M.pointcloud_xyz_msg(F, np.ones((4, 3)), stamp, "os_lidar")


def write_bag(path, items, topics=None):
    """items: [(topic, log_time s, msg)]; writes a rosbag2 mcap directory."""
    types = topics or {"/ouster/points": "sensor_msgs/msg/PointCloud2",
                       "/ouster/imu": "sensor_msgs/msg/Imu"}
    w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    w.open()
    conns = {t: w.add_connection(t, ty, typestore=F.typestore) for t, ty in types.items()}
    for topic, log_time, msg in sorted(items, key=lambda x: x[1]):
        w.write(conns[topic], int(log_time * 1e9), F.serialize(msg))
    w.close()
    return path


@pytest.fixture
def sensor_bag(tmp_path):
    """IMU at 100 Hz logged with jitter, scans at 10 Hz logged 0.1 s after their stamp."""
    rng = np.random.default_rng(1)
    items = []
    for i in range(100):
        t = 100.0 + 0.01 * i
        items.append(("/ouster/imu", t + rng.uniform(0.0, 0.03), _imu(t)))
    for k in range(10):
        t = 100.0 + 0.1 * k
        items.append(("/ouster/points", t + 0.1, _cloud(t)))
    return write_bag(tmp_path / "bag", items)


def test_reader_yields_header_stamp_order(sensor_bag):
    with BagReader(sensor_bag, topics=["/ouster/points", "/ouster/imu"]) as reader:
        assert reader.message_count == 110
        got = list(reader)
        # log order differs from stamp order, so the test is meaningful
        assert [m.log_time for m in got] != sorted(m.log_time for m in got)
    stamps = [m.stamp for m in got]
    assert len(got) == 110 and reader.stats.late == 0
    assert stamps == sorted(stamps)
    assert {m.topic for m in got} == {"/ouster/points", "/ouster/imu"}
    # the scan stamped 100.0 (logged at 100.1) comes before the IMU stamped 100.01
    assert "sensor_msgs/msg/PointCloud2" in {m.msgtype for m in got[:2]}


def test_reader_counts_messages_later_than_window(tmp_path):
    items = [("/ouster/imu", 10.0 + 0.01 * i, _imu(10.0 + 0.01 * i)) for i in range(200)]
    items.append(("/ouster/points", 11.9, _cloud(10.5)))  # 1.4 s late, window 0.5 s
    path = write_bag(tmp_path / "bag", items)
    with BagReader(path, reorder_window=0.5) as reader:
        got = list(reader)
    assert reader.stats.late == 1 and len(got) == 200
    with BagReader(path, reorder_window=2.0) as reader:
        got = list(reader)
    assert reader.stats.late == 0 and len(got) == 201
    assert [m.stamp for m in got] == sorted(m.stamp for m in got)


def test_reader_single_mcap_file_and_progress(sensor_bag):
    mcap = next(sensor_bag.glob("*.mcap"))
    seen = []
    with BagReader(mcap, progress=lambda n, total: seen.append((n, total))) as reader:
        assert len(list(reader)) == 110
    assert seen[-1] == (110, 110)


def _one_line_error(path, **kw) -> str:
    with pytest.raises(UserError) as info:
        with BagReader(path, **kw) as reader:
            list(reader)
    text = str(info.value)
    assert "\n" not in text
    return text


def test_reader_errors(tmp_path, sensor_bag):
    assert "no such file" in _one_line_error(tmp_path / "nope")
    (tmp_path / "empty_dir").mkdir()
    assert "not a rosbag2 bag" in _one_line_error(tmp_path / "empty_dir")
    (tmp_path / "notes.txt").write_text("hello")
    assert "not a rosbag2 bag" in _one_line_error(tmp_path / "notes.txt")
    assert "required topic /platform/odom" in _one_line_error(
        sensor_bag, required=["/ouster/points", "/platform/odom"])
    assert "expected nav_msgs/msg/Odometry" in _one_line_error(
        sensor_bag, expected_types={"/ouster/imu": "nav_msgs/msg/Odometry"})


@pytest.mark.parametrize("keep", [20, 1000, 0.6])
def test_reader_truncated_mcap(tmp_path, sensor_bag, keep):
    data = next(sensor_bag.glob("*.mcap")).read_bytes()
    n = int(len(data) * keep) if isinstance(keep, float) else keep
    bad = tmp_path / "cut.mcap"
    bad.write_bytes(data[:n])
    text = _one_line_error(bad)
    assert str(bad) in text


def test_output_bag_round_trip(tmp_path):
    out_path = tmp_path / "out"
    with OutputBagWriter(out_path, path_period=0.25) as w:
        for i in range(10):
            T = np.eye(4)
            T[0, 3] = i
            w.write_output(OdometryOutput(stamp=5.0 + 0.1 * i, pose=T, twist=np.zeros(6),
                                          covariance=np.eye(6),
                                          degenerate_basis=np.array([[0, 1.0, 0, 0, 0, 0]])))
        w.write_map(np.random.default_rng(0).normal(size=(100, 3)), 6.0)
    with BagReader(out_path, required=(), expected_types={}) as r:
        got = list(r)
        types = r.topic_types
    assert types["/lili_odom/odometry"] == "nav_msgs/msg/Odometry"
    count = {}
    for m in got:
        count[m.topic] = count.get(m.topic, 0) + 1
    assert count["/lili_odom/odometry"] == 10 and count["/lili_odom/degeneracy"] == 10
    assert count["/lili_odom/degeneracy/basis"] == 10 and count["/tf"] == 10
    assert count["/lili_odom/map"] == 1
    assert 3 <= count["/lili_odom/path"] <= 5
    last_odom = [m for m in got if m.topic == "/lili_odom/odometry"][-1]
    assert last_odom.msg.pose.pose.position.x == pytest.approx(9.0)
    last_path = [m for m in got if m.topic == "/lili_odom/path"][-1]
    assert len(last_path.msg.poses) == 10


def test_thin_poses_keeps_last():
    poses = [(float(i), np.eye(4)) for i in range(1000)]
    thin = thin_poses(poses, 50)
    assert len(thin) <= 50 and thin[-1][0] == 999.0 and thin[0][0] == 0.0


def test_tum_format_and_round_trip(tmp_path):
    T = np.eye(4)
    T[:3, :3] = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 deg yaw
    T[:3, 3] = [1.0, 2.0, 3.0]
    line = format_tum_line(1700000000.5, T)
    parts = line.split(" ")
    assert len(parts) == 8
    assert re.fullmatch(r"1700000000\.500000000", parts[0])
    np.testing.assert_allclose([float(x) for x in parts[1:]],
                               [1, 2, 3, 0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-9)
    flip = T.copy()
    flip[:3, :3] = -np.eye(3) + 2 * np.outer([0, 0, 1], [0, 0, 1])  # 180 deg yaw: w = 0
    path = tmp_path / "traj" / "est.tum"
    assert write_tum(path, [(1.0, T), (2.0, flip)]) == 2
    stamps, poses = read_tum(path)
    np.testing.assert_allclose(stamps, [1.0, 2.0])
    np.testing.assert_allclose(poses[0], T, atol=1e-9)
    np.testing.assert_allclose(poses[1], flip, atol=1e-9)
    for row in path.read_text().splitlines():
        assert float(row.split()[-1]) >= 0.0  # canonical w >= 0
