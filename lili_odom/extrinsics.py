"""Default sensor mounting: an Ouster OS1 on a Clearpath Husky.

Frames (REP-105, ``T_parent_child`` maps child points into the parent):
``base_link -> os_sensor -> os_lidar`` and ``os_sensor -> os_imu``. Each transform is given as
``(x, y, z, roll, pitch, yaw)`` in metres and radians, ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

* ``os_sensor -> os_lidar``: the OS1's ``lidar_to_sensor_transform``: yawed 180 deg about z,
  36.18 mm up (Ouster datasheet / driver metadata).
* ``os_sensor -> os_imu``: the OS1's ``imu_to_sensor_transform``: (6.253, -11.775, 7.645) mm,
  no rotation.
* ``base_link -> os_sensor``: robot specific; the default is the OS1 on a 0.40 m mast on the
  Husky's top plate, 0.10 m ahead of base_link (0.65 m above it). Measure yours.
"""
from __future__ import annotations

import math
import typing

import numpy as np

__all__ = ["OS1_SENSOR_TO_LIDAR", "OS1_SENSOR_TO_IMU", "HUSKY_BASE_TO_SENSOR",
           "pose_from_xyz_rpy"]

OS1_SENSOR_TO_LIDAR: tuple[float, ...] = (0.0, 0.0, 0.03618, 0.0, 0.0, math.pi)
OS1_SENSOR_TO_IMU: tuple[float, ...] = (0.006253, -0.011775, 0.007645, 0.0, 0.0, 0.0)
HUSKY_BASE_TO_SENSOR: tuple[float, ...] = (0.10, 0.0, 0.65, 0.0, 0.0, 0.0)


def pose_from_xyz_rpy(values: typing.Sequence[float]) -> np.ndarray:
    """4x4 from ``[x, y, z, roll, pitch, yaw]`` (m, rad; R = Rz(yaw) Ry(pitch) Rx(roll))."""
    x, y, z, roll, pitch, yaw = (float(v) for v in values)
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    T = np.eye(4)
    T[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                 [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                 [-sp, cp * sr, cp * cr]]
    T[:3, 3] = [x, y, z]
    return T
