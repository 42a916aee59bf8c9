"""The odometry's detector on a local map built from the true poses of a simulated run.

Each scan of the simulation is preprocessed exactly as the odometry preprocesses it
(:meth:`~lili_odom.pipeline.scan_matcher.ScanMatcher.preprocess`: range filter, first point per
0.5-voxel cell, KISS-ICP's deskew), but with the *true* sweep motion, and inserted into a
KISS-ICP local map at its *true* pose; the scan under test is then handed to the configured
detector (``PipelineConfig.method``, its ``detection_points`` thinning) with its true pose as
the initial guess. No deskew, registration or fusion error enters, so what the detector
reports there is its answer for the place: a scan the odometry flags where this finds dimension
0 is a false detection of the odometry. With a ``placement`` (e.g. a run's estimated poses) the
same map is built where the odometry put the scans instead, which shows what its drift does.

The map spans either the ``history_s`` seconds before the tested scan, or (``history_s`` None)
what the odometry's own map holds: every scan from the start of the simulation window, inserted
in order into one KISS-ICP map that drops the voxels beyond ``max_range`` of the latest pose.

Frames: ``world`` is the simulation's world frame, poses are ``T_world_lidar`` (os_lidar) at the
time of a sweep's last column. Times are trial times [s] (the bag's stamps are
``EPOCH_NS`` + trial time).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from lili_odom.degeneracy.detection_input import thin_evenly
from lili_odom.degeneracy.result import DegeneracyResult
from lili_odom.pipeline.odometry import PipelineConfig, make_detector
from lili_odom.pipeline.scan_matcher import ScanMatcher
from lili_odom.sim.generator import Simulation

__all__ = ["TruthMapDetection", "TruthMapDetector"]


@dataclass
class TruthMapDetection:
    """One scan's detection against the map from the true poses.

    Attributes:
        t_start: trial time of the scan's first column [s].
        t_end: trial time of its last column [s] (the odometry's stamp of the scan).
        pose: 4x4 ``T_world_lidar`` at ``t_end`` (true, or the placement's ``T_frame_lidar``).
        map_scans: scans inserted into the local map (from ``history_s`` before the scan, or
            from the window's start in the odometry's extent, not before the simulation
            window).
        points: scan points handed to the detector.
        result: the detector's result (``result.dimension``: 0 = constrained).
    """

    t_start: float
    t_end: float
    pose: np.ndarray
    map_scans: int
    points: int
    result: DegeneracyResult

    @property
    def dimension(self) -> int:
        return int(self.result.dimension)


class TruthMapDetector:
    """Detections of a simulation's scans against local maps built from the true poses (or
    from a ``placement``).

    Each sweep is simulated and preprocessed once: the last ``history_s`` worth of them is
    kept, so samples whose maps overlap share their scans. In the odometry's extent
    (``history_s`` None) one map per placement grows with every scan up to the tested one, so
    its detections must come in the order of their scans.

    Args:
        sim: the simulation (world, trajectory, sensors) of the run.
        config: the odometry's parameters whose scan matcher, detector and
            ``detection_points`` are used (default ``PipelineConfig()``; method ``none`` is
            refused).
        history_s: seconds of scans before the tested one that make up its local map
            (default 3.0; every scan of that span, as the odometry inserts every scan); None:
            the odometry's extent (every scan from the window's start, KISS-ICP's range
            pruning).
    """

    def __init__(self, sim: Simulation, config: PipelineConfig | None = None,
                 history_s: float | None = 3.0) -> None:
        self.sim = sim
        self.config = config or PipelineConfig()
        self.history_s = None if history_s is None else float(history_s)
        self.detector = make_detector(self.config)
        if self.detector is None:
            raise ValueError("a truth-map detection needs a detector (method is 'none')")
        self._base_to_lidar = sim.sensors.extrinsics.base_to_lidar
        self._period = sim.sensors.lidar.scan_period
        self._history_scans = (1 if self.history_s is None
                               else int(round(self.history_s / self._period)))
        self._preprocessor = ScanMatcher(self.config.scan_matcher)
        self._sweeps: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, float]] = {}
        # placement -> (its growing map, scans inserted, trial start of the next scan to insert)
        self._running: dict[object, tuple[ScanMatcher, int, float]] = {}

    def sweep(self, t_start: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(map points, source, true ``T_world_lidar``, trial time) of the scan starting at
        ``t_start``, all at its last column: preprocessed as the odometry does, with the true
        sweep motion, in the LiDAR frame there."""
        k = int(round(t_start / self._period))
        if k not in self._sweeps:
            scan = self.sim.scan(t_start)
            col_t = t_start + np.asarray(scan.t_ns, dtype=float) * 1e-9
            T_ends = self.sim.trajectory.pose(col_t[[0, -1]]) @ self._base_to_lidar
            xyz = np.asarray(scan.xyz, dtype=float)
            times = np.broadcast_to(col_t[None, :], xyz.shape[:2])
            finite = np.all(np.isfinite(xyz), axis=-1)
            sweep_motion = np.linalg.inv(T_ends[0]) @ T_ends[1]
            map_points, source = self._preprocessor.preprocess(xyz[finite], times[finite],
                                                               sweep_motion)
            for old in [j for j in self._sweeps if j < k - self._history_scans]:
                del self._sweeps[old]
            self._sweeps[k] = (np.asarray(map_points), np.asarray(source), T_ends[1],
                               float(col_t[-1]))
        return self._sweeps[k]

    def _pose(self, t_start: float, placement) -> np.ndarray | None:
        """``T_frame_lidar`` of the scan starting at ``t_start``: true, or from ``placement``
        (None when it has none)."""
        _, _, T_true, t_end = self.sweep(t_start)
        if placement is None:
            return T_true
        T_base = placement(t_end)
        return None if T_base is None else np.asarray(T_base) @ self._base_to_lidar

    def detect(self, t_start: float,
               placement: Callable[[float], np.ndarray | None] | None = None) -> TruthMapDetection:
        """The detection of the scan starting at trial time ``t_start`` against a map of the
        scans before it (the ``history_s`` before it, or from the window's start in the
        odometry's extent; none before the simulation window).

        ``placement``: ``f(t)`` -> 4x4 ``T_frame_base`` at trial time ``t`` (a sweep's last
        column), or None where there is none: where the scans are inserted and the tested one
        is guessed instead of their true poses (e.g. a run's estimate, to see what its drift
        does to the map); the sweeps are still deskewed with the true motion. Default None:
        the true poses. A scan without a placement is left out of the map (the tested one
        raises ``ValueError``).
        """
        matcher, inserted = (self._grown_map(t_start, placement) if self.history_s is None
                             else self._history_map(t_start, placement))
        _, source, _, t_end = self.sweep(t_start)
        T_end = self._pose(t_start, placement)
        if T_end is None:
            raise ValueError(f"no placement for the scan at {t_start:.2f} s")
        if matcher.map_empty:
            raise ValueError(f"no scan before {t_start:.2f} s in the window: nothing to detect against")
        source = thin_evenly(source, self.config.detection_points)
        result = self.detector.detect(matcher.reference, source, T_end)
        return TruthMapDetection(t_start=float(t_start), t_end=t_end, pose=T_end,
                                 map_scans=inserted, points=len(source), result=result)

    def _insert(self, matcher: ScanMatcher, t: float, placement) -> int:
        """Inserts the scan starting at ``t`` at its pose; 1 if it had one, else 0."""
        pose = self._pose(t, placement)
        if pose is None:
            return 0
        matcher.insert(self.sweep(t)[0], pose)
        return 1

    def _history_map(self, t_start: float, placement) -> tuple[ScanMatcher, int]:
        """A fresh map of the ``history_s`` seconds of scans before ``t_start``."""
        matcher = ScanMatcher(self.config.scan_matcher)
        window_start = self.sim.window()[0]
        inserted = 0
        for k in range(self._history_scans, 0, -1):
            t = t_start - k * self._period
            if t >= window_start - 1e-9:
                inserted += self._insert(matcher, t, placement)
        return matcher, inserted

    def _grown_map(self, t_start: float, placement) -> tuple[ScanMatcher, int]:
        """The placement's map grown by every scan from the window's start (or the last
        call) up to the one before ``t_start``."""
        matcher, inserted, t_next = self._running.get(
            placement, (ScanMatcher(self.config.scan_matcher), 0, self.sim.window()[0]))
        if t_start < t_next - self._period / 2:
            raise ValueError(f"the scan at {t_start:.2f} s comes before one already in the "
                             "map: detections in the odometry's extent go in scan order")
        n = int(round((t_start - t_next) / self._period))
        for k in range(n):
            inserted += self._insert(matcher, t_next + k * self._period, placement)
        self._running[placement] = (matcher, inserted, t_next + n * self._period)
        return matcher, inserted
