"""Feed decoded ROS messages (rosbags or rclpy objects) into an ``OdometryPipeline``.

One place decides what each input topic means and *when* a scan is processed, so the offline
runner and the node behave the same: IMU and wheel messages are buffered, ``/tf_static`` sets
the extrinsics before the first scan, clouds are parsed (bad ones are counted and skipped,
never raised) and queued until the IMU and wheel data covering the sweep have arrived.

Why scans wait: ouster-ros stamps a cloud at the *start* of its sweep, and the pipeline needs
IMU (and wheel) samples up to the sweep's *end* to predict the pose, deskew and form the IMU
factor. Read in header-stamp order (a bag) the cloud comes ~0.1 s before those samples; live,
topics can arrive slightly out of order. A pending scan is processed as soon as every
auxiliary stream has a sample at or after the sweep end, or the stream is considered absent
(its newest sample is more than ``sensor_wait_s`` older than the sweep end, or it never
sent anything), or any input has moved ``sensor_wait_s`` past the sweep end (a stalled
stream), or ``max_pending_scans`` are waiting. ``flush()`` processes whatever still waits
(end of a bag, or the node's wall-clock timeout).
"""
from __future__ import annotations

import logging
from collections import deque
from typing import Any

import numpy as np

from lili_odom import messages
from lili_odom.config import NodeConfig
from lili_odom.pipeline.odometry import OdometryPipeline
from lili_odom.pipeline.types import OdometryOutput, Scan

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


def sweep_end(scan: Scan, default_sweep_s: float) -> float:
    """Stamp [s] of the last point of ``scan`` (stamp + sweep length without per-point times)."""
    t = scan.times
    if t is not None and len(t) and np.all(np.isfinite(t)):
        return scan.stamp + float(np.max(t))
    return scan.stamp + default_sweep_s


class ParsedAhead:
    """A cloud message already parsed (:meth:`MessageFeeder.parse_ahead`, e.g. by a thread
    reading a bag ahead of the pipeline). Fed on the LiDAR topic in place of the message, it
    is queued, or its error counted, exactly as the message would have been."""

    __slots__ = ("_scan", "_error")

    def __init__(self, scan: Scan | None, error: Exception | None) -> None:
        self._scan, self._error = scan, error

    def result(self) -> Scan:
        """The parsed scan; raises what parsing the message raised."""
        if self._error is not None:
            raise self._error
        return self._scan


class MessageFeeder:
    """Dispatch messages by topic to the pipeline (see module docstring).

    ``feed`` and ``flush`` return the outputs of every scan processed by that call, oldest
    first (a scan can be released by a later IMU or wheel message).
    """

    def __init__(self, pipeline: OdometryPipeline, config: NodeConfig):
        self.pipeline = pipeline
        self.config = config
        matcher = config.pipeline.scan_matcher
        self._parse = messages.default_cloud_parser(matcher.min_range, matcher.max_range,
                                                    stride=matcher.point_stride)
        self._tf_edges: dict[tuple[str, str], np.ndarray] = {}
        self._lidar_frame: str | None = None
        self._imu_frame: str | None = None
        self._extrinsics_from_tf = False
        self._pending: deque[tuple[float, Scan]] = deque()
        self._newest_input = -np.inf
        self.processed = 0  # scans handed to the pipeline

    def restart(self) -> None:
        """Forget the input clock and waiting scans (after a pipeline reset on a clock jump)."""
        self._pending.clear()
        self._newest_input = -np.inf

    def _count(self, name: str) -> None:
        counters = self.pipeline.counters
        counters[name] = counters.get(name, 0) + 1

    @property
    def pending(self) -> int:
        """Scans parsed and waiting for their IMU/wheel data."""
        return len(self._pending)

    def feed(self, topic: str, msg: Any) -> list[OdometryOutput]:
        c = self.config
        p = self.pipeline
        try:
            if topic == c.imu_topic:
                self._imu_frame = self._imu_frame or str(msg.header.frame_id)
                sample = messages.imu_from_msg(msg)
                p.add_imu(sample)
                self._saw(sample.stamp)
            elif topic == c.wheel_topic:
                sample = messages.wheel_from_msg(msg)
                p.add_wheel(sample)
                self._saw(sample.stamp)
            elif topic in ("/tf_static",):
                for parent, child, T in messages.transforms_from_tf_msg(msg):
                    self._tf_edges[(parent, child)] = T
            elif topic == c.lidar_topic:
                self._queue_scan(msg)
        except (ValueError, AttributeError, TypeError) as exc:
            self._count(f"bad_message{topic.replace('/', '_')}")
            log.warning("bad message on %s skipped: %s", topic, exc)
        return self._release(force=False)

    def flush(self) -> list[OdometryOutput]:
        """Process every waiting scan now, with whatever IMU/wheel data there is."""
        return self._release(force=True)

    def _saw(self, stamp: float) -> None:
        if np.isfinite(stamp):
            self._newest_input = max(self._newest_input, float(stamp))

    def parse_ahead(self, msg: Any) -> ParsedAhead:
        """``msg`` (a cloud) parsed now, to be fed later in its place. Depends on the
        configuration only, so another thread may call it while this one feeds."""
        try:
            return ParsedAhead(messages.scan_from_msg(msg, self._parse), None)
        except Exception as exc:  # noqa: BLE001 - raised again when fed, handled there
            return ParsedAhead(None, exc)

    def _queue_scan(self, msg: Any) -> None:
        try:
            if isinstance(msg, ParsedAhead):
                scan = msg.result()
            else:
                scan = messages.scan_from_msg(msg, self._parse)
        except ValueError as exc:
            self._count("bad_clouds")
            log.warning("cloud skipped: %s", exc)
            return
        end = sweep_end(scan, self.config.pipeline.sweep_duration)
        if not np.isfinite(end):
            end = scan.stamp
        if scan.stamp < self._newest_input - 1.0:  # clock jumped back (bag loop): new clock
            self._newest_input = -np.inf
        self._pending.append((end, scan))
        self._saw(scan.stamp)

    def _ready(self, end: float) -> bool:
        wait = self.config.pipeline.sensor_wait_s
        if self._newest_input >= end + wait:
            return True
        est = getattr(self.pipeline, "estimator", None)
        if est is None:  # a pipeline without sensor buffers: nothing to wait for
            return True
        streams = [est.wheels.newest_time]
        if est.config.use_imu:
            streams.append(est.imu.newest_time)
        return all(t is None or t >= end or t < end - wait for t in streams)

    def _release(self, force: bool) -> list[OdometryOutput]:
        outputs: list[OdometryOutput] = []
        limit = self.config.pipeline.max_pending_scans
        while self._pending:
            end, scan = self._pending[0]
            if not (force or len(self._pending) > limit or self._ready(end)):
                break
            self._pending.popleft()
            out = self._process(scan)
            if out is not None:
                outputs.append(out)
        return outputs

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

    def _process(self, scan: Scan) -> OdometryOutput | None:
        est = getattr(self.pipeline, "estimator", None)
        if not self._extrinsics_from_tf and est is not None and not est.initialized:
            self._maybe_set_extrinsics(scan.frame_id)
        self.processed += 1
        return self.pipeline.process_scan(scan)
