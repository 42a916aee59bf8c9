"""ROS message objects <-> pipeline types, without importing rclpy.

Inputs are *duck-typed*: a message deserialised by ``rosbags`` (plain dataclasses) and one built
by rclpy have the same attribute names, so every ``*_from_msg`` function takes either.

Outputs are built through a :class:`MessageFactory`, an object that knows one message library:
:class:`lili_odom.bagio.factory.RosbagsFactory` for bags written offline and
:class:`lili_odom.ros.factory.RclpyFactory` for the live node. Builders pass plain Python /
numpy values; the factory converts them to what its library wants (numpy arrays for rosbags,
``array.array`` and exact scalar types for rclpy) and fills every field not given with its
default.

Frames and units (REP-103/105):

* Odometry: ``header.frame_id`` = the odometry frame (``odom_frame``), ``child_frame_id`` =
  ``base_link``. The pose covariance is rotated into the odometry frame (position and rotation
  errors expressed in the parent frame, as ``nav_msgs/Odometry`` specifies); the twist is the
  body twist of ``base_link`` in ``base_link``; its covariance is left all zero ("unknown").
* Covariances: ROS's 6x6 order (x, y, z, rot x, rot y, rot z) is already our ``(v, w)`` order,
  so no reordering is needed, only reshaping.
* Degeneracy markers are drawn in the **odometry frame**, anchored at the robot's fused pose at
  the scan stamp, so rviz shows them with the odometry frame as fixed frame even without any
  ``/tf`` (the pip ROS stack has no tf2). Translational directions are arrows from the robot;
  rotational directions are arrows along the screw axis through its axis point (plus a sphere
  on the axis point). The machine-readable basis (JSON) stays in ``base_link``.
* Times are float seconds from ``header.stamp``.
"""
from __future__ import annotations

import json
import logging
import math
from typing import Any, Callable, Iterable, MutableMapping, Protocol, Sequence

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from lili_odom.errors import ThrottledWarnings
from lili_odom.pipeline.types import ImuSample, OdometryOutput, Scan, WheelSample

log = logging.getLogger(__name__)

__all__ = [
    "MessageFactory",
    "CloudParser",
    "stamp_seconds",
    "split_stamp",
    "pose_to_matrix",
    "matrix_to_pose_values",
    "imu_from_msg",
    "wheel_from_msg",
    "odometry_pose_from_msg",
    "truth_sample",
    "scan_from_msg",
    "default_cloud_parser",
    "transforms_from_tf_msg",
    "time_msg",
    "header_msg",
    "pose_msg",
    "odometry_msg",
    "pose_stamped_msg",
    "path_msg",
    "degeneracy_markers",
    "degeneracy_basis_dict",
    "degeneracy_json_msg",
    "string_msg",
    "pointcloud_xyz_msg",
    "tf_message",
    "classify_twist",
]


class MessageFactory(Protocol):
    """Builds messages of one library by ROS type name (``pkg/msg/Name``)."""

    def new(self, typename: str, **fields: Any) -> Any:
        """A message with ``fields`` set (converted as needed) and every other field default."""


#: ``parser(cloud_msg, stamp_seconds) -> (xyz (N,3) [m], times (N,) [s from stamp] | None,
#: dropped count)``. Only valid points are returned.
CloudParser = Callable[[Any, float], "tuple[np.ndarray, np.ndarray | None, int]"]


# ------------------------------------------------------------------------------------------
# time


def stamp_seconds(header_or_stamp: Any) -> float:
    """``std_msgs/Header`` or ``builtin_interfaces/Time`` -> float seconds."""
    stamp = getattr(header_or_stamp, "stamp", header_or_stamp)
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def split_stamp(t: float) -> tuple[int, int]:
    """Float seconds -> ``(sec, nanosec)`` with ``0 <= nanosec < 1e9`` (rounded to 1 ns)."""
    ns = int(round(float(t) * 1e9))
    return ns // 1_000_000_000, ns % 1_000_000_000


# ------------------------------------------------------------------------------------------
# geometry


def _xyz(v: Any) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=np.float64)


