"""Sensor inputs and odometry outputs of the pipeline, free of any ROS type.

Times are seconds (float) from the sensor ``header.stamp``; never a bag's log time.
Twists are ``(v, w)`` (translation first). Poses are 4x4 float64.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lili_odom.degeneracy.result import DegeneracyResult


@dataclass
class ImuSample:
    """One IMU message in the IMU frame (``os_imu``).

    Attributes:
        stamp: header stamp [s].
        angular_velocity: (3,) [rad/s].
        linear_acceleration: (3,) specific force incl. gravity [m/s^2].
    """

    stamp: float
    angular_velocity: np.ndarray
    linear_acceleration: np.ndarray


@dataclass
class WheelSample:
    """One wheel-odometry message (``nav_msgs/Odometry``, ``odom`` -> ``base_link``).

    Attributes:
        stamp: header stamp [s].
        twist: (6,) body twist of base_link in base_link ``(v [m/s], w [rad/s])``.
        pose: 4x4 integrated pose of base_link in the wheel ``odom`` frame (may drift).
        twist_covariance: 6x6 in ``(v, w)`` order, or None when unset.
    """

    stamp: float
    twist: np.ndarray
    pose: np.ndarray | None = None
    twist_covariance: np.ndarray | None = None


@dataclass
class Scan:
    """One LiDAR sweep in the LiDAR frame (``os_lidar``).

    Attributes:
        stamp: header stamp [s] (ouster-ros: start of the sweep).
        points: (N, 3) float64 [m], finite, already range-filtered.
        times: (N,) per-point time offsets from ``stamp`` [s], or None when the cloud has none.
        frame_id: the cloud's frame.
        dropped: points removed while parsing (NaN, zero range, out of range).
    """

    stamp: float
    points: np.ndarray
    times: np.ndarray | None = None
    frame_id: str = "os_lidar"
    dropped: int = 0


@dataclass
class OdometryOutput:
    """The pipeline's answer for one scan.

    Attributes:
        stamp: time the pose refers to [s] (the scan's reference time).
        pose: 4x4 fused pose of base_link in the odometry frame.
        twist: (6,) fused body twist of base_link ``(v [m/s], w [rad/s])``.
        covariance: 6x6 pose covariance in base_link, ``(v, w)`` order, honest (large) along
            directions only weakly constrained.
        degeneracy: the detector's result (None for ``none`` or when skipped).
        degenerate_basis: (k, 6) plain unit twists of the degenerate subspace in base_link:
            the directions the LiDAR does not hold (the wheels and the IMU do).
        weak_basis: (m, 6) plain unit twists in base_link of the directions of the detected
            subspace that the LiDAR still holds, with less information than a constrained
            direction (``plane_refinement.held_information`` up to ``clear_information``);
            the fusion takes them with the LiDAR's measured weight. Empty unless the
            point-to-plane refinement measured the subspace.
        icp_pose: 4x4 raw registration result of base_link (for diagnostics, never the map).
        timings: seconds per stage (parse, deskew, icp, detector, fusion, map, total).
        warnings: human-readable notes for this scan (e.g. "no wheel data").
    """

    stamp: float
    pose: np.ndarray
    twist: np.ndarray
    covariance: np.ndarray
    degeneracy: DegeneracyResult | None = None
    degenerate_basis: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    weak_basis: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    icp_pose: np.ndarray | None = None
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)
