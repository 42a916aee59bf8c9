"""Door ``feeder``: duck-typed ROS messages into :class:`~lili_odom.pipeline.feeder.MessageFeeder`.

A case feeds three scan periods of valid messages (clouds of a small box room, IMU at 100 Hz,
wheel odometry at 50 Hz, ``/tf_static``) through a fresh feeder and ``none`` pipeline, then one
to five bad messages (malformed objects, missing or garbage headers, non-finite or huge
values, corrupt clouds from the ``clouds`` door, stamps jumping back and forth, unknown
topics), then three more valid periods and a flush. Expected: ``feed`` and ``flush`` never
raise (bad messages are counted and skipped), every output is finite, and the last valid
scan gives an output.
"""
from __future__ import annotations

from types import SimpleNamespace as NS
from typing import Any

import numpy as np

from lili_odom.fuzz.api import DT, SPEED, room
from lili_odom.fuzz.outcome import CLEAN, NONFINITE, STALLED, Outcome, all_finite, from_exception

LIDAR, IMU, WHEEL, TF = "/ouster/points", "/ouster/imu", "/platform/odom", "/tf_static"


def _pick(rng: np.random.Generator, options: list) -> Any:
    return options[int(rng.integers(len(options)))]


def header(t: float, frame: str) -> NS:
    ns = int(round(t * 1e9))
    return NS(stamp=NS(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame)


def _vec(x, y, z) -> NS:
    return NS(x=x, y=y, z=z)


def imu_msg(t: float) -> NS:
    return NS(header=header(t, "os_imu"), angular_velocity=_vec(0.0, 0.0, 0.0),
              linear_acceleration=_vec(0.0, 0.0, 9.80665),
              orientation=NS(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=[-1.0] + [0.0] * 8)


def wheel_msg(t: float, t0: float) -> NS:
    return NS(header=header(t, "odom"), child_frame_id="base_link",
              pose=NS(pose=NS(position=_vec(SPEED * (t - t0), 0.0, 0.0),
                              orientation=NS(x=0.0, y=0.0, z=0.0, w=1.0)),
                      covariance=[0.0] * 36),
              twist=NS(twist=NS(linear=_vec(SPEED, 0.0, 0.0), angular=_vec(0.0, 0.0, 0.0)),
                       covariance=[0.0] * 36))


def cloud_msg(points: np.ndarray, t: float, k: int, t0: float) -> NS:
    from lili_odom.pointcloud2 import encode_xyz_cloud

    times = np.linspace(0.0, DT, len(points))
    moved = points - SPEED * ((t - t0) + times)[:, None] * np.array([1.0, 0.0, 0.0])
    c = encode_xyz_cloud(moved, times=times)
    return NS(header=header(t, "os_lidar"), fields=c.fields, is_bigendian=c.is_bigendian,
              point_step=c.point_step, row_step=c.row_step, height=c.height, width=c.width,
              data=c.data, is_dense=c.is_dense)


def tf_msg(edges: list[tuple[str, str, tuple]]) -> NS:
    return NS(transforms=[NS(header=header(0.0, p), child_frame_id=c,
                             transform=NS(translation=_vec(*xyz), rotation=NS(x=0.0, y=0.0, z=0.0,
                                                                             w=1.0)))
                          for p, c, xyz in edges])


def _bad_header(rng) -> Any:
    what = int(rng.integers(6))
    if what == 0:
        return None
    if what == 1:
        return NS(frame_id="x")
    if what == 2:
        return NS(stamp=NS(sec=_pick(rng, ["1", None, float("nan"), 1e300, -5, 2 ** 80]),
                           nanosec=0), frame_id="os_lidar")
    if what == 3:
        return NS(stamp=NS(sec=100, nanosec=_pick(rng, [-1, 10 ** 12, float("inf"), "0"])),
                  frame_id=_pick(rng, ["", None, 5, "os_lidar"]))
    if what == 4:
        return NS(stamp=None, frame_id="os_lidar")
    return 17


def _bad_message(rng, t: float, t0: float, points: np.ndarray) -> tuple[str, Any, str]:
    from lili_odom.fuzz import clouds

    topic = _pick(rng, [LIDAR, LIDAR, IMU, IMU, WHEEL, WHEEL, TF, "/unknown"])
    what = int(rng.integers(8))
    if what == 0:
        msg = _pick(rng, [None, 5, "text", b"bytes", [], NS()])
        return topic, msg, f"{topic} {type(msg).__name__}"
    if what == 1:
        msg = {LIDAR: lambda: cloud_msg(points, t, 0, t0), IMU: lambda: imu_msg(t),
               WHEEL: lambda: wheel_msg(t, t0), TF: lambda: tf_msg([("base_link", "os_sensor",
                                                                     (0, 0, 0.5))]),
               "/unknown": lambda: imu_msg(t)}[topic]()
        msg.header = _bad_header(rng)
        return topic, msg, f"{topic} bad header"
    if what == 2:  # valid layout, stamp jumping
        dt = _pick(rng, [-DT, -1.0, -1e3, -1e9, 1e-4, 2.0, 1e3, 1e9, 0.0])
        ts = max(t + dt, 0.0)
        msg = {LIDAR: lambda: cloud_msg(points, ts, 0, t0), IMU: lambda: imu_msg(ts),
               WHEEL: lambda: wheel_msg(ts, t0), TF: lambda: tf_msg([]),
               "/unknown": lambda: imu_msg(ts)}[topic]()
        return topic, msg, f"{topic} stamp {dt:+g} s"
    if topic == LIDAR:
        cmsg, _, text = clouds.make_case(rng)
        cmsg.header = header(t, "os_lidar")
        return topic, cmsg, f"cloud: {text}"
    value = _pick(rng, [float("nan"), float("inf"), -1e308, 1e308, None, "x", 1e4, 0.0])
    if topic in (IMU, "/unknown"):
        msg = imu_msg(t)
        field = _pick(rng, ["angular_velocity", "linear_acceleration"])
        setattr(getattr(msg, field), _pick(rng, ["x", "y", "z"]), value)
        if rng.random() < 0.2:
            setattr(msg, field, None)
        return topic, msg, f"IMU {field} {value!r}"
    if topic == WHEEL:
        msg = wheel_msg(t, t0)
        part = int(rng.integers(4))
        if part == 0:
            msg.pose.pose.orientation = NS(x=value, y=0.0, z=0.0, w=_pick(rng, [0.0, 1.0, value]))
        elif part == 1:
            msg.pose.pose.position.x = value
        elif part == 2:
            msg.twist.twist.linear.x = value
        else:
            msg.twist.covariance = _pick(rng, [[value] * 36, [1.0] * 35, None, "cov"])
        return topic, msg, f"wheel part {part} {value!r}"
    msg = tf_msg([("base_link", "os_sensor", (value, 0, 0)), ("os_sensor", "os_lidar", (0, 0, 0)),
                  ("os_lidar", "base_link", (1, 0, 0))])
    if rng.random() < 0.3:
        msg.transforms = _pick(rng, [None, 5, [None], [NS()]])
    return topic, msg, f"tf_static {value!r}"


def run_case(rng: np.random.Generator) -> Outcome:
    from lili_odom.config import NodeConfig
    from lili_odom.pipeline.feeder import MessageFeeder
    from lili_odom.pipeline.odometry import OdometryPipeline

    config = NodeConfig()
    config.pipeline.method = "none"
    feeder = MessageFeeder(OdometryPipeline(config.pipeline), config)
    points = room(rng, 100)
    t0 = 1000.0
    outputs: list = []
    parts: list[str] = []

    def period(k: int) -> None:
        t = t0 + k * DT
        outputs.extend(feeder.feed(LIDAR, cloud_msg(points, t, k, t0)))
        for j in range(10):
            ts = t + 0.01 * j
            outputs.extend(feeder.feed(IMU, imu_msg(ts)))
            if j % 2 == 0:
                outputs.extend(feeder.feed(WHEEL, wheel_msg(ts, t0)))

    try:
        outputs.extend(feeder.feed(TF, tf_msg([("base_link", "os_sensor", (0, 0, 0.5)),
                                               ("os_sensor", "os_lidar", (0, 0, 0.04)),
                                               ("os_sensor", "os_imu", (0.006, -0.01, 0.008))])))
        for k in range(3):
            period(k)
        for _ in range(int(rng.integers(1, 6))):
            topic, msg, text = _bad_message(rng, t0 + 3 * DT, t0, points)
            parts.append(text)
            outputs.extend(feeder.feed(topic, msg))
        n_before = len(outputs)
        for k in range(3, 6):
            period(k)
        outputs.extend(feeder.flush())
    except Exception as exc:  # noqa: BLE001 - nothing may escape the feeder
        return from_exception(exc, (), "; ".join(parts))
    case = "; ".join(parts)
    for out in outputs:
        if not all_finite(out.pose, out.twist, out.covariance, out.stamp):
            return Outcome(NONFINITE, "non-finite output", case)
    last_stamp = t0 + 5 * DT
    if len(outputs) == n_before or not any(abs(o.stamp - last_stamp) < 2 * DT for o in outputs):
        return Outcome(STALLED, f"no output for the last valid scan; counters "
                                f"{dict(feeder.pipeline.counters)}", case)
    return Outcome(CLEAN, f"{len(outputs)} outputs", case)
