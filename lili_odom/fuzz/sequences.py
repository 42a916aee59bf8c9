"""Door ``sequences``: a few hundred scans with sensor faults through the feeder and pipeline.

A case plays the committed CI bag (``bags/tunnel_entrance_32x256``: 150 scans, IMU, wheels,
``/tf_static``) and then its first 50 scans again with the same stamps (a bag loop: the clock
jumps back and the pipeline resets), 200 scans in all, through a fresh :class:`~lili_odom.pipeline.feeder.MessageFeeder`
and pipeline (``lili`` or ``none``). One to three faults hit the first lap inside a window of
0.2-3 s starting 2-9 s in: NaN, saturated, backwards, duplicated or jumping IMU messages, IMU
loss (also before the first scan), NaN or huge wheel twists and poses, a wheel teleport,
wheel and LiDAR outages, reordering (:class:`~lili_odom.evaluation.faults.FaultInjector`),
scan stamps jumping back or forward, corrupt clouds and a non-finite ``/tf_static``.

Expected: nothing raises, every output is finite, and the pipeline keeps producing output:
at least 80 % of the scans stamped more than 1 s after the fault window (first lap) and of
the second lap's scans (after its first second) give an output.
"""
from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np

from lili_odom.fuzz.bags import SOURCE_BAG
from lili_odom.fuzz.outcome import CLEAN, NONFINITE, STALLED, Outcome, all_finite, from_exception

LIDAR, IMU, WHEEL, TF = "/ouster/points", "/ouster/imu", "/platform/odom", "/tf_static"
RECOVERY_DELAY_S = 1.0
MIN_RECOVERED = 0.8

_STREAM: list[tuple[str, Any, float]] | None = None

FAULTS = ("imu_nan", "imu_saturated", "imu_backwards", "imu_duplicate", "imu_jump", "imu_loss",
          "no_imu_at_start", "wheel_nan", "wheel_huge_twist", "wheel_teleport", "wheel_outage",
          "lidar_outage", "reorder", "scan_stamp_back", "scan_stamp_forward", "cloud_corrupt",
          "tf_nonfinite")


def stream() -> list[tuple[str, Any, float]]:
    """The CI bag's messages ``(topic, msg, stamp)`` in header-stamp order (read once)."""
    global _STREAM
    if _STREAM is None:
        from lili_odom.bagio.reader import BagReader

        with BagReader(SOURCE_BAG, topics=[LIDAR, IMU, WHEEL, TF]) as reader:
            _STREAM = [(m.topic, m.msg, m.stamp) for m in reader]
    return _STREAM


def _set_stamp(msg: Any, t: float) -> Any:
    out = copy.deepcopy(msg)
    ns = int(round(t * 1e9))
    out.header.stamp.sec = ns // 1_000_000_000
    out.header.stamp.nanosec = ns % 1_000_000_000
    return out


def _apply(fault: str, rng: np.random.Generator, items: list, t_first: float,
           window: tuple[float, float]) -> list:
    """``items`` [(topic, msg, stamp)] with ``fault`` applied inside ``window`` (s after
    ``t_first``)."""
    from lili_odom.evaluation.faults import FaultInjector, FaultSpec, StreamItem

    w0, w1 = window

    def inside(t: float) -> bool:
        return w0 <= t - t_first <= w1

    if fault in ("imu_loss", "wheel_outage", "lidar_outage", "reorder"):
        spec = {"imu_loss": FaultSpec(imu_drop_fraction=float(rng.choice([0.3, 0.9, 1.0]))),
                "wheel_outage": FaultSpec(wheel_outage=window),
                "lidar_outage": FaultSpec(lidar_outage=window),
                "reorder": FaultSpec(reorder_fraction=0.3,
                                     reorder_max_delay_s=float(rng.choice([0.02, 0.2])))}[fault]
        spec.seed = int(rng.integers(1 << 31))
        injected = FaultInjector(spec)(StreamItem(topic, msg, stamp) for topic, msg, stamp in items)
        return [(it.topic, it.msg, it.stamp) for it in injected]
    out = []
    jumped = False
    for topic, msg, stamp in items:
        hit = inside(stamp)
        if fault == "no_imu_at_start" and topic in (IMU, WHEEL) and stamp - t_first < w1:
            continue
        if not hit:
            if fault == "wheel_teleport" and topic == WHEEL and stamp - t_first > w1:
                msg = copy.deepcopy(msg)
                msg.pose.pose.position.x += 100.0
            out.append((topic, msg, stamp))
            continue
        if topic == IMU and fault.startswith("imu_"):
            if fault == "imu_nan":
                msg = copy.deepcopy(msg)
                msg.angular_velocity.x = math.nan
            elif fault == "imu_saturated":
                msg = copy.deepcopy(msg)
                msg.linear_acceleration.x = 16 * 9.80665
                msg.angular_velocity.z = -34.9
            elif fault == "imu_backwards":
                msg = _set_stamp(msg, stamp - 0.5)
            elif fault == "imu_duplicate":
                out.append((topic, msg, stamp))
            elif fault == "imu_jump" and not jumped:
                jumped = True
                out.append((topic, _set_stamp(msg, stamp + 1e6), stamp))
        elif topic == WHEEL and fault.startswith("wheel_"):
            msg = copy.deepcopy(msg)
            if fault == "wheel_nan":
                msg.pose.pose.position.y = math.nan
                msg.twist.twist.linear.x = math.nan
            elif fault == "wheel_huge_twist":
                msg.twist.twist.linear.x = 1e6
                msg.twist.twist.angular.z = 1e3
            elif fault == "wheel_teleport":
                msg.pose.pose.position.x += 100.0
        elif topic == LIDAR:
            if fault == "scan_stamp_back":
                msg = _set_stamp(msg, stamp - float(rng.choice([0.3, 5.0])))
            elif fault == "scan_stamp_forward":
                msg = _set_stamp(msg, stamp + float(rng.choice([2.0, 1000.0])))
            elif fault == "cloud_corrupt":
                msg = _corrupt_cloud(rng, msg)
        if fault == "tf_nonfinite" and not jumped:
            jumped = True
            tf = copy.deepcopy(next(m for t, m, _ in items if t == TF))
            for ts in tf.transforms:
                ts.transform.translation.x = math.nan
            out.append((TF, tf, stamp))
        out.append((topic, msg, stamp))
    return out


