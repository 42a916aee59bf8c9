"""IMU noise model, GTSAM preintegration parameters, and a sample buffer.

Frames and units:

* The IMU measures in its own frame ``os_imu``: specific force [m/s^2] (gravity reaction
  included, so a resting IMU reads about +9.81 m/s^2 along its up axis) and angular rate
  [rad/s]. ouster-ros publishes these units.
* The estimator's *body* is ``base_link``. The IMU -> body extrinsic ``T_base_imu`` (pose of
  ``os_imu`` in ``base_link``) is handed to GTSAM as ``body_P_sensor``: GTSAM then rotates each
  bias-corrected measurement into the body frame and removes the centripetal acceleration of
  the lever arm. GTSAM neglects the lever arm's angular-acceleration (Euler) term
  ``alpha x r``; with the OS1 on a mast about 0.65 m above ``base_link``, a skid-steer robot
  rocking over a rough floor sees up to about 1 m/s^2 of it, which a LiDAR-held pose
  then trades against the IMU's prediction. :func:`integrate` removes it before GTSAM sees a
  sample (``compensate_angular_acceleration``, :func:`euler_correction`). The bias states
  live in the **IMU frame**.
* The world (odometry) frame is gravity-aligned: gravity is ``-g`` along its z axis
  (``PreintegrationCombinedParams.MakeSharedU``).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import NamedTuple

import gtsam
import numpy as np

from lili_odom.geometry import pose3

__all__ = [
    "ImuNoiseConfig",
    "ImuSample",
    "ImuBuffer",
    "IntegrationReport",
    "GravityAlignment",
    "make_preintegration_params",
    "integrate",
    "gravity_alignment",
    "lever_arm_in_imu",
    "euler_correction",
    "integrate_piece",
]

STANDARD_GRAVITY = 9.80665


@dataclass
class ImuNoiseConfig:
    """Continuous-time IMU noise (ICM-20948 class sensor, as in the OS1), with margin.

    The datasheet white noise of the ICM-20948 is about 2.3e-3 m/s^2/sqrt(Hz) and
    2.6e-4 rad/s/sqrt(Hz); the defaults are inflated ~4x for vibration on a skid-steer robot.

    Attributes:
        accel_noise_density: accelerometer white noise [m/s^2/sqrt(Hz)].
        gyro_noise_density: gyroscope white noise [rad/s/sqrt(Hz)].
        accel_bias_random_walk: accelerometer bias random walk [m/s^3/sqrt(Hz)].
        gyro_bias_random_walk: gyroscope bias random walk [rad/s^2/sqrt(Hz)].
        integration_sigma: position integration error [m/sqrt(Hz)] (GTSAM's
            integrationCovariance), covers the piecewise-constant sample model.
        gravity: magnitude of gravity [m/s^2], along -z of the world frame.
        accel_bias_prior_sigma: prior std of the initial accelerometer bias [m/s^2].
        gyro_bias_prior_sigma: prior std of the initial gyro bias [rad/s].
        max_gap_s: a hole between consecutive samples longer than this [s] makes an interval
            "not covered": the estimator then uses its no-IMU fallback for that interval.
        max_extrapolation_s: how far [s] the first/last sample may be held constant to cover
            the ends of an interval.
        buffer_seconds: samples older than the newest minus this [s] are dropped.
        max_abs_acc: samples with a larger specific-force component [m/s^2] are rejected as
            corrupt (the ICM-20948 saturates at 16 g = 157 m/s^2).
        max_abs_gyro: samples with a larger rate component [rad/s] are rejected (the sensor
            saturates at 2000 deg/s = 34.9 rad/s).
        compensate_angular_acceleration: remove the lever arm's angular-acceleration term
            from the specific force before preintegration (:func:`euler_correction`);
            default True.
    """

    accel_noise_density: float = 1.0e-2
    gyro_noise_density: float = 1.0e-3
    accel_bias_random_walk: float = 2.0e-4
    gyro_bias_random_walk: float = 2.0e-5
    integration_sigma: float = 1.0e-4
    gravity: float = STANDARD_GRAVITY
    accel_bias_prior_sigma: float = 0.1
    gyro_bias_prior_sigma: float = 0.01
    max_gap_s: float = 0.25
    max_extrapolation_s: float = 0.05
    buffer_seconds: float = 30.0
    max_abs_acc: float = 160.0
    max_abs_gyro: float = 35.0
    compensate_angular_acceleration: bool = True

    def validate(self, prefix: str = "imu.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")``."""
        from lili_odom.errors import check_range

        for name in ("accel_noise_density", "gyro_noise_density", "accel_bias_random_walk",
                     "gyro_bias_random_walk", "integration_sigma", "accel_bias_prior_sigma",
                     "gyro_bias_prior_sigma"):
            check_range(prefix + name, getattr(self, name), 0.0, 1e3, lo_open=True)
        check_range(prefix + "gravity", self.gravity, 9.7, 9.9, unit="m/s^2")
        check_range(prefix + "max_gap_s", self.max_gap_s, 0.0, 10.0, lo_open=True, unit="s")
        check_range(prefix + "max_extrapolation_s", self.max_extrapolation_s, 0.0, 1.0, unit="s")
        check_range(prefix + "buffer_seconds", self.buffer_seconds, 1.0, 3600.0, unit="s")
        check_range(prefix + "max_abs_acc", self.max_abs_acc, self.gravity, None, lo_open=True,
                    unit="m/s^2")
        check_range(prefix + "max_abs_gyro", self.max_abs_gyro, 0.0, None, lo_open=True,
                    unit="rad/s")


