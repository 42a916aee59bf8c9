"""The forward speed of a robot that starts while driving, from its first two sweeps.

Without wheel odometry the fusion starts at zero velocity, loosely held: an IMU cannot tell
driving at constant speed from rest. The first sweeps of the local map are then placed as if
the robot stood still, and every later registration against that map is pulled back by it:
on open ground the estimate ends metres behind. Two consecutive sweeps can tell the speed:
deskewed with the right motion and placed the right distance apart, they fit each other's
planes best.

:func:`forward_speed` tries base_link forward speeds (the rotation over the sweeps from the
gyro's mean rate), scores each by the point-to-plane cost of the second sweep on the first
one's planes (:func:`lili_odom.pipeline.plane_refinement.plane_cost`, the scan matcher's
voxelisation and deskew), first on a coarse grid and then finely around its best, and returns
the best speed when the cost rises on both sides of it. A featureless tunnel fits every speed
about alike: then there is no answer.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lili_odom import geometry
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.errors import check_range
from lili_odom.pipeline.plane_refinement import PlaneRefinementConfig, fit_planes, plane_cost
from lili_odom.pipeline.scan_matcher import ScanMatcher
from lili_odom.pipeline.start_sweeps import StartSweep


@dataclass
class StartSpeedConfig:
    """Finding the start speed without wheel odometry (``pipeline.start_speed.*``).

    Attributes:
        enabled: at the second scan of a start whose velocity is unknown (its prior's sigma
            above ``unknown_sigma``: no wheel odometry), search the forward speed and, when
            found, restart the fusion at the first scan with it and rebuild the local map
            from the first sweep deskewed with it. Default True.
        unknown_sigma: start velocity sigma [m/s] above which the speed counts as unknown;
            default 0.5 (wheels give 0.1, wheels at rest 0.05, none 1.0).
        max_speed: speeds from -max_speed to +max_speed are tried [m/s]; default 3.
        coarse_step: step of the first pass [m/s]; default 0.25.
        fine_step: step of the second pass, one coarse step either side of the first pass's
            best [m/s]; default 0.05.
        rise_at: the cost is compared this far either side of the best speed [m/s] (also
            beyond ``max_speed``); default 1.
        min_rise: the cost there must be higher by at least this fraction on both sides, or
            the speed counts as not found (dimensionless); default 0.05.
        min_speed: a found speed below this [m/s] leaves the start as it is (zero, loose
            prior): at rest or creeping, the registration's pull towards the previous pose
            does no harm, and the registration holds the start better than the search's
            0.05-0.1 m/s; default 0.3.
        velocity_sigma: sigma of the start velocity prior at the found speed [m/s]; default
            0.2.
        points: raw points per sweep searched with (drawn at random before the
            voxelisation: the search costs a deskew of both sweeps per speed tried); default
            20000.
    """

    enabled: bool = True
    unknown_sigma: float = 0.5
    max_speed: float = 3.0
    coarse_step: float = 0.25
    fine_step: float = 0.05
    rise_at: float = 1.0
    min_rise: float = 0.05
    min_speed: float = 0.3
    velocity_sigma: float = 0.2
    points: int = 20000

    def validate(self, prefix: str = "start_speed.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")``."""
        check_range(prefix + "unknown_sigma", self.unknown_sigma, 0.0, 100.0, lo_open=True,
                    unit="m/s")
        check_range(prefix + "max_speed", self.max_speed, 0.0, 50.0, lo_open=True, unit="m/s")
        check_range(prefix + "coarse_step", self.coarse_step, 0.0, self.max_speed, lo_open=True,
                    unit="m/s")
        check_range(prefix + "fine_step", self.fine_step, 0.0, self.coarse_step, lo_open=True,
                    unit="m/s")
        check_range(prefix + "rise_at", self.rise_at, 0.0, 2 * self.max_speed, lo_open=True,
                    unit="m/s")
        check_range(prefix + "min_rise", self.min_rise, 0.0, 10.0)
        check_range(prefix + "min_speed", self.min_speed, 0.0, self.max_speed, unit="m/s")
        check_range(prefix + "velocity_sigma", self.velocity_sigma, 0.0, 100.0, lo_open=True,
                    unit="m/s")
        check_range(prefix + "points", self.points, 1000, 10_000_000)


