"""Check that full-resolution clouds cross DDS between two processes on this machine.

``python -m lili_odom.ros.cloud_check publish`` publishes synthetic Ouster clouds (ouster-ros
"original" layout, 128 x 1024 x 48 B = 6.3 MB each by default) at 10 Hz like a driver;
``python -m lili_odom.ros.cloud_check receive`` counts what arrives with the node's subscription
QoS (best effort, depth ``scan_subscription_depth``); ``python -m lili_odom.ros.cloud_check run``
starts the publisher as a subprocess and receives in this process, printing one JSON line:
``{"published", "received", "missing", "fraction", ...}``. With ``--stamp-now`` the publisher
stamps each cloud with the wall clock as it publishes it, and the receiver adds the delivery
latency (its wall clock when the callback has the decoded cloud minus the stamp; p50 / p99 /
mean [ms]). ``--decode raw`` takes the clouds as serialised bytes and decodes them with
rosbags, as ``lili_odom_node`` does; ``--decode rclpy`` (default) lets rclpy convert them.

Both sides load the package's DDS profile like ``lili_odom_node`` does
(:func:`lili_odom.ros.dds.apply_dds_defaults`), unless ``--no-profile`` is given (or the
environment already names a profile). Every message is serialised once; only the stamp in its
header changes, so the publisher costs no Python time per message.
"""
from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import time
from typing import Any

__all__ = ["ouster_cloud_message", "publish_clouds", "receive_clouds", "main"]

#: ouster-ros "original" layout: (name, offset, datatype, count); point_step 48
ORIGINAL_FIELDS = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 16, 7, 1),
                   ("t", 20, 6, 1), ("reflectivity", 24, 4, 1), ("ring", 26, 4, 1),
                   ("ambient", 28, 4, 1), ("range", 32, 6, 1)]
ORIGINAL_POINT_STEP = 48