def make_preintegration_params(
    cfg: ImuNoiseConfig, T_base_imu: np.ndarray | None = None,
    gravity_tilt: np.ndarray | None = None,
) -> gtsam.PreintegrationCombinedParams:
    """GTSAM combined-preintegration parameters (gravity along -z of the world frame).

    Args:
        cfg: noise densities.
        T_base_imu: 4x4 pose of the IMU frame in ``base_link`` (None = identity); set as
            ``body_P_sensor``.
        gravity_tilt: (2,) rotation vector (about the world x and y axes) [rad] applied to
            gravity: the world frame's gravity is ``exp(tilt) (0, 0, -g)`` (None = along -z).
    """
    p = gtsam.PreintegrationCombinedParams.MakeSharedU(cfg.gravity)
    if gravity_tilt is not None and np.any(gravity_tilt):
        R = gtsam.Rot3.Expmap(np.array([gravity_tilt[0], gravity_tilt[1], 0.0])).matrix()
        p.n_gravity = np.asarray(R, dtype=float) @ np.array([0.0, 0.0, -cfg.gravity])
    i3 = np.eye(3)
    p.setAccelerometerCovariance(cfg.accel_noise_density**2 * i3)
    p.setGyroscopeCovariance(cfg.gyro_noise_density**2 * i3)
    p.setIntegrationCovariance(cfg.integration_sigma**2 * i3)
    p.setBiasAccCovariance(cfg.accel_bias_random_walk**2 * i3)
    p.setBiasOmegaCovariance(cfg.gyro_bias_random_walk**2 * i3)
    if T_base_imu is not None and not np.allclose(T_base_imu, np.eye(4)):
        p.setBodyPSensor(pose3(T_base_imu))
    return p


def lever_arm_in_imu(T_base_imu: np.ndarray | None) -> np.ndarray | None:
    """The IMU's offset from the ``base_link`` origin, expressed in the IMU frame [m]
    (``R_base_imu^T p_base_imu``); None when it is zero (no Euler term to remove)."""
    if T_base_imu is None:
        return None
    T = np.asarray(T_base_imu, dtype=float)
    r = T[:3, :3].T @ T[:3, 3]
    return r if np.any(r) else None


def euler_correction(gyro_a: np.ndarray, gyro_b: np.ndarray, dt: float,
                     lever_arm: np.ndarray) -> np.ndarray:
    """The specific force [m/s^2, IMU frame] the lever arm's angular acceleration adds at the
    IMU between two gyro knots ``dt`` [s] apart: ``alpha x r`` with ``alpha`` the slope of the
    piecewise-linear rate (``(gyro_b - gyro_a) / dt``, IMU frame [rad/s^2]) and ``r`` the
    lever arm in the IMU frame (:func:`lever_arm_in_imu`). Summed over an interval its
    integral telescopes to ``(w_end - w_start) x r``, so gyro noise does not accumulate and
    a constant gyro bias cancels."""
    # written out: np.cross is slow on 3-vectors, and this runs for every IMU sample
    ax, ay, az = ((np.asarray(gyro_b) - np.asarray(gyro_a)) / dt).tolist()
    rx, ry, rz = np.asarray(lever_arm, dtype=float).tolist()
    return np.array([ay * rz - az * ry, az * rx - ax * rz, ax * ry - ay * rx])