@dataclass(frozen=True)
class StartSpeed:
    """Outcome of :func:`forward_speed`.

    Attributes:
        speed: base_link forward speed [m/s], None when not found.
        rise: the smaller relative rise of the cost ``rise_at`` either side of the best speed
            (dimensionless; 0 when it could not be scored).
        costs: every speed tried [m/s] -> its cost (dimensionless, lower fits better).
    """

    speed: float | None
    rise: float
    costs: dict[float, float] = field(default_factory=dict)


def speed_cost(first: StartSweep, second: StartSweep, speed: float, rate: np.ndarray,
               matcher: ScanMatcher, T_base_lidar: np.ndarray,
               refine: PlaneRefinementConfig) -> float:
    """Point-to-plane cost (:func:`~lili_odom.pipeline.plane_refinement.plane_cost`, lower
    fits better; inf when nothing fits) of ``second`` on ``first``'s planes, both deskewed with
    base_link moving at ``speed`` [m/s] forward and turning at ``rate`` [rad/s], ``second``
    placed at that motion's travel between the sweeps' last points."""
    twist = geometry.adjoint(np.linalg.inv(T_base_lidar)) @ np.concatenate([[speed, 0.0, 0.0],
                                                                             rate])
    ref_points, _ = matcher.preprocess(first.points, first.times,
                                       geometry.exp(twist * (first.t_last - first.t_first)))
    points, _ = matcher.preprocess(second.points, second.times,
                                   geometry.exp(twist * (second.t_last - second.t_first)))
    reference = ReferenceMap.from_points(ref_points, matcher.config.voxel,
                                         matcher.config.max_points_per_voxel)
    pose = geometry.exp(twist * (second.t_last - first.t_last))
    cost = plane_cost(fit_planes(points, reference, pose, refine), pose, refine)
    return cost if np.isfinite(cost) else np.inf


def _thinned(sweep: StartSweep, points: int) -> StartSweep:
    """``sweep`` with ``points`` of its points drawn at random (seeded: the same sweep gives
    the same points; a regular stride would follow the sensor's ring and column pattern)."""
    if len(sweep.points) <= points:
        return sweep
    keep = np.sort(np.random.default_rng(0).choice(len(sweep.points), points, replace=False))
    return StartSweep(sweep.points[keep], sweep.times[keep], sweep.motion, sweep.pose,
                      sweep.t_first, sweep.t_last)


def forward_speed(first: StartSweep, second: StartSweep, matcher: ScanMatcher,
                  T_base_lidar: np.ndarray, rate: np.ndarray, config: StartSpeedConfig,
                  refine: PlaneRefinementConfig | None = None) -> StartSpeed:
    """The base_link forward speed [m/s] that fits two consecutive sweeps best.

    Args:
        first, second: the sweeps' raw points (``os_lidar``), per-point times and first /
            last point stamps [s] (their ``motion`` and ``pose`` are not used).
        matcher: voxelises and deskews them as the odometry does (its map is not touched).
        T_base_lidar: 4x4 pose of ``os_lidar`` in ``base_link``.
        rate: (3,) angular velocity of base_link over the sweeps [rad/s] (the gyro's mean).
        config: the search; refine: the plane fits (default :class:`PlaneRefinementConfig`).
    """
    refine = refine or PlaneRefinementConfig()
    rate = np.asarray(rate, dtype=float).reshape(3)
    if not (np.all(np.isfinite(rate)) and second.t_last > first.t_last):
        return StartSpeed(None, 0.0)
    first, second = (_thinned(s, config.points) for s in (first, second))
    costs: dict[float, float] = {}

    def cost(v: float) -> float:
        v = round(float(v), 6)
        if v not in costs:
            costs[v] = speed_cost(first, second, v, rate, matcher, T_base_lidar, refine)
        return costs[v]

    m = config.max_speed
    coarse = np.arange(-m, m + 1e-9, config.coarse_step)
    best = min(coarse, key=cost)
    fine = np.arange(best - config.coarse_step, best + config.coarse_step + 1e-9,
                     config.fine_step)
    best = min((v for v in fine if -m - 1e-9 <= v <= m + 1e-9), key=cost)
    c = cost(best)
    if not np.isfinite(c) or c <= 0:
        return StartSpeed(None, 0.0, dict(costs))
    sides = [cost(best - config.rise_at), cost(best + config.rise_at)]
    rise = float(min(sides) / c - 1.0) if np.all(np.isfinite(sides)) else 0.0
    speed = float(best) if rise >= config.min_rise else None
    return StartSpeed(speed, rise, dict(costs))
