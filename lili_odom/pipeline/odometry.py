"""``OdometryPipeline``: one object turns IMU, wheel and LiDAR samples into fused odometry.

It is what the rclpy node, the offline bag runner and the benchmarks all run, so what is
measured offline is what runs on the robot. Per scan (``process_scan``):

1. the cloud arrives parsed (``Scan``: points in ``os_lidar``, per-point times);
2. the pose of base_link over the sweep is predicted from IMU preintegration (wheel odometry or
   the last body twist without IMU) by the fusion estimator, never a constant-velocity guess;
3. the sweep is deskewed with that predicted motion and registered to the local map
   (KISS-ICP, ``ScanMatcher``);
4. the selected detector (``lili`` | ``zhang`` | ``hessian`` | ``none``) finds the degenerate
   subspace of that registration, reusing the ICP optimum, unless a detection of the last
   scans nearby can be carried over; by default a due detection runs in a background process
   and is applied a couple of scans later (:mod:`lili_odom.pipeline.detection_schedule`,
   :mod:`lili_odom.pipeline.detection_worker`; ``start()`` starts and ``close()`` stops
   that process);
5. on a degenerate scan with wheel data the registration is held at the wheels' prediction
   along the subspace (solution remapping, :mod:`lili_odom.pipeline.remap`); directions
   outside the subspace that point-to-plane barely holds join it, and the registration is
   checked by point-to-plane along the direction of travel left outside it (point-to-point
   ICP against a young or sparse map lags along it); the registration is then refined
   inside the subspace by point-to-plane Gauss-Newton, which measures what the LiDAR still
   knows there
   (:mod:`lili_odom.pipeline.plane_refinement`);
6. iSAM2 fuses IMU preintegration, the LiDAR registration with the degenerate directions
   removed, the LiDAR's own (Hessian-weighted) measurement inside them and the wheel
   increment only inside them (``FusionEstimator``);
7. the local map is updated with the FUSED pose, and the k-d tree of the next scan's plane
   fits starts building in a background thread.

Frames: the odometry frame is gravity-aligned at the first scan; poses are of base_link in it.
Scan poses refer to the time of the scan's last point (KISS-ICP deskews to it).
"""
from __future__ import annotations

import logging
import math
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from functools import cache, partial

import numpy as np

from lili_odom import geometry
from lili_odom.degeneracy.config import usable_length
from lili_odom.degeneracy.detection_input import thin_evenly
from lili_odom.degeneracy.hessian import HessianConfig, HessianDetector, ZhangConfig, ZhangDetector
from lili_odom.degeneracy.lili import LiliConfig, LiliDetector
from lili_odom.degeneracy.result import DegeneracyResult
from lili_odom.errors import ThrottledWarnings
from lili_odom.fusion.config import FusionConfig
from lili_odom.degeneracy.subspace import orthonormal_rows
from lili_odom.fusion.estimator import FusionEstimator, SubspaceMeasurement
from lili_odom.fusion.measurements import registration_information
from lili_odom.fusion.subspace import remap_pose, scaled_lidar_to_base
from lili_odom.pipeline.detection_schedule import DetectionSchedule, DetectionScheduleConfig
from lili_odom.pipeline.detection_worker import PENDING, DetectionWorker
from lili_odom.pipeline.plane_refinement import (MIN_TESTED_INFORMATION, PlaneFitCache,
                                                 PlaneRefinement, PlaneRefinementConfig,
                                                 plane_cost, refine_in_subspace,
                                                 returned_directions, without_unheld)
from lili_odom.pipeline.remap import constrained_registration
from lili_odom.pipeline.scan_matcher import ScanMatcher, ScanMatcherConfig, deskew_motion
from lili_odom.pipeline.start_speed import StartSpeedConfig, forward_speed
from lili_odom.pipeline.start_sweeps import StartSweep, StartSweeps
from lili_odom.pipeline.types import ImuSample, OdometryOutput, Scan, WheelSample
from lili_odom.pipeline.validation import checked_scan

log = logging.getLogger(__name__)

METHODS = ("lili", "zhang", "hessian", "none")


