"""The ``lili_odom`` ROS 2 node: a thin shell around the pure-Python odometry pipeline.

Run: ``lili_odom_node --ros-args --params-file config/lili_odom.yaml [-p use_sim_time:=true]``
(or ``ros2 run lili_odom lili_odom_node ...`` under colcon).

Inputs (sensor-data QoS, best effort, so any publisher matches; ``reliable_inputs: true``
subscribes RELIABLE instead, for lossless replays from a reliable publisher such as
``lili-odom play``; topics are parameters):
``lidar_topic`` (``/ouster/points``, PointCloud2, taken as its serialised bytes and decoded
by rosbags, which reads the point buffer in place instead of copying it into an rclpy message,
or by rclpy when rosbags does not read its encoding: :mod:`lili_odom.ros.cloud_decode`,
docs/ros.md "Latency"; a cloud that decodes with neither is counted in
``undecodable_clouds`` and logged), ``imu_topic`` (``/ouster/imu``, Imu),
``wheel_topic`` (``/platform/odom``, Odometry), and ``/tf_static`` when
``extrinsics.use_tf_static`` is true and ``tf2_msgs`` is importable: when it links
``base_frame`` to the cloud's frame before the first scan, it replaces the configured
extrinsics. Without tf2_msgs (the pip ROS stack) the extrinsics parameters rule.

Outputs (node name ``lili_odom``): ``~/odometry`` (Odometry, ``odom_frame`` -> ``base_frame``,
every processed scan), ``~/path`` (Path, every ``path_period`` s of stamp time, at most
``path_max_poses`` poses, evenly thinned), ``~/map`` (PointCloud2 of the local map in
``odom_frame``, reliable + transient-local depth 1, every ``map_publish_period_s`` s of stamp
time), ``~/degeneracy`` (MarkerArray,
see :func:`lili_odom.messages.degeneracy_markers`), ``~/degeneracy/basis`` (JSON String, see
:func:`lili_odom.messages.degeneracy_basis_dict`), ``/tf`` (``odom_frame`` -> ``base_frame``,
or the inverse with ``publish_tf_inverse``) when ``publish_tf`` is true and ``tf2_msgs`` is
importable, and ``/diagnostics`` (DiagnosticArray every ``diagnostics_publish_period`` s of
wall time, statuses from :class:`lili_odom.ros.health.HealthMonitor`).

Service ``~/save_map`` (``std_srvs/srv/Trigger``): writes the accumulated map
(:class:`lili_odom.io.map_file.MapAccumulator`: the local map merged every
``map_accumulate_period_s`` s of stamp time, voxel size ``map_save_voxel``, at most
``map_save_max_points`` points) to ``map_save_path`` (``.pcd`` / ``.ply``); the answer's
``message`` is the absolute path written, or the error with ``success`` false.

Missing scans: a gap between consecutive scan stamps longer than 1.5 periods of
``lidar_rate_hz`` counts the scans lost before the node (``scans_missing``, logged, in
``/diagnostics``); DDS: ``main`` loads the package's Fast DDS profile unless the environment
chose one (:mod:`lili_odom.ros.dds`, docs/ros.md).

Threading: callbacks run on a single-threaded executor and only buffer (IMU, wheel,
``/tf_static``) or hand over (scans), so they are never starved by processing. One worker
thread owns the pipeline and feeds it through the same
:class:`lili_odom.pipeline.feeder.MessageFeeder` as the offline runner, so a scan is
processed with exactly the IMU/wheel data the runner would use: it waits until the samples
covering its sweep end have arrived (at most ``pipeline.sensor_wait_s`` of stamp time, or the
same in wall time when the other inputs fall silent); meanwhile each IMU or wheel message
wakes the worker to feed it. The pipeline runs its degeneracy
detector in a child process (``pipeline.detection_schedule.background``), stopped at
shutdown, and builds the next scan's plane-fit k-d tree in a thread of its own.

Scan-drop policy: the cloud subscription keeps ``scan_subscription_depth`` samples, so clouds
arriving while the executor is busy still reach the callback, which only queues them. At most
``scan_queue_size`` scans wait while another is processed (default 3, 0.3 s at 10 Hz: a short
hiccup of the worker loses nothing). When the queue is full, a new scan pushes out the OLDEST
waiting one, which is dropped, counted (``scans_dropped``) and logged (throttled to once per
5 s). Latency therefore stays below about ``scan_queue_size + 1`` scan periods and, when the
pipeline is persistently slower than the LiDAR, the node keeps working on recent data.

Time: all stamps come from the messages' headers; ``use_sim_time`` (standard parameter) only
affects the node clock. When a scan stamp goes back by more than 1 s (a bag restarted), the
pipeline and the path are reset.

Latency: for every published odometry the node records its clock (ROS time) at publication
minus the scan's sweep end (the output's stamp: ``header.stamp`` + the sweep duration,
:mod:`lili_odom.ros.latency`); p50 / p99 / max over the last 1000 scans are in the
``processing time`` status of ``/diagnostics`` and, with the run's count and maximum, in
:meth:`LiliOdomNode.diagnostics` (logged every ``diagnostics_period`` s and at shutdown).

Not driven by the node: ``ground_truth_topic`` (offline evaluation only).

Parameters: the provider's (``lili_odom.config.NodeConfig``'s dotted names, as in
``config/lili_odom.yaml`` and ``config/lili_odom_advanced.yaml``) plus :data:`NODE_PARAMETERS`; all are declared with dynamic typing
and validated by the provider, so a bad value stops the node with a one-line error.
"""
from __future__ import annotations

