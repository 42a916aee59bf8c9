"""LiLi: Lie-theory perturbation-based degeneracy detection (Algorithm 1 of the paper).

Frames, units and order: the scan is (N, 3) in its own sensor frame [m]; ``initial_pose`` and
the returned pose map the scan frame into the reference frame. Twists are ``(v, w)``
(translation [m], rotation [rad]) in the scan's body frame at P_opt; the *scaled* space is
``(v, L w)`` with ``L`` the median range of the scan points [m] (``geometry`` module docstring).

Algorithm (f_opt = KISS-ICP ``align_points_to_map`` against the reference voxel map, so points
re-associate at every ICP iteration):

1. ``P_opt = f_opt(P_init)`` (skipped when the caller already has it, as the odometry does).
2. Perturbation size from the integer ``k``: a benchmark point at the median range must move
   about ``(k - 1)`` map spacings ``s`` (measured on the voxel map's own points):
   ``d = (k - 1) s`` for translations [m] and ``d / L`` for rotations [rad]. The six body axes
   are perturbed in both signs (12 re-registrations; ``both_signs=False`` gives 6).
3. ``P_pert = f_opt(P_opt exp(delta))``, ``T = P_opt^-1 P_pert``, ``t = log(T)``.
4. ``t`` is kept when the median point displacement under ``T`` divided by the median
   displacement caused by ``delta`` exceeds ``tau_displacement`` (the registration did not
   come back).
5. PCA of the kept twists in the scaled space: eigen-decomposition of the second moment
   ``M = sum t t^T / (n_signs d^2)`` about the origin. Normalised this way a direction along
   which every perturbation slides freely has eigenvalue ~1 whatever the units, density or
   ``k``; eigenvectors with eigenvalue above ``tau_pca`` span the degenerate subspace. (The
   paper centres the twists on their mean; with symmetric +/- perturbations the mean is ~0,
   and about the origin a single kept twist still counts, which is what a subspace through the
   identity needs.)
6. The basis is l1-sparsified (``sparsify``).

Defaults: ``k = 5`` (point-to-point ICP pulls a scan back from ~1.5 map spacings, so
``k = 3`` under-detects), ``tau_displacement = 0.2``, ``tau_pca = 0.25``, 100 ICP iterations
at 1e-3. How they were chosen: ``docs/evaluation.md``.

Cost: almost all of it is the 12 perturbed KISS-ICP runs (each runs to convergence, typically
10-40 iterations; the native call holds the GIL, so Python threads do not overlap them). Most
runs come back: their registration returns to ``P_opt`` and step 4 rejects their twist. With
``return_ratio > 0`` such a run is stopped once its displacement ratio has fallen
below ``return_ratio``, checked every ``return_check_iterations`` ICP iterations (KISS-ICP's
iterations are stateless, so continuing from the pose reached is the same ICP up to rounding);
runs that do not come back (degenerate directions) run to convergence. The detector's own
default is 0 (every run to convergence, as in the paper; ``lili-odom detect``); the odometry
uses 0.1 (:class:`lili_odom.pipeline.odometry.PipelineConfig`). A run can dip below the
ratio and slide out again, so an early stop can miss a direction; each run's ratios at the
checks are returned in ``details["check_ratios"]``. The opt-in ``perturbation_points`` /
``perturbation_iterations`` / ``both_signs=False`` make the runs cheaper but change the
detected subspace on odometry inputs, so their defaults are the paper's. Cost and accuracy
of these settings: ``docs/performance.md``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lili_odom import geometry
from lili_odom.degeneracy.config import RegistrationConfig, finite_points, usable_length
from lili_odom.degeneracy.reference import AlignmentResult, GuardedRegistration, ReferenceMap
from lili_odom.degeneracy.result import DegeneracyResult, failed_result
from lili_odom.degeneracy.sparsify import sparsify


@dataclass
class LiliConfig:
    """LiLi parameters (see module docstring).

    Attributes:
        k: re-association target; perturbations move the median-range point ``k - 1`` spacings.
        tau_displacement: keep a perturbation when (median displacement after re-registration)
            / (median displacement of the perturbation) exceeds this (dimensionless).
        tau_pca: eigenvalue threshold of the normalised second moment (dimensionless, ~1 for a
            fully free direction).
        both_signs: perturb each axis in + and - (12 runs) instead of + only (6 runs).
        sparsify: l1-sparsify the PCA basis.
        ratio_points: scan points used for the displacement medians (evenly thinned).
        min_points: fewer finite scan points -> ``ok = False``.
        registration: f_opt settings for P_opt and (unless overridden below) the perturbed
            re-registrations.
        perturbation_points: scan points used in the perturbed re-registrations (evenly
            thinned from the detection scan; 0 = all). Each ICP iteration costs time
            proportional to this count.
        perturbation_iterations: ICP iteration cap of each perturbed re-registration (0 =
            ``registration.max_iterations``); the convergence criterion stays
            ``registration.convergence``. A degenerate direction does not come back however
            long ICP runs, and a pulled-back one only has to come back below ``sqrt(tau_pca)``
            of the perturbation for the PCA to reject it.
        return_ratio: stop a perturbed re-registration once the median displacement of its
            pose from P_opt, divided by the perturbation's, is below this (dimensionless, in
            ``[0, tau_displacement)``): the run came back and its twist would be rejected. 0
            (default) runs every re-registration to convergence (the paper); the odometry
            uses 0.1 (module docstring).
        return_check_iterations: ICP iterations between two such checks (>= 1); each check
            restarts the native ICP from the pose reached, so fewer iterations per check cost
            Python overhead and more stop later.
        max_perturbation_gate: the translation perturbation ``(k - 1) s`` is capped at this
            fraction of the correspondence gate (dimensionless; 0 = no cap), the rotation
            one with it. KISS-ICP associates a point only within the gate (one voxel), so a
            perturbation near or beyond it cannot come back whatever the scene, and a young
            local map (one or two scans, widely spaced points) gives ``(k - 1) s`` of more
            than a voxel. Default 0.75; a map of the reference's full density
            (``lili-odom detect``, voxel = 10 spacings) is never capped.
    """

    k: int = 5
    tau_displacement: float = 0.2
    tau_pca: float = 0.25
    both_signs: bool = True
    sparsify: bool = True
    ratio_points: int = 2000
    min_points: int = 30
    registration: RegistrationConfig = field(
        default_factory=lambda: RegistrationConfig(max_iterations=100, convergence=1e-3)
    )
    perturbation_points: int = 0
    perturbation_iterations: int = 0
    return_ratio: float = 0.0
    return_check_iterations: int = 4
    max_perturbation_gate: float = 0.75

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ValueError naming the first out-of-range parameter."""
        if self.k < 2:
            raise ValueError(f"k must be >= 2, got {self.k}")
        if not 0.0 < self.tau_displacement < 1.0:
            raise ValueError(f"tau_displacement must be in (0, 1), got {self.tau_displacement}")
        if not self.tau_pca > 0.0:
            raise ValueError(f"tau_pca must be > 0, got {self.tau_pca}")
        if self.ratio_points < 1 or self.min_points < 10:
            raise ValueError("ratio_points must be >= 1 and min_points >= 10")
        if self.perturbation_points < 0:
            raise ValueError(f"perturbation_points must be >= 0, got {self.perturbation_points}")
        if self.perturbation_iterations < 0:
            raise ValueError(
                f"perturbation_iterations must be >= 0, got {self.perturbation_iterations}")
        if not 0.0 <= self.return_ratio < self.tau_displacement:
            raise ValueError(f"return_ratio must be in [0, tau_displacement = "
                             f"{self.tau_displacement}), got {self.return_ratio}")
        if not 0.0 <= self.max_perturbation_gate <= 10.0:
            raise ValueError(
                f"max_perturbation_gate must be in [0, 10], got {self.max_perturbation_gate}")
        if self.return_check_iterations < 1:
            raise ValueError(
                f"return_check_iterations must be >= 1, got {self.return_check_iterations}")
        self.registration.__post_init__()