def ouster_cloud_message(height: int = 128, width: int = 1024, stamp: float = 0.0,
                         frame_id: str = "os_lidar") -> Any:
    """A PointCloud2 (rclpy) in the ouster-ros "original" layout: a 10 m cylinder of points."""
    import numpy as np

    from lili_odom import messages as M
    from lili_odom.ros.factory import RclpyFactory

    f = RclpyFactory()
    az = np.linspace(0.0, 2 * np.pi, width, endpoint=False)
    el = np.radians(np.linspace(22.5, -22.5, height))
    rec = np.zeros((height, width), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                           ("_p", "<f4"), ("intensity", "<f4"), ("t", "<u4"),
                                           ("reflectivity", "<u2"), ("ring", "<u2"),
                                           ("ambient", "<u2"), ("_q", "<u2"), ("range", "<u4"),
                                           ("_r", "V12")])
    assert rec.dtype.itemsize == ORIGINAL_POINT_STEP
    rec["x"] = 10.0 * np.cos(az)[None, :]
    rec["y"] = 10.0 * np.sin(az)[None, :]
    rec["z"] = 10.0 * np.tan(el)[:, None]
    rec["t"] = (np.arange(width) * (100_000_000 // width)).astype(np.uint32)[None, :]
    rec["ring"] = np.arange(height, dtype=np.uint16)[:, None]
    rec["range"] = 10000
    fields = [f.new("sensor_msgs/msg/PointField", name=n, offset=o, datatype=d, count=c)
              for n, o, d, c in ORIGINAL_FIELDS]
    return f.new("sensor_msgs/msg/PointCloud2", header=M.header_msg(f, stamp, frame_id),
                 height=height, width=width, fields=fields, is_bigendian=False,
                 point_step=ORIGINAL_POINT_STEP, row_step=ORIGINAL_POINT_STEP * width,
                 data=rec.tobytes(), is_dense=False)


def _with_stamp(serialized: bytes, stamp: float) -> bytes:
    """The serialised message with header.stamp replaced (CDR: 4-byte encapsulation, then
    int32 sec, uint32 nanosec, little endian as written by this machine)."""
    sec = int(stamp)
    nsec = int(round((stamp - sec) * 1e9))
    return serialized[:4] + struct.pack("<iI", sec, nsec) + serialized[12:]


def qos_profile(kind: str, depth: int) -> Any:
    """``sensor-data`` (best effort, what ouster-ros and most drivers publish) or ``reliable``."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=(ReliabilityPolicy.RELIABLE if kind == "reliable"
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=DurabilityPolicy.VOLATILE)


def publish_clouds(count: int, rate_hz: float, height: int, width: int, qos: str = "sensor-data",
                   topic: str = "/ouster/points", depth: int = 5, wait_s: float = 20.0,
                   t0: float = 1000.0, stamp_now: bool = False) -> int:
    """Publish ``count`` clouds stamped ``t0 + k / rate_hz`` (``stamp_now``: the wall clock at
    publication) at ``rate_hz`` (wall); returns the number published. Waits up to ``wait_s``
    for a subscriber first."""
    import rclpy
    from rclpy.serialization import serialize_message

    from lili_odom.ros.factory import message_class

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("lili_odom_cloud_check_source", context=context,
                             start_parameter_services=False)
    try:
        pub = node.create_publisher(message_class("sensor_msgs/msg/PointCloud2"), topic,
                                    qos_profile(qos, depth))
        deadline = time.monotonic() + wait_s
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.5)  # the reader may learn of this writer slightly later
        base = serialize_message(ouster_cloud_message(height, width, 0.0))
        period = 1.0 / rate_hz
        start = time.monotonic()
        for k in range(count):
            target = start + k * period
            delay = target - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            pub.publish(_with_stamp(base, time.time() if stamp_now else t0 + k * period))
        if qos == "reliable":
            from rclpy.duration import Duration

            pub.wait_for_all_acked(Duration(seconds=5.0))
        time.sleep(0.5)
        return count
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def receive_clouds(expected: int, timeout_s: float, qos: str = "sensor-data",
                   topic: str = "/ouster/points", depth: int = 10,
                   start_publisher: list[str] | None = None, decode: str = "rclpy",
                   latency: bool = False) -> dict[str, Any]:
    """Subscribe (QoS ``qos``, ``depth``; ``decode`` "rclpy" or "raw": see the module
    docstring), optionally start ``start_publisher`` (argv), and count clouds until
    ``expected`` arrived, the publisher exited and 1 s passed, or ``timeout_s``. With
    ``latency`` (the publisher stamps with the wall clock) the result also holds
    ``latency_ms``."""
    import numpy as np
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from lili_odom import messages as M
    from lili_odom.ros.cloud_decode import CloudDecoder
    from lili_odom.ros.factory import message_class

    if decode not in ("rclpy", "raw"):
        raise ValueError(f"decode must be 'rclpy' or 'raw', got {decode!r}")
    decoder = CloudDecoder()

    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("lili_odom_cloud_check_sink", context=context,
                             start_parameter_services=False)
    stamps: list[float] = []
    sizes: list[int] = []
    delays: list[float] = []

    def on_cloud(msg: Any) -> None:
        if decode == "raw":
            msg = decoder(msg)
        stamp = M.stamp_seconds(msg.header)
        delays.append(time.time() - stamp)
        stamps.append(stamp)
        sizes.append(len(msg.data))

    node.create_subscription(message_class("sensor_msgs/msg/PointCloud2"), topic, on_cloud,
                             qos_profile(qos, depth), raw=decode == "raw")
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    proc = None
    t_start = time.monotonic()
    try:
        if start_publisher:
            proc = subprocess.Popen(start_publisher, stdout=subprocess.DEVNULL,
                                    stderr=subprocess.PIPE, text=True)
        exited_at = None
        while time.monotonic() - t_start < timeout_s and len(stamps) < expected:
            executor.spin_once(timeout_sec=0.05)
            if proc is not None and proc.poll() is not None:
                exited_at = exited_at or time.monotonic()
                if time.monotonic() - exited_at > 1.0:
                    break
        publisher_error = ""
        if proc is not None:
            try:
                _, publisher_error = proc.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                _, publisher_error = proc.communicate()
            if proc.returncode != 0:
                raise RuntimeError(f"publisher failed ({proc.returncode}): "
                                   f"{publisher_error.strip()[-500:]}")
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    received = len(set(stamps))
    result = {"published": expected, "received": received, "missing": expected - received,
              "fraction": round(received / expected, 4) if expected else 1.0,
              "bytes_per_cloud": sizes[0] if sizes else 0, "decode": decode,
              "seconds": round(time.monotonic() - t_start, 2)}
    if latency and delays:
        ms = 1e3 * np.asarray(delays)
        result["latency_ms"] = {"p50": round(float(np.percentile(ms, 50)), 2),
                                "p99": round(float(np.percentile(ms, 99)), 2),
                                "mean": round(float(ms.mean()), 2)}
    return result


def _args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m lili_odom.ros.cloud_check", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("role", choices=("publish", "receive", "run"))
    p.add_argument("--count", type=int, default=100)
    p.add_argument("--rate", type=float, default=10.0, help="clouds per second")
    p.add_argument("--height", type=int, default=128)
    p.add_argument("--width", type=int, default=1024)
    p.add_argument("--qos", choices=("sensor-data", "reliable"), default="sensor-data",
                   help="publisher QoS (the receiver subscribes best effort unless "
                   "--reliable-sub)")
    p.add_argument("--reliable-sub", action="store_true")
    p.add_argument("--depth", type=int, default=10, help="subscription depth")
    p.add_argument("--topic", default="/ouster/points")
    p.add_argument("--timeout", type=float, default=60.0)
    p.add_argument("--no-profile", action="store_true",
                   help="do not load the package's DDS profile (measure the middleware default)")
    p.add_argument("--decode", choices=("rclpy", "raw"), default="rclpy",
                   help="receiver: rclpy's message conversion, or serialised bytes decoded by "
                   "rosbags as lili_odom_node does")
    p.add_argument("--stamp-now", action="store_true",
                   help="publisher: stamp with the wall clock; receiver: report the delivery "
                   "latency")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    a = _args(argv)
    if not a.no_profile:
        from lili_odom.ros.dds import apply_dds_defaults

        apply_dds_defaults()
    if a.role == "publish":
        publish_clouds(a.count, a.rate, a.height, a.width, a.qos, a.topic,
                       stamp_now=a.stamp_now)
        return 0
    cmd = None
    if a.role == "run":
        cmd = [sys.executable, "-m", "lili_odom.ros.cloud_check", "publish",
               "--count", str(a.count), "--rate", str(a.rate), "--height", str(a.height),
               "--width", str(a.width), "--qos", a.qos, "--topic", a.topic]
        if a.no_profile:
            cmd.append("--no-profile")
        if a.stamp_now:
            cmd.append("--stamp-now")
    result = receive_clouds(a.count, a.timeout, "reliable" if a.reliable_sub else "sensor-data",
                            a.topic, a.depth, start_publisher=cmd, decode=a.decode,
                            latency=a.stamp_now)
    result.update({"qos": a.qos, "height": a.height, "width": a.width, "rate_hz": a.rate,
                   "profile": os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE", ""),
                   "builtin_transports": os.environ.get("FASTDDS_BUILTIN_TRANSPORTS", "")})
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