def _corrupt_cloud(rng: np.random.Generator, msg: Any) -> Any:
    msg = copy.deepcopy(msg)
    what = int(rng.integers(4))
    data = np.array(msg.data, dtype=np.uint8)
    if what == 0:
        msg.data = data[: int(rng.integers(0, data.size))]
    elif what == 1:
        recs = data.reshape(-1, int(msg.point_step))
        recs[:, 0:12] = np.frombuffer(np.full(3, np.nan, np.float32).tobytes(), np.uint8)
        msg.data = recs.reshape(-1)
    elif what == 2:  # every per-point time at the largest uint32
        recs = data.reshape(-1, int(msg.point_step))
        recs[:, 20:24] = 255
        msg.data = recs.reshape(-1)
    else:
        msg.fields = [f for f in msg.fields if f.name != "z"]
    return msg


def run_case(rng: np.random.Generator, scans_per_lap: int = 150, laps: int = 2,
             loop_scans: int = 50) -> Outcome:
    """One faulted sequence: a first lap of ``scans_per_lap`` scans with the faults, then
    ``laps - 1`` clean loops of the bag's first ``loop_scans`` scans."""
    from lili_odom.config import NodeConfig
    from lili_odom.pipeline.feeder import MessageFeeder
    from lili_odom.pipeline.odometry import OdometryPipeline

    base = stream()
    t_first = base[0][2]
    clouds = [s for t, _, s in base if t == LIDAR]
    t_last = clouds[min(scans_per_lap, len(clouds)) - 1] + 0.05
    lap = [it for it in base if it[2] <= t_last]
    loop = [it for it in base if it[2] <= clouds[min(loop_scans, len(clouds)) - 1] + 0.05]
    lap_s = t_last - t_first
    method = "lili" if rng.random() < 0.5 else "none"
    n_faults = int(rng.integers(1, 4))
    faults = [FAULTS[int(i)] for i in rng.choice(len(FAULTS), n_faults, replace=False)]
    w0 = float(rng.uniform(0.2, 0.6) * lap_s)
    window = (w0, w0 + float(rng.uniform(0.2, min(3.0, 0.3 * lap_s))))
    faulted = list(lap)
    for fault in faults:
        faulted = _apply(fault, rng, faulted, t_first, window)
    n_loop = min(loop_scans, len(clouds))
    case = (f"{method}; {', '.join(faults)} in {window[0]:.2f}-{window[1]:.2f} s; "
            f"{len(clouds[:scans_per_lap])} + {laps - 1} x {n_loop} scans")

    config = NodeConfig()
    config.pipeline.method = method
    feeder = MessageFeeder(OdometryPipeline(config.pipeline), config)
    outputs = []
    try:
        for k in range(laps):
            for topic, msg, _ in (faulted if k == 0 else loop):
                outputs.extend((k, o) for o in feeder.feed(topic, msg))
            if k == laps - 1:
                outputs.extend((k, o) for o in feeder.flush())
    except Exception as exc:  # noqa: BLE001 - nothing may escape the feeder
        return from_exception(exc, (), case)
    for _, out in outputs:
        if not all_finite(out.pose, out.twist, out.covariance, out.stamp):
            return Outcome(NONFINITE, f"non-finite output at {out.stamp:.3f}", case)
    # outputs refer to the sweep end (about 0.1 s after the cloud stamp)
    checks = [(0, t_first + window[1] + RECOVERY_DELAY_S)]
    checks += [(k, t_first + RECOVERY_DELAY_S) for k in range(1, laps)]
    notes = []
    for k, t_from in checks:
        expected = [s for s in clouds[:scans_per_lap if k == 0 else n_loop] if s >= t_from]
        got = {round(o.stamp - 0.1, 2) for kk, o in outputs if kk == k}
        hit = sum(1 for s in expected if round(s, 2) in got or round(s + 0.01, 2) in got
                  or round(s - 0.01, 2) in got)
        notes.append(f"lap {k + 1}: {hit}/{len(expected)} scans after {t_from - t_first:.1f} s")
        if expected and hit < MIN_RECOVERED * len(expected):
            return Outcome(STALLED, f"{'; '.join(notes)}; counters "
                                    f"{dict(feeder.pipeline.counters)}", case)
    return Outcome(CLEAN, f"{len(outputs)} outputs; {'; '.join(notes)}", case)