import array
import json
import sys
import threading
import time
from typing import Any, Callable, Mapping

import numpy as np
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy)
from rcl_interfaces.msg import ParameterDescriptor

from lili_odom import messages as M
from lili_odom.config import coerce_parameter
from lili_odom.io.map_file import MapAccumulator, save_points
from lili_odom.pipeline.feeder import MessageFeeder
from lili_odom.pipeline.types import OdometryOutput
from lili_odom.ros.cloud_decode import CloudDecoder, UndecodableCloud
from lili_odom.ros.dds import apply_dds_defaults
from lili_odom.ros.factory import MessageTypeError, RclpyFactory, message_class
from lili_odom.ros.health import HealthConfig, HealthMonitor
from lili_odom.ros.provider import OdometryPipelineProvider, PipelineLike, PipelineProvider
from lili_odom.ros.queues import SampleBuffer, ScanQueue

__all__ = ["LiliOdomNode", "NODE_PARAMETERS", "main", "parameters_from_mapping"]

#: Parameters the node itself reads, with fallback defaults for providers that do not declare
#: them; all are ``lili_odom.config.NodeConfig`` fields (the provider's defaults win).
NODE_PARAMETERS: dict[str, Any] = {
    "lidar_topic": "/ouster/points",
    "imu_topic": "/ouster/imu",
    "wheel_topic": "/platform/odom",
    "odom_frame": "lili_odom",
    "base_frame": "base_link",
    "publish_tf": True,
    "map_publish_period_s": 2.0,
    "path_max_poses": 5000,
    "extrinsics.use_tf_static": True,
    "path_period": 1.0,
    "diagnostics_period": 10.0,
    "marker_arrow_length": 2.0,
    "scan_queue_size": 3,
    "scan_subscription_depth": 10,
    "reliable_inputs": False,
    "diagnostics_publish_period": 1.0,
    "lidar_rate_hz": 10.0,
    "imu_rate_hz": 100.0,
    "wheel_rate_hz": 50.0,
    "map_save_path": "lili_odom_map.pcd",
    "map_save_voxel": 0.2,
    "map_save_max_points": 5000000,
    "map_accumulate_period_s": 1.0,
    "publish_tf_inverse": False,
    "detection_max_wait_s": 0.02,
}


