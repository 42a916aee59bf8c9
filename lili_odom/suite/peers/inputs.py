"""A bag's inputs as the peers need them: parsed scans, IMU samples, wheel poses, the truth
and the extrinsics, read once in header-stamp order with the project's bag reader.

Scans are parsed by :func:`lili_odom.pointcloud2.parse_cloud`: points (N, 3) [m] in the
cloud's frame (``os_lidar``) and per-point times [s] relative to ``header.stamp`` (None when
the cloud has none). Extrinsics come from the bag's ``/tf_static`` (chain ``base_link`` ->
cloud frame / IMU frame), else from the configuration (:class:`lili_odom.config.ExtrinsicsConfig`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from lili_odom.config import NodeConfig

log = logging.getLogger(__name__)


@dataclass
class ParsedScan:
    stamp: float  # header.stamp [s]
    frame_id: str
    points: np.ndarray  # (N, 3) [m], cloud frame
    times: np.ndarray | None  # (N,) [s] relative to stamp

    @property
    def end(self) -> float:
        """Stamp of the sweep's last point [s] (the stamp itself without per-point times)."""
        return self.stamp + (float(self.times.max()) if self.has_times else 0.0)

    @property
    def has_times(self) -> bool:
        return (self.times is not None and len(self.times) == len(self.points)
                and bool(np.all(np.isfinite(self.times))) and float(np.ptp(self.times)) > 0)


@dataclass
class Imu:
    stamp: float
    frame_id: str
    acceleration: np.ndarray  # m/s^2, IMU frame
    angular_velocity: np.ndarray  # rad/s, IMU frame


@dataclass
class Wheel:
    stamp: float
    pose: np.ndarray  # base_link in the wheel odometry frame


@dataclass
class Truth:
    stamp: float
    pose: np.ndarray  # base_link in the world


@dataclass
class Extrinsics:
    """Mounting of the sensors on base_link; the bag's ``/tf_static`` wins over the config."""

    config: NodeConfig
    edges: dict[tuple[str, str], np.ndarray] = field(default_factory=dict)

    def add_tf(self, msg: Any) -> None:
        from lili_odom.messages import transforms_from_tf_msg

        for parent, child, T in transforms_from_tf_msg(msg):
            self.edges[(parent, child)] = T

    def T_base(self, frame: str, fallback: np.ndarray) -> np.ndarray:
        from lili_odom.pipeline.feeder import chain_transform

        if self.config.extrinsics.use_tf_static and self.edges:
            T = chain_transform(self.edges, self.config.base_frame, frame)
            if T is not None:
                return T
        return np.asarray(fallback, dtype=float)

    def T_base_lidar(self, frame: str = "os_lidar") -> np.ndarray:
        return self.T_base(frame, self.config.extrinsics.T_base_lidar())

    def T_base_imu(self, frame: str = "os_imu") -> np.ndarray:
        return self.T_base(frame, self.config.extrinsics.T_base_imu())


@dataclass
class Context:
    """What a peer gets besides the bag: the configuration (topics, extrinsics defaults,
    ground-truth topic) and the kind of scene (for presets chosen by scene)."""

    config: NodeConfig
    kind: str = ""
    truth_topic: str = "/ground_truth/odom"
    threads: int = 0  # native threads (0: the library's default)


@dataclass
class PeerRun:
    """A peer's result: base_link poses in its odometry frame, the truth read on the way."""

    stamps: np.ndarray
    poses: np.ndarray
    truth_stamps: np.ndarray
    truth_poses: np.ndarray
    scans: int
    wall_s: float
    degenerate_fraction: float | None = None
    notes: dict = field(default_factory=dict)


def read_inputs(bag: Path | str, ctx: Context, *, lidar: bool = True, imu: bool = False,
                wheels: bool = False, extrinsics: Extrinsics | None = None,
                truth: list[Truth] | None = None) -> Iterator[ParsedScan | Imu | Wheel]:
    """Yield the bag's scans / IMU samples / wheel poses in header-stamp order.

    ``/tf_static`` goes into ``extrinsics`` and the truth into ``truth`` (when given) on the
    way; malformed messages are skipped with a warning, as the node does.
    """
    from lili_odom.bagio.reader import BagReader
    from lili_odom.messages import truth_sample
    from lili_odom.pointcloud2 import CloudFormatError, parse_cloud

    c = ctx.config
    topics = ["/tf_static", ctx.truth_topic]
    required = []
    if lidar:
        topics.append(c.lidar_topic)
        required.append(c.lidar_topic)
    if imu:
        topics.append(c.imu_topic)
        required.append(c.imu_topic)
    if wheels:
        topics.append(c.wheel_topic)
        required.append(c.wheel_topic)
    with BagReader(bag, topics=topics, required=required) as reader:
        for item in reader:
            msg = item.msg
            if item.topic == "/tf_static":
                if extrinsics is not None:
                    extrinsics.add_tf(msg)
            elif item.topic == ctx.truth_topic:
                if truth is not None:
                    s = truth_sample(msg)
                    if s is not None:
                        truth.append(Truth(*s))
            elif item.topic == c.lidar_topic:
                try:
                    parsed = parse_cloud(msg, stamp=item.stamp, extra_fields=False)
                except (CloudFormatError, ValueError) as exc:
                    log.warning("cloud at %.3f skipped: %s", item.stamp, exc)
                    continue
                yield ParsedScan(item.stamp, str(msg.header.frame_id),
                                 np.asarray(parsed.xyz, dtype=np.float64), parsed.times)
            elif item.topic == c.imu_topic:
                a, w = msg.linear_acceleration, msg.angular_velocity
                sample = Imu(item.stamp, str(msg.header.frame_id),
                             np.array([a.x, a.y, a.z], dtype=float),
                             np.array([w.x, w.y, w.z], dtype=float))
                if np.isfinite(sample.acceleration).all() and np.isfinite(sample.angular_velocity).all():
                    yield sample
            elif item.topic == c.wheel_topic:
                from lili_odom.messages import odometry_pose_from_msg

                try:
                    stamp, T = odometry_pose_from_msg(msg)
                except (AttributeError, TypeError, ValueError):
                    continue
                if np.isfinite(T).all():
                    yield Wheel(stamp, T)


def truth_arrays(truth: list[Truth]) -> tuple[np.ndarray, np.ndarray]:
    truth = sorted(truth, key=lambda t: t.stamp)
    if not truth:
        return np.zeros(0), np.zeros((0, 4, 4))
    return np.array([t.stamp for t in truth]), np.array([t.pose for t in truth])