def integrate_piece(pim: gtsam.PreintegratedCombinedMeasurements, acc_a: np.ndarray,
                    acc_b: np.ndarray, gyro_a: np.ndarray, gyro_b: np.ndarray, dt: float,
                    lever_arm: np.ndarray | None = None) -> None:
    """Integrate one piece of ``dt`` [s] between two IMU knots into ``pim``: the mean of its
    end values (exact for piecewise-linear signals), minus :func:`euler_correction` when
    ``lever_arm`` (IMU frame [m]) is given."""
    acc = 0.5 * (acc_a + acc_b)
    if lever_arm is not None:
        acc = acc - euler_correction(gyro_a, gyro_b, dt, lever_arm)
    pim.integrateMeasurement(acc, 0.5 * (gyro_a + gyro_b), dt)


class ImuSample(NamedTuple):
    """One IMU reading at time ``t`` [s]: specific force [m/s^2] and rate [rad/s], IMU frame."""

    t: float
    acc: np.ndarray
    gyro: np.ndarray


@dataclass
class IntegrationReport:
    """What :func:`integrate` did for an interval [t0, t1]."""

    covered: bool = False
    n_segments: int = 0
    integrated_s: float = 0.0
    largest_gap_s: float = 0.0
    reason: str = ""


class StampJumpFilter:
    """Guards a time-ordered buffer against single corrupt stamps and real clock jumps.

    A stamp more than ``max_forward_s`` after the newest buffered one, or more than
    ``max_backward_s`` before it, does not fit the buffer's timeline. One such sample is
    *held*: when the next sample fits the timeline again, the held ones were corrupt stamps
    and are discarded (``n_outliers``); when ``confirm`` consecutive samples agree with each
    other (increasing, each at most ``max_forward_s`` after the previous), the clock really
    jumped (a sensor restart or a bag loop) and they are released (``n_jumps``).

    Without this a single sample stamped far in the future would prune the whole buffer (its
    horizon is measured from the newest stamp) and every later, correct, sample with it.
    """

    def __init__(self, max_forward_s: float = 1.0, max_backward_s: float = 30.0,
                 confirm: int = 3) -> None:
        self.max_forward_s = float(max_forward_s)
        self.max_backward_s = float(max_backward_s)
        self.confirm = max(1, int(confirm))
        self.held: list[tuple[float, object]] = []
        self.n_outliers = 0
        self.n_jumps = 0

    def offer(self, t: float, item: object, newest: float | None) -> tuple[str, list]:
        """Classify a sample at ``t`` against the buffer's ``newest`` stamp.

        Returns ``("fits", [])``, ``("held", [])``, or ``("forward" | "backward", items)``
        with the held ``(t, item)`` pairs to insert (after clearing the buffer for
        ``"backward"``).
        """
        if newest is None or newest - self.max_backward_s <= t <= newest + self.max_forward_s:
            if self.held:
                self.n_outliers += len(self.held)
                self.held = []
            return "fits", []
        if self.held and not 0.0 < t - self.held[-1][0] <= self.max_forward_s:
            self.n_outliers += len(self.held)
            self.held = []
        self.held.append((t, item))
        if len(self.held) < self.confirm:
            return "held", []
        released, self.held = self.held, []
        self.n_jumps += 1
        return ("forward" if t > newest else "backward"), released


