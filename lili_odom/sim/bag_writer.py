"""rosbag2 MCAP writer for the simulated topics (``rosbags.rosbag2.Writer``, zstd chunks).

Topics and types are those of ``shared/design.md``. ``/tf_static`` is offered with
transient-local durability so that ``ros2 bag play`` latches it like a live robot.
"""
from __future__ import annotations

from pathlib import Path

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

from lili_odom.sim.ros_messages import typestore

try:  # the zstd module rosbags itself uses
    from compression import zstd as _zstd  # Python >= 3.14
except ImportError:  # pragma: no cover
    from backports import zstd as _zstd

__all__ = ["TOPICS", "SimBagWriter"]

#: topic -> message type, exactly as in the design's input contract
TOPICS = {
    "/ouster/points": "sensor_msgs/msg/PointCloud2",
    "/ouster/imu": "sensor_msgs/msg/Imu",
    "/platform/odom": "nav_msgs/msg/Odometry",
    "/ground_truth/odom": "nav_msgs/msg/Odometry",
    "/tf_static": "tf2_msgs/msg/TFMessage",
}

_ZERO = QosTime(0, 0)
_INF = QosTime(2147483647, 4294967295)


def _qos(reliable: bool, latched: bool) -> Qos:
    return Qos(
        QosHistory.KEEP_LAST,
        1 if latched else 10,
        QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE,
        _INF,
        _INF,
        QosLiveliness.AUTOMATIC,
        _INF,
        False,
    )


class SimBagWriter:
    """Context manager: ``with SimBagWriter(path) as w: w.write(topic, log_time_ns, cdr_bytes)``.

    ``path`` must not exist (rosbag2 bags are directories: metadata.yaml + <name>.mcap)."""

    #: zstd level of the mcap chunks: level 2 compresses point clouds as well as rosbags'
    #: default (3) at ~2/3 of the time; 19 is for small committed bags.
    DEFAULT_ZSTD_LEVEL = 2

    def __init__(self, path: Path | str, compress: bool = True, zstd_level: int | None = DEFAULT_ZSTD_LEVEL):
        self.path = Path(path)
        self.zstd_level = zstd_level
        self._writer = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
        if compress:
            # STORAGE mode = MCAP chunk compression with zstd (the rosbag2 mcap plugin default style)
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._conns = {}
        self.counts = {topic: 0 for topic in TOPICS}

    def __enter__(self) -> "SimBagWriter":
        self._writer.open()
        storage = getattr(self._writer, "storage", None)
        if self.zstd_level is not None and getattr(storage, "compression", "") == "zstd":
            # rosbags compresses chunks with zstd's default level; small committed bags use more
            level = int(self.zstd_level)
            storage.compressor = lambda data: _zstd.compress(data, level=level)
        ts = typestore()
        for topic, msgtype in TOPICS.items():
            self._conns[topic] = self._writer.add_connection(
                topic, msgtype, typestore=ts,
                offered_qos_profiles=[_qos(reliable=topic != "/ouster/points", latched=topic == "/tf_static")],
            )
        return self

    def write(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self._writer.write(self._conns[topic], int(log_time_ns), data)
        self.counts[topic] += 1

    def __exit__(self, exc_type, exc, tb) -> None:
        self._writer.close()
