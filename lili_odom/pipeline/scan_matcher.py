"""LiDAR front end: KISS-ICP deskewing, voxelisation, scan-to-map registration and local map.

Everything here is in the LiDAR frame (``os_lidar``) for scan points and the odometry frame for
poses of the LiDAR (``T_odom_lidar``). The map is updated only through ``update_map`` with the
pose the caller decides on (the fused pose, never the raw ICP result), so a degenerate stretch
cannot corrupt it.

KISS-ICP building blocks used as KISS-ICP uses them: ``Preprocessor`` (range filter + deskew; it
normalises per-point times to [0, 1] itself and deskews to the time of the *last* point),
``voxel_down_sample`` (0.5 voxel for the map, 1.5 voxel for registration), ``AdaptiveThreshold``
(gate 3 sigma, kernel sigma) and ``Registration.align_points_to_map`` (through the guarded
wrapper, so no invalid pose ever reaches Sophus). One difference from KISS-ICP's pipeline: the
points to keep are chosen on the raw sweep and only they are deskewed
(:mod:`lili_odom.pipeline.voxel_select`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from kiss_icp.config import KISSConfig
from kiss_icp.mapping import VoxelHashMap
from kiss_icp.preprocess import Preprocessor
from kiss_icp.threshold import AdaptiveThreshold
from kiss_icp.voxelization import voxel_down_sample

from lili_odom.degeneracy.reference import AlignmentResult, GuardedRegistration, ReferenceMap
from lili_odom.geometry import is_valid_pose, orthonormalize
from lili_odom.pipeline.voxel_select import first_in_voxel


@dataclass
class ScanMatcherConfig:
    """KISS-ICP parameters (KISS-ICP's defaults unless noted).

    Attributes:
        max_range / min_range: range filter [m] (min 1.0 m drops the Husky's own body).
        point_stride: use every n-th point of each cloud, in the cloud's own order (an
            organised Ouster cloud whose width is a multiple of n: every n-th column of each
            ring), read before anything else; 1 (default) uses every point. For a small
            computer with a dense sensor: less to parse and to voxelise, fewer map points far
            away (``docs/performance.md``).
        voxel_size: map voxel [m]; 0 -> ``max_range / 100`` as KISS-ICP does.
        max_points_per_voxel: map capacity per voxel.
        initial_threshold: adaptive threshold before enough motion was seen [m].
        min_motion_th: motion below which the threshold model is not updated [m].
        max_iterations / convergence: ICP settings.
        deskew: motion-compensate the sweep with the predicted motion.
        max_threads: native threads (0 = all).
    """

    max_range: float = 100.0
    min_range: float = 1.0
    point_stride: int = 1
    voxel_size: float = 0.0
    max_points_per_voxel: int = 20
    initial_threshold: float = 2.0
    min_motion_th: float = 0.1
    max_iterations: int = 500
    convergence: float = 1e-4
    deskew: bool = True
    max_threads: int = 0

    @property
    def voxel(self) -> float:
        return float(self.voxel_size if self.voxel_size > 0 else self.max_range / 100.0)

    def validate(self) -> None:
        checks = {
            "max_range": self.max_range > 0,
            "min_range": 0 <= self.min_range < self.max_range,
            "point_stride": 1 <= self.point_stride <= 64,
            "voxel_size": self.voxel_size >= 0,
            "max_points_per_voxel": self.max_points_per_voxel >= 1,
            "initial_threshold": self.initial_threshold > 0,
            "min_motion_th": self.min_motion_th >= 0,
            "max_iterations": self.max_iterations >= 1,
            "convergence": self.convergence > 0,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ValueError(f"invalid scan matcher parameter(s): {', '.join(bad)}")


class ScanMatcher:
    """Deskew, downsample, register against and maintain the local map."""

    def __init__(self, config: ScanMatcherConfig | None = None):
        self.config = config or ScanMatcherConfig()
        self.config.validate()
        c = self.config
        kiss = KISSConfig()
        kiss.data.max_range = c.max_range
        kiss.adaptive_threshold.initial_threshold = c.initial_threshold
        kiss.adaptive_threshold.min_motion_th = c.min_motion_th
        self._kiss_config = kiss
        self._preprocessor = Preprocessor(c.max_range, c.min_range, c.deskew, c.max_threads)
        self._registration = GuardedRegistration(c.max_iterations, c.convergence, c.max_threads)
        self._single_step = GuardedRegistration(1, c.convergence, c.max_threads)
        self.reset()

    def reset(self) -> None:
        """Forget the map and the threshold model (e.g. after a clock jump backwards)."""
        self.clear_map()
        self._threshold = AdaptiveThreshold(self._kiss_config)

    def clear_map(self) -> None:
        """Forget the map only (the threshold model stays)."""
        c = self.config
        self.voxel_map = VoxelHashMap(c.voxel, c.max_range, c.max_points_per_voxel)
        self.reference = ReferenceMap(self.voxel_map, c.voxel, c.max_points_per_voxel)

    @property
    def map_empty(self) -> bool:
        return self.voxel_map.empty()

    def preprocess(
        self, points: np.ndarray, times: np.ndarray | None, sweep_motion: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Range-filter, deskew and voxelise a sweep.

        The first point of each 0.5-voxel cell of the raw sweep is kept
        (:func:`~lili_odom.pipeline.voxel_select.first_in_voxel`, with the points of the
        first and last time, which fix KISS-ICP's time normalisation), and only those are
        range-filtered and deskewed: each kept point is deskewed exactly as KISS-ICP's
        ``Preprocessor`` deskews it in the whole sweep.

        Args:
            points: (N, 3) finite points in the LiDAR frame [m].
            times: (N,) per-point times [s] (any offset; KISS-ICP normalises them) or None.
            sweep_motion: 4x4 LiDAR motion from the first to the last point time
                (``T_lidar(t_first)^-1 T_lidar(t_last)``).

        Returns:
            (map_points, source): the kept points deskewed into the LiDAR frame at the time of
            the last point (to insert in the map), and those downsampled to 1.5 voxel (to
            register).
        """
        times = None if times is None else np.asarray(times, dtype=float).reshape(-1)
        if (times is None or len(times) != len(points) or len(times) == 0
                or not np.all(np.isfinite(times)) or not 0 < np.ptp(times) < np.inf):
            # KISS-ICP normalises times by their span: a zero span gives 0/0 and a NaN rotation
            # that aborts the process inside Sophus, and so does a span that overflows to
            # inf (finite times near +-1e308). An empty time array skips deskewing.
            times = np.zeros(0)
        motion = deskew_motion(sweep_motion)
        v = self.config.voxel
        points = np.asarray(points)
        keep = first_in_voxel(points, 0.5 * v)
        if keep is None:  # cells that cannot be packed: KISS-ICP's order of work
            frame = self._preprocessor.preprocess(points, times, motion)
            map_points = np.asarray(voxel_down_sample(frame, 0.5 * v))
        else:
            if len(times):
                ends = [i for i in sorted({int(np.argmin(times)), int(np.argmax(times))})
                        if not np.any(keep == i)]  # np.setdiff1d without sorting keep
                keep = np.concatenate([keep, np.asarray(ends, dtype=keep.dtype)])
                times = times[keep]
            map_points = np.asarray(self._preprocessor.preprocess(points[keep], times, motion))
        source = voxel_down_sample(map_points, 1.5 * v)
        return map_points, source

    def register(self, source: np.ndarray, guess: np.ndarray) -> AlignmentResult:
        """Align ``source`` (LiDAR frame) to the map from ``guess`` (``T_odom_lidar``).

        With an empty map (the first scan) the guess is returned with ``ok=True``.
        """
        if self.map_empty:
            return AlignmentResult(orthonormalize(guess), True, "first scan")
        sigma = float(self._threshold.get_threshold())
        result = self._registration.align(source, self.reference, guess, 3.0 * sigma, sigma)
        return result

    def step(self, source: np.ndarray, pose: np.ndarray) -> np.ndarray | None:
        """One ICP iteration (re-association and update) of ``source`` from ``pose``
        (``T_odom_lidar``) with the registration's gate; None when it failed."""
        if self.map_empty:
            return None
        sigma = float(self._threshold.get_threshold())
        result = self._single_step.align(source, self.reference, pose, 3.0 * sigma, sigma)
        return result.pose if result.ok else None

    @property
    def threshold(self) -> float:
        return float(self._threshold.get_threshold())

    def update_map(self, map_points: np.ndarray, pose: np.ndarray,
                   model_deviation: np.ndarray) -> np.ndarray:
        """Insert ``map_points`` (LiDAR frame) at ``pose`` and update the threshold model;
        returns the pose inserted at (re-orthonormalised), for a mirror of the map.

        ``model_deviation`` is ``guess^-1 @ pose`` (how far the prediction was off).
        """
        if is_valid_pose(model_deviation, 1e-3):
            self._threshold.update_model_deviation(orthonormalize(model_deviation))
        return self.insert(map_points, pose)

    def insert(self, map_points: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """Insert ``map_points`` (LiDAR frame) at ``pose`` (``T_odom_lidar``) without touching
        the threshold model; returns the pose inserted at (re-orthonormalised)."""
        pose = orthonormalize(pose)
        insert_scan(self.reference, map_points, pose)
        return pose

    def map_points(self) -> np.ndarray:
        """(M, 3) points of the local map in the odometry frame [m]."""
        return np.asarray(self.voxel_map.point_cloud()).reshape(-1, 3)


def deskew_motion(sweep_motion: np.ndarray) -> np.ndarray:
    """The sweep motion a sweep is deskewed with: ``sweep_motion`` re-orthonormalised, or the
    identity (no deskew) when it is not a valid rigid transform."""
    return orthonormalize(sweep_motion) if is_valid_pose(sweep_motion, 1e-3) else np.eye(4)


def insert_scan(reference: ReferenceMap, points: np.ndarray, pose: np.ndarray) -> None:
    """Insert ``points`` (LiDAR frame) into ``reference``'s voxel map at ``pose`` (a valid
    ``T_odom_lidar``): KISS-ICP's update, which also drops the voxels beyond ``max_range`` of
    the pose. The one way the local map changes, so that a mirror of it stays identical."""
    if len(points):
        reference.voxel_map.update(points, pose)
    reference.invalidate()
