"""Feed decoded ROS messages (rosbags or rclpy objects) into an ``OdometryPipeline``.

One place decides what each input topic means, so the offline runner and the node behave the
same: IMU and wheel messages are buffered, ``/tf_static`` sets the extrinsics before the first
scan, clouds are parsed (bad ones are counted and skipped, never raised) and processed.
"""
from __future__ import annotations

import logging
from typing import Any

import numpy as np

from lili_odom import messages
from lili_odom.config import NodeConfig
from lili_odom.pipeline.odometry import OdometryPipeline
from lili_odom.pipeline.types import OdometryOutput

log = logging.getLogger(__name__)


def chain_transform(edges: dict[tuple[str, str], np.ndarray], parent: str, child: str) -> np.ndarray | None:
    """``T_parent_child`` from a set of ``(parent, child) -> T`` edges (either direction)."""
    graph: dict[str, list[tuple[str, np.ndarray]]] = {}
    for (a, b), T in edges.items():
        graph.setdefault(a, []).append((b, T))
        graph.setdefault(b, []).append((a, np.linalg.inv(T)))
    stack = [(parent, np.eye(4))]
    seen = {parent}
    while stack:
        frame, T = stack.pop()
        if frame == child:
            return T
        for nxt, T_edge in graph.get(frame, []):
            if nxt not in seen:
                seen.add(nxt)
                stack.append((nxt, T @ T_edge))
    return None


class MessageFeeder:
    """Dispatch messages by topic to the pipeline (see module docstring)."""

    def __init__(self, pipeline: OdometryPipeline, config: NodeConfig):
        self.pipeline = pipeline
        self.config = config
        self._parse = messages.default_cloud_parser(
            config.pipeline.scan_matcher.min_range, config.pipeline.scan_matcher.max_range)
        self._tf_edges: dict[tuple[str, str], np.ndarray] = {}
        self._lidar_frame: str | None = None
        self._imu_frame: str | None = None
        self._extrinsics_from_tf = False

    def feed(self, topic: str, msg: Any) -> OdometryOutput | None:
        c = self.config
        p = self.pipeline
        try:
            if topic == c.imu_topic:
                self._imu_frame = self._imu_frame or str(msg.header.frame_id)
                p.add_imu(messages.imu_from_msg(msg))
            elif topic == c.wheel_topic:
                p.add_wheel(messages.wheel_from_msg(msg))
            elif topic in ("/tf_static",):
                for parent, child, T in messages.transforms_from_tf_msg(msg):
                    self._tf_edges[(parent, child)] = T
            elif topic == c.lidar_topic:
                return self._scan(msg)
        except (ValueError, AttributeError, TypeError) as exc:
            p.counters[f"bad_message{topic.replace('/', '_')}"] += 1
            log.warning("bad message on %s skipped: %s", topic, exc)
        return None

    def _maybe_set_extrinsics(self, lidar_frame: str) -> None:
        if self._extrinsics_from_tf or not self.config.extrinsics.use_tf_static or not self._tf_edges:
            return
        base = self.config.base_frame
        T_bl = chain_transform(self._tf_edges, base, lidar_frame)
        T_bi = chain_transform(self._tf_edges, base, self._imu_frame or "os_imu")
        if T_bl is None:
            log.warning("no /tf_static chain %s -> %s; using configured extrinsics", base, lidar_frame)
            return
        if T_bi is None:
            T_bi = self.config.pipeline.fusion.T_base_imu
        self.pipeline.set_extrinsics(T_bl, T_bi)
        self._extrinsics_from_tf = True
        log.info("extrinsics from /tf_static: %s -> %s", base, lidar_frame)

    def _scan(self, msg: Any) -> OdometryOutput | None:
        try:
            scan = messages.scan_from_msg(msg, self._parse)
        except ValueError as exc:
            self.pipeline.counters["bad_clouds"] += 1
            log.warning("cloud skipped: %s", exc)
            return None
        if not self._extrinsics_from_tf and not self.pipeline.estimator.initialized:
            self._maybe_set_extrinsics(scan.frame_id)
        return self.pipeline.process_scan(scan)