def perturbation_twists(spacing: float, length: float, k: int, both_signs: bool) -> np.ndarray:
    """(6 or 12, 6) plain body-frame perturbation twists: translations ``(k-1) s`` [m] along
    x, y, z and rotations ``(k-1) s / L`` [rad] about x, y, z, in + (and -) sign."""
    d = (k - 1) * spacing
    steps = np.concatenate([np.full(3, d), np.full(3, d / length)])
    deltas = np.diag(steps)
    return np.vstack([deltas, -deltas]) if both_signs else deltas


def thin(points: np.ndarray, n: int) -> np.ndarray:
    """Every ``ceil(N / n)``-th row of ``points``: at most ``n`` evenly spread points."""
    return points[:: max(1, -(-len(points) // max(n, 1)))]


def _median_displacement(T: np.ndarray, points: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(geometry.transform_points(T, points) - points, axis=1)))


def pca_subspace(
    twists_scaled: np.ndarray, normaliser: float, tau_pca: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-analysis of ``sum t t^T / normaliser``; returns (eigenvalues desc, basis rows)."""
    T = np.asarray(twists_scaled, dtype=float).reshape(-1, 6)
    M = T.T @ T / normaliser
    w, V = np.linalg.eigh(M)
    order = np.argsort(w)[::-1]
    w, V = w[order], V[:, order]
    return w, V[:, w > tau_pca].T


class LiliDetector:
    """The LiLi detector; one instance can serve many scans (it owns one ICP object)."""

    name = "lili"

    def __init__(
        self, config: LiliConfig | None = None, registration: GuardedRegistration | None = None
    ):
        self.config = config or LiliConfig()
        rc = self.config.registration
        self.registration = registration or GuardedRegistration(
            rc.max_iterations, rc.convergence, rc.max_threads
        )
        iterations = self.config.perturbation_iterations or rc.max_iterations
        self.perturbation_registration = (
            self.registration if iterations == self.registration.max_iterations
            else GuardedRegistration(iterations, rc.convergence, rc.max_threads)
        )
        self._chunks: dict[int, GuardedRegistration] = {}

    def _chunk(self, iterations: int) -> GuardedRegistration:
        """A registration capped at ``iterations`` (same convergence and threads)."""
        if iterations not in self._chunks:
            rc = self.config.registration
            self._chunks[iterations] = GuardedRegistration(iterations, rc.convergence,
                                                           rc.max_threads)
        return self._chunks[iterations]

    def _reregister(self, points: np.ndarray, reference: ReferenceMap, guess: np.ndarray,
                    gate: float, kernel: float, P_opt_inv: np.ndarray, probe: np.ndarray,
                    scale: float) -> tuple[AlignmentResult, bool, list[float]]:
        """One perturbed re-registration from ``guess``; (result, stopped because it came back,
        the displacement ratio at each check).

        Without ``return_ratio`` one KISS-ICP call to convergence. Otherwise the same ICP in
        pieces of ``return_check_iterations`` iterations, each from the pose the previous one
        reached, until it converged (a piece moved the pose by less than the convergence
        criterion), the iteration budget is spent, or the displacement ratio of the pose
        reached (``probe`` points, ``scale`` = the perturbation's median displacement [m])
        is below ``return_ratio``.
        """
        cfg, whole = self.config, self.perturbation_registration
        if not cfg.return_ratio > 0.0:
            return whole.align(points, reference, guess, gate, kernel), False, []
        pose, done, checks = guess, 0, []
        while True:
            n = min(cfg.return_check_iterations, whole.max_iterations - done)
            res = self._chunk(n).align(points, reference, pose, gate, kernel)
            if not res.ok:
                return res, False, checks
            done += n
            step = float(np.linalg.norm(geometry.log(np.linalg.inv(pose) @ res.pose)))
            pose = res.pose
            if done >= whole.max_iterations or step < whole.convergence:
                return res, False, checks
            checks.append(_median_displacement(P_opt_inv @ pose, probe) / scale)
            if checks[-1] < cfg.return_ratio:
                return res, True, checks

    def detect(
        self,
        reference: ReferenceMap,
        scan: np.ndarray,
        initial_pose: np.ndarray,
        optimized_pose: np.ndarray | None = None,
    ) -> DegeneracyResult:
        """Detect the degenerate subspace of aligning ``scan`` to ``reference``.

        Args:
            reference: the map (reference frame).
            scan: (N, 3) scan points in the scan's own frame [m].
            initial_pose: 4x4 initial guess, scan frame -> reference frame.
            optimized_pose: P_opt when the caller already registered the scan (skips step 1).
        """
        t0 = time.perf_counter()
        cfg = self.config
        scan = finite_points(scan)
        L = usable_length(scan)

        def failed(pose: np.ndarray, reason: str) -> DegeneracyResult:
            return failed_result(self.name, pose, L, t0, reason)

        if len(scan) < cfg.min_points:
            return failed(np.asarray(initial_pose, dtype=float), f"only {len(scan)} usable scan points")
        s = reference.spacing
        if not (np.isfinite(s) and s > 0):
            return failed(np.asarray(initial_pose, dtype=float), "reference map has too few points")
        gate = cfg.registration.gate(reference.voxel_size)
        kernel = cfg.registration.kernel_for(reference.voxel_size)

        if optimized_pose is None:
            opt = self.registration.align(scan, reference, initial_pose, gate, kernel)
            if not opt.ok:
                return failed(opt.pose, f"initial alignment failed: {opt.reason}")
            P_opt = opt.pose
        else:
            P_opt = geometry.orthonormalize(optimized_pose)

        probe = scan[:: max(1, len(scan) // cfg.ratio_points)]
        moved = thin(scan, cfg.perturbation_points) if cfg.perturbation_points else scan
        s_raw = s
        if cfg.max_perturbation_gate > 0.0:  # a perturbation beyond the gate cannot come back
            s = min(s, cfg.max_perturbation_gate * gate / (cfg.k - 1))
        deltas = perturbation_twists(s, L, cfg.k, cfg.both_signs)
        twists = np.zeros_like(deltas)
        ratios = np.zeros(len(deltas))
        valid = np.zeros(len(deltas), dtype=bool)
        returned = 0
        check_ratios: list[list[float]] = []
        P_opt_inv = np.linalg.inv(P_opt)
        for i, delta in enumerate(deltas):
            scale = max(_median_displacement(geometry.exp(delta), probe), 1e-12)
            res, came_back, checks = self._reregister(moved, reference,
                                                      P_opt @ geometry.exp(delta), gate, kernel,
                                                      P_opt_inv, probe, scale)
            check_ratios.append(checks)
            if not res.ok:
                continue
            returned += came_back
            T_deg = P_opt_inv @ res.pose
            twists[i] = geometry.log(T_deg)
            ratios[i] = _median_displacement(T_deg, probe) / scale
            valid[i] = True
        if not valid.any():
            return failed(P_opt, "every perturbed re-registration failed")
        kept = valid & (ratios > cfg.tau_displacement)

        d = (cfg.k - 1) * s
        n_signs = 2.0 if cfg.both_signs else 1.0
        eigenvalues, basis = pca_subspace(
            geometry.scale_twist(twists[kept], L), n_signs * d * d, cfg.tau_pca
        )
        if cfg.sparsify and len(basis):
            basis = sparsify(basis)
        return DegeneracyResult(
            method=self.name,
            pose=P_opt,
            basis_scaled=basis,
            characteristic_length=L,
            runtime_s=time.perf_counter() - t0,
            eigenvalues=eigenvalues,
            twists=twists,
            ratios=ratios,
            kept=kept,
            details={
                "spacing": s_raw,
                "perturbation_m": d,
                "perturbation_rad": d / L,
                "valid_runs": int(valid.sum()),
                "perturbation_points": len(moved),
                "returned_early": returned,
                # per perturbed run, its displacement ratio at each return check (empty
                # without return_ratio)
                "check_ratios": check_ratios,
            },
        )
