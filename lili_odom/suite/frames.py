"""Trajectories of every method in one frame: base_link in the method's odometry frame.

A LiDAR odometry (KISS-ICP, GenZ-ICP) reports ``T_lidar0_lidar(t)``, the LiDAR's pose in the
frame of its first scan. With the mounting ``T_base_lidar`` (the bag's ``/tf_static`` or the
configured extrinsics) the robot's pose in the frame of its first base_link pose is

    T_odom_base(t) = T_base_lidar · T_lidar0_lidar(t) · T_base_lidar^-1

which starts at the identity, as our odometry and the wheel odometry do (up to a constant
transform that the SE(3) alignment of the scoring removes).
"""
from __future__ import annotations

import numpy as np


def lidar_to_base(poses_lidar: np.ndarray, T_base_lidar: np.ndarray) -> np.ndarray:
    """(n, 4, 4) LiDAR poses in the first LiDAR frame -> base_link poses in the first
    base_link frame (see module docstring)."""
    poses = np.asarray(poses_lidar, dtype=float).reshape(-1, 4, 4)
    T = np.asarray(T_base_lidar, dtype=float)
    return T[None] @ poses @ np.linalg.inv(T)[None]
