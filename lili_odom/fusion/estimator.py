"""Degeneracy-aware LiDAR-inertial-wheel fusion on an iSAM2 factor graph.

States (one per LiDAR scan, at the scan's ``header.stamp``):

* ``X(i)``: ``gtsam.Pose3`` of ``base_link`` in the odometry frame (gravity-aligned at the
  start, z up; with ``gravity_tracking_gain`` the IMU factors' gravity may later tilt by up to
  ``gravity_tracking_max`` in it, to keep the frame of the local map, see
  :meth:`FusionEstimator._track_gravity`). With ``gravity_variable``, ``X(i)`` is in the
  gravity frame instead, and one more variable ``FRAME`` (``Pose3``) is the odometry frame's
  pose in it: its tilt about x and y is estimated with the accelerometer bias (a prior of
  ``gravity_variable_sigma``), its yaw and translation are held at zero; the estimator's
  outputs are in the odometry frame (``FRAME^-1 X(i)``).
* ``V(i)``: velocity of ``base_link`` in the odometry (resp. gravity) frame [m/s].
* ``B(i)``: ``imuBias.ConstantBias`` (accelerometer [m/s^2], gyro [rad/s]) in the IMU frame.

Factors between consecutive states ``i-1 -> i``:

* ``CombinedImuFactor`` from the IMU samples between the two stamps (IMU -> base_link extrinsic
  as GTSAM ``body_P_sensor``; see :mod:`lili_odom.fusion.imu`).
* LiDAR factor, from the *absolute* scan-to-map registration result ``T_icp`` (base_link in
  the odometry frame; the map is built from fused poses). Its information is the LiDAR
  information with the detected degenerate directions removed
  (:mod:`lili_odom.fusion.subspace`), plus a tiny epsilon there. ``lidar.factor`` chooses
  the form: ``"between"``, a ``BetweenFactorPose3`` with the relative measurement
  ``Z = T_fused(i-1)^-1 T_icp`` against the previous **fused** pose; or ``"prior"``
  (experimental), a ``PriorFactorPose3`` at ``T_icp`` whose degenerate components are taken
  from the wheel prediction (solution remapping, weighted by the wheels' information) and
  held with ``lidar.anchor_sigma``. The relative form counts a correction twice when iSAM2
  later moves ``X(i-1)`` (the new pose is dragged along and the next registration corrects
  it back), so the estimate oscillates across the tunnel scan to scan; the absolute form
  does not, but is sensitive to spurious components of the detected basis (see
  :func:`lili_odom.fusion.subspace.degenerate_anchor` and solution remapping,
  :mod:`lili_odom.pipeline.remap`). ``"hybrid"`` (default)
  adds the prior restricted to translation and yaw and the between factor restricted to roll
  and pitch.
* LiDAR subspace factor (optional, ``subspace`` argument of :meth:`FusionEstimator.update`):
  a ``PriorFactorPose3`` at the registration refined inside the degenerate subspace by
  point-to-plane Gauss-Newton (:mod:`lili_odom.pipeline.plane_refinement`), whose information
  is the LiDAR's own (point-to-plane Hessian) information there, capped at the configured
  LiDAR information. A weakly constrained direction keeps the LiDAR's weight; in a truly
  degenerate place it is about zero and the wheels and the IMU carry the direction.
* Wheel ``BetweenFactorPose3`` whose information lives only inside the degenerate subspace
  (the paper's solution remapping, as a factor): by default the wheels' own weighted fit of
  the motion along it (``wheel_restriction``,
  :func:`lili_odom.fusion.subspace.weighted_restriction`), so the roll and pitch they do not
  measure neither weaken nor move it. Without degeneracy there is no wheel factor unless
  ``wheel_weak_scale`` > 0. The increment's distance is first divided by the wheel
  scale estimated online from registrations that constrain the direction of travel
  (:mod:`lili_odom.fusion.wheel_scale`), since inside the subspace a scale error is drift.

Error convention: GTSAM's ``BetweenFactorPose3`` error is ``Logmap(Z^-1 X(i-1)^-1 X(i))``, a
twist in the body frame of ``X(i)``; all informations here are 6x6 in our ``(v, w)`` order in
base_link and converted with the order permutation at the GTSAM boundary
(:mod:`lili_odom.fusion.factors`).

One :meth:`FusionEstimator.update`: the measurements are checked
(:mod:`lili_odom.fusion.measurements`), the information is split between LiDAR and wheels and
the factors planned (``_plan_factors``), the factors built (:mod:`lili_odom.fusion.factors`)
and iSAM2 solved with the no-IMU retry (``_solve``, ``_motion_factors``), then the
post-update calibration runs (``_after_update``).

Fallbacks:

* No IMU samples covering an interval (or ``use_imu`` False, or a gap longer than
  ``max_interval_s``): the IMU factor is replaced by a loose velocity prior at the motion
  model's velocity and a bias random-walk ``BetweenFactorConstantBias``. The pose then rests on
  the LiDAR factor outside the degenerate subspace and, inside it, on the wheel factor; without
  wheels a loose constant-twist ``BetweenFactorPose3`` (the previous interval's body twist,
  "velocity-free": it does not involve ``V``) takes the wheels' place, with its information
  likewise restricted to the degenerate subspace so that a LiDAR/motion-model disagreement
  elsewhere cannot leak into it. Without LiDAR, that subspace is everything.
* No wheel data: LiDAR + IMU only; degenerate directions are then constrained only by IMU
  preintegration and the covariance reports that.
* Invalid LiDAR pose or degeneracy basis: the LiDAR factor is dropped (counted) and the
  wheel factor, if any, gets its full information (nothing else observes those directions).
* Any non-finite input is rejected with a counter; GTSAM exceptions are caught, the graph is
  rebuilt from the last good state and the update is reported as rejected.

Bounded graph: plain ``gtsam.ISAM2`` (QR factorisation — Cholesky hit "indeterminant
system" after ~300 keyframes in our tests because the absolute pose information decays while
the bias random-walk information is ~1e9) and every ``reset_every`` keyframes the graph is
rebuilt from a single ``LinearContainerFactor`` holding the joint marginal information of the
newest ``X, V, B`` (and ``FRAME``) (so cross-correlations survive, unlike per-variable priors).
``IncrementalFixedLagSmoother`` exists in the wheel but has open marginalisation bugs for
exactly this X/V/B chain (borglab/gtsam#1638), so it is not used.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, Iterable

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from lili_odom.fusion.config import FusionConfig
from lili_odom.fusion.factors import (
    absolute_factor,
    add_cruise_factor,
    add_lidar_factors,
    add_motion_model_factors,
    add_subspace_factor,
    add_wheel_factor,
    from_gtsam_matrix,
    robust_kernel,
)
from lili_odom.fusion.imu import (
    ImuBuffer,
    gravity_alignment,
    integrate,
    integrate_piece,
    lever_arm_in_imu,
    make_preintegration_params,
)
from lili_odom.fusion.measurements import (
    LidarMeasurement,
    WheelIncrement,
    as_pose,
    finite,
    lidar_measurement,
    plausible,
    wheel_increment,
)
from lili_odom.fusion.subspace import (
    SubspaceSplit,
    covariance_along,
    degenerate_anchor,
    inflate_along,
    scaled_lidar_to_base,
    split_information,
    sqrt_information,
)
from lili_odom.fusion.wheel import WheelBuffer
from lili_odom.fusion.wheel_scale import WheelScaleEstimator
from lili_odom.geometry import exp, log, matrix, orthonormalize

__all__ = ["FRAME", "FusionEstimator", "FusionOutput", "FusionStats", "SubspaceMeasurement"]

#: Key of the odometry frame's pose in the gravity frame (``FusionConfig.gravity_variable``).
FRAME = gtsam.symbol("g", 0)

#: Prior sigma [rad, m] of the frame variable's yaw and translation (a gauge: held at zero).
FRAME_GAUGE_SIGMA = 1e-6

@dataclass
class FusionOutput:
    """Fused state at one LiDAR stamp.

    Attributes:
        t: stamp [s].
        index: keyframe index i.
        pose: 4x4 pose of base_link in the odometry frame.
        velocity: (3,) velocity of base_link in the odometry frame [m/s].
        accel_bias: (3,) accelerometer bias, IMU frame [m/s^2].
        gyro_bias: (3,) gyro bias, IMU frame [rad/s].
        covariance: 6x6 marginal covariance of the pose, order (v, w), base_link body frame
            (perturbation ``pose @ exp(xi)``) [m^2, rad^2].
        degenerate_dimension: dimension of the degenerate subspace used for this update.
        used_lidar / used_imu / used_wheel: which measurements entered the update.
        notes: human-readable remarks (fallbacks, rejected inputs).
        gravity_tilt: (2,) rotation [rad] about the odometry frame's x and y axes of
            gravity: the estimate of the frame variable (``FusionConfig.gravity_variable``),
            or the gravity the IMU factors use from this update on
            (``gravity_tracking_gain``; zero without tracking).
    """

    t: float
    index: int
    pose: np.ndarray
    velocity: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    covariance: np.ndarray
    degenerate_dimension: int = 0
    used_lidar: bool = False
    used_imu: bool = False
    used_wheel: bool = False
    notes: list[str] = field(default_factory=list)
    gravity_tilt: np.ndarray = field(default_factory=lambda: np.zeros(2))


@dataclass
class SubspaceMeasurement:
    """The LiDAR's own measurement inside the detected degenerate subspace.

    Attributes:
        pose: 4x4 pose of base_link in the odometry frame (the registration refined inside
            the subspace).
        information_scaled: 6x6 information over scaled LiDAR body twists ``(v, L w)``
            [1/m^2], supported on the subspace.
        length: characteristic length L [m] of the scaling.
    """

    pose: np.ndarray
    information_scaled: np.ndarray
    length: float


@dataclass
class FusionStats:
    """Counters of everything the estimator rejected or worked around."""

    n_updates: int = 0
    n_rejected_stamp: int = 0
    n_rejected_lidar: int = 0
    n_rejected_basis: int = 0
    n_rejected_lidar_information: int = 0
    n_rejected_wheel: int = 0
    n_no_imu: int = 0
    n_no_wheel: int = 0
    n_solver_failures: int = 0
    n_resets: int = 0
    n_reset_fallbacks: int = 0
    last_failure: str = ""


def _joint_prior(joint: gtsam.JointMarginal, keys: list[int]) -> gtsam.JacobianFactor:
    """One linear factor over ``keys`` holding their joint marginal information (GTSAM's
    wrapped ``JacobianFactor`` takes at most three keys: the information is summed from
    one- and two-key ``HessianFactor`` pieces and the sum turned into a ``JacobianFactor``)."""
    pieces = gtsam.GaussianFactorGraph()
    for a, ka in enumerate(keys):
        block = np.asarray(joint.at(ka, ka), dtype=float)
        if not finite(block):
            raise ValueError("bad joint marginal")
        d = block.shape[0]
        pieces.add(gtsam.HessianFactor(ka, 0.5 * (block + block.T), np.zeros(d), 0.0))
        for kb in keys[a + 1:]:
            cross = np.asarray(joint.at(ka, kb), dtype=float)
            if not finite(cross):
                raise ValueError("bad joint marginal")
            m, n = cross.shape
            pieces.add(gtsam.HessianFactor(ka, kb, np.zeros((m, m)), cross, np.zeros(m),
                                           np.zeros((n, n)), np.zeros(n), 0.0))
    return gtsam.JacobianFactor(gtsam.HessianFactor(pieces))


@dataclass
class _FactorPlan:
    """How one update's information is shared out (:meth:`FusionEstimator._plan_factors`).

    ``split``: LiDAR and wheel informations restricted along the degenerate subspace;
    ``lidar_target`` / ``lidar_information``: pose (4x4) and ``(v, w)`` information of the
    LiDAR factor (the registration, or with the degenerate anchor its anchored version);
    ``sub_pose`` / ``sub_info``: the LiDAR subspace factor or None; ``walk_step``: wheel
    random-walk variance [m^2] the anchor hides in this update, or None without anchor.
    """

    split: SubspaceSplit
    lidar_target: np.ndarray | None
    lidar_information: np.ndarray | None
    sub_pose: np.ndarray | None
    sub_info: np.ndarray | None
    walk_step: float | None = None


@dataclass
class _State:
    t: float
    index: int
    pose: gtsam.Pose3  # odometry frame
    velocity: np.ndarray  # odometry frame
    bias: gtsam.imuBias.ConstantBias
    cov_gtsam: np.ndarray  # 6x6 pose marginal, GTSAM order
    frame: gtsam.Pose3 = field(default_factory=gtsam.Pose3)  # odometry frame in the graph's

    @property
    def graph_pose(self) -> gtsam.Pose3:
        """``X(i)`` as the graph holds it (the gravity frame with ``gravity_variable``)."""
        return self.frame.compose(self.pose)

    @property
    def graph_velocity(self) -> np.ndarray:
        """``V(i)`` as the graph holds it."""
        return self.frame.rotation().matrix() @ self.velocity


class FusionEstimator:
    """iSAM2 fusion of IMU preintegration, degeneracy-filtered LiDAR and wheel increments.

    Typical use (all stamps are ``header.stamp`` in seconds)::

        est = FusionEstimator(FusionConfig())
        est.add_imu(t, acc, gyro)            # as IMU messages arrive (os_imu frame)
        est.add_wheel(t, T_odom_base)        # as wheel odometry arrives
        out0 = est.initialize(t_scan0)       # first scan: pose at which it enters the map
        guess = est.predict(t_scan)          # ICP initial guess / deskewing
        out = est.update(t_scan, T_icp, degeneracy_result)
    """

    def __init__(self, config: FusionConfig | None = None) -> None:
        self.config = config or FusionConfig()
        cfg = self.config
        self.T_base_lidar = orthonormalize(cfg.T_base_lidar)
        self.T_base_imu = orthonormalize(cfg.T_base_imu)
        self.imu = ImuBuffer(cfg.imu.buffer_seconds, max_abs_acc=cfg.imu.max_abs_acc,
                             max_abs_gyro=cfg.imu.max_abs_gyro)
        self.wheels = WheelBuffer(cfg.wheel)
        self.wheel_scale = WheelScaleEstimator(cfg.wheel_scale)
        self.stats = FusionStats()
        self._gravity_tilt = np.zeros(2)  # gravity_tracking_gain: rad about odom x, y
        self._tilt_difference = np.zeros(2)  # averaged registration - fused tilt [rad]
        self._frame0 = gtsam.Pose3()  # gravity_variable: prior mean of FRAME at initialize
        self._params = make_preintegration_params(cfg.imu, self.T_base_imu)
        self._lever_arm = (lever_arm_in_imu(self.T_base_imu)
                           if cfg.imu.compensate_angular_acceleration else None)
        self._isam: gtsam.ISAM2 | None = None
        self._state: _State | None = None
        self._since_reset = 0
        self._history: deque[tuple[float, np.ndarray]] = deque(maxlen=max(2, cfg.history_size))
        self._body_rate = np.zeros(6)  # (v, w) per second, base_link, previous interval
        self._kernel_holdoff = self.config.lidar.robust_after_updates
        self._consecutive_failures = 0
        self._anchor_walk = 0.0  # wheel random-walk variance since the anchor took over [m^2]
        self._last_meas: tuple[int, np.ndarray] | None = None  # (index, T_icp) of the last update
        self.last_output: FusionOutput | None = None

    # ---------------------------------------------------------------------------------------
    # inputs

    def add_imu(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> bool:
        """Buffer one IMU sample (IMU frame, m/s^2 and rad/s); False if rejected."""
        return self.imu.add(t, acc, gyro)

    def add_wheel(self, t: float, T_odom_base: np.ndarray) -> bool:
        """Buffer one wheel odometry pose (base_link in the wheel ``odom`` frame)."""
        return self.wheels.add(t, T_odom_base)

    @property
    def initialized(self) -> bool:
        return self._state is not None

    @property
    def graph_size(self) -> int:
        """Number of factors currently held by iSAM2 (bounded by ``reset_every``)."""
        return 0 if self._isam is None else int(self._isam.getFactorsUnsafe().size())

    # ---------------------------------------------------------------------------------------
    # initialisation

    def _new_isam(self) -> gtsam.ISAM2:
        p = gtsam.ISAM2Params()
        p.setRelinearizeThreshold(self.config.relinearize_threshold)
        p.relinearizeSkip = 1
        p.setFactorization("QR")
        return gtsam.ISAM2(p)

    def initialize(
        self, t: float, pose: np.ndarray | None = None, velocity: np.ndarray | None = None,
        velocity_sigma: float | None = None,
    ) -> FusionOutput:
        """Create the first state at stamp ``t`` [s].

        Args:
            pose: 4x4 initial pose of base_link in the odometry frame. None: identity, with
                roll/pitch aligned to gravity from the preceding IMU samples when enabled.
            velocity: (3,) initial velocity in the odometry frame [m/s]. None: from the wheel
                odometry just before ``t`` when the robot is moving, else zero (tight prior if
                the wheels report rest and the IMU agrees, loose otherwise).
            velocity_sigma: sigma of the prior on a given ``velocity`` [m/s]; None:
                ``prior_sigma_velocity``.

        Raises:
            ValueError: non-finite ``t``, invalid ``pose`` or ``velocity``.
        """
        cfg = self.config
        t = float(t)
        if not math.isfinite(t):
            raise ValueError("initial stamp must be finite")
        notes: list[str] = []
        stationary = False
        gyro_bias = np.zeros(3)
        samples = self.imu.samples(t - cfg.gravity_window_s, t) if cfg.use_imu else []
        # a steady IMU also fits constant-speed driving: the wheels, when there, decide
        wheel_v = self._wheel_velocity(t) if velocity is None else None
        wheels_at_rest = wheel_v is not None and np.linalg.norm(wheel_v) < 0.01
        if wheels_at_rest:
            wheel_v = None  # at rest: the IMU's stationary test and tight prior apply
        if samples:
            align = gravity_alignment(samples, self.T_base_imu[:3, :3])
            stationary = align.stationary and wheel_v is None
            if stationary and cfg.estimate_gyro_bias_at_rest:
                gyro_bias = align.gyro_bias
        if pose is None:  # a new odometry frame: gravity along its -z
            self._set_gravity_tilt(np.zeros(2), reset_average=True)
            T0 = np.eye(4)
            if cfg.gravity_align and samples:
                T0[:3, :3] = align.R_world_base
                notes.append("gravity aligned" + (" (at rest)" if stationary else " (moving)"))
        else:
            T0 = as_pose(pose)
            if T0 is None:
                raise ValueError("initial pose must be a finite rigid 4x4 transform")
        if wheel_v is not None:  # started while moving: the wheels know the speed
            v0 = T0[:3, :3] @ wheel_v
            sigma_v = cfg.prior_sigma_velocity_wheel
            notes.append("initial velocity from wheel odometry")
        elif velocity is None:
            # a steady IMU alone cannot tell rest from driving at constant speed (a bag that
            # starts mid-drive): only wheels that report rest make the zero velocity certain
            v0 = np.zeros(3)
            at_rest = stationary and wheels_at_rest
            sigma_v = cfg.prior_sigma_velocity if at_rest else cfg.prior_sigma_velocity_moving
        else:
            v0 = np.asarray(velocity, dtype=float).reshape(3)
            if not finite(v0):
                raise ValueError("initial velocity must be finite")
            sigma_v = cfg.prior_sigma_velocity if velocity_sigma is None else float(velocity_sigma)
            if not (math.isfinite(sigma_v) and sigma_v > 0):
                raise ValueError("initial velocity sigma must be finite and positive")
        bias0 = gtsam.imuBias.ConstantBias(np.zeros(3), gyro_bias)

        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        pose_sigmas = np.array([cfg.prior_sigma_rotation] * 3 + [cfg.prior_sigma_translation] * 3)
        frame, frame_key = gtsam.Pose3(), None
        if cfg.gravity_variable:
            frame, frame_key = self._frame0, FRAME
            graph.add(gtsam.PriorFactorPose3(FRAME, frame, self._frame_noise()))
            values.insert(FRAME, frame)
        graph.add(absolute_factor(X(0), T0, gtsam.noiseModel.Diagonal.Sigmas(pose_sigmas),
                                  frame_key))
        v0 = frame.rotation().matrix() @ v0
        graph.add(gtsam.PriorFactorVector(V(0), v0, gtsam.noiseModel.Isotropic.Sigma(3, sigma_v)))
        bias_sigmas = np.array([cfg.imu.accel_bias_prior_sigma] * 3
                               + [cfg.imu.gyro_bias_prior_sigma] * 3)
        graph.add(gtsam.PriorFactorConstantBias(B(0), bias0,
                                                gtsam.noiseModel.Diagonal.Sigmas(bias_sigmas)))
        values.insert(X(0), frame.compose(gtsam.Pose3(T0)))
        values.insert(V(0), v0)
        values.insert(B(0), bias0)
        self._isam = self._new_isam()
        self._isam.update(graph, values)
        self._since_reset = 0
        self._history.clear()
        self._last_meas = None
        self.wheel_scale.interrupt()
        self._body_rate = np.zeros(6)
        self._anchor_walk = 0.0
        # the LiDAR kernel trusts the IMU prediction only once the velocity is known
        known_velocity = sigma_v <= max(cfg.prior_sigma_velocity, cfg.prior_sigma_velocity_wheel)
        self._kernel_holdoff = 0 if known_velocity else cfg.lidar.robust_after_updates
        self._state = None
        out = self._commit(t, 0, notes, 0, False, False, False)
        assert out is not None
        return out

    def _wheel_velocity(self, t: float) -> np.ndarray | None:
        """Mean body velocity of base_link [m/s] from the wheel poses just before t."""
        for window in (0.2, 0.1, 0.05):
            delta = self.wheels.delta(t - window, t)
            if delta is not None:
                v = delta[:3, 3] / window
                return v if finite(v) and np.linalg.norm(v) < self.config.max_speed else None
        return None

    # ---------------------------------------------------------------------------------------
    # update

    def update(
        self,
        t: float,
        T_icp: np.ndarray | None,
        degeneracy: Any = None,
        *,
        wheel_delta: np.ndarray | None = None,
        lidar_information: np.ndarray | None = None,
        wheel_info: np.ndarray | None = None,
        subspace: SubspaceMeasurement | None = None,
    ) -> FusionOutput | None:
        """Add the state at scan stamp ``t`` and return the fused estimate.

        The steps: check the LiDAR measurement and the wheel increment
        (:mod:`lili_odom.fusion.measurements`), split the information between them along the
        degenerate subspace (:meth:`_plan_factors`), build the factors and solve, retrying
        without the IMU factor when it makes the graph unsolvable (:meth:`_solve`), then
        calibrate from the result: gravity direction, wheel scale, motion model
        (:meth:`_after_update`).

        Args:
            t: scan stamp [s]; must be later than the previous one.
            T_icp: 4x4 pose of base_link in the odometry frame from scan-to-map registration
                (None or invalid: no LiDAR factor).
            degeneracy: object with ``basis_scaled`` ((k, 6) rows, scaled twists ``(v, L w)`` in
                the LiDAR scan body frame) and ``characteristic_length`` L [m] — a
                ``DegeneracyResult``. None or ``ok == False``: nothing is degenerate.
            wheel_delta: 4x4 wheel motion of base_link from the previous stamp to ``t`` in
                base_link at the previous stamp. None: taken from the wheel buffer.
            lidar_information: 6x6 ``(v, w)`` information of the registration in the LiDAR body
                frame (e.g. from the ICP Hessian). None: from ``config.lidar``.
            wheel_info: 6x6 ``(v, w)`` information of the wheel increment in base_link. None:
                from ``config.wheel``.
            subspace: the LiDAR's measurement inside the degenerate subspace (refined pose
                and its information), used only with a valid ``T_icp`` and a non-empty
                subspace (``lidar.subspace_information``).

        Returns:
            The fused output, or None when the update was rejected (bad stamp or solver
            failure; see ``stats``). Before :meth:`initialize` the first call initialises at
            ``t`` (identity/gravity-aligned pose) and ignores ``T_icp``.
        """
        if self._state is None:
            try:
                return self.initialize(t)
            except ValueError:
                self.stats.n_rejected_stamp += 1
                return None
        cfg = self.config
        prev = self._state
        try:
            t = float(t)
        except (TypeError, ValueError):
            t = math.nan
        if not math.isfinite(t) or t <= prev.t + 1e-6:
            self.stats.n_rejected_stamp += 1
            return None
        dt = t - prev.t
        notes: list[str] = []
        T_prev = matrix(prev.pose)
        lidar = lidar_measurement(T_icp, degeneracy, lidar_information, T_prev, dt, cfg,
                                  self.stats, notes)
        wheel = wheel_increment(prev.t, t, wheel_delta, wheel_info, self.wheels,
                                self.wheel_scale, cfg, self.stats, notes)
        if wheel.corrected is None:
            self.stats.n_no_wheel += 1
            if lidar.pose is not None and len(lidar.basis):
                notes.append(f"{len(lidar.basis)} degenerate direction(s) without wheel "
                             "odometry: they rest on the IMU alone (large covariance)")
        plan = self._plan_factors(prev, lidar, wheel, subspace, notes)
        out = self._solve(prev, t, lidar, wheel, plan, notes)
        if out is None:
            self.stats.n_solver_failures += 1
            self._recover(prev)
            return None
        self.stats.n_updates += 1
        self._consecutive_failures = 0
        self._after_update(out, prev, dt, lidar, wheel, plan)
        return out

    def _plan_factors(self, prev: _State, lidar: LidarMeasurement, wheel: WheelIncrement,
                      subspace: SubspaceMeasurement | None, notes: list[str]) -> _FactorPlan:
        """Split the information between LiDAR and wheels along the degenerate subspace,
        prepare the LiDAR subspace factor and, for an absolute LiDAR factor, the degenerate
        anchor at the wheel prediction."""
        cfg = self.config
        if lidar.pose is not None:
            split = split_information(
                lidar.information, wheel.information, lidar.basis, lidar.length,
                self.T_base_lidar, epsilon=cfg.lidar.degenerate_epsilon,
                wheel_weak_scale=cfg.wheel_weak_scale, mode=cfg.lidar.restriction,
                wheel_mode=cfg.wheel_restriction,
            )
        else:  # nothing from the LiDAR: every direction is "degenerate"
            split = split_information(
                lidar.information, wheel.information, np.eye(6), lidar.length,
                self.T_base_lidar, mode=cfg.lidar.restriction,
            )
        sub_pose, sub_info = self._subspace_factor(subspace, lidar.pose, lidar.basis, notes)
        plan = _FactorPlan(split, lidar.pose, split.lidar, sub_pose, sub_info)
        if (split.lidar is not None and cfg.lidar.factor != "between" and split.dimension
                and wheel.corrected is not None and wheel.information is not None
                and cfg.lidar.anchor_sigma > 0.0):
            self._anchor(plan, prev, lidar, wheel)
        return plan

    def _anchor(self, plan: _FactorPlan, prev: _State, lidar: LidarMeasurement,
                wheel: WheelIncrement) -> None:
        """The absolute LiDAR prior held along the degenerate subspace with
        ``lidar.anchor_sigma``: at the wheel prediction's components along the directions the
        wheels measure (mostly planar motion, ``lidar.anchor_min_planar_share``; 0: all of
        them), at the registration's own along the rest."""
        cfg = self.config.lidar
        plan.lidar_target, omega_anchor = degenerate_anchor(
            lidar.pose, matrix(prev.pose) @ wheel.corrected, lidar.basis, lidar.length,
            self.T_base_lidar, cfg.anchor_sigma,
            reference_covariance=from_gtsam_matrix(prev.cov_gtsam),
            reference_information=wheel.information,
            min_planar_share=cfg.anchor_min_planar_share)
        plan.lidar_information = plan.split.lidar + omega_anchor
        # the anchor is an absolute pseudo-measurement: the graph's marginal along the
        # subspace stops growing, so the wheel random walk is added to the reported one
        plan.walk_step = float(np.linalg.eigvalsh(covariance_along(
            np.linalg.inv(wheel.information), lidar.basis, lidar.length,
            self.T_base_lidar)).max())

    def _solve(self, prev: _State, t: float, lidar: LidarMeasurement, wheel: WheelIncrement,
               plan: _FactorPlan, notes: list[str]) -> FusionOutput | None:
        """Add state ``i = prev.index + 1`` with its factors to iSAM2 and read the estimate.

        A graph that the IMU factor makes unsolvable (corrupt but finite samples) is retried
        once with the no-IMU fallback before the update is given up (None; iSAM2 is then
        rebuilt at ``prev`` by the caller).
        """
        cfg = self.config
        i = prev.index + 1
        T_prev = matrix(prev.pose)
        split = plan.split
        out = None
        saturated = cfg.use_imu and self.imu.saturated(prev.t - cfg.imu.max_gap_s, t, 0.95)
        if saturated:  # clipped samples integrate garbage: bridge with the motion model
            notes.append("IMU samples at the sensor's range: IMU factor skipped")
            self._kernel_holdoff = cfg.lidar.robust_after_updates
        for allow_imu in ((False,) if saturated else (True, False)):
            graph = gtsam.NonlinearFactorGraph()
            values = gtsam.Values()
            used_imu, pose_guess, vel_guess = self._motion_factors(
                graph, prev, t, allow_imu, lidar, wheel, notes)
            kernel = None
            used_lidar = split.lidar is not None
            if used_lidar:
                kernel = robust_kernel(cfg.lidar.robust_kernel, cfg.lidar.robust_threshold)
                # the kernel trusts the IMU prediction: not while it may be wrong (samples at
                # the sensor's range, or a velocity not yet observed after (re)initialisation)
                if used_imu and self._kernel_holdoff > 0:
                    kernel = None
                add_lidar_factors(graph, i, cfg.lidar.factor, T_prev, lidar.pose,
                                  plan.lidar_target, plan.lidar_information, kernel,
                                  self._frame_key)
            if used_lidar and plan.sub_info is not None:
                add_subspace_factor(graph, i, plan.sub_pose, plan.sub_info, kernel,
                                    self._frame_key)
            used_wheel = split.wheel is not None and wheel.corrected is not None
            if used_wheel:
                add_wheel_factor(graph, i, wheel.corrected, split.wheel)
            if used_imu and wheel.corrected is None and split.dimension and self._cruising(
                    prev, t, vel_guess):
                add_cruise_factor(graph, i, cfg.cruise_sigma * (t - prev.t),
                                  robust_kernel(cfg.lidar.robust_kernel,
                                                cfg.lidar.robust_threshold))

            values.insert(X(i), pose_guess)
            values.insert(V(i), np.asarray(vel_guess, dtype=float))
            values.insert(B(i), prev.bias)
            try:
                self._isam.update(graph, values)
                for _ in range(max(0, cfg.extra_iterations)):
                    self._isam.update()
                out = self._commit(t, i, notes, split.dimension, used_lidar, used_imu, used_wheel)
            except (RuntimeError, ValueError, IndexError) as exc:
                out = None
                self.stats.last_failure = " ".join(str(exc).split())[:200]
            else:
                if out is None:
                    self.stats.last_failure = "non-finite or implausible estimate"
            if out is not None or not used_imu:
                break
            self._recover(prev)
            notes = notes + ["IMU factor made the update unsolvable; retried without it"]
        return out

    def _cruising(self, prev: _State, t: float, velocity: np.ndarray) -> bool:
        """True when the cruise factor applies from ``prev`` to ``t``: on
        (``cruise_sigma``) and the IMU's prediction ``velocity`` [m/s, graph frame] differs
        from ``prev``'s by at most ``cruise_max_accel`` over the interval."""
        cfg = self.config
        change = float(np.linalg.norm(np.asarray(velocity, dtype=float) - prev.graph_velocity))
        return cfg.cruise_sigma > 0.0 and change <= cfg.cruise_max_accel * (t - prev.t)

    def _motion_factors(self, graph: gtsam.NonlinearFactorGraph, prev: _State, t: float,
                        allow_imu: bool, lidar: LidarMeasurement, wheel: WheelIncrement,
                        notes: list[str]) -> tuple[bool, gtsam.Pose3, np.ndarray]:
        """The IMU factor ``prev -> i`` or, without IMU coverage, the motion-model fallback
        (:func:`lili_odom.fusion.factors.add_motion_model_factors`); returns (IMU used,
        initial pose guess, initial velocity guess [m/s, odometry frame])."""
        cfg = self.config
        i = prev.index + 1
        dt = t - prev.t
        used_imu = False
        pim = None
        if allow_imu and cfg.use_imu and dt <= cfg.max_interval_s:
            pim = gtsam.PreintegratedCombinedMeasurements(self._params, prev.bias)
            rep = integrate(self.imu, pim, prev.t, t, cfg.imu.max_gap_s,
                            cfg.imu.max_extrapolation_s, self._lever_arm)
            used_imu = rep.covered
            if not used_imu:
                notes.append(f"no IMU: {rep.reason}")
        if used_imu:
            graph.add(gtsam.CombinedImuFactor(X(i - 1), V(i - 1), X(i), V(i), B(i - 1), B(i), pim))
            nav = pim.predict(gtsam.NavState(prev.graph_pose, prev.graph_velocity), prev.bias)
            return True, nav.pose(), np.asarray(nav.velocity())
        self.stats.n_no_imu += 1
        omega_cv = None
        if wheel.corrected is not None:
            motion = wheel.corrected
            notes.append("no IMU: wheel increment covers the LiDAR-blind directions")
        else:
            motion = exp(self._body_rate * dt)
            s_t = max(cfg.no_imu_sigma_floor_translation, cfg.no_imu_sigma_translation_per_s * dt)
            s_r = max(cfg.no_imu_sigma_floor_rotation, cfg.no_imu_sigma_rotation_per_s * dt)
            # like the wheels, the motion model only acts where the LiDAR is blind, so a
            # LiDAR/motion-model disagreement elsewhere cannot leak into those directions
            omega_cv = split_information(
                lidar.information, np.diag([s_t**-2] * 3 + [s_r**-2] * 3),
                lidar.basis if lidar.pose is not None else np.eye(6), lidar.length,
                self.T_base_lidar, mode=cfg.lidar.restriction,
            ).wheel
            notes.append("no IMU: constant-velocity motion model")
        pose_guess = prev.graph_pose.compose(gtsam.Pose3(motion))
        vel_guess = matrix(prev.graph_pose)[:3, :3] @ motion[:3, 3] / dt
        add_motion_model_factors(graph, i, motion, omega_cv, vel_guess, dt, cfg)
        return False, pose_guess, vel_guess

    def _after_update(self, out: FusionOutput, prev: _State, dt: float,
                      lidar: LidarMeasurement, wheel: WheelIncrement, plan: _FactorPlan) -> None:
        """Post-update calibration and bookkeeping: gravity tracking, the anchor's random walk
        in the reported covariance, the wheel scale, the motion model's body rate, the robust
        kernel's hold-off, IMU buffer pruning and the periodic graph reset."""
        cfg = self.config
        i = out.index
        T_meas, basis, length = lidar.pose, lidar.basis, lidar.length
        if (out.used_lidar and T_meas is not None and cfg.gravity_tracking_gain > 0.0
                and not cfg.gravity_variable):
            self._track_gravity(T_meas, out.pose, basis, dt)
            out.gravity_tilt = self._gravity_tilt.copy()
        if plan.walk_step is not None and out.used_lidar:
            self._anchor_walk += plan.walk_step
            out.covariance = inflate_along(out.covariance, basis, self._anchor_walk, length,
                                           self.T_base_lidar)
        else:
            self._anchor_walk = 0.0
        # the wheel scale is calibrated on chains of consecutive registrations that constrain
        # the direction of travel (not on the fused poses, which lag them by the fusion's
        # compromise)
        T_scale = None
        if T_meas is not None and out.used_lidar and wheel.raw is not None:
            T_scale = self._scale_measurement(T_meas, wheel.raw, plan.split.lidar, basis,
                                              plan.sub_pose, plan.sub_info)
        if (T_scale is not None and self._last_meas is not None
                and self._last_meas[0] == i - 1):
            self.wheel_scale.observe(wheel.raw, np.linalg.inv(self._last_meas[1]) @ T_scale)
        else:
            self.wheel_scale.interrupt()
        self._last_meas = (i, T_scale) if T_scale is not None else None
        if dt >= 0.01:  # shorter intervals turn registration noise into absurd rates
            rate = log(np.linalg.inv(matrix(prev.pose)) @ out.pose) / dt
            # the constant-velocity fallback never extrapolates faster than the plausibility gates
            for part, limit in ((slice(0, 3), cfg.max_speed), (slice(3, 6), cfg.max_rate)):
                n = float(np.linalg.norm(rate[part]))
                if n > limit:
                    rate[part] *= limit / n
            self._body_rate = rate
        # after an interval without IMU the velocity is unobserved again: kernel off for a while
        self._kernel_holdoff = (max(0, self._kernel_holdoff - 1) if out.used_imu
                                else cfg.lidar.robust_after_updates)
        self.imu.discard_before(prev.t - 1.0)
        self._since_reset += 1
        if self._since_reset >= max(1, cfg.reset_every):
            self._reset()

    def _subspace_factor(self, subspace: SubspaceMeasurement | None, T_meas: np.ndarray | None,
                         basis: np.ndarray, notes: list[str]
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(pose, base_link ``(v, w)`` information) of the LiDAR subspace factor, or Nones.

        The information is mapped from scaled LiDAR twists to base_link, its eigenvalues
        capped at the configured LiDAR information's largest in the scaled space (the
        subspace never claims more than a well-constrained direction) and dropped when its
        largest is below ``lidar.subspace_min_information``.
        """
        cfg = self.config.lidar
        if subspace is None or not cfg.subspace_information or T_meas is None or not len(basis):
            return None, None
        pose = as_pose(getattr(subspace, "pose", None))
        try:
            info = np.asarray(subspace.information_scaled, dtype=float)
            length = float(subspace.length)
        except (AttributeError, TypeError, ValueError):
            info, length = np.full((6, 6), np.nan), math.nan
        if (pose is None or info.shape != (6, 6) or not finite(info)
                or not (math.isfinite(length) and 1e-3 <= length <= 1e6)):
            self.stats.n_rejected_lidar_information += 1
            notes.append("LiDAR subspace measurement rejected")
            return None, None
        w, v = np.linalg.eigh(0.5 * (info + info.T))
        S_inv = np.diag([1.0, 1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
        nominal = float(np.linalg.eigvalsh(S_inv @ cfg.information() @ S_inv).max())
        w = np.clip(w, 0.0, nominal)
        if not w.max() >= cfg.subspace_min_information:
            return None, None
        Minv = np.linalg.inv(scaled_lidar_to_base(self.T_base_lidar, length))
        base = Minv.T @ ((v * w) @ v.T) @ Minv
        return pose, 0.5 * (base + base.T)

    def _scale_measurement(self, T_meas: np.ndarray, wheel: np.ndarray,
                           lidar_info: np.ndarray | None, basis: np.ndarray,
                           sub_pose: np.ndarray | None, sub_info: np.ndarray | None
                           ) -> np.ndarray | None:
        """The LiDAR pose the wheel scale may compare the wheels with, or None.

        Without a degenerate subspace, the registration. With one, the subspace-refined
        registration when the LiDAR's information (kept part plus subspace factor) holds the
        wheels' direction of travel to ``wheel_scale.max_lidar_sigma`` (marginal 1-sigma
        along it; ``max_lidar_sigma_start`` until the scale is established); else None (the
        registration's components along the subspace are the wheels' own prediction).
        """
        if not len(basis):
            return T_meas
        cfg = self.config.wheel_scale
        limit = cfg.max_lidar_sigma
        if limit > 0 and cfg.max_lidar_sigma_start > 0 and not self.wheel_scale.established:
            limit = cfg.max_lidar_sigma_start
        if sub_pose is None or sub_info is None or lidar_info is None or not limit > 0:
            return None
        d = np.asarray(wheel, dtype=float)[:3, 3]
        n = float(np.linalg.norm(d))
        if not n > 1e-3:
            return None
        u = np.concatenate([d / n, np.zeros(3)])
        total = 0.5 * (lidar_info + lidar_info.T) + sub_info
        try:
            var = float(u @ np.linalg.solve(total, u))
        except np.linalg.LinAlgError:
            return None
        return sub_pose if 0.0 <= var <= limit * limit else None

    @property
    def gravity_tilt(self) -> np.ndarray:
        """(2,) rotation [rad] about the odometry frame's x and y of the gravity the IMU
        factors use (``gravity_tracking_gain``, or the newest estimate of the frame variable
        with ``gravity_variable``); settable, e.g. to carry it over to a new estimator in the
        same odometry frame (with ``gravity_variable``: the prior mean of the next
        :meth:`initialize`)."""
        if self.config.gravity_variable:
            frame = self._state.frame if self._state is not None else self._frame0
            return self._tilt_of(frame)
        return self._gravity_tilt.copy()

    @gravity_tilt.setter
    def gravity_tilt(self, tilt: np.ndarray) -> None:
        tilt = np.asarray(tilt, dtype=float).reshape(2)
        if not finite(tilt):
            raise ValueError("gravity tilt must be finite")
        self._set_gravity_tilt(tilt)

    @staticmethod
    def _tilt_of(frame: gtsam.Pose3) -> np.ndarray:
        """Gravity tilt (about the odometry frame's x and y) of a frame variable value: gravity
        in the odometry frame is ``R^T (0, 0, -g)``."""
        return np.asarray(gtsam.Rot3.Logmap(frame.rotation().inverse()), dtype=float)[:2]

    @property
    def _frame_key(self) -> int | None:
        return FRAME if self.config.gravity_variable else None

    def _frame_noise(self) -> gtsam.noiseModel.Base:
        """Prior of the frame variable: tilt ``gravity_variable_sigma``, the gauge held."""
        sigma = self.config.gravity_variable_sigma
        return gtsam.noiseModel.Diagonal.Sigmas(
            np.array([sigma, sigma] + [FRAME_GAUGE_SIGMA] * 4))

    def _set_gravity_tilt(self, tilt: np.ndarray, reset_average: bool = False) -> None:
        if self.config.gravity_variable:  # the IMU factors keep the gravity frame's -z
            self._frame0 = gtsam.Pose3(gtsam.Rot3.Expmap(np.array([tilt[0], tilt[1], 0.0]))
                                       .inverse(), np.zeros(3))
            return
        self._gravity_tilt = np.asarray(tilt, dtype=float).copy()
        if reset_average:
            self._tilt_difference = np.zeros(2)
        self._params = make_preintegration_params(self.config.imu, self.T_base_imu,
                                                  self._gravity_tilt)

    def _track_gravity(self, T_meas: np.ndarray, T_fused: np.ndarray, basis: np.ndarray,
                       dt: float) -> None:
        """One integral step of the gravity direction towards the registration's tilt.

        The registration ``T_meas`` (base_link in the odometry frame, against the local map)
        carries the map's tilt, ``T_fused`` the IMU's. Their world-frame rotation difference
        about x and y is averaged (exponentially, ``gravity_tracking_window_s``); where the
        average exceeds ``gravity_tracking_deadband``, the excess times
        ``gravity_tracking_gain`` rotates the gravity of the following IMU factors, so a
        persistent disagreement (the map built in a frame tilted by an accelerometer bias
        taken for gravity at the start) is absorbed by gravity instead of the pose, while the
        small lag of a map that follows the estimate is not integrated. Skipped when the
        detected subspace contains a tilt (the registration's tilt is then not measured) or
        the difference exceeds ``gravity_tracking_gate``.
        """
        cfg = self.config
        if len(basis):
            R_bl = self.T_base_lidar[:3, :3]
            tilt_part = np.linalg.norm((basis[:, 3:] @ R_bl.T)[:, :2], axis=1)
            if np.any(tilt_part > 0.3 * np.linalg.norm(basis, axis=1)):
                return
        d = np.asarray(gtsam.Rot3.Logmap(gtsam.Rot3(T_meas[:3, :3] @ T_fused[:3, :3].T)))[:2]
        if not finite(d) or np.linalg.norm(d) > cfg.gravity_tracking_gate:
            return
        alpha = min(1.0, max(0.0, dt) / cfg.gravity_tracking_window_s)
        self._tilt_difference += alpha * (d - self._tilt_difference)
        m = float(np.linalg.norm(self._tilt_difference))
        if m <= cfg.gravity_tracking_deadband:
            return
        excess = self._tilt_difference * (1.0 - cfg.gravity_tracking_deadband / m)
        tilt = self._gravity_tilt + cfg.gravity_tracking_gain * excess
        n = float(np.linalg.norm(tilt))
        if n > cfg.gravity_tracking_max:
            tilt *= cfg.gravity_tracking_max / n
        self._set_gravity_tilt(tilt)

    # ---------------------------------------------------------------------------------------
    # bookkeeping

    def _commit(self, t: float, i: int, notes: list[str], dim: int, used_lidar: bool,
                used_imu: bool, used_wheel: bool) -> FusionOutput | None:
        """Read the newest state from iSAM2; None when it is not finite."""
        est = self._isam.calculateEstimate()
        pose = est.atPose3(X(i))
        vel = np.asarray(est.atVector(V(i)), dtype=float)
        bias = est.atConstantBias(B(i))
        frame = gtsam.Pose3()
        if self.config.gravity_variable:
            frame = est.atPose3(FRAME)
            pose = frame.between(pose)
            vel = frame.rotation().matrix().T @ vel
        cov_g = self._pose_covariance(pose, i)
        T = matrix(pose)
        if (not finite(T, vel, bias.vector(), cov_g, matrix(frame))
                or not self._sane(T, vel, bias, cov_g)):
            return None
        self._state = _State(t, i, pose, vel, bias, cov_g, frame)
        self._history.append((t, T))
        out = FusionOutput(
            t=t, index=i, pose=T, velocity=vel,
            accel_bias=np.asarray(bias.accelerometer(), dtype=float),
            gyro_bias=np.asarray(bias.gyroscope(), dtype=float),
            covariance=from_gtsam_matrix(cov_g), degenerate_dimension=dim,
            used_lidar=used_lidar, used_imu=used_imu, used_wheel=used_wheel, notes=notes,
            gravity_tilt=self.gravity_tilt,
        )
        self.last_output = out
        return out

    def _pose_covariance(self, pose: gtsam.Pose3, i: int) -> np.ndarray:
        """6x6 marginal covariance (GTSAM order, body frame) of state ``i``'s pose in the
        odometry frame (``pose``). With ``gravity_variable``, ``FRAME^-1 X(i)`` perturbed by
        the frame's ``eta`` and the pose's ``xi`` moves by ``xi - Ad(pose^-1) eta``, so the
        frame's uncertainty (a tilt's lever over the distance from the origin) does not count
        where the odometry frame is concerned."""
        if not self.config.gravity_variable:
            return np.asarray(self._isam.marginalCovariance(X(i)), dtype=float)
        joint = self._isam.jointMarginalCovariance([FRAME, X(i)])
        blocks = [[np.asarray(joint.at(a, b), dtype=float) for b in (FRAME, X(i))]
                  for a in (FRAME, X(i))]
        J = np.hstack([-np.asarray(pose.inverse().AdjointMap()), np.eye(6)])
        cov = J @ np.block(blocks) @ J.T
        return 0.5 * (cov + cov.T)

    def _sane(self, T: np.ndarray, vel: np.ndarray, bias: gtsam.imuBias.ConstantBias,
              cov_g: np.ndarray) -> bool:
        """Reject finite but absurd estimates (they would poison every later update)."""
        cfg = self.config
        return bool(
            np.abs(T[:3, 3]).max() < 1e7
            and np.linalg.norm(vel) < 10.0 * cfg.max_speed + 10.0
            and np.abs(bias.accelerometer()).max() < cfg.imu.max_abs_acc
            and np.abs(bias.gyroscope()).max() < cfg.imu.max_abs_gyro
            and np.diag(cov_g).min() >= 0.0
            and np.diag(cov_g).max() < 1e12
        )

    def _reset(self) -> None:
        """Rebuild iSAM2 from the joint marginal of the newest (X, V, B) and, with
        ``gravity_variable``, the frame variable."""
        s = self._state
        keys = [X(s.index), V(s.index), B(s.index)]
        lin = gtsam.Values()
        lin.insert(keys[0], s.graph_pose)
        lin.insert(keys[1], s.graph_velocity)
        lin.insert(keys[2], s.bias)
        if self.config.gravity_variable:
            keys.append(FRAME)
            lin.insert(FRAME, s.frame)
        graph = gtsam.NonlinearFactorGraph()
        try:
            if self.config.gravity_variable:
                jf = _joint_prior(self._isam.jointMarginalInformation(keys), keys)
            else:
                info = np.asarray(self._isam.jointMarginalInformation(keys).fullMatrix(),
                                  dtype=float)
                if info.shape != (15, 15) or not finite(info):
                    raise ValueError("bad joint marginal")
                R = np.linalg.qr(sqrt_information(info), mode="r")
                jf = gtsam.JacobianFactor(keys[0], R[:, 0:6], keys[1], R[:, 6:9], keys[2],
                                          R[:, 9:15], np.zeros(15),
                                          gtsam.noiseModel.Unit.Create(15))
            graph.add(gtsam.LinearContainerFactor(jf, lin))
            isam = self._new_isam()
            isam.update(graph, lin)
        except (RuntimeError, ValueError, IndexError):
            self.stats.n_reset_fallbacks += 1
            isam = self._priors_isam(s)
        self._isam = isam
        self._since_reset = 0
        self.stats.n_resets += 1

    def _priors_isam(self, s: _State) -> gtsam.ISAM2:
        """Fresh iSAM2 with independent priors at state ``s`` (recovery path)."""
        cfg = self.config
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        cov = 0.5 * (s.cov_gtsam + s.cov_gtsam.T)
        w, v = np.linalg.eigh(cov)
        cov = (v * np.clip(w, 1e-12, 1e6)) @ v.T  # well-conditioned: never an unsolvable prior
        try:
            pose_noise = gtsam.noiseModel.Gaussian.Covariance(cov)
        except RuntimeError:
            pose_noise = gtsam.noiseModel.Isotropic.Sigma(6, 1.0)
        if cfg.gravity_variable:  # the frame as it stands: the bias is reset around it
            graph.add(gtsam.PriorFactorPose3(FRAME, s.frame, gtsam.noiseModel.Isotropic.Sigma(
                6, FRAME_GAUGE_SIGMA)))
            values.insert(FRAME, s.frame)
        graph.add(absolute_factor(X(s.index), matrix(s.pose), pose_noise, self._frame_key))
        graph.add(gtsam.PriorFactorVector(V(s.index), s.graph_velocity,
                                          gtsam.noiseModel.Isotropic.Sigma(
                                              3, cfg.prior_sigma_velocity_moving)))
        graph.add(gtsam.PriorFactorConstantBias(B(s.index), s.bias, gtsam.noiseModel.Diagonal.Sigmas(
            np.array([cfg.imu.accel_bias_prior_sigma] * 3 + [cfg.imu.gyro_bias_prior_sigma] * 3))))
        values.insert(X(s.index), s.graph_pose)
        values.insert(V(s.index), s.graph_velocity)
        values.insert(B(s.index), s.bias)
        isam = self._new_isam()
        isam.update(graph, values)
        return isam

    def _recover(self, prev: _State) -> None:
        """After a solver failure: restart from the last good state.

        After ``3`` failures in a row the velocity, bias and motion model are also reset
        (zero, with loose priors), so a poisoned state cannot block the estimator for good.
        """
        self._consecutive_failures += 1
        self._body_rate = np.zeros(6)
        self._anchor_walk = 0.0
        self._kernel_holdoff = self.config.lidar.robust_after_updates
        if self._consecutive_failures >= 3:
            prev = replace(prev, velocity=np.zeros(3), bias=gtsam.imuBias.ConstantBias())
        self._state = prev
        try:
            self._isam = self._priors_isam(prev)
        except (RuntimeError, ValueError, IndexError):  # pragma: no cover - last resort
            self._isam = None
            self._state = None
        self._since_reset = 0

    # ---------------------------------------------------------------------------------------
    # prediction

    def predict(self, t: float) -> np.ndarray | None:
        """Pose of base_link (4x4, odometry frame) at ``t`` [s]; None before initialisation.

        Later than the newest state: IMU propagation from it (current bias); without IMU
        coverage the wheel increment, else the previous interval's constant body twist.
        Earlier: interpolation between recent fused keyframes.
        """
        out = self.predict_poses([t])
        return None if out is None else out[0]

    def velocity_sigma(self) -> float | None:
        """Largest standard deviation [m/s] of the newest state's velocity (odometry frame,
        iSAM2's marginal); None before the first state or when it cannot be computed."""
        s = self._state
        if s is None or self._isam is None:
            return None
        try:
            cov = np.asarray(self._isam.marginalCovariance(V(s.index)), dtype=float)
        except RuntimeError:
            return None
        if cov.shape != (3, 3) or not finite(cov):
            return None
        return math.sqrt(max(float(np.linalg.eigvalsh(0.5 * (cov + cov.T)).max()), 0.0))

    def wheel_prediction(self, t: float) -> np.ndarray | None:
        """Pose of base_link (4x4, odometry frame) at ``t`` [s]: the newest fused pose moved by
        the (scale-corrected) wheel increment since it; None without wheel data or state.

        Unlike :meth:`predict` it does not depend on the fused velocity, so a measurement
        built from it (solution remapping) cannot confirm a velocity error back to the state.
        """
        s = self._state
        if s is None or not t > s.t:
            return None
        delta = self.wheels.delta(s.t, t)
        delta = as_pose(delta) if delta is not None else None
        if delta is None or not plausible(delta, t - s.t, self.config):
            return None
        return matrix(s.pose) @ self.wheel_scale.correct(delta)

    def predict_poses(self, times: Iterable[float]) -> np.ndarray | None:
        """Poses (n, 4, 4) at many stamps with one IMU integration pass (for deskewing).

        Each query costs one ``NavState`` prediction, so deskewers should query a coarse grid
        (tens of stamps per sweep) and interpolate between them.
        """
        if self._state is None:
            return None
        s = self._state
        times = np.asarray(list(times), dtype=float).reshape(-1)
        out = np.empty((times.size, 4, 4))
        T_last = matrix(s.pose)
        future = []
        for k, tq in enumerate(times):
            if not math.isfinite(tq):
                out[k] = T_last
            elif tq <= s.t:
                out[k] = self._interpolate_history(tq)
            else:
                future.append(k)
        if not future:
            return out
        order = sorted(future, key=lambda k: times[k])
        t_max = float(times[order[-1]])
        cfg = self.config
        covered = False
        if cfg.use_imu and t_max - s.t <= cfg.max_interval_s:
            probe = gtsam.PreintegratedCombinedMeasurements(self._params, s.bias)
            covered = integrate(self.imu, probe, s.t, t_max, cfg.imu.max_gap_s,
                                cfg.imu.max_extrapolation_s, self._lever_arm).covered
        if covered:
            nav0 = gtsam.NavState(s.graph_pose, s.graph_velocity)
            to_odom = np.linalg.inv(matrix(s.frame)) if cfg.gravity_variable else None
            knots = self.imu.knots(s.t, t_max, cfg.imu.max_extrapolation_s)
            pim = gtsam.PreintegratedCombinedMeasurements(self._params, s.bias)
            kt = [k[0] for k in knots]
            j = 0  # current knot segment start
            t_cur = s.t
            acc_cur, gyr_cur = knots[0][1], knots[0][2]
            for k in order:
                tq = float(times[k])
                while j + 1 < len(knots) and kt[j + 1] <= tq:
                    tn, an, gn = knots[j + 1]
                    if tn > t_cur:
                        integrate_piece(pim, acc_cur, an, gyr_cur, gn, tn - t_cur,
                                        self._lever_arm)
                    t_cur, acc_cur, gyr_cur = tn, an, gn
                    j += 1
                if tq > t_cur:
                    ta, aa, ga = knots[j]
                    tb, ab, gb = knots[min(j + 1, len(knots) - 1)]
                    w = 0.0 if tb <= ta else (tq - ta) / (tb - ta)
                    aq, gq = (1 - w) * aa + w * ab, (1 - w) * ga + w * gb
                    integrate_piece(pim, acc_cur, aq, gyr_cur, gq, tq - t_cur, self._lever_arm)
                    t_cur, acc_cur, gyr_cur = tq, aq, gq
                out[k] = matrix(pim.predict(nav0, s.bias).pose())
                if to_odom is not None:
                    out[k] = to_odom @ out[k]
            return out
        for k in order:
            tq = float(times[k])
            delta = self.wheels.delta(s.t, tq)
            if delta is None:
                delta = exp(self._body_rate * (tq - s.t))
            out[k] = T_last @ delta
        return out

    def _interpolate_history(self, t: float) -> np.ndarray:
        hist = list(self._history)
        if t <= hist[0][0]:
            return hist[0][1]
        for (ta, Ta), (tb, Tb) in zip(hist[:-1], hist[1:]):
            if ta <= t <= tb:
                w = (t - ta) / (tb - ta) if tb > ta else 0.0
                return Ta @ exp(w * log(np.linalg.inv(Ta) @ Tb))
        return hist[-1][1]
