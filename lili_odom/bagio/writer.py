"""Write the pipeline's outputs into a rosbag2 MCAP bag (zstd-compressed chunks).

Topics mirror the live node (node ``lili_odom``): ``/lili_odom/odometry`` (every scan),
``/lili_odom/path`` (at most every ``path_period`` seconds of stamp time, and at the end),
``/lili_odom/degeneracy`` (MarkerArray) and ``/lili_odom/degeneracy/basis`` (JSON String) every
scan, ``/lili_odom/map`` (PointCloud2 in the odometry frame, on request) and ``/tf``
(odometry frame -> ``base_link``; rosbags knows ``tf2_msgs`` even where rclpy does not).
Log times are the header stamps, so the bag replays in the data's own time.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from lili_odom import messages as M
from lili_odom.bagio.factory import RosbagsFactory
from lili_odom.errors import UserError
from lili_odom.pipeline.types import OdometryOutput

__all__ = ["OutputBagWriter", "OUTPUT_TOPICS", "thin_poses"]

_Entry = TypeVar("_Entry")

OUTPUT_TOPICS: dict[str, str] = {
    "odometry": "nav_msgs/msg/Odometry",
    "path": "nav_msgs/msg/Path",
    "degeneracy": "visualization_msgs/msg/MarkerArray",
    "degeneracy/basis": "std_msgs/msg/String",
    "map": "sensor_msgs/msg/PointCloud2",
}


def thin_poses(poses: list[_Entry], limit: int) -> list[_Entry]:
    """At most ``limit`` evenly spaced entries of ``poses`` (any entries, e.g. ``(stamp,
    4x4)`` or pose messages), always including the last."""
    if len(poses) <= limit:
        return list(poses)
    idx = np.unique(np.linspace(0, len(poses) - 1, limit).round().astype(int))
    return [poses[i] for i in idx]


def _ns(t: float) -> int:
    return max(0, int(round(t * 1e9)))


class OutputBagWriter:
    """Streams :class:`OdometryOutput` into a new bag directory (context manager).

    Args:
        path: bag directory to create (must not exist).
        odom_frame: frame of the odometry, path, markers and map.
        base_frame: child frame of the odometry.
        namespace: topic prefix (the node name).
        path_period: minimum stamp time between two ``path`` messages [s].
        max_path_poses: a path message holds at most this many poses (evenly thinned, the
            newest always kept), so the bag grows linearly, not quadratically.
        write_tf: also write ``/tf``.
        compress: zstd chunk compression.
    """

    def __init__(self, path: str | Path, odom_frame: str = "lili_odom",
                 base_frame: str = "base_link", namespace: str = "/lili_odom",
                 path_period: float = 2.0, max_path_poses: int = 2000, write_tf: bool = True,
                 compress: bool = True) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

        self.path = Path(path)
        self.odom_frame = odom_frame
        self.base_frame = base_frame
        self.namespace = namespace.rstrip("/")
        self.path_period = float(path_period)
        self.max_path_poses = max(2, int(max_path_poses))
        self.factory = RosbagsFactory()
        self.poses: list[tuple[float, np.ndarray]] = []
        self._last_path_stamp = -float("inf")
        self.counts: dict[str, int] = {}
        try:
            self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            if compress:
                self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
            self._writer.open()
        except (WriterError, OSError) as exc:
            raise UserError(f"{self.path}: cannot create output bag: {exc}") from None
        self._conns: dict[str, Any] = {}
        for name, msgtype in OUTPUT_TOPICS.items():
            self._conns[name] = self._writer.add_connection(
                f"{self.namespace}/{name}", msgtype, typestore=self.factory.typestore)
        if write_tf:
            self._conns["/tf"] = self._writer.add_connection(
                "/tf", "tf2_msgs/msg/TFMessage", typestore=self.factory.typestore)

    def _write(self, key: str, stamp: float, msg: Any) -> None:
        self._writer.write(self._conns[key], _ns(stamp), self.factory.serialize(msg))
        self.counts[key] = self.counts.get(key, 0) + 1

    def write_output(self, out: OdometryOutput) -> None:
        """Odometry, degeneracy markers + JSON, ``/tf`` and (rate-limited) path of one scan."""
        f = self.factory
        self.poses.append((out.stamp, np.asarray(out.pose, dtype=np.float64)))
        self._write("odometry", out.stamp, M.odometry_msg(f, out, self.odom_frame,
                                                           self.base_frame))
        self._write("degeneracy", out.stamp, M.degeneracy_markers(f, out, self.odom_frame))
        self._write("degeneracy/basis", out.stamp, M.degeneracy_json_msg(f, out))
        if "/tf" in self._conns:
            self._write("/tf", out.stamp, M.tf_message(
                f, [(out.stamp, self.odom_frame, self.base_frame, out.pose)]))
        if out.stamp - self._last_path_stamp >= self.path_period:
            self.write_path(out.stamp)

    def write_path(self, stamp: float) -> None:
        if not self.poses:
            return
        self._write("path", stamp, M.path_msg(self.factory, thin_poses(self.poses,
                                                                   self.max_path_poses),
                                              self.odom_frame, stamp))
        self._last_path_stamp = stamp

    def write_map(self, points: np.ndarray, stamp: float) -> None:
        """The local map (N, 3) [m] in the odometry frame."""
        self._write("map", stamp, M.pointcloud_xyz_msg(self.factory, points, stamp,
                                                       self.odom_frame))

    def close(self) -> None:
        """Write the final path and the bag's metadata."""
        if self._writer is None:
            return
        try:
            if self.poses and self._last_path_stamp < self.poses[-1][0]:
                self.write_path(self.poses[-1][0])
            self._writer.close()
        finally:
            self._writer = None

    def __enter__(self) -> "OutputBagWriter":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
