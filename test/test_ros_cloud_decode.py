"""Serialised clouds as the node takes them (``raw=True``): decoded by rosbags, by rclpy when
rosbags cannot, and corrupt bytes rejected with one error type, never a crash."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy")

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from lili_odom import messages as M  # noqa: E402
from lili_odom.ros.cloud_check import ouster_cloud_message  # noqa: E402
from lili_odom.ros.cloud_decode import CloudDecoder, UndecodableCloud  # noqa: E402

MSG = ouster_cloud_message(height=4, width=16, stamp=12.25)
RAW = serialize_message(MSG)


def _same_scan(decoded) -> None:
    want, got = M.scan_from_msg(MSG), M.scan_from_msg(decoded)
    assert got.stamp == pytest.approx(12.25) and got.frame_id == "os_lidar"
    np.testing.assert_array_equal(got.points, want.points)
    np.testing.assert_array_equal(got.times, want.times)


def test_rosbags_decodes_the_cloud_without_copying_its_points():
    decoded = CloudDecoder()(RAW)
    assert isinstance(decoded.data, np.ndarray) and not decoded.data.flags.owndata
    assert [f.name for f in decoded.fields] == [f.name for f in MSG.fields]
    _same_scan(decoded)


def test_rclpy_decodes_what_rosbags_cannot():
    # an encapsulation id rosbags does not read (0x0007, XCDR2); rclpy reads the payload
    other = b"\x00\x07\x00\x00" + RAW[4:]
    with pytest.raises(Exception):
        CloudDecoder().typestore.deserialize_cdr(other, "sensor_msgs/msg/PointCloud2")
    decoded = CloudDecoder()(other)
    assert type(decoded).__module__.startswith("sensor_msgs")
    _same_scan(decoded)


@pytest.mark.parametrize("raw", [b"", RAW[:3], RAW[:40], RAW[:4] + b"\xff" * 64])
def test_bytes_that_are_no_cloud_raise_one_error(raw):
    with pytest.raises(UndecodableCloud, match="rosbags: .*; rclpy: "):
        CloudDecoder()(raw)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(cut=st.integers(0, len(RAW)), flips=st.lists(
    st.tuples(st.integers(0, len(RAW) - 1), st.integers(0, 255)), max_size=4),
    tail=st.binary(max_size=16))
def test_mutated_bytes_decode_or_raise_undecodable(cut, flips, tail):
    raw = bytearray(RAW)
    for i, value in flips:
        raw[i] = value
    raw = bytes(raw[:cut]) + tail
    try:
        decoded = CloudDecoder()(raw)
    except UndecodableCloud:
        return
    assert hasattr(decoded, "header") and hasattr(decoded, "data")
