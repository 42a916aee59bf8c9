"""``lili-odom play --restamp``: the header stamp moved in the raw CDR bytes, without ROS."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory
from lili_odom.commands.play import header_stamp_ns, shift_header_stamp

F = RosbagsFactory()


def _roundtrip(msg, offset_ns: int):
    data = F.serialize(msg)
    shifted = shift_header_stamp(data, offset_ns)
    assert isinstance(shifted, bytes) and len(shifted) == len(data)
    assert shifted[12:] == data[12:] and shifted[:4] == data[:4]  # only the stamp changed
    assert header_stamp_ns(shifted) == header_stamp_ns(data) + offset_ns
    return F.typestore.deserialize_cdr(shifted, msg.__msgtype__)


@pytest.mark.parametrize("offset_ns", [0, 250_000_000, 900_000_001, -1_700_000_000_123_456_789])
def test_stamps_move_by_the_offset_with_carry(offset_ns):
    stamp = 1_700_000_000.75
    imu = F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, stamp, "os_imu"),
                angular_velocity=F.new("geometry_msgs/msg/Vector3", z=0.5))
    before = imu.header.stamp.sec * 1_000_000_000 + imu.header.stamp.nanosec
    back = _roundtrip(imu, offset_ns)
    total = back.header.stamp.sec * 1_000_000_000 + back.header.stamp.nanosec
    assert total == before + offset_ns
    assert 0 <= back.header.stamp.nanosec < 1_000_000_000
    assert back.header.frame_id == "os_imu" and back.angular_velocity.z == 0.5


def test_clouds_and_odometry_keep_their_content():
    pts = np.random.default_rng(0).normal(size=(50, 3))
    cloud = M.pointcloud_xyz_msg(F, pts, 12.5, "os_lidar", times=np.linspace(0, 0.099, 50))
    back = _roundtrip(cloud, 3_000_000_000)
    assert M.stamp_seconds(back.header) == pytest.approx(15.5)
    assert bytes(back.data) == bytes(cloud.data) and back.width == 50
    odom = F.new("nav_msgs/msg/Odometry", header=M.header_msg(F, 7.0, "odom"),
                 child_frame_id="base_link")
    back = _roundtrip(odom, -2_000_000_000)
    assert M.stamp_seconds(back.header) == pytest.approx(5.0)
    assert back.child_frame_id == "base_link"


def test_bad_input_is_a_value_error():
    with pytest.raises(ValueError):
        shift_header_stamp(b"\x00\x01\x00\x00\x01", 1)
    with pytest.raises(ValueError):
        header_stamp_ns(b"\x00\x01\x00\x00\x01")
    imu = F.new("sensor_msgs/msg/Imu", header=M.header_msg(F, 1.0, "os_imu"))
    with pytest.raises(ValueError):
        shift_header_stamp(F.serialize(imu), -2_000_000_000)
