"""The first sweeps of a new local map, deskewed again once the motion is known.

A sweep is deskewed with the motion the fusion predicts over it. For the first sweep of a new
map there is no prediction (no deskew), and for the second it comes from the start's velocity
prior: zero, unless the wheels report motion (an IMU cannot tell driving at constant speed from
standing still). A robot or a recording that starts while moving therefore builds its map from
sweeps smeared by up to one sweep's travel, and every later sweep, deskewed with the motion the
fusion has estimated by then, registers against that smear about half a sweep's travel off
(about 12 cm at 2.5 m/s and 10 Hz).

:class:`StartSweeps` keeps the raw points of the first ``count`` sweeps inserted into an empty
map. Once they are all in, the fused body twist at the last of them (``os_lidar``, constant over
these few sweeps) gives each one's motion over its sweep; a sweep whose motion differs from the
one it was deskewed with by more than ``tolerance_m`` at ``reach_m`` from the sensor gets the
new one, and the caller rebuilds the map from the same points, inserted at the same poses. A
start at rest, or one whose wheels gave the speed from the second sweep on, deskews with (nearly)
the right motion already: those sweeps keep theirs, and nothing changes when none differs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lili_odom import geometry


@dataclass
class StartSweep:
    """One sweep inserted into a young map.

    Attributes:
        points: (N, 3) the sweep's points as given to the scan matcher (``os_lidar``) [m].
        times: (N,) their per-point times [s] (empty or constant: not deskewed).
        motion: 4x4 LiDAR motion from the first to the last point time it was deskewed with
            (a valid rigid transform).
        pose: 4x4 ``T_odom_lidar`` it was inserted at (time of its last point).
        t_first / t_last: stamps of its first and last point [s].
    """

    points: np.ndarray
    times: np.ndarray
    motion: np.ndarray
    pose: np.ndarray
    t_first: float
    t_last: float


class StartSweeps:
    """The first sweeps of each new map, until the motion they were deskewed with is checked.

    Args:
        count: sweeps kept, at least 2 (the twist at the last is used for all). Default 2.
        tolerance_m: largest change of a point's deskewed position, at ``reach_m`` from the
            sensor, that leaves the map as it is [m]. Default 0.01.
        reach_m: range at which rotations are judged [m]. Default 10.
        max_gap_s: longest time between the first and the last kept sweep over which the
            twist counts as constant [s]; beyond it nothing is rebuilt. Default 0.5.
        significance: a fused speed below this many of its standard deviations counts as
            none. Default 3.
    """

    def __init__(self, count: int = 2, tolerance_m: float = 0.01, reach_m: float = 10.0,
                 max_gap_s: float = 0.5, significance: float = 3.0):
        if count < 2:
            raise ValueError(f"count must be >= 2, got {count}")
        self.count = count
        self.tolerance_m = tolerance_m
        self.reach_m = reach_m
        self.max_gap_s = max_gap_s
        self.significance = significance
        self._sweeps: list[StartSweep] | None = None

    @property
    def collecting(self) -> bool:
        """Sweeps of the current map are being kept (a sweep into a non-empty map is added
        only then)."""
        return self._sweeps is not None

    @property
    def due(self) -> bool:
        """The next sweep added to the same map completes the kept ones (its twist is used)."""
        return self._sweeps is not None and len(self._sweeps) == self.count - 1

    def replace(self, sweep: StartSweep) -> None:
        """Keep ``sweep`` instead of the kept one that ends at the same stamp (the caller
        deskewed it again and rebuilt the map from it)."""
        if self._sweeps is not None:
            self._sweeps = [sweep if s.t_last == sweep.t_last else s for s in self._sweeps]

    def add(self, sweep: StartSweep, map_was_empty: bool, twist: np.ndarray,
            speed_sigma: float | None = 0.0) -> list[StartSweep] | None:
        """Record a sweep just inserted into the map (``map_was_empty``: the first of a new
        map) with the fused body twist of the LiDAR at its last point (``(v [m/s],
        w [rad/s])`` in ``os_lidar``) and the standard deviation of the fused speed [m/s]
        (None: unknown). A speed below ``significance`` times its sigma counts as none: after
        two sweeps without wheels the fused speed of a robot at rest in a degenerate place
        is what a sliding registration made it (the rotation comes from the gyro and is kept).

        Returns:
            None, or once the ``count``-th sweep is in and the motion differs from the one
            they were deskewed with: the kept sweeps with ``motion`` set to the one to
            deskew them with now; the caller rebuilds the map from them. Either way the
            sweeps are then dropped.
        """
        if map_was_empty:
            self._sweeps = []
        if self._sweeps is None:
            return None
        self._sweeps.append(sweep)
        if len(self._sweeps) < self.count:
            return None
        sweeps, self._sweeps = self._sweeps, None
        twist = np.array(twist, dtype=float).reshape(6)
        if speed_sigma is None or not np.linalg.norm(twist[:3]) > self.significance * speed_sigma:
            twist[:3] = 0.0
        return self._remotioned(sweeps, twist)

    def _remotioned(self, sweeps: list[StartSweep], twist: np.ndarray) -> list[StartSweep] | None:
        if not (0 < sweeps[-1].t_last - sweeps[0].t_last <= self.max_gap_s
                and np.all(np.isfinite(twist))):
            return None
        redone = []
        changed = False
        for s in sweeps:
            if len(s.times) and np.ptp(s.times) > 0:
                motion = geometry.exp(twist * (s.t_last - s.t_first))
                d = geometry.log(np.linalg.inv(s.motion) @ motion)
                if np.linalg.norm(d[:3]) + np.linalg.norm(d[3:]) * self.reach_m > self.tolerance_m:
                    changed = True
                    s = StartSweep(s.points, s.times, motion, s.pose, s.t_first, s.t_last)
            redone.append(s)
        return redone if changed else None
