"""Ouster recordings (``.pcap`` + metadata ``.json``, or ``.osf``) as ROS messages.

Reads a recording with the Ouster SDK (``pip install ouster-sdk``, optional) and turns it into
what the ouster-ros driver would have published, as rosbags message objects (the type the
offline runner reads from bags):

* clouds on ``/ouster/points`` (``sensor_msgs/PointCloud2``) in one of the ouster-ros layouts
  (:data:`LAYOUTS`; default ``original``: x, y, z float32 @ 0/4/8, intensity float32 @ 16, t
  uint32 @ 20 [ns from ``header.stamp``], reflectivity / ring / ambient uint16 @ 24/26/28, range
  uint32 @ 32 [mm], point_step 48), organized ``H x W`` and destaggered, in the ``os_lidar``
  frame [m]; no-return pixels have NaN x, y, z and range 0; ``header.stamp`` is the first
  valid column's time;
* IMU samples on ``/ouster/imu`` (``sensor_msgs/Imu``, frame ``os_imu``, SI units, orientation
  unset) when the recording has IMU packets.

Frames follow ouster-ros: ``os_sensor`` is the sensor's housing frame, ``os_lidar`` the lidar
frame (:attr:`OusterRecording.T_sensor_lidar` from the metadata, metres), ``os_imu`` the IMU's
(:attr:`OusterRecording.T_sensor_imu`). Time is the sensor's timestamps (ns) as recorded.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from lili_odom.errors import UserError

__all__ = ["LAYOUTS", "RecordingMessage", "OusterRecording", "frame_to_cloud_fields",
           "cloud_message", "sdk_available", "sensor_frame_points"]

# layout -> (point_step, [(name, offset, numpy type, PointField datatype)])
LAYOUTS: dict[str, tuple[int, list[tuple[str, int, str, int]]]] = {
    "original": (48, [("x", 0, "<f4", 7), ("y", 4, "<f4", 7), ("z", 8, "<f4", 7),
                      ("intensity", 16, "<f4", 7), ("t", 20, "<u4", 6),
                      ("reflectivity", 24, "<u2", 4), ("ring", 26, "<u2", 4),
                      ("ambient", 28, "<u2", 4), ("range", 32, "<u4", 6)]),
    # pcl::PointXYZ / PointXYZI / ouster-ros PointXYZIR: 16-byte aligned x, y, z (+ padding)
    "xyz": (16, [("x", 0, "<f4", 7), ("y", 4, "<f4", 7), ("z", 8, "<f4", 7)]),
    "xyzi": (32, [("x", 0, "<f4", 7), ("y", 4, "<f4", 7), ("z", 8, "<f4", 7),
                  ("intensity", 16, "<f4", 7)]),
    "xyzir": (32, [("x", 0, "<f4", 7), ("y", 4, "<f4", 7), ("z", 8, "<f4", 7),
                   ("intensity", 16, "<f4", 7), ("ring", 20, "<u2", 4)]),
}

LIDAR_TOPIC = "/ouster/points"
IMU_TOPIC = "/ouster/imu"


def sdk_available() -> bool:
    try:
        import ouster.sdk  # noqa: F401
    except ImportError:
        return False
    return True


def _sdk() -> Any:
    try:
        import ouster.sdk as sdk
        from ouster.sdk import core  # noqa: F401
    except ImportError:
        raise UserError("reading Ouster recordings needs the Ouster SDK: "
                        "pip install ouster-sdk (see docs/ros.md)") from None
    return sdk


def _value(obj: Any, name: str, default: Any) -> Any:
    """An SDK attribute that is a property in some versions and a method in others."""
    v = getattr(obj, name, default)
    return v() if callable(v) else v


def _metres(T: np.ndarray) -> np.ndarray:
    """A metadata transform (translation in mm) in metres."""
    T = np.array(T, dtype=np.float64).reshape(4, 4)
    T[:3, 3] *= 1e-3
    return T


def frame_to_cloud_fields(frame: Any, info: Any, xyz_lut: Any,
                          T_lidar_sensor: np.ndarray) -> tuple[int, dict[str, np.ndarray]]:
    """A LidarFrame -> (stamp [ns], destaggered ``H x W`` arrays: x, y, z [m, os_lidar; NaN
    without return], t [ns from stamp], range [mm], reflectivity, ambient, intensity, ring)."""
    from ouster.sdk import core

    rng = np.asarray(frame.field("RANGE"), dtype=np.uint32)
    xyz = np.asarray(xyz_lut(frame), dtype=np.float64)  # os_sensor, m, staggered
    xyz = xyz @ T_lidar_sensor[:3, :3].T + T_lidar_sensor[:3, 3]
    xyz[rng == 0] = np.nan
    ts = np.asarray(frame.timestamp, dtype=np.int64)
    status = np.asarray(frame.status) if hasattr(frame, "status") else np.ones_like(ts)
    valid = (ts > 0) & (status.astype(np.int64) & 1 == 1)
    if not valid.any():
        raise ValueError("frame has no valid column")
    stamp = int(ts[valid].min())
    t = np.clip(ts - stamp, 0, None).astype(np.uint32)
    t_img = np.broadcast_to(t[None, :], rng.shape)
    xyz[:, ~valid] = np.nan
    rng = np.where(valid[None, :], rng, 0).astype(np.uint32)

    def field(*names: str, dtype=np.uint16) -> np.ndarray:
        for n in names:
            if frame.has_field(n):
                return np.asarray(frame.field(n)).astype(dtype)
        return np.zeros(rng.shape, dtype=dtype)

    staggered = {"x": xyz[..., 0], "y": xyz[..., 1], "z": xyz[..., 2], "t": t_img,
                 "range": rng, "reflectivity": field("REFLECTIVITY"),
                 "ambient": field("NEAR_IR"),
                 "intensity": field("SIGNAL", dtype=np.float32)}
    out = {k: np.asarray(core.destagger(info, np.ascontiguousarray(v))) for k, v in
           staggered.items()}
    out["ring"] = np.broadcast_to(np.arange(rng.shape[0], dtype=np.uint16)[:, None], rng.shape)
    return stamp, out


def cloud_message(stamp_ns: int, fields: dict[str, np.ndarray], layout: str = "original",
                  frame_id: str = "os_lidar", factory: Any = None) -> Any:
    """The ouster-ros ``PointCloud2`` (rosbags message) of :func:`frame_to_cloud_fields`'s
    arrays in ``layout`` (:data:`LAYOUTS`); padding bytes are zero."""
    from lili_odom.bagio.factory import RosbagsFactory

    if layout not in LAYOUTS:
        raise ValueError(f"unknown ouster-ros layout {layout!r} (one of {', '.join(LAYOUTS)})")
    f = factory or RosbagsFactory()
    step, spec = LAYOUTS[layout]
    h, w = fields["range"].shape
    dtype = np.dtype({"names": [n for n, *_ in spec], "formats": [t for _, _, t, _ in spec],
                      "offsets": [o for _, o, _, _ in spec], "itemsize": step})
    rec = np.zeros((h, w), dtype=dtype)
    for name, *_ in spec:
        rec[name] = fields[name]
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    header = f.new("std_msgs/msg/Header",
                   stamp=f.new("builtin_interfaces/msg/Time", sec=sec, nanosec=nsec),
                   frame_id=frame_id)
    point_fields = [f.new("sensor_msgs/msg/PointField", name=n, offset=o, datatype=d, count=1)
                    for n, o, _, d in spec]
    return f.new("sensor_msgs/msg/PointCloud2", header=header, height=h, width=w,
                 fields=point_fields, is_bigendian=False, point_step=step, row_step=step * w,
                 data=np.frombuffer(rec.tobytes(), dtype=np.uint8), is_dense=False)


@dataclass
class RecordingMessage:
    """One message of a recording, as the bag reader yields them (``topic``, ``stamp`` [s],
    ``msgtype``, ``msg``)."""

    topic: str
    stamp: float
    msgtype: str
    msg: Any


class OusterRecording:
    """An Ouster ``.pcap`` (with its metadata ``.json``) or ``.osf`` recording.

    Iterating yields :class:`RecordingMessage` in stamp order: each cloud at the end of its
    sweep's IMU samples (as a driver publishes it), IMU samples as recorded. Use as a context
    manager.

    Raises:
        UserError: SDK missing, unreadable file or metadata.
    """

    def __init__(self, path: str | Path, metadata: str | Path | None = None,
                 layout: str = "original", lidar_topic: str = LIDAR_TOPIC,
                 imu_topic: str = IMU_TOPIC) -> None:
        self.path = Path(path)
        self.metadata = Path(metadata) if metadata else None
        if layout not in LAYOUTS:
            raise UserError(f"unknown ouster-ros layout {layout!r}")
        self.layout = layout
        self.lidar_topic = lidar_topic
        self.imu_topic = imu_topic
        if not self.path.is_file():
            raise UserError(f"{self.path}: no such file")
        if self.path.suffix.lower() == ".pcap" and self.metadata is None:
            raise UserError(f"{self.path}: a .pcap recording needs --metadata META.json")
        if self.metadata is not None and not self.metadata.is_file():
            raise UserError(f"{self.metadata}: no such file")
        sdk = _sdk()
        meta = [str(self.metadata)] if self.metadata else None
        try:
            src = sdk.open_source(str(self.path), meta=meta) if meta else \
                sdk.open_source(str(self.path))
            self.info = src.sensor_info[0]
            src.close()
        except UserError:
            raise
        except Exception as exc:  # noqa: BLE001 - the SDK raises many kinds
            raise UserError(f"{self.path}: cannot open the recording: "
                            f"{type(exc).__name__}: {exc}") from None
        self.T_sensor_lidar = _metres(self.info.lidar_to_sensor_transform)
        self.T_sensor_imu = _metres(self.info.imu_to_sensor_transform)
        fmt = self.info.format
        self.imu_per_frame = int(_value(fmt, "imu_packets_per_frame", 0) or 0)
        self._count: int | None = None

    def __enter__(self) -> "OusterRecording":
        return self

    def __exit__(self, *exc: Any) -> None:
        return None

    @property
    def message_count(self) -> int:
        """Messages in the recording (counted by reading its packets once)."""
        if self._count is None:
            lidar = imu = 0
            src = self._open(packets=True)
            try:
                for item in src:
                    packet = item[1] if isinstance(item, tuple) else item
                    if type(packet).__name__ == "ImuPacket":
                        imu += 1
                    else:
                        lidar += 1
            finally:
                src.close()
            fmt = self.info.format
            per_frame = max(1, int(_value(fmt, "lidar_packets_per_frame", 1)))
            self._count = -(-lidar // per_frame) + imu * max(
                1, int(_value(fmt, "imu_measurements_per_packet", 1) or 1))
        return self._count

    def _open(self, packets: bool) -> Any:
        sdk = _sdk()
        meta = [str(self.metadata)] if self.metadata else None
        opener = sdk.open_packet_source if packets else sdk.open_source
        return opener(str(self.path), meta=meta) if meta else opener(str(self.path))

    def clouds(self) -> Iterator[RecordingMessage]:
        """The clouds, in recording order."""
        from lili_odom.bagio.factory import RosbagsFactory
        from ouster.sdk import core

        f = RosbagsFactory()
        lut = core.XYZLut(self.info)
        T_lidar_sensor = np.linalg.inv(self.T_sensor_lidar)
        src = self._open(packets=False)
        try:
            for item in src:  # one FrameSet (a list of LidarFrames, one per sensor) per step
                frame = item[0] if hasattr(item, "__getitem__") else item
                if frame is None:
                    continue
                try:
                    stamp, fields = frame_to_cloud_fields(frame, self.info, lut, T_lidar_sensor)
                except ValueError:
                    continue
                msg = cloud_message(stamp, fields, self.layout, factory=f)
                yield RecordingMessage(self.lidar_topic, stamp * 1e-9,
                                       "sensor_msgs/msg/PointCloud2", msg)
        finally:
            src.close()

    def imu(self) -> Iterator[RecordingMessage]:
        """The IMU samples (none when the recording has no IMU packets)."""
        from lili_odom.bagio.factory import RosbagsFactory

        f = RosbagsFactory()  # samples stay in os_imu (the SDK's axes); SI units
        src = self._open(packets=True)
        try:
            for item in src:
                packet = item[1] if isinstance(item, tuple) else item
                if type(packet).__name__ != "ImuPacket":
                    continue
                accel = np.asarray(packet.accel(), dtype=np.float64).reshape(-1, 3)
                gyro = np.asarray(packet.gyro(), dtype=np.float64).reshape(-1, 3)
                stamps = np.asarray(packet.gyro_ts(), dtype=np.int64).reshape(-1)
                for a, g, t in zip(accel, gyro, stamps):
                    if t <= 0 or not (np.isfinite(a).all() and np.isfinite(g).all()):
                        continue
                    sec, nsec = divmod(int(t), 1_000_000_000)
                    msg = f.new(
                        "sensor_msgs/msg/Imu",
                        header=f.new("std_msgs/msg/Header",
                                     stamp=f.new("builtin_interfaces/msg/Time", sec=sec,
                                                 nanosec=nsec), frame_id="os_imu"),
                        orientation_covariance=np.r_[-1.0, np.zeros(8)],
                        angular_velocity=f.new("geometry_msgs/msg/Vector3", x=g[0], y=g[1],
                                               z=g[2]),
                        linear_acceleration=f.new("geometry_msgs/msg/Vector3", x=a[0], y=a[1],
                                                  z=a[2]))
                    yield RecordingMessage(self.imu_topic, t * 1e-9, "sensor_msgs/msg/Imu", msg)
        finally:
            src.close()

    def __iter__(self) -> Iterator[RecordingMessage]:
        """Clouds and IMU merged in arrival order: a cloud at its sweep's end (stamp + 0.1 s),
        as a driver publishes it."""
        sweep = 1.0 / max(1, int(_value(self.info.format, "fps", 10) or 10))

        def keyed(it: Iterator[RecordingMessage], delay: float):
            for m in it:
                yield (m.stamp + delay, m.topic, m)

        merged = heapq.merge(keyed(self.clouds(), sweep), keyed(self.imu(), 0.0),
                             key=lambda x: (x[0], x[1]))
        for _, _, m in merged:
            yield m


def sensor_frame_points(path: str | Path, metadata: str | Path | None = None,
                        count: int = 1) -> list[np.ndarray]:
    """The first ``count`` frames of a recording as (N, 3) points [m] in ``os_sensor`` (the
    frame of the SDK's XYZ look-up table and of its reference poses), no-return pixels
    dropped. Raises :class:`~lili_odom.errors.UserError` when the SDK or the file is missing."""
    sdk = _sdk()
    try:
        source = (sdk.open_source(str(path), meta=[str(metadata)]) if metadata
                  else sdk.open_source(str(path)))
        lut = sdk.core.XYZLut(source.sensor_info[0])
        clouds = []
        for frames in source:
            xyz = np.asarray(lut(frames[0].field(sdk.core.ChanField.RANGE))).reshape(-1, 3)
            clouds.append(xyz[np.linalg.norm(xyz, axis=1) > 0])
            if len(clouds) >= count:
                break
    except (OSError, RuntimeError, ValueError) as exc:
        raise UserError(f"{path}: cannot read the recording: {exc}") from None
    return clouds