def _sensor_qos(depth: int, reliable: bool = False) -> QoSProfile:
    """Sensor-data QoS (best effort, volatile), or RELIABLE for lossless replays."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.RELIABLE if reliable
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=DurabilityPolicy.VOLATILE)


def _reliable_qos(depth: int, latched: bool = False) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                  else DurabilityPolicy.VOLATILE))


def _ros_value(value: Any) -> Any:
    """A value rclpy can declare (lists made homogeneous; empty lists become unset)."""
    if isinstance(value, (list, tuple)):
        if not value:
            return None
        if all(isinstance(v, bool) for v in value):
            return list(value)
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            return [float(v) for v in value] if any(isinstance(v, float) for v in value) \
                else [int(v) for v in value]
        if all(isinstance(v, str) for v in value):
            return list(value)
        return json.dumps(value)
    return value


class LiliOdomNode(Node):
    """See the module docstring.

    Args:
        provider: source of parameter defaults and the pipeline (default: the real pipeline).
        **kwargs: passed to ``rclpy.node.Node`` (e.g. ``context``, ``parameter_overrides``).
    """

    def __init__(self, provider: PipelineProvider | None = None, **kwargs: Any) -> None:
        super().__init__("lili_odom", **kwargs)
        self._provider = provider or OdometryPipelineProvider()
        self._factory = RclpyFactory()
        self.p = self._declare_parameters()
        self.pipeline: PipelineLike = self._provider.create(dict(self.p))
        self.config = OdometryPipelineProvider().node_config(self.p)
        self._feeder = MessageFeeder(self.pipeline, self.config)
        start = getattr(self.pipeline, "start", None)
        if callable(start):
            start()  # the background detector process starts before the first scan arrives

        self.counters: dict[str, int] = {
            "scans_received": 0, "scans_processed": 0, "scans_dropped": 0,
            "scans_no_output": 0, "scan_errors": 0, "imu_received": 0, "wheel_received": 0,
            "resets": 0, "scans_missing": 0, "undecodable_clouds": 0,
        }
        self.health = HealthMonitor(HealthConfig(lidar_hz=float(self.p["lidar_rate_hz"]),
                                                 imu_hz=float(self.p["imu_rate_hz"]),
                                                 wheel_hz=float(self.p["wheel_rate_hz"])))
        self.map = MapAccumulator(float(self.p["map_save_voxel"]),
                                  int(self.p["map_save_max_points"]))
        self._map_lock = threading.Lock()
        self._map_requests: list[threading.Event] = []  # served by the worker
        self._last_accumulate_stamp = -float("inf")
        self._processing_time = 0.0
        self._scans = ScanQueue(int(self.p["scan_queue_size"]))
        self._inputs = SampleBuffer(maxlen=30000)  # (topic, msg): IMU, wheel, /tf_static
        self._pending_since: float | None = None
        # PoseStamped of each published T_odom_base, built once when it is published
        self._path: list[Any] = []
        self._last_stamp = -float("inf")
        self._last_path_stamp = -float("inf")
        self._last_map_stamp = -float("inf")

        odom_frame = self.p["odom_frame"]
        self.get_logger().info(f"odometry frame {odom_frame!r} -> {self.p['base_frame']!r}")
        self.pub_odom = self.create_publisher(message_class("nav_msgs/msg/Odometry"),
                                              "~/odometry", _reliable_qos(10))
        self.pub_path = self.create_publisher(message_class("nav_msgs/msg/Path"), "~/path",
                                              _reliable_qos(1))
        self.pub_map = self.create_publisher(message_class("sensor_msgs/msg/PointCloud2"),
                                             "~/map", _reliable_qos(1, latched=True))
        self.pub_markers = self.create_publisher(
            message_class("visualization_msgs/msg/MarkerArray"), "~/degeneracy",
            _reliable_qos(5))
        self.pub_basis = self.create_publisher(message_class("std_msgs/msg/String"),
                                               "~/degeneracy/basis", _reliable_qos(10))
        self.pub_tf = None
        tf_cls = self._optional_class("tf2_msgs/msg/TFMessage")
        if self.p["publish_tf"]:
            if tf_cls is None:
                self.get_logger().warn("publish_tf is true but tf2_msgs is not installed: "
                                       "no /tf output")
            else:
                self.pub_tf = self.create_publisher(tf_cls, "/tf", _reliable_qos(100))

        reliable = bool(self.p["reliable_inputs"])
        self._decode = CloudDecoder()
        self.create_subscription(message_class("sensor_msgs/msg/PointCloud2"),
                                 self.p["lidar_topic"], self._on_scan,
                                 _sensor_qos(int(self.p["scan_subscription_depth"]), reliable),
                                 raw=True)
        self.create_subscription(message_class("sensor_msgs/msg/Imu"), self.p["imu_topic"],
                                 self._on_imu, _sensor_qos(200, reliable))
        self.create_subscription(message_class("nav_msgs/msg/Odometry"), self.p["wheel_topic"],
                                 self._on_wheel, _sensor_qos(100, reliable))
        if self.p["extrinsics.use_tf_static"]:
            if tf_cls is None:
                self.get_logger().info("tf2_msgs is not installed: extrinsics come from the "
                                       "parameters, not /tf_static")
            else:
                self.create_subscription(tf_cls, "/tf_static", self._on_tf_static,
                                         _reliable_qos(100, latched=True))

        self.pub_diagnostics = self.create_publisher(
            message_class("diagnostic_msgs/msg/DiagnosticArray"), "/diagnostics",
            _reliable_qos(10))
        self._hardware_id = f"{self.get_namespace().rstrip('/')}/{self.get_name()}"
        diag_period = float(self.p["diagnostics_publish_period"])
        if diag_period > 0:
            self.create_timer(diag_period, self.publish_diagnostics,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.create_service(message_class("std_srvs/srv/Trigger"), "~/save_map",
                            self._on_save_map)
        period = float(self.p["diagnostics_period"])
        if period > 0:
            self.create_timer(period, self._log_diagnostics,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._stop = threading.Event()
        self._summary_logged = False
        self._worker = threading.Thread(target=self._work, name="lili_odom_worker", daemon=True)
        self._worker.start()

    # -- parameters ----------------------------------------------------------------------

    def _declare_parameters(self) -> dict[str, Any]:
        descriptor = ParameterDescriptor(dynamic_typing=True)
        defaults = dict(NODE_PARAMETERS)
        defaults.update(self._provider.parameter_defaults())
        values: dict[str, Any] = {}
        for name, value in defaults.items():
            self.declare_parameter(name, _ros_value(value), descriptor)
            got = self.get_parameter(name).value
            if isinstance(got, (array.array, tuple)):
                got = list(got)
            if name in NODE_PARAMETERS and got is not None:
                got = coerce_parameter(name, got, NODE_PARAMETERS[name])
            values[name] = got
        return values


    def _optional_class(self, typename: str) -> type | None:
        try:
            return message_class(typename)
        except MessageTypeError:
            return None

    # -- callbacks (cheap) ---------------------------------------------------------------

    def _on_scan(self, msg: Any) -> None:
        """A cloud: its serialised bytes (decoded here) or a message object."""
        self.counters["scans_received"] += 1
        if isinstance(msg, (bytes, bytearray, memoryview)):
            msg = self._decode_cloud(msg)
            if msg is None:
                return
        try:
            missing = self.health.on_scan(M.stamp_seconds(msg.header))
        except (AttributeError, TypeError, ValueError):
            missing = 0
        if missing:
            self.counters["scans_missing"] += missing
            self.get_logger().warn(
                f"{missing} scan(s) missing before stamp {M.stamp_seconds(msg.header):.3f} "
                f"({self.counters['scans_missing']} so far): lost between the LiDAR driver "
                "and this node (see docs/ros.md, DDS profile)", throttle_duration_sec=5.0)
        if self._scans.put(msg):
            self.counters["scans_dropped"] = self._scans.dropped
            self.health.on_dropped()
            self.get_logger().warn(
                f"processing slower than the LiDAR: dropped {self._scans.dropped} older "
                f"scan(s) so far (at most {self._scans.maxlen} scans wait; the oldest goes)",
                throttle_duration_sec=5.0)

    def _decode_cloud(self, raw: bytes) -> Any | None:
        """The serialised cloud decoded (:class:`lili_odom.ros.cloud_decode.CloudDecoder`), or
        None, counted and logged, when it does not decode."""
        try:
            return self._decode(raw)
        except UndecodableCloud as exc:
            self.counters["undecodable_clouds"] += 1
            self.get_logger().warn(f"cloud skipped: it does not decode as a PointCloud2 ({exc})",
                                   throttle_duration_sec=5.0)
            return None

    def _on_imu(self, msg: Any) -> None:
        self.counters["imu_received"] += 1
        self.health.on_imu()
        self._inputs.append((self.p["imu_topic"], msg))
        self._wake_if_waiting()

    def _on_wheel(self, msg: Any) -> None:
        self.counters["wheel_received"] += 1
        self.health.on_wheel()
        self._inputs.append((self.p["wheel_topic"], msg))
        self._wake_if_waiting()

    def _wake_if_waiting(self) -> None:
        """A scan waits for the samples covering its sweep: let the worker feed this one."""
        if self._feeder.pending:
            self._scans.wake()

    def _on_tf_static(self, msg: Any) -> None:
        for parent, child, T in M.transforms_from_tf_msg(msg):
            self.get_logger().info(f"/tf_static {parent} -> {child}: t = "
                                   f"{np.round(T[:3, 3], 4).tolist()} m")
        self._inputs.append(("/tf_static", msg))

    # -- worker --------------------------------------------------------------------------

    def _work(self) -> None:
        wait_wall = float(self.config.pipeline.sensor_wait_s)
        while not self._stop.is_set():
            msg = self._scans.take(timeout=0.01 if self._feeder.pending else 0.2)
            t0 = time.perf_counter()
            try:
                self._step(msg, wait_wall)
            except Exception as exc:  # noqa: BLE001 - one bad scan must not stop the node
                self.counters["scan_errors"] += 1
                self.get_logger().error(f"scan processing failed: {type(exc).__name__}: {exc}",
                                        throttle_duration_sec=5.0)
            self._processing_time += time.perf_counter() - t0
            self._serve_map_requests()

    def _step(self, msg: Any, wait_wall: float) -> None:
        """Feed the buffered inputs, then the scan (if any); publish what comes out."""
        feeder = self._feeder
        t_step = time.perf_counter()
        before = feeder.processed
        outputs = []
        for topic, item in self._inputs.drain():
            outputs += feeder.feed(topic, item)
        if msg is not None:
            stamp = M.stamp_seconds(msg.header)
            if stamp < self._last_stamp - 1.0:
                self.get_logger().warn(f"scan stamp jumped back by {self._last_stamp - stamp:.2f}"
                                       " s: resetting the pipeline")
                self._publish_all(outputs + feeder.flush())
                outputs = []
                self.pipeline.reset()
                feeder.restart()
                self._path.clear()
                self._last_path_stamp = self._last_map_stamp = -float("inf")
                self._last_accumulate_stamp = -float("inf")
                with self._map_lock:
                    self.map.clear()  # a new odometry frame: the old map does not fit it
                self.counters["resets"] += 1
            self._last_stamp = stamp
            outputs += feeder.feed(self.p["lidar_topic"], msg)
        now = time.monotonic()
        if not feeder.pending:
            self._pending_since = None
        elif self._pending_since is None or feeder.processed != before:
            self._pending_since = now
        elif now - self._pending_since > wait_wall:  # the other inputs fell silent
            outputs += feeder.flush()
            self._pending_since = None
        processed = feeder.processed - before
        self.counters["scans_processed"] += processed
        self.counters["scans_no_output"] += processed - len(outputs)
        if processed:
            seconds = (time.perf_counter() - t_step) / processed
            for k in range(processed):
                self.health.on_processed(seconds, outputs[k] if k < len(outputs) else None)
            self.health.on_pipeline_counters(dict(getattr(self.pipeline, "counters", {}) or {}))
        self._publish_all(outputs)

    def _publish_all(self, outputs: list[OdometryOutput]) -> None:
        for out in outputs:
            self._publish(out)

    def _publish(self, out: OdometryOutput) -> None:
        f, p = self._factory, self.p
        frame = p["odom_frame"]
        self.pub_odom.publish(M.odometry_msg(f, out, frame, p["base_frame"]))
        self.health.on_published(self.get_clock().now().nanoseconds * 1e-9 - float(out.stamp))
        self.pub_markers.publish(M.degeneracy_markers(f, out, frame,
                                                      float(p["marker_arrow_length"])))
        self.pub_basis.publish(M.degeneracy_json_msg(f, out))
        if self.pub_tf is not None:
            if p["publish_tf_inverse"]:
                tf = (out.stamp, p["base_frame"], frame, np.linalg.inv(out.pose))
            else:
                tf = (out.stamp, frame, p["base_frame"], out.pose)
            self.pub_tf.publish(M.tf_message(f, [tf]))
        self._path.append(M.pose_stamped_msg(f, out.stamp, out.pose, frame))
        if out.stamp - self._last_path_stamp >= float(p["path_period"]):
            from lili_odom.bagio.writer import thin_poses

            poses = thin_poses(self._path, int(p["path_max_poses"]))
            self.pub_path.publish(M.path_of(f, poses, frame, out.stamp))
            self._last_path_stamp = out.stamp
        if len(self._path) > 4 * int(p["path_max_poses"]):  # bound memory on long runs
            from lili_odom.bagio.writer import thin_poses

            self._path = thin_poses(self._path, 2 * int(p["path_max_poses"]))
        points = None
        if out.stamp - self._last_map_stamp >= float(p["map_publish_period_s"]):
            points = np.asarray(self.pipeline.local_map_points(), dtype=np.float64)
            self.pub_map.publish(M.pointcloud_xyz_msg(f, points, out.stamp, frame))
            self._last_map_stamp = out.stamp
        if out.stamp - self._last_accumulate_stamp >= float(p["map_accumulate_period_s"]):
            self._accumulate_map(points)
            self._last_accumulate_stamp = out.stamp

    # -- the saved map -------------------------------------------------------------------

    def _accumulate_map(self, points: np.ndarray | None = None) -> None:
        """Merge the local map (odometry frame, fused poses) into the saved map."""
        if points is None:
            points = np.asarray(self.pipeline.local_map_points(), dtype=np.float64)
        with self._map_lock:
            coarsened = self.map.coarsened
            self.map.add(points)
            if self.map.coarsened != coarsened:
                self.get_logger().warn(
                    f"saved map reached map_save_max_points ({self.map.max_points}): voxel "
                    f"size now {self.map.voxel_size:.3f} m")

    def _serve_map_requests(self) -> None:
        """Worker thread: merge the current local map for waiting ``save_map`` calls (only
        the worker touches the pipeline)."""
        with self._map_lock:
            requests, self._map_requests = self._map_requests, []
        if requests:
            try:
                self._accumulate_map()
            finally:
                for done in requests:
                    done.set()

    def save_map(self, path: str | None = None, wait_s: float = 2.0) -> str:
        """Write the accumulated map to ``path`` (default: parameter ``map_save_path``);
        returns the absolute path. The worker first merges the current local map (waited for
        up to ``wait_s``; a worker busy longer leaves the map as of its last merge).
        Raises ValueError / OSError."""
        done = threading.Event()
        with self._map_lock:
            self._map_requests.append(done)
        if self._worker.is_alive():
            done.wait(wait_s)
        with self._map_lock:
            points = self.map.points()
        return str(save_points(path or self.p["map_save_path"], points))

    def _on_save_map(self, request: Any, response: Any) -> Any:
        try:
            response.message = self.save_map()
            response.success = True
            self.get_logger().info(f"map saved: {response.message} ({len(self.map)} points)")
        except Exception as exc:  # noqa: BLE001 - a failed save answers, never kills the node
            response.success = False
            response.message = f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"save_map failed: {response.message}")
        return response

    # -- diagnostics and shutdown --------------------------------------------------------

    def diagnostics(self) -> dict[str, Any]:
        """Node counters plus the pipeline's counters (prefixed ``pipeline.``)."""
        out: dict[str, Any] = dict(self.counters)
        out["scans_dropped"] = self._scans.dropped
        out["input_overflow"] = self._inputs.overflow
        out["scans_waiting"] = self._feeder.pending
        out["scans_queued"] = len(self._scans)  # handed over, not yet taken by the worker
        n = max(1, out["scans_processed"])
        out["mean_processing_s"] = round(self._processing_time / n, 4)
        out.update(self.health.latency.summary())
        for k, v in dict(getattr(self.pipeline, "counters", {}) or {}).items():
            out[f"pipeline.{k}"] = v
        return out

    def diagnostic_statuses(self) -> list:
        """The ``/diagnostics`` statuses now (:class:`lili_odom.ros.health.Status`)."""
        return self.health.statuses(self.diagnostics())

    def publish_diagnostics(self) -> None:
        """Publish one ``diagnostic_msgs/DiagnosticArray`` on ``/diagnostics``."""
        f = self._factory
        try:
            statuses = self.diagnostic_statuses()
        except Exception as exc:  # noqa: BLE001 - monitoring must not stop the node
            self.get_logger().error(f"diagnostics failed: {type(exc).__name__}: {exc}",
                                    throttle_duration_sec=10.0)
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        status_msgs = []
        for s in statuses:
            st = f.new("diagnostic_msgs/msg/DiagnosticStatus", name=s.name, message=s.message,
                       hardware_id=self._hardware_id,
                       values=[f.new("diagnostic_msgs/msg/KeyValue", key=k, value=v)
                               for k, v in s.values.items()])
            st.level = bytes([s.level])  # octet: rclpy wants one byte
            status_msgs.append(st)
        msg = f.new("diagnostic_msgs/msg/DiagnosticArray", header=M.header_msg(f, now, ""),
                    status=status_msgs)
        self.pub_diagnostics.publish(msg)

    def _log_diagnostics(self) -> None:
        self.get_logger().info("diagnostics " + json.dumps(self.diagnostics(), default=str))

    def shutdown(self, timeout: float = 5.0) -> None:
        """Stop the worker thread (waits for the scan in progress) and log the final
        :meth:`diagnostics` once."""
        self._stop.set()
        self._scans.close()
        if self._worker.is_alive():
            self._worker.join(timeout)
        close = getattr(self.pipeline, "close", None)
        if callable(close) and not self._worker.is_alive():
            close()  # the background detector process
        if not self._summary_logged:
            self._summary_logged = True
            try:
                self.get_logger().info("final diagnostics "
                                       + json.dumps(self.diagnostics(), default=str))
            except Exception:  # noqa: BLE001 - a failed last log must not fail the shutdown
                pass

    def destroy_node(self) -> None:
        self.shutdown()
        super().destroy_node()


def main(args: list[str] | None = None,
         provider_factory: Callable[[], PipelineProvider] | None = None) -> int:
    """Console entry point ``lili_odom_node`` (accepts ``--ros-args ...``).

    Loads the package's Fast DDS profile (:mod:`lili_odom.ros.dds`) unless the environment
    already chose one."""
    profile = apply_dds_defaults()
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = LiliOdomNode(provider=provider_factory() if provider_factory else None)
        except (ImportError, RuntimeError, ValueError, TypeError) as exc:
            print(f"lili_odom_node: error: {type(exc).__name__}: {exc}", file=sys.stderr)
            return 1
        if profile:
            node.get_logger().info(f"DDS profile: {profile}")
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def parameters_from_mapping(values: Mapping[str, Any]) -> list[Parameter]:
    """``{name: value}`` -> rclpy parameter overrides (for tests and embedding)."""
    return [Parameter(k, value=_ros_value(v)) for k, v in values.items()]


if __name__ == "__main__":
    raise SystemExit(main())