def pose_to_matrix(pose: Any) -> np.ndarray:
    """``geometry_msgs/Pose`` (or ``Transform``: translation/rotation) -> 4x4.

    A zero quaternion (never set) is read as identity. A non-finite quaternion gives a NaN
    rotation, so every consumer rejects the pose instead of taking a made-up orientation.
    """
    position = getattr(pose, "position", None)
    if position is None:
        position = pose.translation
    q = getattr(pose, "orientation", None)
    if q is None:
        q = pose.rotation
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    T = np.eye(4)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not all(map(math.isfinite, (x, y, z, w))):
        T[:3, :3] = np.nan
    elif norm > 1e-12 and math.isfinite(norm):
        T[:3, :3] = gtsam.Rot3.Quaternion(w / norm, x / norm, y / norm, z / norm).matrix()
    T[:3, 3] = _xyz(position)
    return T


def matrix_to_pose_values(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """4x4 -> (position (3,), quaternion (x, y, z, w) with w >= 0)."""
    T = np.asarray(T, dtype=np.float64)
    q = gtsam.Rot3(np.ascontiguousarray(T[:3, :3])).toQuaternion()
    quat = np.array([q.x(), q.y(), q.z(), q.w()])
    if not (np.all(np.isfinite(quat)) and abs(float(quat @ quat) - 1.0) < 1e-6):
        quat = Rotation.from_matrix(T[:3, :3]).as_quat()  # not a rotation: scipy's projection
    if quat[3] < 0:
        quat = -quat
    return T[:3, 3].copy(), quat


def _cov6(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=np.float64).reshape(6, 6)


# ------------------------------------------------------------------------------------------
# inputs


def imu_from_msg(msg: Any) -> ImuSample:
    """``sensor_msgs/Imu`` -> :class:`ImuSample` (IMU frame; rad/s and m/s^2)."""
    return ImuSample(
        stamp=stamp_seconds(msg.header),
        angular_velocity=_xyz(msg.angular_velocity),
        linear_acceleration=_xyz(msg.linear_acceleration),
    )


def wheel_from_msg(msg: Any) -> WheelSample:
    """``nav_msgs/Odometry`` wheel odometry -> :class:`WheelSample`.

    Twist from ``msg.twist.twist`` (body twist of base_link in base_link); pose from
    ``msg.pose.pose`` (base_link in the wheel ``odom`` frame). The twist covariance is None
    when it is all zero or its first element is negative (ROS's "unknown" markers).
    """
    tw = msg.twist.twist
    cov = _cov6(msg.twist.covariance)
    unset = not np.any(cov) or cov[0, 0] < 0 or not np.all(np.isfinite(cov))
    return WheelSample(
        stamp=stamp_seconds(msg.header),
        twist=np.concatenate([_xyz(tw.linear), _xyz(tw.angular)]),
        pose=pose_to_matrix(msg.pose.pose),
        twist_covariance=None if unset else cov,
    )


def odometry_pose_from_msg(msg: Any) -> tuple[float, np.ndarray]:
    """``nav_msgs/Odometry`` -> (stamp [s], 4x4 pose of child in header frame); e.g. truth."""
    return stamp_seconds(msg.header), pose_to_matrix(msg.pose.pose)


def truth_sample(msg: Any) -> tuple[float, np.ndarray] | None:
    """:func:`odometry_pose_from_msg` for ground truth: None for a malformed or non-finite
    message (the evaluation skips it)."""
    try:
        stamp, T = odometry_pose_from_msg(msg)
    except (AttributeError, TypeError, ValueError):
        return None
    return (stamp, T) if np.isfinite(stamp) and np.all(np.isfinite(T)) else None


_WARNINGS = ThrottledWarnings(log)


def default_cloud_parser(min_range: float = 0.0, max_range: float = math.inf,
                         counters: "MutableMapping[str, int] | None" = None,
                         stride: int = 1) -> CloudParser:
    """A :data:`CloudParser` backed by :func:`lili_odom.pointcloud2.parse_cloud`.

    A cloud is used as far as it is valid: a corrupt per-point time field is ignored (no
    deskewing) and isolated corrupt times drop their points. Each case is counted in
    ``counters`` (when given: ``cloud_times_ignored``, ``cloud_bad_time_points``) and logged
    as a throttled warning saying why. Malformed layouts raise ``CloudFormatError``.
    ``stride`` > 1 reads every ``stride``-th point only (``parse_cloud``); the points it
    leaves out are not counted as dropped.
    """

    def parse(msg: Any, stamp: float) -> tuple[np.ndarray, np.ndarray | None, int]:
        from lili_odom.pointcloud2 import parse_cloud  # lazy: keeps this module light

        parsed = parse_cloud(msg, min_range=min_range, max_range=max_range, stamp=stamp,
                             extra_fields=False, stride=stride)
        s = parsed.stats
        if s.times_ignored:
            if counters is not None:
                counters["cloud_times_ignored"] = counters.get("cloud_times_ignored", 0) + 1
            _WARNINGS.warning("times_ignored", "cloud at %.3f: per-point times ignored "
                              "(no deskewing): %s", stamp, s.times_ignored)
        if s.n_bad_time:
            if counters is not None:
                counters["cloud_bad_time_points"] = (counters.get("cloud_bad_time_points", 0)
                                                     + s.n_bad_time)
            _WARNINGS.warning("bad_time", "cloud at %.3f: %d points with corrupt "
                              "per-point times dropped", stamp, s.n_bad_time)
        return parsed.xyz, parsed.times, s.n_total - s.n_skipped - s.n_kept

    return parse


def scan_from_msg(msg: Any, parse_fn: CloudParser | None = None) -> Scan:
    """``sensor_msgs/PointCloud2`` -> :class:`Scan` in the cloud's frame.

    Args:
        msg: the cloud (rosbags or rclpy).
        parse_fn: byte parser; default :func:`default_cloud_parser` with no range limits.

    Raises:
        lili_odom.pointcloud2.CloudFormatError: malformed cloud (a ``ValueError``).
    """
    stamp = stamp_seconds(msg.header)
    parse = parse_fn or default_cloud_parser()
    xyz, times, dropped = parse(msg, stamp)
    return Scan(
        stamp=stamp,
        points=np.asarray(xyz, dtype=np.float64).reshape(-1, 3),
        times=None if times is None else np.asarray(times, dtype=np.float64),
        frame_id=str(msg.header.frame_id),
        dropped=int(dropped),
    )


def transforms_from_tf_msg(msg: Any) -> list[tuple[str, str, np.ndarray]]:
    """``tf2_msgs/TFMessage`` -> ``[(parent, child, T_parent_child 4x4)]``.

    Transforms with a non-finite translation or rotation are left out (warned, throttled):
    an extrinsic must never poison the estimator.
    """
    out = []
    for ts in msg.transforms:
        parent, child = str(ts.header.frame_id), str(ts.child_frame_id)
        T = pose_to_matrix(ts.transform)
        if not np.all(np.isfinite(T)):
            _WARNINGS.warning(f"tf {parent} {child}", "transform %s -> %s ignored: "
                              "non-finite translation or rotation", parent, child)
            continue
        out.append((parent, child, T))
    return out


# ------------------------------------------------------------------------------------------
# output building blocks


def time_msg(f: MessageFactory, t: float) -> Any:
    sec, nanosec = split_stamp(t)
    return f.new("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)


def header_msg(f: MessageFactory, t: float, frame_id: str) -> Any:
    return f.new("std_msgs/msg/Header", stamp=time_msg(f, t), frame_id=frame_id)


def _point(f: MessageFactory, p: Sequence[float]) -> Any:
    return f.new("geometry_msgs/msg/Point", x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _vector3(f: MessageFactory, p: Sequence[float]) -> Any:
    return f.new("geometry_msgs/msg/Vector3", x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _quaternion(f: MessageFactory, q: Sequence[float]) -> Any:
    return f.new("geometry_msgs/msg/Quaternion", x=float(q[0]), y=float(q[1]), z=float(q[2]),
                 w=float(q[3]))


def pose_msg(f: MessageFactory, T: np.ndarray) -> Any:
    """4x4 -> ``geometry_msgs/Pose``."""
    p, q = matrix_to_pose_values(T)
    return f.new("geometry_msgs/msg/Pose", position=_point(f, p), orientation=_quaternion(f, q))


def _covariance_in_parent(T: np.ndarray, cov_body: np.ndarray) -> np.ndarray:
    """Body (right-perturbation) pose covariance -> errors expressed in the parent frame.

    With ``T exp(xi)`` the first-order position error is ``R v`` and the rotation error ``R w``.
    """
    R = np.asarray(T, dtype=np.float64)[:3, :3]
    J = np.zeros((6, 6))
    J[:3, :3] = R
    J[3:, 3:] = R
    C = J @ np.asarray(cov_body, dtype=np.float64).reshape(6, 6) @ J.T
    return 0.5 * (C + C.T)


def odometry_msg(f: MessageFactory, out: OdometryOutput, frame_id: str,
                 child_frame_id: str = "base_link") -> Any:
    """:class:`OdometryOutput` -> ``nav_msgs/Odometry`` (see module docstring for frames)."""
    pose_cov = _covariance_in_parent(out.pose, out.covariance)
    twist = np.asarray(out.twist, dtype=np.float64).reshape(6)
    return f.new(
        "nav_msgs/msg/Odometry",
        header=header_msg(f, out.stamp, frame_id),
        child_frame_id=child_frame_id,
        pose=f.new("geometry_msgs/msg/PoseWithCovariance", pose=pose_msg(f, out.pose),
                   covariance=pose_cov.reshape(36)),
        twist=f.new(
            "geometry_msgs/msg/TwistWithCovariance",
            twist=f.new("geometry_msgs/msg/Twist", linear=_vector3(f, twist[:3]),
                        angular=_vector3(f, twist[3:])),
            covariance=np.zeros(36),
        ),
    )


def pose_stamped_msg(f: MessageFactory, t: float, T: np.ndarray, frame_id: str) -> Any:
    return f.new("geometry_msgs/msg/PoseStamped", header=header_msg(f, t, frame_id),
                 pose=pose_msg(f, T))


def path_msg(f: MessageFactory, poses: Iterable[tuple[float, np.ndarray]], frame_id: str,
             stamp: float | None = None) -> Any:
    """``[(stamp, 4x4)]`` -> ``nav_msgs/Path``; header stamp = last pose's unless given."""
    return path_of(f, [pose_stamped_msg(f, t, T, frame_id) for t, T in poses], frame_id, stamp)


def path_of(f: MessageFactory, pose_msgs: list, frame_id: str, stamp: float | None = None) -> Any:
    """``nav_msgs/Path`` of ``geometry_msgs/PoseStamped`` messages built before (a live path
    builds each pose's message once, not at every publication); header stamp = last pose's
    unless given."""
    if stamp is None:
        stamp = stamp_seconds(pose_msgs[-1].header) if pose_msgs else 0.0
    return f.new("nav_msgs/msg/Path", header=header_msg(f, stamp, frame_id), poses=pose_msgs)


def string_msg(f: MessageFactory, text: str) -> Any:
    return f.new("std_msgs/msg/String", data=text)


# ------------------------------------------------------------------------------------------
# degeneracy


def classify_twist(twist: np.ndarray, length: float, rotation_share: float = 0.2
                   ) -> dict[str, Any]:
    """Describe a plain unit twist ``(v, w)`` geometrically (frame of the twist).

    ``kind`` is ``"translation"`` when the rotation part is small in the scaled space
    (``|L w| < rotation_share * |(v, L w)|``), else ``"rotation"``, with the screw ``axis``
    (unit ``w``), the ``axis_point`` closest to the origin (``w x v / |w|^2`` [m]) and the
    ``pitch`` (``w . v / |w|^2`` [m/rad]).
    """
    xi = np.asarray(twist, dtype=np.float64).reshape(6)
    v, w = xi[:3], xi[3:]
    L = float(length) if length and length > 0 else 1.0
    scaled = math.sqrt(float(v @ v) + L * L * float(w @ w))
    wn = float(np.linalg.norm(w))
    if scaled == 0.0:
        return {"kind": "translation", "direction": [0.0, 0.0, 0.0]}
    if L * wn < rotation_share * scaled:
        vn = float(np.linalg.norm(v))
        return {"kind": "translation", "direction": (v / vn).tolist() if vn > 0 else [0.0] * 3}
    return {
        "kind": "rotation",
        "axis": (w / wn).tolist(),
        "axis_point": (np.cross(w, v) / (wn * wn)).tolist(),
        "pitch": float(w @ v) / (wn * wn),
    }


def _length_of(out: OdometryOutput) -> float:
    if out.degeneracy is not None and out.degeneracy.characteristic_length > 0:
        return float(out.degeneracy.characteristic_length)
    return 1.0


def degeneracy_basis_dict(out: OdometryOutput) -> dict[str, Any]:
    """The machine-readable degeneracy of one scan (JSON-ready).

    Schema (a superset of ``lili-odom detect --json``'s basis items)::

        {"stamp": s, "frame_id": "base_link", "method": str | null, "dimension": k,
         "basis": [{"translation": [3] m, "rotation": [3] rad, "kind": ..., ...}] (base_link),
         "weak_dimension": m, "weak_basis": [...] (as "basis"),
         "characteristic_length": L m, "pose": 4x4 fused pose (odom frame),
         "ok": bool, "reason": str, "runtime_s": s}

    ``basis``: the directions the LiDAR does not hold; ``weak_basis``: those it holds weakly
    (:attr:`OdometryOutput.weak_basis`).
    """
    L = _length_of(out)
    det = out.degeneracy

    def items(rows: Any) -> list[dict[str, Any]]:
        listed = []
        for row in np.asarray(rows, dtype=np.float64).reshape(-1, 6):
            item: dict[str, Any] = {"translation": row[:3].tolist(),
                                    "rotation": row[3:].tolist()}
            item.update(classify_twist(row, L))
            listed.append(item)
        return listed

    basis = items(out.degenerate_basis)
    weak = items(getattr(out, "weak_basis", np.zeros((0, 6))))
    return {
        "stamp": float(out.stamp),
        "frame_id": "base_link",
        "method": det.method if det is not None else None,
        "dimension": len(basis),
        "basis": basis,
        "weak_dimension": len(weak),
        "weak_basis": weak,
        "characteristic_length": L,
        "pose": np.asarray(out.pose, dtype=np.float64).tolist(),
        "ok": bool(det.ok) if det is not None else True,
        "reason": det.reason if det is not None else "",
        "runtime_s": float(det.runtime_s) if det is not None else 0.0,
    }


def degeneracy_json_msg(f: MessageFactory, out: OdometryOutput) -> Any:
    """``std_msgs/String`` holding :func:`degeneracy_basis_dict` as compact JSON."""
    return string_msg(f, json.dumps(degeneracy_basis_dict(out), separators=(",", ":")))


_TRANSLATION_RGBA = (1.0, 0.25, 0.1, 0.9)
_ROTATION_RGBA = (0.15, 0.45, 1.0, 0.9)
#: opacity of a weakly constrained direction's marker, relative to a degenerate one's
_WEAK_ALPHA = 1.0 / 3.0
_MARKER_DELETEALL = 3
_MARKER_ARROW = 0
_MARKER_SPHERE = 2
_MARKER_ADD = 0


def _rgba(f: MessageFactory, c: Sequence[float]) -> Any:
    return f.new("std_msgs/msg/ColorRGBA", r=c[0], g=c[1], b=c[2], a=c[3])


def degeneracy_markers(f: MessageFactory, out: OdometryOutput, frame_id: str,
                       arrow_length: float = 2.0, ns: str = "degeneracy") -> Any:
    """``visualization_msgs/MarkerArray`` for the degenerate basis of one scan.

    The first marker is a DELETEALL, so directions of earlier scans disappear. Markers are in
    ``frame_id`` (the odometry frame) at the fused pose: translations are orange arrows of
    ``arrow_length`` [m] from the robot; rotations are blue arrows of the same length centred
    on the axis point along the rotation axis, with a sphere on the axis point. Weakly
    constrained directions (:attr:`OdometryOutput.weak_basis`) follow in the same shapes,
    faint (alpha 0.3).
    """
    T = np.asarray(out.pose, dtype=np.float64)
    R, p = T[:3, :3], T[:3, 3]
    header = header_msg(f, out.stamp, frame_id)
    identity = pose_msg(f, np.eye(4))
    markers = [f.new("visualization_msgs/msg/Marker", header=header, ns=ns, id=0,
                     action=_MARKER_DELETEALL, pose=identity)]
    L = _length_of(out)
    basis = np.asarray(out.degenerate_basis, dtype=np.float64).reshape(-1, 6)
    weak = np.asarray(getattr(out, "weak_basis", np.zeros((0, 6))),
                      dtype=np.float64).reshape(-1, 6)
    next_id = 0
    for i, row in enumerate(np.vstack([basis, weak])):
        info = classify_twist(row, L)
        alpha = 1.0 if i < len(basis) else _WEAK_ALPHA
        if info["kind"] == "translation":
            start = p
            end = p + arrow_length * (R @ np.asarray(info["direction"]))
            colour = (*_TRANSLATION_RGBA[:3], _TRANSLATION_RGBA[3] * alpha)
        else:
            centre = p + R @ np.asarray(info["axis_point"])
            half = 0.5 * arrow_length * (R @ np.asarray(info["axis"]))
            start, end = centre - half, centre + half
            colour = (*_ROTATION_RGBA[:3], _ROTATION_RGBA[3] * alpha)
            markers.append(f.new(
                "visualization_msgs/msg/Marker", header=header, ns=ns, id=next_id,
                type=_MARKER_SPHERE, action=_MARKER_ADD, pose=pose_msg(f, _translation(centre)),
                scale=_vector3(f, (0.25, 0.25, 0.25)), color=_rgba(f, colour)))
            next_id += 1
        markers.append(f.new(
            "visualization_msgs/msg/Marker", header=header, ns=ns, id=next_id,
            type=_MARKER_ARROW, action=_MARKER_ADD, pose=identity,
            scale=_vector3(f, (0.08, 0.2, 0.3)), color=_rgba(f, colour),
            points=[_point(f, start), _point(f, end)]))
        next_id += 1
    return f.new("visualization_msgs/msg/MarkerArray", markers=markers)


def _translation(p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


# ------------------------------------------------------------------------------------------
# clouds and tf


def pointcloud_xyz_msg(f: MessageFactory, points: np.ndarray, t: float, frame_id: str,
                       times: np.ndarray | None = None) -> Any:
    """(N, 3) points [m] -> unorganized ``sensor_msgs/PointCloud2`` with float32 x, y, z.

    With ``times`` (N,) [s from ``t``] a float32 ``time`` field is added.
    """
    from lili_odom.pointcloud2 import encode_xyz_cloud

    content = encode_xyz_cloud(np.asarray(points, dtype=np.float64).reshape(-1, 3), times)
    fields = [f.new("sensor_msgs/msg/PointField", name=s.name, offset=s.offset,
                    datatype=s.datatype, count=s.count) for s in content.fields]
    return f.new(
        "sensor_msgs/msg/PointCloud2",
        header=header_msg(f, t, frame_id),
        height=content.height,
        width=content.width,
        fields=fields,
        is_bigendian=content.is_bigendian,
        point_step=content.point_step,
        row_step=content.row_step,
        data=content.data,
        is_dense=content.is_dense,
    )


def tf_message(f: MessageFactory, transforms: Iterable[tuple[float, str, str, np.ndarray]]
               ) -> Any:
    """``[(stamp, parent, child, T_parent_child)]`` -> ``tf2_msgs/TFMessage``."""
    items = []
    for t, parent, child, T in transforms:
        p, q = matrix_to_pose_values(T)
        items.append(f.new(
            "geometry_msgs/msg/TransformStamped",
            header=header_msg(f, t, parent),
            child_frame_id=child,
            transform=f.new("geometry_msgs/msg/Transform", translation=_vector3(f, p),
                            rotation=_quaternion(f, q)),
        ))
    return f.new("tf2_msgs/msg/TFMessage", transforms=items)
