"""Online calibration of the wheel odometry's distance scale from well-constrained LiDAR.

Inside a degenerate subspace the fused motion *is* the wheel motion, so a wheel scale error
becomes drift at the same rate: 1 % over a 200 m featureless tunnel is 2 m along its axis. Tyre
radius, load and surface change that scale by around a percent on a skid-steer robot, so it
cannot be trusted from the robot's description. Where the registration is not degenerate, the
LiDAR measures the same motion far better than the wheels; this module estimates

    s = (distance the wheels report) / (distance the LiDAR measured)

over the recent non-degenerate travel and divides the translation of every wheel increment
by it before the increment enters the graph.

Which registrations count: fully constrained ones, and those with a degenerate subspace whose
LiDAR information (what the registration keeps plus the LiDAR's own information inside the
subspace, :mod:`lili_odom.pipeline.plane_refinement`) still holds the direction of travel to
``max_lidar_sigma`` (``max_lidar_sigma_start`` until the estimate is established); the
latter are compared through the pose refined inside the subspace, never through the
registration held at the wheels' prediction there.

The LiDAR side is not compared increment by increment: a registration is a few centimetres
off along a weakly constrained axis, which at 10 cm per scan makes single-increment ratios
swing between 0.6 and 3, and any gate on them biases the estimate by percents. Instead
consecutive fully constrained increments are chained into *segments*; the LiDAR distance of a
segment is the displacement between the registrations at its two ends (per-scan errors
telescope away, leaving two endpoint errors over metres of travel), and the wheel distance is
the wheels' translations over the same scans, rotated into the segment's start frame with the
LiDAR's orientations (so a wheel *yaw* error does not shorten the chord). A segment ends and
is used when ``segment_m`` of wheel travel is reached, or earlier when the chain is broken
(degenerate scan, no registration, reset) if it covered ``min_segment_m``. Its ends are only
placed at steady speed (the last ``steady_scans`` wheel increments within
``steady_ratio``), because a registration that loses ground while the robot accelerates from
rest would otherwise put its shortfall into the first segment.

Inside a segment, a slip (the wheels over-read by tens of percent for a second) is cut out
before the segment is used: the segment is split into pieces of ``slip_piece_m`` of wheel
travel, each piece's ratio is compared with the median piece's, and pieces off by more than
``slip_piece_ratio`` lose both their wheel and their LiDAR distance. Over a metre the
registrations' endpoint errors move a piece's ratio by a few percent, a slip by tens of
percent. Without this, the first segments (before any estimate exists to gate them) carry a
slip straight into the scale: 1 s of a 35 % over-read at 1 m/s in a 5 m segment raises its
ratio by 7 %.

Segments that disagree with the current estimate by more than the slip gate are not used
(wheels spinning, bad registration); after ``max_rejections`` rejected segments in a row the
estimate itself is taken to be wrong and restarted. Each segment counts with its LiDAR
distance; older travel fades with ``window_m`` so a changed surface is followed. Until
``min_distance_m`` of accepted travel was seen, the scale is 1.

The scale is a Huber M-estimate of the segments' ratios (threshold ``robust_ratio``), not their
plain distance-weighted mean. A slip event (the wheels over-read by tens of percent for a
second, on grass, mud or a wet floor) inside a segment raises its ratio by a few percent, and
the first segments, before the estimate exists, have no slip gate to stop it. With only a few
segments before a featureless stretch, one such segment moves a plain mean by about a percent,
which the featureless stretch then turns into drift, while the registrations' endpoint errors
scatter honest segments by about a percent too. The Huber estimate is the mean while the
segments agree within ``robust_ratio`` and bounds the pull of one that does not.

Frames and units: increments are 4x4 motions of base_link from the previous scan, expressed
in base_link at the previous scan [m]; the scale is dimensionless.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["ClosedSegment", "WheelScaleConfig", "WheelScaleEstimator"]


@dataclass
class WheelScaleConfig:
    """Attributes:
        enabled: estimate and apply the wheel distance scale (False: scale 1).
        min_distance_m: accepted LiDAR-constrained travel needed before the estimate is
            applied [m].
        window_m: travel over which old segments fade (exponential, per metre) [m].
        min_scale / max_scale: the estimate is clamped to this range; before any estimate,
            segments outside it are rejected.
        segment_m: wheel travel after which a segment is closed and used [m].
        min_segment_m: a segment broken off earlier is used only if it covered this much [m].
        steady_ratio / steady_scans: a segment end needs the last ``steady_scans`` wheel
            increments to differ by less than this fraction of their mean (plus 2 mm) and to
            move (>= 1 cm per scan).
        slip_gate_m / slip_gate_ratio: a segment whose wheel distance differs from the current
            scale times its LiDAR distance by more than ``slip_gate_m + slip_gate_ratio *
            distance`` is not used.
        max_rejections: that many rejected segments in a row restart the estimate.
        robust_ratio: Huber threshold on a segment's ratio's deviation from the estimate
            (dimensionless; 0.015 = 1.5 %); 0 = plain distance-weighted mean.
        slip_piece_m: wheel travel of the pieces a segment is split into to find slips [m].
        slip_piece_ratio: a piece whose wheel/LiDAR ratio differs from the segment's median
            piece ratio by more than this fraction is cut out of the segment (0 = off).
        max_lidar_sigma: an increment whose registration has a degenerate subspace is still
            chained when the LiDAR (the kept information plus its own information inside the
            subspace) holds the wheels' direction of travel to this 1-sigma [m]; 0 = only
            fully constrained registrations are chained. Default 0.03.
        max_lidar_sigma_start: the same limit until the estimate is established
            (``min_distance_m`` of accepted travel) [m], when ``max_lidar_sigma`` is not 0;
            0 = ``max_lidar_sigma``. Default 0.05: on open ground few registrations hold the
            direction of travel to 3 cm, and the first segments would form only after tens
            of metres.
    """

    enabled: bool = True
    min_distance_m: float = 5.0
    window_m: float = 200.0
    min_scale: float = 0.8
    max_scale: float = 1.25
    segment_m: float = 5.0
    min_segment_m: float = 2.0
    steady_ratio: float = 0.05
    steady_scans: int = 10
    slip_gate_m: float = 0.05
    slip_gate_ratio: float = 0.03
    max_rejections: int = 3
    robust_ratio: float = 0.015
    slip_piece_m: float = 1.0
    slip_piece_ratio: float = 0.08
    max_lidar_sigma: float = 0.03
    max_lidar_sigma_start: float = 0.05

    def validate(self, prefix: str = "wheel_scale.") -> None:
        from lili_odom.errors import check_range

        check_range(prefix + "min_distance_m", self.min_distance_m, 0.0, 1e4, unit="m")
        check_range(prefix + "window_m", self.window_m, 0.0, 1e6, lo_open=True, unit="m")
        check_range(prefix + "min_scale", self.min_scale, 0.0, 1.0, lo_open=True)
        check_range(prefix + "max_scale", self.max_scale, 1.0, 100.0)
        check_range(prefix + "segment_m", self.segment_m, 0.0, 1e4, lo_open=True, unit="m")
        check_range(prefix + "min_segment_m", self.min_segment_m, 0.0, self.segment_m,
                    lo_open=True, unit="m")
        check_range(prefix + "steady_ratio", self.steady_ratio, 0.0, 10.0)
        check_range(prefix + "steady_scans", self.steady_scans, 1, 1000)
        check_range(prefix + "slip_gate_m", self.slip_gate_m, 0.0, 10.0, unit="m")
        check_range(prefix + "slip_gate_ratio", self.slip_gate_ratio, 0.0, 10.0)
        check_range(prefix + "max_rejections", self.max_rejections, 1, 1000)
        check_range(prefix + "robust_ratio", self.robust_ratio, 0.0, 1.0)
        check_range(prefix + "slip_piece_m", self.slip_piece_m, 0.0, 1e3, lo_open=True,
                    unit="m")
        check_range(prefix + "slip_piece_ratio", self.slip_piece_ratio, 0.0, 10.0)
        check_range(prefix + "max_lidar_sigma", self.max_lidar_sigma, 0.0, 10.0, unit="m")
        check_range(prefix + "max_lidar_sigma_start", self.max_lidar_sigma_start, 0.0, 10.0,
                    unit="m")


class _Segment:
    """A chain of consecutive constrained increments since a steady start."""

    def __init__(self) -> None:
        self.lidar = np.eye(4)        # LiDAR motion since the start (start frame)
        self.path = 0.0               # wheel path length [m]
        self.end: tuple[float, int] | None = None  # last steady end: path, increments
        # per increment: wheel translation (start frame) [m], LiDAR position after it [m]
        self.steps: list[tuple[np.ndarray, np.ndarray]] = []


@dataclass(frozen=True)
class ClosedSegment:
    """A used segment: wheel and LiDAR distance [m] and the accepted travel [m] at its close."""

    wheel: float
    lidar: float
    travel: float

    @property
    def ratio(self) -> float:
        return self.wheel / self.lidar


class WheelScaleEstimator:
    """Running estimate of the wheel distance scale (see module docstring)."""

    def __init__(self, config: WheelScaleConfig | None = None) -> None:
        self.config = config or WheelScaleConfig()
        self.segments: deque[ClosedSegment] = deque()  # used segments, oldest first
        self.travel = 0.0    # wheel distance of all used segments [m]
        self.used = 0        # segments used
        self.rejected = 0    # segments rejected by the slip gate
        self.restarts = 0    # estimates restarted after repeated rejections
        self.slip_pieces = 0  # pieces cut out of segments as slips
        self._segment: _Segment | None = None
        self._steps: deque[float] = deque(maxlen=self.config.steady_scans)  # wheel steps [m]
        self._rejections_in_row = 0
        self._estimate = 1.0  # robust ratio of the current segments (unclamped)
        self._lidar_m = 0.0   # their faded LiDAR distance (the fading only moves at a close)

    # -- feeding -------------------------------------------------------------------------

    def observe(self, wheel_delta: np.ndarray, lidar_delta: np.ndarray) -> bool:
        """Add one increment pair over the same interval; returns True when it was chained.

        Args:
            wheel_delta: the *raw* wheel increment (4x4).
            lidar_delta: the LiDAR increment between two consecutive, fully constrained
                registrations (4x4).
        A non-finite pair breaks the chain (as :meth:`interrupt`).
        """
        W = np.asarray(wheel_delta, dtype=float)
        L = np.asarray(lidar_delta, dtype=float)
        if W.shape != (4, 4) or L.shape != (4, 4) or not (np.all(np.isfinite(W))
                                                         and np.all(np.isfinite(L))):
            self.interrupt()
            return False
        step = float(np.linalg.norm(W[:3, 3]))
        self._steps.append(step)
        steady = self._steady()
        seg = self._segment
        if seg is None:
            # the increment only tells the speed; a segment starts at a steady scan
            if steady:
                self._segment = _Segment()
            return False
        w_start = seg.lidar[:3, :3] @ W[:3, 3]
        seg.lidar = seg.lidar @ L
        seg.path += step
        seg.steps.append((w_start, seg.lidar[:3, 3].copy()))
        if steady:
            seg.end = (seg.path, len(seg.steps))
            if seg.path >= self.config.segment_m:
                self._close(seg)
                self._segment = _Segment()  # contiguous: the next segment starts here
        return True

    def interrupt(self) -> None:
        """The chain is broken (degenerate or missing registration, reset): the segment so
        far is used up to its last steady end if it is long enough, and a new one starts at
        the next steady scan."""
        if self._segment is not None:
            self._close(self._segment)
        self._segment = None
        self._steps.clear()

    def _steady(self) -> bool:
        steps = self._steps
        if len(steps) < (steps.maxlen or 1):
            return False
        mean = sum(steps) / len(steps)
        return mean >= 0.01 and max(steps) - min(steps) <= self.config.steady_ratio * mean + 0.002

    def _close(self, seg: _Segment) -> None:
        cfg = self.config
        if seg.end is None:
            return
        path, steps = seg.end
        lidar_t, wheel = self._without_slips(seg.steps[:steps])
        w = float(np.linalg.norm(wheel))
        if path < cfg.min_segment_m or w < 0.5 * path:  # too short, or turned back on itself
            return
        along = float(lidar_t @ (wheel / w))  # LiDAR distance along the wheels' chord
        ref = self.scale if self.established else None
        if ref is None:
            ok = cfg.min_scale * along <= w <= cfg.max_scale * along
        else:
            ok = abs(w - ref * along) <= cfg.slip_gate_m + cfg.slip_gate_ratio * w
        if not ok:
            self.rejected += 1
            self._rejections_in_row += 1
            if self._rejections_in_row >= cfg.max_rejections:
                # the segments keep disagreeing with the estimate: the estimate is wrong
                self.segments.clear()
                self._estimate, self._lidar_m = 1.0, 0.0
                self.restarts += 1
                self._rejections_in_row = 0
            return
        self._rejections_in_row = 0
        self.travel += w
        self.segments.append(ClosedSegment(wheel=w, lidar=along, travel=self.travel))
        while self.segments and self._fade(self.segments[0]) < 1e-3:
            self.segments.popleft()
        self.used += 1
        self._estimate = self._robust_ratio()
        self._lidar_m = float(sum(self._fade(s) * s.lidar for s in self.segments))

    def _without_slips(self, steps: list[tuple[np.ndarray, np.ndarray]]
                       ) -> tuple[np.ndarray, np.ndarray]:
        """LiDAR displacement and wheel vector of a segment's increments [m], start frame,
        without the pieces whose ratio marks a slip (see the module docstring)."""
        if not steps:
            return np.zeros(3), np.zeros(3)
        wheels = np.array([w for w, _ in steps])
        ends = np.array([p for _, p in steps])
        lidar, wheel = ends[-1].copy(), wheels.sum(axis=0)
        cfg = self.config
        if cfg.slip_piece_ratio <= 0.0:
            return lidar, wheel
        path = np.cumsum(np.linalg.norm(wheels, axis=1))
        cut = np.searchsorted(path, np.arange(cfg.slip_piece_m, path[-1], cfg.slip_piece_m),
                              side="left")
        bounds = np.unique(np.r_[0, cut + 1, len(steps)])
        if len(bounds) > 2 and path[-1] - path[bounds[-2] - 1] < 0.5 * cfg.slip_piece_m:
            bounds = np.delete(bounds, -2)  # a short last piece joins the one before
        pieces = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            pw = wheels[a:b].sum(axis=0)
            pl = ends[b - 1] - (ends[a - 1] if a > 0 else 0.0)
            n = float(np.linalg.norm(pw))
            along = float(pl @ pw) / n if n > 0 else 0.0
            pieces.append((pw, pl, n / along if along > 0.5 * n else np.inf))
        if len(pieces) < 3:
            return lidar, wheel
        median = float(np.median([r for _, _, r in pieces]))
        for pw, pl, r in pieces:
            if not abs(r / median - 1.0) <= cfg.slip_piece_ratio:
                lidar, wheel = lidar - pl, wheel - pw
                self.slip_pieces += 1
        return lidar, wheel

    def _fade(self, seg: ClosedSegment) -> float:
        return math.exp(-(self.travel - seg.travel) / self.config.window_m)

    def _robust_ratio(self) -> float:
        """Huber M-estimate of the segments' ratios, weighted by faded LiDAR distance."""
        if not self.segments:
            return 1.0
        r = np.array([s.ratio for s in self.segments])
        w = np.array([self._fade(s) * s.lidar for s in self.segments])
        c = self.config.robust_ratio
        if c <= 0.0 or len(r) < 3:  # the plain ratio of the faded distances
            return float(np.sum(w * r) / np.sum(w))
        order = np.argsort(r)  # start at the weighted median
        cum = np.cumsum(w[order])
        est = float(r[order][np.searchsorted(cum, 0.5 * cum[-1])])
        for _ in range(50):
            dev = np.abs(r - est)
            u = w * np.minimum(1.0, c / np.maximum(dev, 1e-12))
            new = float(np.sum(u * r) / np.sum(u))
            if abs(new - est) < 1e-9:
                return new
            est = new
        return est

    # -- result --------------------------------------------------------------------------

    @property
    def lidar_m(self) -> float:
        """Faded LiDAR distance of the used segments [m]."""
        return self._lidar_m

    @property
    def chaining(self) -> bool:
        """True while increments are chained into an open segment (after a steady start)."""
        return self._segment is not None

    @property
    def established(self) -> bool:
        """True once enough constrained travel was accepted for the estimate to apply."""
        return self._lidar_m >= self.config.min_distance_m and self._lidar_m > 0

    @property
    def scale(self) -> float:
        """Wheel distance per LiDAR distance (1 until enough travel was observed)."""
        cfg = self.config
        if not cfg.enabled or not self.established:
            return 1.0
        return float(np.clip(self._estimate, cfg.min_scale, cfg.max_scale))

    def correct(self, wheel_delta: np.ndarray) -> np.ndarray:
        """``wheel_delta`` with its translation divided by the scale (a new array)."""
        out = np.array(wheel_delta, dtype=float)
        out[:3, 3] /= self.scale
        return out
