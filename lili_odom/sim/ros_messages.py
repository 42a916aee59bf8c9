"""Build ROS 2 messages (rosbags ROS2_JAZZY typestore) from simulated data. No rclpy.

Layouts follow ``shared/design.md``: PointCloud2 in the ouster-ros "original" point layout,
sensor_msgs/Imu without orientation, nav_msgs/Odometry for wheels and truth, tf2_msgs/TFMessage
for ``/tf_static``. Times are ROS ``builtin_interfaces/Time`` from integer nanoseconds.
"""
from __future__ import annotations

import numpy as np
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from lili_odom.sim.lidar import Scan

__all__ = ["OUSTER_DTYPE", "OUSTER_FIELDS", "MessageFactory", "typestore", "scan_to_array"]

# ouster-ros "original" point type (PointXYZIR + t/ambient/range/reflectivity), 48-byte stride.
OUSTER_FIELDS = [
    # name, offset, PointField datatype, numpy type
    ("x", 0, 7, np.float32),
    ("y", 4, 7, np.float32),
    ("z", 8, 7, np.float32),
    ("intensity", 16, 7, np.float32),
    ("t", 20, 6, np.uint32),
    ("reflectivity", 24, 4, np.uint16),
    ("ring", 26, 4, np.uint16),
    ("ambient", 28, 4, np.uint16),
    ("range", 32, 6, np.uint32),
]
POINT_STEP = 48
OUSTER_DTYPE = np.dtype({
    "names": [f[0] for f in OUSTER_FIELDS],
    "formats": [f[3] for f in OUSTER_FIELDS],
    "offsets": [f[1] for f in OUSTER_FIELDS],
    "itemsize": POINT_STEP,
})

_TYPESTORE = None


def typestore():
    """The shared ROS 2 Jazzy typestore."""
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def scan_to_array(scan: Scan) -> np.ndarray:
    """Scan -> (rows, cols) structured array in the ouster-ros layout (padding bytes zero)."""
    rows, cols = scan.range_mm.shape
    a = np.zeros((rows, cols), dtype=OUSTER_DTYPE)
    a["x"], a["y"], a["z"] = scan.xyz[..., 0], scan.xyz[..., 1], scan.xyz[..., 2]
    a["intensity"] = scan.intensity
    a["t"] = scan.t_ns[None, :]
    a["reflectivity"] = scan.reflectivity
    a["ring"] = np.arange(rows, dtype=np.uint16)[:, None]
    a["ambient"] = scan.ambient
    a["range"] = scan.range_mm
    return a


def _quat(R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_quat()  # x, y, z, w


class MessageFactory:
    """Creates typestore message objects. ``t`` arguments are integer nanoseconds."""

    def __init__(self):
        ts = typestore()
        self.ts = ts
        T = ts.types
        self.Time = T["builtin_interfaces/msg/Time"]
        self.Header = T["std_msgs/msg/Header"]
        self.PointField = T["sensor_msgs/msg/PointField"]
        self.PointCloud2 = T["sensor_msgs/msg/PointCloud2"]
        self.Imu = T["sensor_msgs/msg/Imu"]
        self.Odometry = T["nav_msgs/msg/Odometry"]
        self.Vector3 = T["geometry_msgs/msg/Vector3"]
        self.Point = T["geometry_msgs/msg/Point"]
        self.Quaternion = T["geometry_msgs/msg/Quaternion"]
        self.Pose = T["geometry_msgs/msg/Pose"]
        self.PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
        self.Twist = T["geometry_msgs/msg/Twist"]
        self.TwistWithCovariance = T["geometry_msgs/msg/TwistWithCovariance"]
        self.Transform = T["geometry_msgs/msg/Transform"]
        self.TransformStamped = T["geometry_msgs/msg/TransformStamped"]
        self.TFMessage = T["tf2_msgs/msg/TFMessage"]
        self.fields = [self.PointField(name=n, offset=o, datatype=d, count=1) for n, o, d, _ in OUSTER_FIELDS]

    def header(self, t_ns: int, frame: str):
        return self.Header(stamp=self.Time(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000)), frame_id=frame)

    def _vec(self, v):
        return self.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def _q(self, q):
        return self.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def serialize(self, msg) -> bytes:
        return self.ts.serialize_cdr(msg, msg.__msgtype__)

    def pointcloud2(self, scan: Scan, t_ns: int, frame: str = "os_lidar"):
        """Organised ouster-ros cloud; header.stamp = scan start ``t_ns``."""
        a = scan_to_array(scan)
        rows, cols = a.shape
        return self.PointCloud2(
            header=self.header(t_ns, frame),
            height=rows,
            width=cols,
            fields=self.fields,
            is_bigendian=False,
            point_step=POINT_STEP,
            row_step=POINT_STEP * cols,
            data=a.reshape(-1).view(np.uint8),
            is_dense=False,
        )

    def imu(self, t_ns: int, gyro, accel, gyro_var: float, accel_var: float, frame: str = "os_imu"):
        """Imu with orientation unset (orientation_covariance[0] = -1, REP-145)."""
        ocov = np.zeros(9)
        ocov[0] = -1.0
        return self.Imu(
            header=self.header(t_ns, frame),
            orientation=self._q([0.0, 0.0, 0.0, 1.0]),
            orientation_covariance=ocov,
            angular_velocity=self._vec(gyro),
            angular_velocity_covariance=np.diag([gyro_var] * 3).reshape(-1).astype(np.float64),
            linear_acceleration=self._vec(accel),
            linear_acceleration_covariance=np.diag([accel_var] * 3).reshape(-1).astype(np.float64),
        )

    def odometry(self, t_ns: int, frame: str, child: str, T: np.ndarray, v_lin, v_ang,
                 pose_cov: np.ndarray | None = None, twist_cov: np.ndarray | None = None,
                 quat: np.ndarray | None = None):
        """Odometry: pose ``T`` (4x4) of ``child`` in ``frame``; twist (linear, angular) in child.
        ``quat`` (x, y, z, w) of ``T``'s rotation when already known (saves converting it here)."""
        q = _quat(T[:3, :3]) if quat is None else quat
        pose = self.Pose(position=self.Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                         orientation=self._q(q))
        return self.Odometry(
            header=self.header(t_ns, frame),
            child_frame_id=child,
            pose=self.PoseWithCovariance(pose=pose, covariance=np.asarray(pose_cov if pose_cov is not None else np.zeros(36), dtype=np.float64).reshape(-1)),
            twist=self.TwistWithCovariance(
                twist=self.Twist(linear=self._vec(v_lin), angular=self._vec(v_ang)),
                covariance=np.asarray(twist_cov if twist_cov is not None else np.zeros(36), dtype=np.float64).reshape(-1),
            ),
        )

    def tf_static(self, t_ns: int, transforms: list[tuple[str, str, np.ndarray]]):
        """TFMessage of (parent, child, T_parent_child) triples."""
        out = []
        for parent, child, T in transforms:
            out.append(self.TransformStamped(
                header=self.header(t_ns, parent),
                child_frame_id=child,
                transform=self.Transform(translation=self._vec(T[:3, 3]), rotation=self._q(_quat(T[:3, :3]))),
            ))
        return self.TFMessage(transforms=out)
