"""When to run the degeneracy detector, and how to carry a recent result over to a new scan.

A detector run (LiLi: 12 perturbed re-registrations) costs several times the scan
registration itself, while the degenerate subspace is a property of the *place*: consecutive
scans 0.1 s and a few centimetres apart see the same tunnel. The schedule therefore runs the
detector on a scan unless a recent, successful result exists, taken at most
``max_reuse`` scans ago, less than ``reuse_distance_m`` and ``reuse_angle_deg`` away from the
current registered pose. A reused result is *carried over* rigidly: its degenerate motions are
fixed in the odometry frame, so its basis is moved from the old sensor body frame to the new
one with the adjoint of the relative pose and re-orthonormalised in the scaled space.

``max_reuse = 0`` runs the detector on every scan (the paper's setting).

A scan whose point-to-plane planes hold every direction (``screened``:
:class:`lili_odom.pipeline.plane_refinement.PlaneRefinementConfig` ``screen_detections``,
constrained, or with ``screen_weak_information`` the planes' own subspace of weakly held
directions) does not run the detector; its result becomes the one carried over while the next
detection is computed once the last detection is out of reach, but is never reused itself.

In the *background* (``background``, default), a detection that is due runs in a process of
its own (:mod:`lili_odom.pipeline.detection_worker`) while the main loop goes on: the scan that
asked for it, and the next ones until the result is applied, carry the last result over
(``stale``, past the reuse bounds); the result is applied ``background_lag`` scans after the
scan it was asked for, waiting for it then if it is not ready, so a run's results do not depend
on the machine's speed. Only one background detection is in flight at a time. The first
detection after a (re)start, and every detection while no earlier result is available (the
last one failed), runs in the main loop.

A degenerate subspace can also be *held* (``hold_distance_m`` > 0): after a detection found
one, the next results, fresh or reused, are merged with it (carried over the same way) until
the sensor has moved ``hold_distance_m`` from it. A place does not stop being a tunnel from
one scan to the next, while a detector misses single scans now and then (a sparse scan, a
bump); with an absolute LiDAR factor one missed scan measures the registration's slide along
the axis and pins the position to it. Holding costs, at a real exit from the degenerate
place, the wheels' error over that distance. ``hold_warmup_m`` > 0 limits the hold to the
first metres of travel after the local map was (re)started: a map built from a few scans of a
moving sensor is mostly the ground rings of those scans, which can hold the registration (and
the detector's verdict) along a featureless axis until the map spans several scan positions.
How the defaults affect the detected subspace, the odometry and the time per scan:
``docs/performance.md`` and ``docs/design/fusion.md``.

Frames: ``pose`` arguments are 4x4 sensor (os_lidar) poses in the odometry frame [m]; basis
twists are ``(v, w)`` in the sensor's body frame (:mod:`lili_odom.degeneracy.result`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lili_odom import geometry
from lili_odom.degeneracy.result import DegeneracyResult


@dataclass
class DetectionScheduleConfig:
    """Attributes:
        max_reuse: consecutive scans that may reuse one detection (0: detect every scan).
            Default 8: at the Husky's 0.8-1 m/s the 0.75 m bound ends a reuse after 7-8
            scans, so the detector runs about once per 0.75 m of travel (at least every 9th
            scan when slower).
        reuse_distance_m: re-detect once the sensor moved this far from the detection [m];
            default 0.75.
        reuse_angle_deg: re-detect once the sensor turned this much from the detection [deg].
        hold_distance_m: a degenerate subspace is merged into the following results until
            the sensor moved this far from its detection [m]; 0 = no hold.
            Default: 1 m, during the first 10 m after a (re)start (``hold_warmup_m``).
        hold_warmup_m: the hold applies only until the sensor has travelled this far (path
            length) since the local map was (re)started [m]; 0 = for the whole run.
        background: run due detections in a separate process (module docstring); default
            True. False: every detection runs in the main loop and serves its own scan.
        background_lag: scans after the requesting one at which a background result is
            applied (>= 1); default 3 (``docs/performance.md``, "Detection in the
            background").
        background_timeout_s: longest wait for a background result [s]; beyond it the
            detector process counts as hung and detection moves into the main loop.
            Default 10.
    """

    max_reuse: int = 8
    reuse_distance_m: float = 0.75
    reuse_angle_deg: float = 5.0
    hold_distance_m: float = 1.0
    hold_warmup_m: float = 10.0
    background: bool = True
    background_lag: int = 3
    background_timeout_s: float = 10.0

    def validate(self, prefix: str = "detection_schedule.") -> None:
        """Raise ``ValueError("<prefix><name> must be <range>, got <value>")``."""
        from lili_odom.errors import check_range

        check_range(prefix + "max_reuse", self.max_reuse, 0, 1000)
        check_range(prefix + "reuse_distance_m", self.reuse_distance_m, 0.0, 100.0, unit="m")
        check_range(prefix + "reuse_angle_deg", self.reuse_angle_deg, 0.0, 180.0, unit="deg")
        check_range(prefix + "hold_distance_m", self.hold_distance_m, 0.0, 1000.0, unit="m")
        check_range(prefix + "hold_warmup_m", self.hold_warmup_m, 0.0, 1e6, unit="m")
        check_range(prefix + "background_lag", self.background_lag, 1, 100)
        check_range(prefix + "background_timeout_s", self.background_timeout_s, 0.0, 3600.0,
                    lo_open=True, unit="s")


def _angle_deg(T: np.ndarray) -> float:
    """Rotation angle of the 4x4 pose ``T`` [deg]."""
    cos = np.clip((np.trace(T[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)))


def carry_over(result: DegeneracyResult, pose: np.ndarray, age: int) -> DegeneracyResult:
    """``result`` re-expressed at the sensor pose ``pose`` (same motions in the odometry frame).

    Args:
        result: a successful detection at ``result.pose``.
        pose: 4x4 current sensor pose in the odometry frame.
        age: scans since ``result`` was computed (reported in ``details["reused_age"]``).
    """
    T_new_old = np.linalg.inv(pose) @ result.pose
    L = result.characteristic_length
    basis = result.basis_scaled
    if len(basis):
        moved = geometry.scale_twist(geometry.unscale_twist(basis, L)
                                     @ geometry.adjoint(T_new_old).T, L)
        q, r = np.linalg.qr(moved.T)  # Gram-Schmidt: row order and sparse rows preserved
        basis = (q * np.where(np.diag(r) < 0, -1.0, 1.0)).T
    details = {**result.details, "reused": True, "reused_age": int(age)}
    return replace(result, pose=np.asarray(pose, dtype=float), basis_scaled=basis,
                   runtime_s=0.0, details=details)


class DetectionSchedule:
    """Decides per scan whether to detect or to carry the last detection over."""

    def __init__(self, config: DetectionScheduleConfig | None = None) -> None:
        self.config = config or DetectionScheduleConfig()
        self._last: DegeneracyResult | None = None
        self._age = 0
        self._held: DegeneracyResult | None = None  # last fresh degenerate detection
        self._held_age = 0
        self._travelled = 0.0  # path length since the local map was (re)started [m]
        self._last_pose: np.ndarray | None = None

    def reset(self, new_map: bool = False) -> None:
        """Forget the last detection (pipeline reset, re-initialisation, failed registration).

        Args:
            new_map: the local map was cleared too: the hold's warm-up starts again.
        """
        self._last = None
        self._age = 0
        self._held = None
        self._held_age = 0
        if new_map:
            self._travelled = 0.0
            self._last_pose = None

    def _within_reach(self, pose: np.ndarray) -> bool:
        """The last detection may serve ``pose`` (age, distance and angle bounds)."""
        cfg, last = self.config, self._last
        if last is None or self._age >= cfg.max_reuse:
            return False
        delta = np.linalg.inv(last.pose) @ pose
        return bool(np.linalg.norm(delta[:3, 3]) <= cfg.reuse_distance_m
                    and _angle_deg(delta) <= cfg.reuse_angle_deg)

    def reusable(self, pose: np.ndarray) -> DegeneracyResult | None:
        """The last detection carried over to ``pose``, or None when the detector must run."""
        if not self._within_reach(pose):
            return None
        self._age += 1
        return carry_over(self._last, pose, self._age)

    def screened(self, result: DegeneracyResult) -> None:
        """A scan the screen decided without the detector (``result``, at the scan's pose:
        not degenerate, or the planes' subspace). It replaces the last detection once that
        one can no longer serve this pose, as what is carried over (``stale``) while the next
        detection is computed, but is never reused in place of one: the next scan the screen
        does not pass is detected."""
        if not self._within_reach(result.pose):
            self._last, self._age = result, self.config.max_reuse

    @property
    def has_last(self) -> bool:
        """A successful detection is available to carry over (``stale``)."""
        return self._last is not None

    def stale(self, pose: np.ndarray) -> DegeneracyResult:
        """The last detection carried over to ``pose`` whatever its age and distance (while a
        newer one is computed in the background); requires ``has_last``."""
        self._age += 1
        return carry_over(self._last, pose, self._age)

    def record(self, result: DegeneracyResult, age: int = 0) -> None:
        """A fresh detection, made ``age`` scans before the current one (0: on it): reusable
        from the next scan on (``age`` 0) or from the current one, when it succeeded."""
        self._last = result if result.ok else None
        self._age = max(0, int(age) - 1)
        if result.ok and result.degenerate:
            self._held, self._held_age = result, 0

    def hold(self, result: DegeneracyResult, pose: np.ndarray) -> DegeneracyResult:
        """``result`` with the held degenerate subspace merged in (see module docstring).

        The result's own rows are kept as they are; a held direction is added where it is
        not already (nearly) inside them. Failed results are returned unchanged.
        """
        if self._last_pose is not None:
            self._travelled += float(np.linalg.norm(pose[:3, 3] - self._last_pose[:3, 3]))
        self._last_pose = np.asarray(pose, dtype=float)
        held, cfg = self._held, self.config
        if held is None or not result.ok or cfg.hold_distance_m <= 0:
            return result
        if 0 < cfg.hold_warmup_m < self._travelled:
            self._held = None
            return result
        if np.linalg.norm((np.linalg.inv(held.pose) @ pose)[:3, 3]) > cfg.hold_distance_m:
            self._held = None
            return result
        self._held_age += 1
        carried = carry_over(held, pose, self._held_age)
        L = result.characteristic_length
        rows = list(result.basis_scaled)
        added = 0
        for b in geometry.scale_twist(geometry.unscale_twist(carried.basis_scaled,
                                                             carried.characteristic_length), L):
            b = b / np.linalg.norm(b)
            for r in rows:
                b = b - (b @ r) * r
            n = float(np.linalg.norm(b))
            if n > 0.5:  # more than 30 deg away from the result's own subspace
                rows.append(b / n)
                added += 1
        if not added:
            return result
        details = {**result.details, "held": added, "held_age": self._held_age}
        return replace(result, basis_scaled=np.array(rows), details=details)
