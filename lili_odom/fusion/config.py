"""Configuration of the fusion estimator (dataclasses; SI units, 1-sigma values).

Why the defaults are what they are, and how they were measured: ``docs/design/fusion.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from lili_odom.errors import check_range
from lili_odom.extrinsics import OS1_SENSOR_TO_IMU, OS1_SENSOR_TO_LIDAR, pose_from_xyz_rpy
from lili_odom.fusion.imu import ImuNoiseConfig
from lili_odom.fusion.wheel import WheelNoiseConfig
from lili_odom.fusion.wheel_scale import WheelScaleConfig

__all__ = ["LidarNoiseConfig", "FusionConfig", "ImuNoiseConfig", "WheelNoiseConfig"]

ROBUST_KERNELS = ("none", "huber", "cauchy")
RESTRICTIONS = ("marginalize", "project")
WHEEL_RESTRICTIONS = ("same", *RESTRICTIONS, "weighted")
LIDAR_FACTORS = ("prior", "between", "hybrid")


@dataclass
class LidarNoiseConfig:
    """Noise of one scan-to-map registration increment, in the LiDAR body frame.

    Attributes:
        sigma_translation: [m] per axis.
        sigma_rotation: [rad] per axis.
        degenerate_epsilon: information kept along removed (degenerate) directions, relative
            to the largest eigenvalue of the scaled LiDAR information; keeps the factor
            positive definite while contributing (for the defaults) a ~20 m sigma.
        restriction: ``"marginalize"`` (treat the degenerate components of the measurement
            as unknown, Schur complement) or ``"project"`` (plain ``P Omega P``).
        default_length: characteristic length L [m] used when no detector result is given.
        robust_kernel: M-estimator on the LiDAR factor: ``none``, ``huber`` or ``cauchy``. A
            registration that slid along a direction the detector missed then disagrees with
            the IMU/wheel prediction by many sigmas and is down-weighted instead of dragging
            the velocity and bias along.
        robust_threshold: kernel threshold on the whitened residual norm (sigmas). The
            residual of a 6-DoF factor has norm ~sqrt(6) = 2.4 under nominal noise, so a
            threshold of 1 already down-weights a correct registration about 7x and lets one
            noisy axis (e.g. roll about a horseshoe tunnel's arch) silence the axes that are
            well measured; 3 keeps ~60 % weight at nominal noise and still cuts a slid
            registration (10 sigma) to ~8 %.
        factor: how the scan-to-map registration enters the graph. ``"between"``:
            a ``BetweenFactorPose3`` from the previous fused pose with
            ``Z = T_fused(i-1)^-1 T_icp`` (when iSAM2 later moves ``X(i-1)`` the correction
            is counted twice). ``"prior"`` (experimental): an absolute ``PriorFactorPose3``
            on the new pose (the registration measures the pose against the map, which lives
            in the odometry frame); see ``anchor_sigma``. ``"hybrid"`` (default): the prior
            for translation and yaw, the between factor for roll and pitch (each with the
            information restricted to those directions). It relies on solution remapping
            (``pipeline.remap_iterations``) and, when the odometry starts while moving, on
            the detection hold of the map's first metres (``pipeline.detection_schedule``).
        basis_snap: components of a degenerate basis row below this fraction of its largest
            one are zeroed before the LiDAR information is restricted
            (:func:`lili_odom.fusion.subspace.snap_basis`); 0 = use the basis as detected.
        anchor_sigma: with ``factor="prior"`` or ``"hybrid"`` and wheel odometry, the
            prior's degenerate components are taken from the wheel-predicted pose and held
            with this sigma (scaled twist units, m;
            :func:`lili_odom.fusion.subspace.degenerate_anchor`).
            Without it the LiDAR information kept next to a detected direction moves the
            position along it (a detected basis carries small spurious off-axis components,
            so the well-measured directions the factor keeps are tilted towards the axis).
            The wheel prediction's components along the subspace are its own weighted fit
            (``reference_information``): wheels measure no roll or pitch, and a detected
            axis carrying some would otherwise trade them against the distance. The reported
            covariance adds the wheel random walk along the subspace, which the anchor would
            otherwise hide. Default 0.05; 0 = no anchor.
        anchor_min_planar_share: the anchor takes from the wheel prediction only the
            components along the directions of the subspace that are at least this share
            planar motion of base_link (x, y, yaw;
            :func:`lili_odom.fusion.subspace.planar_directions`), and holds the others at the
            registration's own. A detected roll about a distant axis (a corridor's floor
            edge) carries a little lateral translation: fitted to the wheels through it alone,
            the prior's target would move sideways by their lateral error, amplified.
            Default 0.5; 0: every direction from the wheel prediction.
        subspace_information: keep the LiDAR's own information inside the detected degenerate
            subspace (a prior at the registration refined there by point-to-plane
            Gauss-Newton, weighted by its Hessian; :mod:`lili_odom.pipeline.plane_refinement`)
            instead of leaving the subspace to the wheels and the IMU alone. Default True.
        subspace_min_information: the subspace factor is dropped when its largest eigenvalue
            is below this [1/m^2, scaled twists] (1 = a 1 m sigma). Default 1.
        robust_after_updates: the kernel is off for this many updates after (re)initialisation
            or after an interval whose IMU samples reach 95 % of the sensor range (then the
            velocity is not observed or corrupt, so the IMU prediction cannot be trusted; such
            an interval itself is bridged without its IMU factor).
    """

    sigma_translation: float = 0.02
    sigma_rotation: float = 0.002
    degenerate_epsilon: float = 1e-6
    restriction: str = "marginalize"
    default_length: float = 10.0
    robust_kernel: str = "cauchy"
    robust_threshold: float = 3.0
    robust_after_updates: int = 20
    factor: str = "hybrid"
    anchor_sigma: float = 0.05
    anchor_min_planar_share: float = 0.5
    basis_snap: float = 0.0
    subspace_information: bool = True
    subspace_min_information: float = 1.0

    def validate(self, prefix: str = "lidar.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")``."""
        check_range(prefix + "sigma_translation", self.sigma_translation, 0.0, 100.0,
                    lo_open=True, unit="m")
        check_range(prefix + "sigma_rotation", self.sigma_rotation, 0.0, 10.0, lo_open=True,
                    unit="rad")
        check_range(prefix + "degenerate_epsilon", self.degenerate_epsilon, 0.0, 1.0,
                    hi_open=True)
        if self.restriction not in RESTRICTIONS:
            raise ValueError(f"{prefix}restriction must be one of {', '.join(RESTRICTIONS)}, "
                             f"got {self.restriction!r}")
        check_range(prefix + "default_length", self.default_length, 1e-3, 1e6, unit="m")
        if self.robust_kernel not in ROBUST_KERNELS:
            raise ValueError(f"{prefix}robust_kernel must be one of {', '.join(ROBUST_KERNELS)}, "
                             f"got {self.robust_kernel!r}")
        check_range(prefix + "robust_threshold", self.robust_threshold, 0.0, 100.0, lo_open=True)
        check_range(prefix + "basis_snap", self.basis_snap, 0.0, 1.0, hi_open=True)
        check_range(prefix + "anchor_sigma", self.anchor_sigma, 0.0, 100.0, unit="m")
        check_range(prefix + "anchor_min_planar_share", self.anchor_min_planar_share, 0.0, 1.0)
        if self.factor not in LIDAR_FACTORS:
            raise ValueError(f"{prefix}factor must be one of {', '.join(LIDAR_FACTORS)}, "
                             f"got {self.factor!r}")
        check_range(prefix + "robust_after_updates", self.robust_after_updates, 0, 100000)
        check_range(prefix + "subspace_min_information", self.subspace_min_information, 0.0,
                    1e12)

    def information(self) -> np.ndarray:
        """6x6 diagonal information ``(v, w)`` in the LiDAR body frame."""
        return np.diag(
            [self.sigma_translation**-2] * 3 + [self.sigma_rotation**-2] * 3
        )


