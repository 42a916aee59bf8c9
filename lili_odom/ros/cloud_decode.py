"""Decode a serialised ``sensor_msgs/PointCloud2`` (CDR bytes, as an rclpy subscription with
``raw=True`` hands them over) into a message object the feeder parses.

rosbags decodes it first: it reads the point buffer in place (``data`` is a numpy view of the
bytes), where rclpy's conversion copies the buffer into a Python message. A cloud rosbags does
not read (an encoding it does not know) is decoded by rclpy instead.
"""
from __future__ import annotations

from typing import Any

from lili_odom.bagio.factory import jazzy_typestore
from lili_odom.ros.factory import message_class

__all__ = ["CloudDecoder", "UndecodableCloud"]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"


class UndecodableCloud(ValueError):
    """Neither rosbags nor rclpy decodes the bytes as a PointCloud2."""


class CloudDecoder:
    """Serialised PointCloud2 -> message object (rosbags', or rclpy's when rosbags fails).

    Args:
        typestore: the rosbags type store (default: ROS 2 Jazzy's).
    """

    def __init__(self, typestore: Any = None) -> None:
        self.typestore = typestore if typestore is not None else jazzy_typestore()

    def __call__(self, raw: bytes | bytearray | memoryview) -> Any:
        """The decoded cloud; raises :class:`UndecodableCloud` naming both failures."""
        try:
            return self.typestore.deserialize_cdr(raw, POINTCLOUD2)
        except Exception as exc:  # noqa: BLE001 - e.g. an encoding rosbags does not read
            first = f"{type(exc).__name__}: {exc}"
        try:
            from rclpy.serialization import deserialize_message

            return deserialize_message(bytes(raw), message_class(POINTCLOUD2))
        except Exception as exc:  # noqa: BLE001 - any failure means: not a cloud
            raise UndecodableCloud(f"rosbags: {first}; rclpy: {type(exc).__name__}: "
                                   f"{exc}") from None