class ImuBuffer:
    """Time-ordered IMU samples with robust insertion.

    ``add`` keeps the buffer sorted even when samples arrive out of order, drops exact
    duplicates (same stamp within 1 us), non-finite samples and samples beyond the sensor's
    range (``max_abs_acc`` [m/s^2], ``max_abs_gyro`` [rad/s]), holds back samples whose stamp
    jumps away from the buffer's timeline until the jump is confirmed
    (:class:`StampJumpFilter`), and prunes samples older than ``buffer_seconds`` before the
    newest. Counters say what happened.
    """

    def __init__(self, buffer_seconds: float = 30.0, max_samples: int = 20000,
                 max_abs_acc: float = 160.0, max_abs_gyro: float = 35.0,
                 max_stamp_jump_s: float = 1.0) -> None:
        self.buffer_seconds = float(buffer_seconds)
        self.max_samples = int(max_samples)
        self.max_abs_acc = float(max_abs_acc)
        self.max_abs_gyro = float(max_abs_gyro)
        self.jumps = StampJumpFilter(max_stamp_jump_s, self.buffer_seconds)
        self.n_out_of_range = 0
        self.n_held = 0
        self._t: list[float] = []
        self._s: list[ImuSample] = []
        self.n_added = 0
        self.n_nonfinite = 0
        self.n_duplicates = 0
        self.n_out_of_order = 0

    def __len__(self) -> int:
        return len(self._t)

    @property
    def newest_time(self) -> float | None:
        return self._t[-1] if self._t else None

    @property
    def oldest_time(self) -> float | None:
        return self._t[0] if self._t else None

    def add(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> bool:
        """Insert a sample; returns False (and counts why) when it was rejected."""
        try:
            t = float(t)
            acc = np.asarray(acc, dtype=np.float64).reshape(3)
            gyro = np.asarray(gyro, dtype=np.float64).reshape(3)
        except (TypeError, ValueError):
            self.n_nonfinite += 1
            return False
        if not (math.isfinite(t) and np.all(np.isfinite(acc)) and np.all(np.isfinite(gyro))):
            self.n_nonfinite += 1
            return False
        if np.abs(acc).max() > self.max_abs_acc or np.abs(gyro).max() > self.max_abs_gyro:
            self.n_out_of_range += 1
            return False
        verdict, released = self.jumps.offer(t, (acc, gyro), self.newest_time)
        if verdict == "held":
            self.n_held += 1
            return False
        if verdict == "backward":
            self._t.clear()
            self._s.clear()
        if released:
            for tr, (ar, gr) in released:
                self._insert(tr, ar, gr)
            return True
        return self._insert(t, acc, gyro)

    def _insert(self, t: float, acc: np.ndarray, gyro: np.ndarray) -> bool:
        i = bisect.bisect_left(self._t, t)
        if (i < len(self._t) and abs(self._t[i] - t) < 1e-6) or (
            i > 0 and abs(self._t[i - 1] - t) < 1e-6
        ):
            self.n_duplicates += 1
            return False
        if i < len(self._t):
            self.n_out_of_order += 1
        self._t.insert(i, t)
        self._s.insert(i, ImuSample(t, acc, gyro))
        self.n_added += 1
        self._prune()
        return True

    def _prune(self) -> None:
        horizon = self._t[-1] - self.buffer_seconds
        k = bisect.bisect_left(self._t, horizon)
        k = max(k, len(self._t) - self.max_samples)
        if k > 0:
            del self._t[:k]
            del self._s[:k]

    def samples(self, t0: float, t1: float) -> list[ImuSample]:
        """Samples with t0 <= t <= t1 (sorted)."""
        a = bisect.bisect_left(self._t, t0)
        b = bisect.bisect_right(self._t, t1)
        return self._s[a:b]

    def saturated(self, t0: float, t1: float, fraction: float = 0.95) -> bool:
        """True when a sample in [t0, t1] reaches ``fraction`` of the sensor's range."""
        return any(np.abs(s.acc).max() >= fraction * self.max_abs_acc
                   or np.abs(s.gyro).max() >= fraction * self.max_abs_gyro
                   for s in self.samples(t0, t1))

    def value_at(self, t: float, max_extrapolation_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Linearly interpolated (acc, gyro) at ``t``; held constant up to the limit beyond the
        data; None when ``t`` is farther than that from every sample."""
        if not self._t:
            return None
        i = bisect.bisect_left(self._t, t)
        if i < len(self._t) and self._t[i] == t:
            s = self._s[i]
            return s.acc, s.gyro
        if i == 0:
            s = self._s[0]
            return (s.acc, s.gyro) if s.t - t <= max_extrapolation_s else None
        if i == len(self._t):
            s = self._s[-1]
            return (s.acc, s.gyro) if t - s.t <= max_extrapolation_s else None
        a, b = self._s[i - 1], self._s[i]
        w = (t - a.t) / (b.t - a.t)
        return (1 - w) * a.acc + w * b.acc, (1 - w) * a.gyro + w * b.gyro

    def knots(self, t0: float, t1: float, max_extrapolation_s: float
              ) -> list[tuple[float, np.ndarray, np.ndarray]] | None:
        """Knots (t, acc, gyro) covering [t0, t1]: the interpolated ends plus inner samples."""
        start = self.value_at(t0, max_extrapolation_s)
        end = self.value_at(t1, max_extrapolation_s)
        if start is None or end is None:
            return None
        out = [(t0, start[0], start[1])]
        for s in self.samples(t0, t1):
            if t0 < s.t < t1:
                out.append((s.t, s.acc, s.gyro))
        out.append((t1, end[0], end[1]))
        return out

    def discard_before(self, t: float) -> None:
        """Drop samples older than ``t`` but keep the last one before it (for interpolation)."""
        k = bisect.bisect_left(self._t, t) - 1
        if k > 0:
            del self._t[:k]
            del self._s[:k]


def integrate(
    buffer: ImuBuffer,
    pim: gtsam.PreintegratedCombinedMeasurements,
    t0: float,
    t1: float,
    max_gap_s: float,
    max_extrapolation_s: float,
    lever_arm: np.ndarray | None = None,
) -> IntegrationReport:
    """Integrate the buffer's samples over [t0, t1] into ``pim``.

    Each piece between consecutive knots is integrated by :func:`integrate_piece` (with
    ``lever_arm``, IMU frame [m], its Euler term removed). The interval counts as covered when the ends can be
    interpolated (or held for at most ``max_extrapolation_s``) and no hole between samples
    exceeds ``max_gap_s``; otherwise nothing is integrated.
    """
    rep = IntegrationReport()
    if not (math.isfinite(t0) and math.isfinite(t1)) or t1 <= t0:
        rep.reason = "empty or invalid interval"
        return rep
    knots = buffer.knots(t0, t1, max_extrapolation_s)
    if knots is None:
        rep.reason = "no IMU samples near the interval ends"
        return rep
    # holes are measured inside the interval: between its ends and the samples within it
    knot_gaps = np.diff([k[0] for k in knots])
    rep.largest_gap_s = float(knot_gaps.max()) if knot_gaps.size else 0.0
    if rep.largest_gap_s > max_gap_s:
        rep.reason = f"IMU gap of {rep.largest_gap_s:.3f} s"
        return rep
    for (ta, aa, ga), (tb, ab, gb) in zip(knots[:-1], knots[1:]):
        dt = tb - ta
        if dt <= 0.0:
            continue
        integrate_piece(pim, aa, ab, ga, gb, dt, lever_arm)
        rep.n_segments += 1
        rep.integrated_s += dt
    rep.covered = rep.n_segments > 0
    if not rep.covered:
        rep.reason = "nothing to integrate"
    return rep


@dataclass
class GravityAlignment:
    """Initial attitude from resting IMU samples.

    Attributes:
        R_world_base: 3x3 rotation of base_link in the gravity-aligned world frame (yaw 0).
        stationary: True when the samples looked like a robot at rest.
        gyro_bias: mean angular rate [rad/s] in the IMU frame (a bias estimate when stationary).
        acc_mean_imu: mean specific force [m/s^2] in the IMU frame.
        n_samples: samples used.
    """

    R_world_base: np.ndarray
    stationary: bool
    gyro_bias: np.ndarray
    acc_mean_imu: np.ndarray
    n_samples: int


def gravity_alignment(
    samples: list[ImuSample],
    R_base_imu: np.ndarray,
    *,
    max_acc_std: float = 0.2,
    max_gyro_norm: float = 0.05,
    min_samples: int = 10,
) -> GravityAlignment:
    """Roll and pitch of base_link from the mean specific force (yaw is set to 0).

    At rest the accelerometer measures the reaction to gravity, i.e. +g along the world's up
    axis expressed in the sensor frame; the returned rotation maps that direction onto +z.

    Args:
        samples: IMU samples (IMU frame) taken while the robot is hopefully at rest.
        R_base_imu: 3x3 rotation of the IMU frame in base_link.
        max_acc_std: stationarity threshold on the std of the specific force norm [m/s^2].
        max_gyro_norm: stationarity threshold on the mean rate norm [rad/s].
        min_samples: fewer samples -> identity attitude, not stationary.
    """
    if len(samples) < min_samples:
        return GravityAlignment(np.eye(3), False, np.zeros(3), np.zeros(3), len(samples))
    acc = np.array([s.acc for s in samples])
    gyro = np.array([s.gyro for s in samples])
    acc_mean = acc.mean(axis=0)
    gyro_mean = gyro.mean(axis=0)
    stationary = bool(
        np.linalg.norm(acc, axis=1).std() < max_acc_std
        and np.linalg.norm(gyro_mean) < max_gyro_norm
        and np.linalg.norm(gyro, axis=1).max() < 4 * max_gyro_norm
    )
    up_base = np.asarray(R_base_imu) @ acc_mean
    norm = np.linalg.norm(up_base)
    if not np.isfinite(norm) or norm < 1e-3:
        return GravityAlignment(np.eye(3), False, gyro_mean, acc_mean, len(samples))
    up_base /= norm
    # Rotation taking up_base onto z with zero yaw: R = Ry(pitch) Rx(roll) (ZYX with yaw 0).
    roll = math.atan2(up_base[1], up_base[2])
    pitch = math.atan2(-up_base[0], math.hypot(up_base[1], up_base[2]))
    R = np.asarray(gtsam.Rot3.Ypr(0.0, pitch, roll).matrix())
    return GravityAlignment(R, stationary, gyro_mean, acc_mean, len(samples))