@dataclass
class PipelineConfig:
    """Everything the pipeline needs (the ``pipeline.*`` parameters of the node).

    Attributes:
        method: degeneracy detector, one of ``METHODS``.
        sweep_duration: sweep length [s] assumed for clouds without per-point times.
        min_points: scans with fewer valid points are skipped (counted, warned).
        max_backward_jump_s: a scan stamp this much older than the previous one is a clock
            jump backwards (bag loop): the pipeline resets.
        max_forward_gap_s: a gap longer than this between scans re-initialises the estimator
            at the last fused pose instead of integrating the IMU over it.
        detection_points: scan points handed to the detector (evenly thinned), 0 = all.
        sensor_wait_s: how long [s of stamp time] a scan waits for IMU/wheel samples at or
            after its sweep end before it is processed without them (see
            :mod:`lili_odom.pipeline.feeder`).
        max_pending_scans: scans allowed to wait for IMU/wheel data at once; beyond, the
            oldest is processed with what there is.
        detection_schedule: when a recent detection is carried over instead of running the
            detector again (:mod:`lili_odom.pipeline.detection_schedule`).
        redeskew_start: once the first two sweeps of a new local map are in it, deskew again
            those whose motion by the fused twist differs from the one they were deskewed
            with, and rebuild the map from them (a start while moving:
            :mod:`lili_odom.pipeline.start_sweeps`). Default True.
        start_speed: without wheel odometry, find the speed of a start while driving from the
            first two sweeps (:mod:`lili_odom.pipeline.start_speed`).
        remap_iterations: on a degenerate scan with wheel data, the registration is re-run
            held at the wheel prediction along the degenerate subspace (solution remapping,
            :mod:`lili_odom.pipeline.remap`) for at most this many single ICP iterations, and
            that pose is what the LiDAR factor measures; 0 = the unconstrained
            registration. Needed by an absolute LiDAR factor (``fusion.lidar.factor``
            ``hybrid`` or ``prior``): without it the registration's slide along the axis
            leaks into the kept components and pins the axial position to the slide.
        plane_refinement: the point-to-plane refinement inside a detected subspace whose
            information the fusion keeps (``fusion.lidar.subspace_information``).
        scan_matcher / fusion / lili / zhang / hessian: the stages' own configurations; in
            the odometry LiLi stops a perturbed re-registration once it has come back
            (``lili.return_ratio`` 0.1), the standalone detector (``lili-odom detect``) runs
            each to convergence.
    """

    method: str = "lili"
    sweep_duration: float = 0.1
    min_points: int = 100
    max_backward_jump_s: float = 0.05
    max_forward_gap_s: float = 1.0
    detection_points: int = 4000
    sensor_wait_s: float = 0.3
    max_pending_scans: int = 3
    redeskew_start: bool = True
    start_speed: StartSpeedConfig = field(default_factory=StartSpeedConfig)
    remap_iterations: int = 10
    detection_schedule: DetectionScheduleConfig = field(default_factory=DetectionScheduleConfig)
    plane_refinement: PlaneRefinementConfig = field(default_factory=PlaneRefinementConfig)
    scan_matcher: ScanMatcherConfig = field(default_factory=ScanMatcherConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    lili: LiliConfig = field(default_factory=lambda: LiliConfig(return_ratio=0.1))
    zhang: ZhangConfig = field(default_factory=ZhangConfig)
    hessian: HessianConfig = field(default_factory=HessianConfig)

    def validate(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {', '.join(METHODS)}, got '{self.method}'")
        if not self.sweep_duration > 0:
            raise ValueError(f"sweep_duration must be > 0 s, got {self.sweep_duration}")
        if self.min_points < 10:
            raise ValueError(f"min_points must be >= 10, got {self.min_points}")
        if not self.max_forward_gap_s > 0:
            raise ValueError(f"max_forward_gap_s must be > 0, got {self.max_forward_gap_s}")
        if self.detection_points < 0:
            raise ValueError(f"detection_points must be >= 0, got {self.detection_points}")
        if not 0 <= self.sensor_wait_s <= 10:
            raise ValueError(f"sensor_wait_s must be in [0, 10] s, got {self.sensor_wait_s}")
        if not 1 <= self.max_pending_scans <= 100:
            raise ValueError(f"max_pending_scans must be in [1, 100], got {self.max_pending_scans}")
        if not 0 <= self.remap_iterations <= 100:
            raise ValueError(f"remap_iterations must be in [0, 100], got {self.remap_iterations}")
        self.detection_schedule.validate()
        self.plane_refinement.validate()
        self.start_speed.validate()
        self.scan_matcher.validate()
        self.lili.validate()


@dataclass
class _AlongTrack:
    """Outcome of the along-track check: the refined pose (``ok``) or the direction of travel
    as a degenerate subspace."""

    ok: bool
    pose: np.ndarray
    degeneracy: DegeneracyResult | None


def detector_factory(config: PipelineConfig):
    """A picklable callable that builds the configured detector, or None for ``none``."""
    if config.method == "lili":
        return partial(LiliDetector, config.lili)
    if config.method == "zhang":
        return partial(ZhangDetector, config.zhang)
    if config.method == "hessian":
        return partial(HessianDetector, config.hessian)
    return None


def make_detector(config: PipelineConfig):
    """The configured detector object, or None for ``none``."""
    factory = detector_factory(config)
    return None if factory is None else factory()


def basis_in_base(result: DegeneracyResult, T_base_lidar: np.ndarray) -> np.ndarray:
    """Plain unit twists (k, 6) of the degenerate subspace in base_link (``(v, w)``)."""
    if result is None or result.dimension == 0:
        return np.zeros((0, 6))
    return _rows_in_base(result.basis_scaled, result.characteristic_length, T_base_lidar)


def _rows_in_base(rows_scaled: np.ndarray, length: float, T_base_lidar: np.ndarray
                  ) -> np.ndarray:
    """Scaled LiDAR twists (k, 6) (characteristic length ``length`` [m]) as plain unit twists
    (k, 6) of base_link."""
    if not len(rows_scaled):
        return np.zeros((0, 6))
    B = geometry.unscale_twist(rows_scaled, length) @ geometry.adjoint(T_base_lidar).T
    return B / np.linalg.norm(B, axis=1, keepdims=True)


def reported_bases(result: DegeneracyResult | None, held: tuple[np.ndarray, np.ndarray] | None,
                   held_information: float, T_base_lidar: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(degenerate, weakly constrained) plain unit twists in base_link of the subspace
    ``result`` the fusion used: ``held`` = (rows (k, 6) scaled LiDAR twists spanning it, the
    point-to-plane information [1/m^2] along each) splits it at ``held_information``; without
    ``held`` (no refinement measured it) the whole subspace is degenerate."""
    if result is None or result.dimension == 0:
        return np.zeros((0, 6)), np.zeros((0, 6))
    if held is None:
        return basis_in_base(result, T_base_lidar), np.zeros((0, 6))
    rows, information = held
    weak = np.asarray(information, dtype=float) >= held_information
    L = result.characteristic_length
    return (_rows_in_base(rows[~weak], L, T_base_lidar),
            _rows_in_base(rows[weak], L, T_base_lidar))


class OdometryPipeline:
    """Degeneracy-aware LiDAR-inertial-wheel odometry (pure Python; see module docstring).

    Args:
        config: the pipeline's parameters (default: ``PipelineConfig()``).
        max_detection_wait_s: longest the main loop waits for a background detection that is
            due [s]; when it has not arrived by then, the last detection serves the scan and
            the result is applied when it has arrived, at the latest ``2 * background_lag``
            scans after its own (waited for then). When the result before was late too, a
            late result is waited for at once (the detector lacks CPU, and the wait gives
            it). None (default) waits for every due result, so the outputs do not depend on
            timing (offline runs, the benchmarks); the node sets its
            ``detection_max_wait_s`` parameter, so an occasional slow detection does not hold
            up the scans behind it.
    """

    def __init__(self, config: PipelineConfig | None = None,
                 max_detection_wait_s: float | None = None):
        self.config = config or PipelineConfig()
        self.config.validate()
        if max_detection_wait_s is not None and not max_detection_wait_s >= 0:
            raise ValueError(f"max_detection_wait_s must be >= 0 or None, got "
                             f"{max_detection_wait_s}")
        self.max_detection_wait_s = max_detection_wait_s
        self.counters: Counter[str] = Counter()
        self._detector = make_detector(self.config)
        self._schedule = DetectionSchedule(self.config.detection_schedule)
        self._background = self.config.detection_schedule.background
        self._worker: DetectionWorker | None = None  # start() or the first map update
        self._pending: int | None = None  # detection request in flight (its sequence number)
        self._late_before = False  # the last background result was late when due
        self._pending_late = False  # the one in flight was
        self._detection_seq = 0
        #: this scan's screen: point-to-plane information (scaled, 6x6) and its length [m]
        self._screen_information: tuple[np.ndarray, float] | None = None
        self._matcher = ScanMatcher(self.config.scan_matcher)
        self._start_sweeps = StartSweeps()
        self._first_sweep: StartSweep | None = None  # a new start's first sweep, raw
        self._new_estimator()
        self._last_stamp: float | None = None
        self._last_output: OdometryOutput | None = None
        self._warn = ThrottledWarnings(log)

    def _skip(self, counter: str, message: str, *args) -> None:
        """Count a skipped scan under ``counter`` and say why.

        Throttled per counter *and* message, so a burst of one kind of bad scan cannot hide
        the first occurrence of another cause counted under the same name.
        """
        self.counters[counter] += 1
        self._warn.warning(f"{counter}:{message}", "scan skipped (%s): " + message, counter,
                           *args)

    # ------------------------------------------------------------------ set-up and inputs
    def _new_estimator(self) -> None:
        self.estimator = FusionEstimator(self.config.fusion)

    @property
    def T_base_lidar(self) -> np.ndarray:
        return self.estimator.T_base_lidar

    def set_extrinsics(self, T_base_lidar: np.ndarray, T_base_imu: np.ndarray) -> None:
        """Replace the extrinsics (e.g. from ``/tf_static``); resets map and state.

        The buffered IMU and wheel samples are kept: they are in the sensors' own frames.
        """
        self.config.fusion.T_base_lidar = geometry.orthonormalize(T_base_lidar)
        self.config.fusion.T_base_imu = geometry.orthonormalize(T_base_imu)
        imu, wheels, scale = self.estimator.imu, self.estimator.wheels, self.estimator.wheel_scale
        self.reset(count=False)
        self.estimator.imu, self.estimator.wheels = imu, wheels
        self.estimator.wheel_scale = scale

    def reset(self, count: bool = True, keep_from: float | None = None) -> None:
        """Forget map, state and buffers (clock jump backwards, new bag loop).

        Args:
            keep_from: keep the buffered IMU/wheel samples stamped at or after this time [s]
                and before the old timeline resumes (the new timeline's samples that arrived
                before the scan that revealed the jump).
        """
        old = self.estimator
        self._matcher.reset()
        self._forget_detections(new_map=True)
        self._new_estimator()
        if keep_from is not None and self._last_stamp is not None:
            t1 = self._last_stamp - self.config.max_backward_jump_s
            for s in old.imu.samples(keep_from, t1):
                self.estimator.add_imu(s.t, s.acc, s.gyro)
            for t, T in old.wheels.samples(keep_from, t1):
                self.estimator.add_wheel(t, T)
        self._last_stamp = None
        self._last_output = None
        self._first_sweep = None
        if count:
            self.counters["resets"] += 1

    def add_imu(self, sample: ImuSample) -> None:
        if not self.estimator.add_imu(sample.stamp, sample.linear_acceleration, sample.angular_velocity):
            self.counters["imu_rejected"] += 1
        else:
            self.counters["imu"] += 1

    def add_wheel(self, sample: WheelSample) -> None:
        if sample.pose is None or not self.estimator.add_wheel(sample.stamp, sample.pose):
            self.counters["wheel_rejected"] += 1
        else:
            self.counters["wheel"] += 1

    def local_map_points(self) -> np.ndarray:
        """(M, 3) local map in the odometry frame [m]."""
        return self._matcher.map_points()

    # ------------------------------------------------------------------ per scan
    def _sweep_times(self, scan: Scan) -> tuple[np.ndarray, float, float]:
        times = scan.times
        if (times is None or len(times) != len(scan.points) or not np.all(np.isfinite(times))
                or not np.ptp(times) > 0):
            # no usable per-point time (absent, non-finite, or all equal: a driver that fills
            # the field with a constant): the sweep ends sweep_duration after its stamp, as for
            # a cloud without times, so both kinds of cloud share one timeline; no deskew
            t_end = scan.stamp + self.config.sweep_duration
            return np.zeros(len(scan.points)), t_end, t_end
        return times, scan.stamp + float(times.min()), scan.stamp + float(times.max())

    def process_scan(self, scan: Scan) -> OdometryOutput | None:
        """Run one scan through the pipeline; None when it was skipped (see ``counters``).

        Raises:
            lili_odom.pipeline.validation.PipelineInputError: malformed scan (a ValueError).
        """
        scan = checked_scan(scan, self.counters)
        t_start = time.perf_counter()
        timings: dict[str, float] = {}
        warnings: list[str] = []
        self.counters["scans"] += 1
        points = np.asarray(scan.points, dtype=np.float64).reshape(-1, 3)
        bad = geometry.nonfinite_rows(points)
        if bad is not None:
            points = points[~bad]
            scan = Scan(scan.stamp, points, None if scan.times is None else scan.times[~bad],
                        scan.frame_id, scan.dropped + int(bad.sum()))
        if not np.isfinite(scan.stamp):
            self._skip("skipped_bad_stamp", "non-finite stamp")
            return None
        if len(points) < self.config.min_points:
            self._skip("skipped_too_few_points", "%d valid points at %.3f, need %d", len(points),
                       scan.stamp, self.config.min_points)
            return None
        times, t_first, t_ref = self._sweep_times(scan)
        reinit_pose = None
        if self._last_stamp is not None:
            if t_ref < self._last_stamp - self.config.max_backward_jump_s:
                log.warning("clock jumped back %.3f s: resetting", self._last_stamp - t_ref)
                self.reset(keep_from=t_first - self.config.fusion.gravity_window_s)
                self.counters["clock_jumps_back"] += 1
                warnings.append("clock jump backwards: pipeline reset")
            elif t_ref <= self._last_stamp:
                self._skip("skipped_stale_stamp", "stamp %.3f not after the previous %.3f",
                           t_ref, self._last_stamp)
                return None
            elif t_ref - self._last_stamp > self.config.max_forward_gap_s:
                self.counters["forward_gaps"] += 1
                gap = t_ref - self._last_stamp
                self._warn.warning("forward_gaps", "%.2f s gap before the scan at %.3f: "
                                   "re-initialised at the registered pose", gap, t_ref)
                warnings.append(f"{gap:.2f} s gap: re-initialised at the registered pose")
                old = self.estimator
                self._forget_detections()
                self._new_estimator()  # keeps the map; the state restarts at this scan
                self.estimator.imu, self.estimator.wheels = old.imu, old.wheels
                self.estimator.wheel_scale = old.wheel_scale  # same wheels, same calibration
                self.estimator.gravity_tilt = old.gravity_tilt  # same map, same frame
                reinit_pose = self._last_output.pose if self._last_output is not None else None

        est = self.estimator
        first = not est.initialized
        t0 = time.perf_counter()
        T_bl = self.T_base_lidar
        if not first and self._first_sweep is not None:
            self._find_start_speed(StartSweep(points, times, np.eye(4), np.eye(4), t_first, t_ref))
        if first and reinit_pose is not None:
            sweep_motion = np.eye(4)
            guess = reinit_pose @ T_bl
        elif first:
            est.initialize(t_ref)
            sweep_motion = np.eye(4)
            guess = est.predict(t_ref) @ T_bl
        else:
            poses = est.predict_poses([t_first, t_ref])
            L0, L1 = poses[0] @ T_bl, poses[1] @ T_bl
            sweep_motion = np.linalg.inv(L0) @ L1
            guess = L1
        timings["predict"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        map_points, source = self._matcher.preprocess(points, times, sweep_motion)
        timings["deskew"] = time.perf_counter() - t0
        if len(source) < 10:
            self._skip("skipped_too_few_points", "%d points left after voxelisation at %.3f",
                       len(source), t_ref)
            return None

        t0 = time.perf_counter()
        reg = self._matcher.register(source, guess)
        timings["icp"] = time.perf_counter() - t0
        if not reg.ok:
            self.counters["icp_failures"] += 1
            warnings.append(f"registration failed: {reg.reason}")

        degeneracy = None
        self._screen_information = None
        t0 = time.perf_counter()
        wheels_recent = self._wheels_recent(t_ref)  # else there is no wheel data for this scan
        planes = PlaneFitCache(map_points, self._matcher.reference,
                               self._plane_config(not wheels_recent))
        if self._detector is not None and not reg.ok:
            self._forget_detections()
        if self._detector is not None and reg.ok and not first:
            degeneracy = self._detection(source, guess, reg.pose, planes)
            degeneracy = self._schedule.hold(degeneracy, reg.pose)
            if degeneracy.details.get("held"):
                self.counters["detections_held"] += 1
            if not degeneracy.ok:
                self.counters["detector_failures"] += 1
                warnings.append(f"detector: {degeneracy.reason}")
            elif degeneracy.degenerate:
                self.counters["degenerate_scans"] += 1
        timings["detector"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        wheel_prediction = cache(partial(est.wheel_prediction, t_ref))  # at most once a scan
        measured = reg.pose
        if self._remaps(degeneracy):
            measured = self._remap(source, reg.pose, wheel_prediction(), degeneracy)
        timings["remap"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        if degeneracy is not None and degeneracy.ok and self._last_output is not None:
            weak = self._weak_directions(planes, measured, guess, degeneracy)
            if weak is not None:
                degeneracy = weak
                if self._remaps(degeneracy):
                    measured = self._remap(source, reg.pose, wheel_prediction(), degeneracy)
            along = self._along_track(planes, measured, guess, degeneracy)
            if along is not None and along.ok:
                measured = along.pose
            elif along is not None:
                degeneracy = along.degeneracy
                if self._remaps(degeneracy):
                    measured = self._remap(source, reg.pose, wheel_prediction(), degeneracy)
            if reg.ok:
                measured = self._refine_constrained(planes, measured, degeneracy, guess)
        timings["along_track"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        subspace = None
        held = None
        refine = self.config.plane_refinement
        if (refine.enabled and self.config.fusion.lidar.subspace_information and reg.ok
                and degeneracy is not None and degeneracy.ok and degeneracy.degenerate):
            refined = refine_in_subspace(map_points, self._matcher.reference, measured,
                                         degeneracy.basis_scaled,
                                         degeneracy.characteristic_length, refine,
                                         fits=planes.at(measured))
            check_return = wheel_prediction() is None and wheels_recent
            if refine.predicted_start and wheel_prediction() is None:
                refined = self._refined_from_prediction(planes, refined, measured, guess,
                                                        degeneracy, check_return)
            if refine.return_check == "offset" and refined.ok and check_return:
                refined = self._checked_by_offset(planes, refined, degeneracy)
            if refined.ok:
                degeneracy, info, held = self._clear_held_directions(degeneracy, refined)
                measured = refined.pose
                if degeneracy.degenerate:
                    if (refine.information_without_wheels != 1.0
                            and wheel_prediction() is None):  # no wheel data for this scan
                        info = refine.information_without_wheels * info
                    subspace = SubspaceMeasurement(refined.pose @ np.linalg.inv(T_bl), info,
                                                   degeneracy.characteristic_length)
            else:
                self.counters["refinement_failures"] += 1
        timings["refine"] = time.perf_counter() - t0
        self.counters["plane_fits"] += planes.queries

        t0 = time.perf_counter()
        if first and reinit_pose is not None:
            start = reg.pose @ np.linalg.inv(T_bl) if reg.ok else reinit_pose
            fused = est.initialize(t_ref, pose=start)
        elif first:
            fused = est.last_output
        else:
            T_icp_base = measured @ np.linalg.inv(T_bl) if reg.ok else None
            fused = est.update(t_ref, T_icp_base, degeneracy, subspace=subspace,
                               lidar_information=self._registration_information())
        timings["fusion"] = time.perf_counter() - t0
        if fused is None:
            self._skip("fusion_rejected", "the estimator rejected the update at %.3f (%s)", t_ref,
                       est.stats.last_failure or "stamp or solver")
            return None
        warnings += list(fused.notes)

        t0 = time.perf_counter()
        fused_lidar = fused.pose @ T_bl
        twist = self._body_twist(fused)
        map_was_empty = self._matcher.map_empty
        inserted = self._matcher.update_map(map_points, fused_lidar,
                                            np.linalg.inv(guess) @ fused_lidar)
        self._first_sweep = None
        if (first and reinit_pose is None and map_was_empty and self.config.start_speed.enabled
                and self.config.scan_matcher.deskew):
            self._first_sweep = StartSweep(points, times, deskew_motion(sweep_motion), inserted,
                                           t_first, t_ref)
        self._start_worker()
        if self._worker is not None and self._worker.alive:
            self._worker.update_map(map_points, inserted)
        if (self.config.redeskew_start and self.config.scan_matcher.deskew
                and (map_was_empty or self._start_sweeps.collecting)):
            redo = self._start_sweeps.add(
                StartSweep(points, times, deskew_motion(sweep_motion), inserted, t_first, t_ref),
                map_was_empty, geometry.adjoint(np.linalg.inv(T_bl)) @ twist,
                est.velocity_sigma() if self._start_sweeps.due else 0.0)
            if redo is not None:
                self._rebuild_map(redo)
                warnings.append("local map rebuilt from its first sweeps deskewed again")
        if self.config.plane_refinement.enabled and self._detector is not None:
            self._matcher.reference.build_kdtree_ahead()  # the next scan's plane fits need it
        timings["map"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_start

        degenerate_basis, weak_basis = reported_bases(degeneracy, held,
                                                      refine.held_information, T_bl)
        if len(weak_basis):
            self.counters["weakly_held_scans"] += 1
        out = OdometryOutput(
            stamp=t_ref,
            pose=fused.pose,
            twist=twist,
            covariance=fused.covariance,
            degeneracy=degeneracy,
            degenerate_basis=degenerate_basis,
            weak_basis=weak_basis,
            icp_pose=reg.pose @ np.linalg.inv(T_bl),
            timings=timings,
            warnings=warnings,
            details={"points": len(points), "source_points": len(source),
                     "threshold": self._matcher.threshold, "used_wheel": fused.used_wheel,
                     "used_imu": fused.used_imu,
                     "wheel_scale": est.wheel_scale.scale,
                     "accel_bias": np.asarray(fused.accel_bias, dtype=float),
                     "gyro_bias": np.asarray(fused.gyro_bias, dtype=float),
                     "gravity_tilt": np.asarray(fused.gravity_tilt, dtype=float)},
        )
        self._last_stamp = t_ref
        self._last_output = out
        self.counters["processed"] += 1
        return out

    def start(self) -> None:
        """Start the background detector process now rather than at the first map update
        (its start-up, most of a second, runs in a thread and is then over before the first
        scans, or overlaps them). Nothing when
        detection is not in the background, the process runs already, or the local map
        already holds scans (a process started now would mirror a map without them)."""
        if self._matcher.map_empty:
            self._start_worker()

    def _start_worker(self) -> None:
        if self._background_enabled() and self._worker is None:
            timeout = self.config.detection_schedule.background_timeout_s
            self._worker = DetectionWorker(detector_factory(self.config),
                                           *self._map_parameters(), timeout_s=timeout)

    def close(self) -> None:
        """Stop the background detector process, if any (idempotent; the pipeline keeps
        working, detecting in its main loop)."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None
        self._pending = None
        self._background = False

    def _background_enabled(self) -> bool:
        return self._detector is not None and self._background

    def _map_parameters(self) -> tuple[float, float, int]:
        c = self.config.scan_matcher
        return c.voxel, c.max_range, c.max_points_per_voxel

    def _find_start_speed(self, second: StartSweep) -> None:
        """At the second scan of a start whose speed is unknown (no wheel odometry), find the
        forward speed from the first two sweeps; when found and at least ``min_speed``,
        restart the fusion at the first scan with it and rebuild the map from the first
        sweep deskewed with it."""
        first, self._first_sweep = self._first_sweep, None
        cfg = self.config.start_speed
        est = self.estimator
        sigma = est.velocity_sigma()
        if sigma is None or sigma <= cfg.unknown_sigma or self._last_output is None:
            return
        samples = est.imu.samples(first.t_first, second.t_last)
        rate = (est.T_base_imu[:3, :3] @ np.mean([s.gyro for s in samples], axis=0)
                if samples else np.zeros(3))
        try:
            found = forward_speed(first, second, self._matcher, self.T_base_lidar, rate, cfg,
                                  self.config.plane_refinement)
        except (RuntimeError, ValueError) as exc:
            self._warn.warning("start_speed", "start speed not searched: %s", exc)
            return
        if found.speed is None:
            self.counters["start_speed_unknown"] += 1
            log.info("start speed not found from the first two sweeps (cost rise %.3f)",
                     found.rise)
            return
        if abs(found.speed) < cfg.min_speed:
            self.counters["start_speed_slow"] += 1
            log.info("start speed %.2f m/s from the first two sweeps, below min_speed: the "
                     "start is kept", found.speed)
            return
        self.counters["start_speed_found"] += 1
        log.info("start speed %.2f m/s forward, from the first two sweeps", found.speed)
        T0 = self._last_output.pose
        body = np.concatenate([[found.speed, 0.0, 0.0], rate])
        est.initialize(first.t_last, pose=T0, velocity=T0[:3, :3] @ body[:3],
                       velocity_sigma=cfg.velocity_sigma)
        twist = geometry.adjoint(np.linalg.inv(self.T_base_lidar)) @ body
        sweep = StartSweep(first.points, first.times,
                           geometry.exp(twist * (first.t_last - first.t_first)), first.pose,
                           first.t_first, first.t_last)
        self._rebuild_map([sweep])
        self._start_sweeps.replace(sweep)

    def _rebuild_map(self, sweeps: list[StartSweep]) -> None:
        """Replace the local map (and the background detector's mirror) by ``sweeps``
        deskewed with their ``motion``, inserted at their poses."""
        self.counters["start_map_rebuilt"] += 1
        log.info("started while moving: the first %d sweeps of the local map deskewed again "
                 "with the fused motion", len(sweeps))
        self._matcher.clear_map()
        self._forget_detections(new_map=True)
        for s in sweeps:
            map_points, _ = self._matcher.preprocess(s.points, s.times, s.motion)
            inserted = self._matcher.insert(map_points, s.pose)
            if self._worker is not None and self._worker.alive:
                self._worker.update_map(map_points, inserted)

    def _forget_detections(self, new_map: bool = False) -> None:
        """Drop the last detection and the one in flight (re-initialisation, failed
        registration); with ``new_map`` the local map was cleared too."""
        self._schedule.reset(new_map=new_map)
        self._pending = None
        if new_map and self._worker is not None:
            self._worker.reset()

    def _detection_points(self, source: np.ndarray) -> np.ndarray:
        return thin_evenly(source, self.config.detection_points)

    def _detection(self, source: np.ndarray, guess: np.ndarray, pose: np.ndarray,
                   planes: PlaneFitCache) -> DegeneracyResult:
        """This scan's detection (registered at ``pose`` from ``guess``): constrained by its
        planes (:meth:`_screen`), a recent one carried over, a background result that is due,
        or a new detection (:mod:`lili_odom.pipeline.detection_schedule`)."""
        self._detection_seq += 1
        seq = self._detection_seq
        self._collect_background(seq)
        screened = self._screen(source, pose, planes)
        if screened is not None:
            self.counters["detections_screened_weak" if screened.degenerate
                          else "detections_screened"] += 1
            self._schedule.screened(screened)
            return screened
        worker = self._worker
        background = worker is not None and worker.alive
        degeneracy = self._schedule.reusable(pose)
        if degeneracy is not None:
            self.counters["detections_reused"] += 1
            return degeneracy
        if background and self._schedule.has_last:
            if self._pending is None:
                self._submit(seq, source, guess, pose)
            if self._pending is not None:
                self.counters["detections_reused"] += 1
                return self._schedule.stale(pose)
        points = self._detection_points(source)
        degeneracy = self._detector.detect(self._matcher.reference, points, guess,
                                           optimized_pose=pose)
        self._schedule.record(degeneracy)
        self.counters["detections"] += 1
        return degeneracy

    def _screen(self, source: np.ndarray, pose: np.ndarray,
                planes: PlaneFitCache) -> DegeneracyResult | None:
        """A not-degenerate result for the scan registered at ``pose`` when its point-to-plane
        planes hold every direction with at least ``plane_refinement.clear_information``
        (``screen_detections``); with ``screen_weak_information`` > 0, when they hold every
        direction with at least that, a result whose subspace is the directions held with
        less than ``clear_information``; else None (the detector decides).

        The information is the debiased point-to-plane information of the registration over
        all six scaled twists (characteristic length of ``source``, as the detectors scale),
        on the planes the later checks use. Any direction a detection flagged on such a scan
        would be cleared by those checks (:meth:`_clear_held_directions`), so the detection
        is not run: in a constrained place the detector's cost is saved and its false flags
        (point-to-point perturbations held back by a young map) cannot steer the remapping.
        """
        cfg = self.config.plane_refinement
        if not (cfg.enabled and cfg.screen_detections and cfg.clear_information > 0):
            return None
        length = usable_length(source)
        full = refine_in_subspace(planes.points, planes.reference, pose, np.eye(6), length,
                                  replace(cfg, iterations=0), fits=planes.probe(pose))
        if not (full.ok and np.all(np.isfinite(full.information))):
            return None
        self._screen_information = (full.information, length)
        w, V = np.linalg.eigh(0.5 * (full.information + full.information.T))
        weakest = float(w[0])
        if weakest < cfg.clear_information:
            if not 0 < cfg.screen_weak_information <= weakest:
                return None
            basis = V[:, w < cfg.clear_information].T  # scaled twists, orthonormal rows
        else:
            basis = np.zeros((0, 6))
        return DegeneracyResult(method=self._detector.name, pose=np.asarray(pose, dtype=float),
                                basis_scaled=basis, characteristic_length=length,
                                details={"screened": True, "min_information": weakest})

    def _registration_information(self) -> np.ndarray | None:
        """The registration's ``(v, w)`` information for the fusion from this scan's screen
        (``plane_refinement.weigh_registration``), or None (the configured sigmas)."""
        if not (self.config.plane_refinement.weigh_registration
                and self._screen_information is not None):
            return None
        planes, length = self._screen_information
        return registration_information(self.config.fusion.lidar.information(), planes, length)

    def _submit(self, seq: int, source: np.ndarray, guess: np.ndarray,
                pose: np.ndarray) -> None:
        """Ask the background detector for scan ``seq``'s detection."""
        if self._worker.submit(seq, self._detection_points(source), guess, pose):
            self._pending = seq
            self.counters["detections"] += 1
            self.counters["detections_background"] += 1

    def _collect_background(self, seq: int) -> None:
        """Apply the background detection in flight when it is due at scan ``seq``
        (``background_lag`` scans after its own), waiting for it if needed (see
        ``max_detection_wait_s``)."""
        lag = self.config.detection_schedule.background_lag
        if self._pending is None or self._worker is None or seq - self._pending < lag:
            return
        wait = self.max_detection_wait_s
        if wait is None:
            result = self._worker.result(self._pending)
        else:
            # A late result gets up to 2 x lag scans, unless the one before was late too: the
            # detector then falls behind for want of CPU, and waiting gives it the time.
            due = seq - self._pending == lag
            grace = not self._late_before and seq - self._pending < 2 * lag
            result = self._worker.result(self._pending, wait_s=wait if grace else 0.0)
            if result is PENDING:
                if due:
                    self.counters["background_detections_late"] += 1
                    self._pending_late = True
                if grace:  # the last detection serves this scan too
                    return
                result = self._worker.result(self._pending)
            elif due:
                self._pending_late = False
            self._late_before = self._pending_late
        pending, self._pending = self._pending, None
        if result is None:
            self.counters["background_detection_failures"] += 1
            self._warn.warning("background", "background detection lost (%s)",
                               self._worker.failure)
            if not self._worker.alive:
                self._worker = None
                self._background = False
            return
        self._schedule.record(result, age=seq - pending)

    def _remaps(self, degeneracy: DegeneracyResult | None) -> bool:
        """Solution remapping applies: a degenerate detection, ``remap_iterations`` > 0, and
        not the planes' subspace of this scan's screen when
        ``plane_refinement.screened_subspace_remap`` is ``off``."""
        if not (self.config.remap_iterations and degeneracy is not None and degeneracy.ok
                and degeneracy.degenerate):
            return False
        return (self.config.plane_refinement.screened_subspace_remap != "off"
                or not _screen_result_here(degeneracy))

    def _remap(self, source: np.ndarray, registered: np.ndarray, wheel: np.ndarray | None,
               degeneracy: DegeneracyResult) -> np.ndarray:
        """The registration held at the wheels' prediction ``wheel`` (base_link pose, odometry
        frame, :meth:`FusionEstimator.wheel_prediction`) along the degenerate subspace
        (solution remapping), ``T_odom_lidar``; the registration itself without wheel data
        (``wheel`` None).

        Only the wheels' prediction: the IMU's prediction carries the fused velocity, which a
        measurement held at it only confirms; the refinement inside the subspace then starts
        there too and finds no planes within its residual gate once the IMU has drifted
        farther, so the IMU would drift on unchecked (a tunnel with a few features during a
        wheel outage).
        """
        if wheel is None:
            self.counters["remap_without_wheels"] += 1
            return registered
        reference = wheel @ self.T_base_lidar
        remapped = constrained_registration(
            lambda pose: self._matcher.step(source, pose), registered, reference,
            degeneracy.basis_scaled, degeneracy.characteristic_length,
            self.config.remap_iterations)
        if not remapped.ok:
            self.counters["remap_failures"] += 1
        return remapped.pose

    def _refined_from_prediction(self, planes: PlaneFitCache, refined: PlaneRefinement,
                                 measured: np.ndarray, guess: np.ndarray,
                                 degeneracy: DegeneracyResult,
                                 check_return: bool) -> PlaneRefinement:
        """Without wheel data, the refinement inside the subspace run again from the
        prediction's components there (``guess``, the fused motion model), and the one of the
        two whose pose fits the planes better kept (:func:`plane_cost` on both starts' planes).

        A registration that slides along a weakly held direction can end beyond the
        refinement's residual gate from the surfaces that hold it (on open ground the
        point-to-point pull of the ground's rings drags a sparse scan back towards the last
        pose), so the refinement started there finds too few of them; started at the
        prediction it finds them. The prediction's refinement is kept only when the planes hold
        every direction of the subspace there (``min_along_information``) and fit better;
        where they hold nothing (a featureless tunnel) both fit alike, and keeping the
        prediction would only confirm the fused velocity, so the registration's stays, and
        with ``check_return`` its information is checked against the prediction's
        (:meth:`_checked_against_prediction`).
        """
        refine = self.config.plane_refinement
        start = remap_pose(measured, guess, degeneracy.basis_scaled,
                           degeneracy.characteristic_length)
        if np.linalg.norm(start[:3, 3] - measured[:3, 3]) < 0.02:
            return refined  # the two starts share their planes: one refinement is enough
        fits_registration = planes.at(measured)
        fits_prediction = planes.at(start)
        other = refine_in_subspace(planes.points, planes.reference, start,
                                   degeneracy.basis_scaled, degeneracy.characteristic_length,
                                   refine, fits=fits_prediction)
        if not (other.ok and other.information.size
                and np.all(np.isfinite(other.information))):
            return refined
        if np.linalg.eigvalsh(other.information)[0] < refine.min_along_information:
            return self._checked_against_prediction(refined, other, measured, start,
                                                    degeneracy, check_return)
        if refined.ok:
            cost = [plane_cost(fits_registration, r.pose, refine)
                    + plane_cost(fits_prediction, r.pose, refine) for r in (refined, other)]
            if not cost[1] < cost[0]:
                return self._checked_against_prediction(refined, other, measured, start,
                                                        degeneracy, check_return)
        self.counters["refined_from_prediction"] += 1
        return other

    def _checked_against_prediction(self, refined: PlaneRefinement, other: PlaneRefinement,
                                    measured: np.ndarray, start: np.ndarray,
                                    degeneracy: DegeneracyResult,
                                    check_return: bool) -> PlaneRefinement:
        """``refined`` (started at the registration ``measured``) without its information
        along the direction from ``measured`` to the prediction's start ``start`` when the
        refinement started there (``other``, on planes found there) did not come back to it
        by ``max_return_ratio`` of that distance (``return_check`` ``prediction``): the
        planes do not settle where the registration and the prediction disagree. With
        ``bounded`` it keeps at most ``1 / d^2`` there, ``d`` how far apart the two
        refinements ended along it [m, scaled]. ``refined`` as it is without
        ``check_return`` (no wheel data within ``return_check_window_s``)."""
        cfg = self.config.plane_refinement
        checking = cfg.return_check in ("prediction", "bounded") and check_return
        if not (checking and refined.ok):
            return refined
        length = degeneracy.characteristic_length
        B = refined.basis_scaled
        apart = B @ geometry.scale_twist(geometry.log(np.linalg.inv(measured) @ start), length)
        gap = float(np.linalg.norm(apart))
        if gap <= 0.0:
            return refined
        u = apart / gap
        if float(u @ refined.information @ u) < MIN_TESTED_INFORMATION:
            return refined  # nothing to drop along it
        left = B @ geometry.scale_twist(geometry.log(np.linalg.inv(refined.pose) @ other.pose),
                                        length)
        ratio = float(left @ u) / gap
        self.counters["return_checks"] += 1
        bounds = None
        if cfg.return_check == "bounded":
            apart_end = abs(ratio) * gap
            bounds = np.array([1.0 / apart_end**2 if apart_end > 0 else np.inf])
        held = without_unheld(refined, (u @ B)[None, :], np.array([ratio]), cfg.max_return_ratio,
                              bounds)
        if held is not refined:
            self.counters["unheld_directions"] += 1
        return held

    def _plane_config(self, without_wheels: bool) -> PlaneRefinementConfig:
        """The plane fits' settings for a scan: with vertical lines when
        ``vertical_lines_without_wheels`` and with blobs when ``blobs_without_wheels``, and
        ``without_wheels`` (no wheel data for longer than ``return_check_window_s``, or none
        at all: :meth:`_wheels_recent` is False)."""
        cfg = self.config.plane_refinement
        if without_wheels and cfg.vertical_lines_without_wheels and not cfg.vertical_lines:
            cfg = replace(cfg, vertical_lines=True)
        if without_wheels and cfg.blobs_without_wheels and not cfg.blobs:
            cfg = replace(cfg, blobs=True)
        return cfg

    def _wheels_recent(self, t: float) -> bool:
        """True when the newest wheel data is at most ``return_check_window_s`` older than
        ``t`` [s] (the window in which the return check may leave a direction to the IMU)."""
        newest = self.estimator.wheels.newest_time
        window = self.config.plane_refinement.return_check_window_s
        return newest is not None and t - newest <= window

    def _checked_by_offset(self, planes: PlaneFitCache, refined: PlaneRefinement,
                   degeneracy: DegeneracyResult) -> PlaneRefinement:
        """``refined`` without the information along the directions of its subspace it does
        not come back along when moved (``plane_refinement.return_check``,
        :func:`lili_odom.pipeline.plane_refinement.returned_directions`).

        Run on scans without wheel data, where that information alone holds the fused pose
        along the subspace against the IMU: information without a return (planes whose tilt
        follows the sampling pattern) holds the point-to-point registration's lag and
        slows the fused motion down scan after scan.
        """
        cfg = self.config.plane_refinement
        rows, ratios = returned_directions(planes.points, planes.reference, refined,
                                           degeneracy.characteristic_length, cfg)
        self.counters["return_checks"] += int(np.count_nonzero(ratios))
        held = without_unheld(refined, rows, ratios, cfg.max_return_ratio)
        if held is not refined:
            self.counters["unheld_directions"] += int(held.details["unheld"])
        return held

    def _travel(self, guess: np.ndarray) -> np.ndarray:
        """Predicted translation [m] of the LiDAR since the previous output (odometry frame)."""
        return guess[:3, 3] - (self._last_output.pose @ self.T_base_lidar)[:3, 3]

    def _weak_directions(self, planes: PlaneFitCache, pose: np.ndarray, guess: np.ndarray,
                         degeneracy: DegeneracyResult) -> DegeneracyResult | None:
        """The detection with the directions of the robot's planar motion that point-to-plane
        barely holds added (``plane_refinement.weak_information``), or None when there are
        none.

        LiLi asks whether point-to-point re-registrations come back; against a young or sparse
        map a direction can come back to a point-to-point optimum that the scene does not fix
        (open ground: the ground's rings, fixed to the sensor, hold x, y and yaw wherever the
        last scans left them). The debiased point-to-plane information of the registration
        (:func:`lili_odom.pipeline.plane_refinement.refine_in_subspace`, no step) tells such
        directions: the ground's normals say nothing about them. Only base_link's forward,
        lateral and yaw motion outside the detected subspace is checked: the wheels and the
        IMU carry those well, while roll, pitch and height, which a tunnel's walls may hold
        only weakly, are not the wheels' to carry. Directions it holds are left to LiLi. Like
        the along-track check it applies only while the sensor moves (predicted travel since
        the previous scan of at least ``min_travel_m``): the pull comes from the motion
        against the map's sampling pattern.
        """
        cfg = self.config.plane_refinement
        limit = cfg.weak_information
        if not (cfg.enabled and limit > 0):
            return None
        if float(np.linalg.norm(self._travel(guess))) < cfg.min_travel_m:
            return None
        if self._held_outside(degeneracy) >= limit:
            return None  # every direction outside the subspace, so every planar one, holds it
        B = degeneracy.basis_scaled
        length = degeneracy.characteristic_length
        C = self._outside(degeneracy, planar=True)
        if not len(C):
            return None
        full = refine_in_subspace(planes.points, planes.reference, pose, C, length,
                                  replace(cfg, iterations=0), fits=planes.at(pose))
        if not full.ok:
            return None
        w, V = np.linalg.eigh(full.information)
        C = full.basis_scaled
        weak = w < limit
        if not weak.any():
            return None
        self.counters["weak_directions"] += int(weak.sum())
        rows = V[:, weak].T @ C  # orthonormal, orthogonal to the subspace
        details = {**degeneracy.details, "weak": int(weak.sum())}
        return replace(degeneracy, basis_scaled=np.vstack([B, rows]), details=details)

    def _along_track(self, planes: PlaneFitCache, pose: np.ndarray, guess: np.ndarray,
                     degeneracy: DegeneracyResult):
        """Point-to-plane along the direction of travel where the detector found it
        constrained (``plane_refinement.along_track``), or None when it does not apply: no
        travel, or a scan its planes hold in every direction to ``constrained_information``
        (this scan's screen), where the constrained refinement
        (:meth:`_refine_constrained`) takes the full step along the travel anyway.

        The direction is the predicted translation since the previous scan (LiDAR frame)
        without its part inside the detected subspace (scaled twists, characteristic length
        of the detection); it applies when at least ``min_along_share`` of the travel is left.
        Point-to-point ICP against a local map built from a moving sensor's scans is pulled
        back towards the earlier poses along the direction of travel (the scans' ring and
        column patterns are fixed to the sensor), and LiLi's perturbations are held by the
        same pull, so they come back and the direction looks constrained: on open ground,
        where the ground's rings are most of the points, the registration lags metres behind
        while LiLi flags only the yaw the few poles leave free. Point-to-plane has no such
        pull: when it holds the direction (information >= ``min_along_information``) its pose
        is the measurement (``ok``); when it does not (a featureless tunnel seen through a
        young map, open ground between distant poles), the direction joins the degenerate
        subspace (``ok`` False, ``degeneracy`` set).
        """
        cfg = self.config.plane_refinement
        if not (cfg.enabled and cfg.along_track):
            return None
        if (cfg.refine_constrained != "off"
                and self._held_outside(degeneracy) >= cfg.constrained_information):
            return None  # held outside the subspace: the constrained refinement steps there
        travel = pose[:3, :3].T @ self._travel(guess)
        n = float(np.linalg.norm(travel))
        if n < cfg.min_travel_m:
            return None
        direction = np.concatenate([travel / n, np.zeros(3)])  # scaled = plain (no rotation)
        B = degeneracy.basis_scaled
        if len(B):
            direction = direction - B.T @ (B @ direction)
            left = float(np.linalg.norm(direction))
            if left < cfg.min_along_share:
                return None
            direction = direction / left
        direction = direction[None, :]
        length = degeneracy.characteristic_length
        refined = refine_in_subspace(planes.points, planes.reference, pose, direction, length,
                                     cfg, fits=planes.at(pose))
        if refined.ok and refined.information[0, 0] >= cfg.min_along_information:
            self.counters["along_track_refined"] += 1
            return _AlongTrack(True, refined.pose, None)
        self.counters["along_track_degenerate"] += 1
        details = {**degeneracy.details, "along_track": True}
        return _AlongTrack(False, pose, replace(degeneracy,
                                                basis_scaled=np.vstack([B, direction]),
                                                details=details))

    def _held_outside(self, degeneracy: DegeneracyResult) -> float:
        """The information [1/m^2, scaled] this scan's screen says every direction outside
        ``degeneracy``'s subspace holds, or -inf when it says nothing: the weakest direction's
        on a scan it found held in every direction; ``clear_information`` on its planes'
        subspace when ``plane_refinement.check_screened_subspace`` is False (True: the checks
        measure those directions themselves); -inf for a detection, or a result carried over
        from another scan."""
        if not _screen_result_here(degeneracy):
            return -math.inf
        if not len(degeneracy.basis_scaled):
            return float(degeneracy.details["min_information"])
        cfg = self.config.plane_refinement
        return -math.inf if cfg.check_screened_subspace else float(cfg.clear_information)

    def _outside(self, degeneracy: DegeneracyResult, planar: bool) -> np.ndarray:
        """Orthonormal rows (scaled LiDAR twists, the detection's characteristic length)
        spanning the directions outside the detected subspace: all of them, or with
        ``planar`` only the ground robot's own motion (forward, lateral and yaw of
        base_link)."""
        B = degeneracy.basis_scaled
        if planar:
            length = degeneracy.characteristic_length
            rows = np.linalg.solve(scaled_lidar_to_base(self.T_base_lidar, length),
                                   np.eye(6)[:, [0, 1, 5]]).T
        else:
            rows = np.eye(6)
        if len(B):
            rows = rows - rows @ B.T @ B
        return orthonormal_rows(rows, rtol=1e-3)

    def _refine_constrained(self, planes: PlaneFitCache, pose: np.ndarray,
                            degeneracy: DegeneracyResult,
                            prediction: np.ndarray | None = None) -> np.ndarray:
        """``pose`` refined by point-to-plane in the directions outside the degenerate
        subspace (all, or base_link's planar motion: ``plane_refinement.refine_constrained``)
        that point-to-plane holds with at least ``plane_refinement.constrained_information``;
        ``pose`` itself when there are none.

        The refinement runs in all those directions at once; its information at the result
        (where the residuals no longer carry the registration's offset) tells which of them
        are held that well, and only the step's part along those is kept (scaled twists);
        along the others the registration stays. On a scan the screen found held in every
        direction it runs in up to ``plane_refinement.constrained_rounds`` rounds, each from
        where the last ended (on planes found again there when it is out of their reach),
        until a round moves the pose less than ``constrained_settle_m``; elsewhere in one.
        With ``constrained_from_prediction`` such a scan's rounds also start from
        ``prediction`` (``T_odom_lidar``) and the result the planes fit better is kept (in
        the directions the rounds do not move, the prediction's own).
        """
        cfg = self.config.plane_refinement
        if not cfg.enabled or cfg.refine_constrained == "off":
            return pose
        C = self._outside(degeneracy, planar=cfg.refine_constrained == "planar")
        if not len(C):
            return pose
        length = degeneracy.characteristic_length
        screened = _screened_here(degeneracy)
        rounds = cfg.constrained_rounds if screened else 1
        refined = self._constrained_rounds(planes, pose, C, length, rounds)
        if (screened and cfg.constrained_from_prediction and prediction is not None
                and np.all(np.isfinite(prediction))):
            start = geometry.orthonormalize(np.asarray(prediction, dtype=float))
            other = self._constrained_rounds(planes, start, C, length, rounds)
            fits = planes.at(refined)
            if plane_cost(fits, other, cfg) < plane_cost(fits, refined, cfg):
                self.counters["constrained_from_prediction"] += 1
                refined = other
        if refined is not pose:  # scans, not rounds
            self.counters["constrained_refined"] += 1
        return refined

    def _constrained_rounds(self, planes: PlaneFitCache, pose: np.ndarray, C: np.ndarray,
                            length: float, rounds: int) -> np.ndarray:
        """Up to ``rounds`` rounds of :meth:`_constrained_round` from ``pose``, each from
        where the last ended, until one moves the pose less than ``constrained_settle_m``;
        ``pose`` itself when no round took a step."""
        for round_ in range(rounds):
            refined = self._constrained_round(planes, pose, C, length)
            moved = float(np.linalg.norm(refined[:3, 3] - pose[:3, 3]))
            if round_:
                self.counters["constrained_rounds_extra"] += 1
            pose = refined
            if moved < self.config.plane_refinement.constrained_settle_m:
                break
        return pose

    def _constrained_round(self, planes: PlaneFitCache, pose: np.ndarray, C: np.ndarray,
                           length: float) -> np.ndarray:
        """One round of :meth:`_refine_constrained` from ``pose`` in the directions ``C``
        (orthonormal rows of scaled LiDAR twists, characteristic length ``length`` [m])."""
        cfg = self.config.plane_refinement
        refined = refine_in_subspace(planes.points, planes.reference, pose, C, length, cfg,
                                     fits=planes.at(pose))
        if not refined.ok:
            return pose
        w, V = np.linalg.eigh(0.5 * (refined.information + refined.information.T))
        strong = w >= cfg.constrained_information
        if not strong.any():
            return pose
        if strong.all():
            return refined.pose
        rows = V[:, strong].T @ refined.basis_scaled
        step = geometry.scale_twist(geometry.log(np.linalg.inv(pose) @ refined.pose), length)
        kept = geometry.unscale_twist(rows.T @ (rows @ step), length)
        return geometry.orthonormalize(pose @ geometry.exp(kept))

    def _clear_held_directions(self, degeneracy: DegeneracyResult, refined
                               ) -> tuple[DegeneracyResult, np.ndarray,
                                          tuple[np.ndarray, np.ndarray]]:
        """The detection without the directions point-to-plane holds as well as a
        well-constrained one (information >= ``plane_refinement.clear_information``), the
        subspace information (scaled, 6x6) of the directions left, and those directions as
        rows (k, 6) of scaled LiDAR twists with the information [1/m^2] along each.

        Point-to-point LiLi flags a direction whose perturbations do not come back; in a young
        local map, whose sampling pattern moved with the sensor, that happens along the
        direction of travel in a well-constrained hall too. Such a direction is measured
        fully by the refined pose.
        """
        limit = self.config.plane_refinement.clear_information
        info = refined.information_scaled
        w, V = np.linalg.eigh(0.5 * (refined.information + refined.information.T))
        keep = w < limit if limit > 0 else np.ones(len(w), dtype=bool)
        rows = V[:, keep].T @ refined.basis_scaled
        held = (rows, w[keep])
        if keep.all():
            return degeneracy, info, held
        self.counters["directions_cleared"] += int((~keep).sum())
        info = rows.T @ np.diag(w[keep]) @ rows
        details = {**degeneracy.details, "cleared": int((~keep).sum())}
        return replace(degeneracy, basis_scaled=rows, details=details), info, held

    def _body_twist(self, fused) -> np.ndarray:
        """(v, w) of base_link in base_link from the fused velocity and the pose change."""
        R = fused.pose[:3, :3]
        v = R.T @ np.asarray(fused.velocity, dtype=float)
        w = np.zeros(3)
        last = self._last_output
        if last is not None and fused.t > last.stamp:
            w = geometry.log(np.linalg.inv(last.pose) @ fused.pose)[3:] / (fused.t - last.stamp)
        return np.concatenate([v, w])


def _screen_result_here(degeneracy: DegeneracyResult) -> bool:
    """True for this scan's own screen result (:meth:`OdometryPipeline._screen`), with or
    without the planes' subspace, not one carried over from an earlier scan nor merged with
    a held subspace."""
    d = degeneracy.details
    return bool(d.get("screened")) and not (d.get("reused") or d.get("held"))


def _screened_here(degeneracy: DegeneracyResult) -> bool:
    """True for this scan's own screen result that found every direction held
    (:meth:`OdometryPipeline._screen`), not the planes' subspace of weakly held directions, not
    one carried over from an earlier scan nor merged with a held subspace."""
    return _screen_result_here(degeneracy) and not len(degeneracy.basis_scaled)