def _default_T_base_lidar() -> np.ndarray:
    """The OS1's ``os_sensor -> os_lidar`` with ``base_link`` at ``os_sensor`` (the robot's mount
    is set by :class:`lili_odom.config.ExtrinsicsConfig`)."""
    return pose_from_xyz_rpy(OS1_SENSOR_TO_LIDAR)


def _default_T_base_imu() -> np.ndarray:
    """The OS1's ``os_sensor -> os_imu`` with ``base_link`` at ``os_sensor``."""
    return pose_from_xyz_rpy(OS1_SENSOR_TO_IMU)


@dataclass
class FusionConfig:
    """All parameters of :class:`lili_odom.fusion.estimator.FusionEstimator`.

    Attributes:
        imu: IMU noise and buffer limits.
        wheel: wheel increment noise and buffer limits.
        lidar: LiDAR increment noise and degenerate-direction handling.
        T_base_lidar: 4x4 pose of ``os_lidar`` in ``base_link``.
        T_base_imu: 4x4 pose of ``os_imu`` in ``base_link``.
        use_imu: False ignores the IMU entirely (fallback motion model every step).
        prior_sigma_translation: initial pose prior [m].
        prior_sigma_rotation: initial pose prior [rad].
        prior_sigma_velocity: initial velocity prior [m/s] when the robot was seen at rest
            (wheels at rest and a steady IMU; an IMU alone cannot tell rest from driving at
            constant speed).
        prior_sigma_velocity_moving: initial velocity prior [m/s] otherwise.
        prior_sigma_velocity_wheel: initial velocity prior [m/s] when the robot started while
            moving and the wheel odometry gave its velocity.
        gravity_align: align roll/pitch of the initial pose with gravity from the IMU samples
            preceding the first stamp (only when no initial pose is given).
        gravity_window_s: length of that IMU window [s].
        estimate_gyro_bias_at_rest: start the gyro bias at the mean rate when at rest.
        gravity_tracking_gain: with ``gravity_variable`` off, the direction of gravity in the
            odometry frame is tracked (0 = always the frame's -z). At rest the accelerometer
            cannot tell its bias from a tilt, so the start's gravity alignment takes a bias
            ``b`` as a tilt of about
            ``b / g`` and the local map is built in that frame; once a turn makes the bias
            observable, the IMU pulls the estimate towards true gravity, away from the map.
            With a gain, each LiDAR update moves the gravity used by the IMU preintegration
            by this fraction of the averaged tilt between the registration and the fused pose
            beyond the deadband, so the IMU's gravity follows the map's frame (an integral
            controller; per update, 0..1; default 0.01, 0 = off).
        gravity_tracking_window_s: time constant of that average [s].
        gravity_tracking_deadband: averaged tilt differences up to this [rad] are not
            integrated (a map built from the estimate lags it by a little whenever the tilt
            moves, and integrating that lag can walk gravity and map away together).
            Default 0.
        gravity_tracking_max: bound of that rotation of gravity [rad].
        gravity_tracking_gate: registrations whose tilt differs from the fused pose's by more
            than this [rad] are not used for it (outliers).
        gravity_variable: estimate the tilt of the odometry frame against gravity as a
            variable of the graph, jointly with the accelerometer bias, instead of tracking
            it with a gain (the ``gravity_tracking_*`` parameters are then unused). The
            odometry frame (the local map's) stays the start's gravity-aligned frame; the
            IMU factors act in a gravity frame tilted from it by the variable, and the
            LiDAR's absolute factors tie the two. Default on.
        gravity_variable_sigma: prior standard deviation of that tilt about x and y [rad]
            (an accelerometer bias ``b`` taken for gravity at the start tilts the frame by
            about ``b / g``; default 0.01, about ``imu.accel_bias_prior_sigma / g``).
        cruise_sigma: on an interval without wheel data whose registration leaves a
            degenerate direction, a robust factor (``lidar.robust_kernel``) holds the
            velocity (odometry frame) constant with this standard deviation of the
            acceleration [m/s^2] times the interval: along a direction nothing else measures,
            a robot that cruises tells the accelerometer's bias from its motion, as a
            LiDAR-only constant-velocity model does. Default 0.1; 0 = no such factor.
        cruise_max_accel: the cruise factor applies only where the IMU's own prediction
            accelerates by at most this over the interval [m/s^2] (mean, bias-corrected,
            gravity removed): starting, stopping and turning are left to the IMU. Default
            0.1.
        wheel_scale: online calibration of the wheel distance scale
            (:mod:`lili_odom.fusion.wheel_scale`).
        wheel_weak_scale: factor on the wheel information outside the degenerate subspace
            (0 = wheels act only inside it, and not at all when nothing is degenerate).
        wheel_restriction: how the wheel information is restricted to the degenerate
            subspace: ``"weighted"`` (default), the wheels' own weighted estimate of the
            motion along the subspace (:func:`lili_odom.fusion.subspace.weighted_restriction`),
            so a detected direction that mixes tilt into the translation is neither weakened
            by the wheels' unknown tilt nor moved by it; ``"same"`` as the LiDAR's
            (``lidar.restriction``), ``"marginalize"`` or ``"project"``.
        no_imu_sigma_translation_per_s: fallback motion-model sigma [m per s of interval].
        no_imu_sigma_rotation_per_s: fallback motion-model sigma [rad per s of interval].
        no_imu_sigma_floor_translation: [m] floor of the fallback translation sigma.
        no_imu_sigma_floor_rotation: [rad] floor of the fallback rotation sigma.
        no_imu_sigma_velocity: loose prior on the velocity of a state without IMU [m/s].
        max_interval_s: a gap between consecutive updates longer than this [s] is bridged by
            the fallback motion model only (IMU integration over long gaps is meaningless).
        reset_every: keyframes between graph resets (bounded memory): the graph is then
            rebuilt from one prior holding the joint marginal of the newest pose, velocity
            and bias (LIO-SAM style, but keeping the cross-correlations).
        relinearize_threshold: iSAM2 relinearisation threshold.
        extra_iterations: additional iSAM2 update() calls per update (helps large corrections).
        history_size: fused keyframe poses kept for ``predict`` at past times.
        max_speed: plausibility gate [m/s]: a LiDAR or wheel increment implying more than
            ``max_speed * dt + gate_margin_translation`` is rejected (a Husky does 1 m/s).
        max_rate: plausibility gate [rad/s] on the rotation of an increment, with
            ``gate_margin_rotation``.
        gate_margin_translation: [m] added to the translation gate.
        gate_margin_rotation: [rad] added to the rotation gate.
    """

    imu: ImuNoiseConfig = field(default_factory=ImuNoiseConfig)
    wheel: WheelNoiseConfig = field(default_factory=WheelNoiseConfig)
    wheel_scale: WheelScaleConfig = field(default_factory=WheelScaleConfig)
    lidar: LidarNoiseConfig = field(default_factory=LidarNoiseConfig)
    T_base_lidar: np.ndarray = field(default_factory=_default_T_base_lidar)
    T_base_imu: np.ndarray = field(default_factory=_default_T_base_imu)
    use_imu: bool = True
    prior_sigma_translation: float = 1e-3
    prior_sigma_rotation: float = 1e-3
    prior_sigma_velocity: float = 0.05
    prior_sigma_velocity_moving: float = 1.0
    prior_sigma_velocity_wheel: float = 0.1
    gravity_align: bool = True
    gravity_window_s: float = 1.0
    estimate_gyro_bias_at_rest: bool = True
    gravity_tracking_gain: float = 0.01
    gravity_tracking_window_s: float = 5.0
    gravity_tracking_deadband: float = 0.0
    gravity_tracking_max: float = 0.035
    gravity_tracking_gate: float = 0.05
    gravity_variable: bool = True
    gravity_variable_sigma: float = 0.01
    cruise_sigma: float = 0.1
    cruise_max_accel: float = 0.1
    wheel_weak_scale: float = 0.0
    wheel_restriction: str = "weighted"
    no_imu_sigma_translation_per_s: float = 1.0
    no_imu_sigma_rotation_per_s: float = 0.5
    no_imu_sigma_floor_translation: float = 0.05
    no_imu_sigma_floor_rotation: float = 0.02
    no_imu_sigma_velocity: float = 1.0
    max_interval_s: float = 2.0
    reset_every: int = 100
    relinearize_threshold: float = 0.05
    extra_iterations: int = 1
    history_size: int = 50
    max_speed: float = 5.0
    max_rate: float = 5.0
    gate_margin_translation: float = 1.0
    gate_margin_rotation: float = 0.5

    def validate(self, prefix: str = "fusion.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")`` for the first
        out-of-range parameter (the nested imu/wheel/lidar configurations included)."""
        self.imu.validate(prefix + "imu.")
        self.wheel.validate(prefix + "wheel.")
        self.wheel_scale.validate(prefix + "wheel_scale.")
        self.lidar.validate(prefix + "lidar.")
        for name in ("prior_sigma_translation", "prior_sigma_rotation", "prior_sigma_velocity",
                     "prior_sigma_velocity_moving", "prior_sigma_velocity_wheel",
                     "no_imu_sigma_translation_per_s", "no_imu_sigma_rotation_per_s",
                     "no_imu_sigma_floor_translation", "no_imu_sigma_floor_rotation",
                     "no_imu_sigma_velocity"):
            if hasattr(self, name):
                check_range(prefix + name, getattr(self, name), 0.0, 1e3, lo_open=True)
        check_range(prefix + "gravity_window_s", self.gravity_window_s, 0.0, 60.0, lo_open=True,
                    unit="s")
        check_range(prefix + "gravity_tracking_gain", self.gravity_tracking_gain, 0.0, 1.0)
        check_range(prefix + "gravity_tracking_window_s", self.gravity_tracking_window_s, 0.0,
                    3600.0, lo_open=True, unit="s")
        check_range(prefix + "gravity_tracking_deadband", self.gravity_tracking_deadband, 0.0,
                    0.5, unit="rad")
        check_range(prefix + "gravity_tracking_max", self.gravity_tracking_max, 0.0, 0.5,
                    unit="rad")
        check_range(prefix + "gravity_tracking_gate", self.gravity_tracking_gate, 0.0, 0.5,
                    lo_open=True, unit="rad")
        check_range(prefix + "gravity_variable_sigma", self.gravity_variable_sigma, 0.0, 0.5,
                    lo_open=True, unit="rad")
        check_range(prefix + "cruise_sigma", self.cruise_sigma, 0.0, 1e3, unit="m/s^2")
        check_range(prefix + "cruise_max_accel", self.cruise_max_accel, 0.0, 1e3,
                    lo_open=True, unit="m/s^2")
        check_range(prefix + "wheel_weak_scale", self.wheel_weak_scale, 0.0, 1.0)
        if self.wheel_restriction not in WHEEL_RESTRICTIONS:
            raise ValueError(f"{prefix}wheel_restriction must be one of "
                             f"{', '.join(WHEEL_RESTRICTIONS)}, got {self.wheel_restriction!r}")
        check_range(prefix + "max_interval_s", self.max_interval_s, 0.0, 3600.0, lo_open=True,
                    unit="s")
        check_range(prefix + "reset_every", self.reset_every, 1, 100000)
        check_range(prefix + "relinearize_threshold", self.relinearize_threshold, 0.0, 10.0,
                    lo_open=True)
        check_range(prefix + "extra_iterations", self.extra_iterations, 0, 100)
        check_range(prefix + "history_size", self.history_size, 2, 100000)
        check_range(prefix + "max_speed", self.max_speed, 0.0, 1000.0, lo_open=True, unit="m/s")
        check_range(prefix + "max_rate", self.max_rate, 0.0, 1000.0, lo_open=True, unit="rad/s")
        check_range(prefix + "gate_margin_translation", self.gate_margin_translation, 0.0, 1e3,
                    unit="m")
        check_range(prefix + "gate_margin_rotation", self.gate_margin_rotation, 0.0, 10.0,
                    unit="rad")
