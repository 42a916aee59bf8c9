"""Hessian-based degeneracy detection: Zhang's test as LIO-SAM uses it, and a normalised variant.

Both detectors analyse the Gauss-Newton approximation ``H = A^T A`` of the point-to-plane cost
``C = sum_i r_i^2`` with ``r_i = n_i^T (T p_i - q_i)``: ``p_i`` a scan point (scan/sensor frame),
``q_i`` its reference point and ``n_i`` the unit reference normal (reference frame), ``T`` the
scan pose (scan -> reference). Directions of small eigenvalues change the cost little and are
called degenerate (Zhang, Kaess and Singh, ICRA 2016).

Conventions: twists are ``(v, w)`` = (translation [m], rotation [rad]) as everywhere in
``lili_odom``; a *body* twist ``xi`` perturbs a pose as ``T exp(xi)``, a *world* (reference-side)
twist as ``exp(xi) T``. Scaled twists are ``(v, L w)`` [m] with ``L`` the median range of the scan
points from the sensor origin. ``DegeneracyResult.basis_scaled`` holds orthonormal scaled body
twists at the reported pose P_opt.

Linearisation (our convention). For a body twist ``xi = (v, w)`` and the scan point ``p``,
``T exp(xi) p ~= R (p + w x p + v) + t``, so with ``m = R^T n`` (the normal in the scan frame)::

    d r / d v = m^T,    d r / d w = (p x m)^T.

With a world twist about the reference origin and ``q' = T p``: ``d r / d(v, w) = (n, q' x n)``;
the two are related by the adjoint, ``J_body = J_world Ad_T``. In the scaled space the rotation
columns are divided by ``L``.

Two detectors
-------------
``ZhangDetector`` (``name = "zhang"``): the baseline, as LIO-SAM's ``mapOptimization``
(``surfOptimization`` + ``LMOptimization``) and LOAM's ``laserMapping`` implement Zhang's test.

  Follows LIO-SAM:
    * correspondences at the *initial guess* (the first LM iteration, ``iterCount == 0``): each
      scan point is moved into the reference frame with the guess, its 5 nearest map points are
      searched, and it is rejected when the 5th neighbour is 1 m or farther;
    * a plane is fitted to the 5 neighbours and rejected when any of them lies more than 0.2 m
      from it;
    * LIO-SAM's residual gate ``s = 1 - 0.9 |r| / sqrt(|p|)`` (``|p|`` = range of the scan point
      in the sensor frame): the correspondence is dropped when ``s <= 0.1``. The rows of ``A``
      are *unweighted* by default, as the product specification of the baseline asks
      (``ZhangConfig.lio_sam_weights = True`` multiplies them by ``s`` as LIO-SAM's code does;
      for inliers ``s`` is 0.9-1, so the two barely differ);
    * the parameterisation of ``LMOptimization``: world-frame translation increments and increments
      of the roll/pitch/yaw angles of ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (columns ordered
      ``(roll, pitch, yaw, tx, ty, tz)``), rotations in radians, points in metres;
    * ``A^T A`` summed over all correspondences, not normalised; its eigenvectors with an
      eigenvalue below the *absolute* threshold 100 (``eignThre``) are degenerate;
    * solution remapping ``matP = matV^-1 matV2`` (``solution_remapping_matrix``), which LIO-SAM
      computes at the first iteration and then applies to every update (``remap_update``).

  Differs from LIO-SAM:
    * the neighbourhood plane is fitted by PCA (smallest-eigenvalue eigenvector of the 5 points'
      covariance) instead of solving ``a x + b y + c z = -1`` by QR. They agree whenever the latter
      is well posed; the ``= -1`` form breaks down for planes through the map origin, which our
      synthetic shapes can contain;
    * all scan points (as handed to ``detect``) are plane-feature candidates; LIO-SAM uses
      curvature-selected surface features down-sampled at 0.4 m plus edge (corner) features,
      whose point-to-line rows also enter ``A^T A``. There is no feature extraction here;
    * the reported pose is KISS-ICP's point-to-point optimum P_opt (``GuardedRegistration.align``
      against the ``ReferenceMap``), the same ``f_opt`` as LiLi, so poses are comparable across
      detectors. LIO-SAM's own LM solve with remapping is not run; the remapping functions are
      offered to the odometry instead;
    * the degenerate eigenvectors (Euler-parameter space, linearised at the initial guess) are
      mapped to rigid motions through the Euler-rate matrix at the initial guess and expressed as
      body twists at P_opt (rotating the world-axes increments by ``R_opt^T``, i.e.
      ``Ad(P_opt^-1)`` of the world twist about the sensor position), scaled by ``L`` and
      re-orthonormalised. That change of space is not an isometry, so ``basis_scaled`` spans the
      same motions LIO-SAM would freeze but is orthonormal in a different metric;
    * fewer than ``min_correspondences`` (default 10; LIO-SAM skips the whole optimisation below
      50) gives ``ok=False``.

  Kept on purpose (the baseline's known weakness): the threshold 100 is absolute, so the verdict
  depends on the number of correspondences, the point density and the scene scale (rotation
  eigenvalues grow with range squared), and on the world frame's orientation through the Euler
  parameterisation.

``HessianDetector`` (``name = "hessian"``): a fair, improved Hessian test.

    * the same point-to-plane ``A^T A`` (unweighted), evaluated at the converged P_opt;
    * each scan point (moved with P_opt) is paired with its nearest map point within the
      correspondence distance; the normal is the PCA normal of that map point's ``normal_k``
      nearest map neighbours (``ReferenceMap.normals``), rejected below ``min_planarity``;
    * in the scaled body twist space ``(v, L w)`` and divided by the number of correspondences:
      an eigenvalue is the mean squared point-to-plane displacement per correspondence caused by a
      unit scaled twist (a motion moving points at range ``L`` by about one metre), so it is
      free of units, density and point count; the translational block has trace 1;
    * directions with an eigenvalue below ``HESSIAN_THRESHOLD`` are degenerate. The threshold was
      tuned once and frozen; see ``HESSIAN_THRESHOLD``.

Point-to-point ICP (KISS-ICP's own cost) has a Hessian that is never rank deficient for a
non-collinear cloud, so it is no usable baseline; both detectors use plane normals.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lili_odom.degeneracy.config import RegistrationConfig, finite_points, usable_length
from lili_odom.degeneracy.reference import (AlignmentResult, GuardedRegistration, ReferenceMap,
                                          kdtree_workers)
from lili_odom.degeneracy.result import DegeneracyResult, failed_result
from lili_odom.degeneracy.subspace import orthonormal_rows
from lili_odom.geometry import adjoint, orthonormalize, scaling_matrix, transform_points

__all__ = [
    "HESSIAN_THRESHOLD",
    "LIO_SAM_EIGEN_THRESHOLD",
    "ZhangConfig",
    "HessianConfig",
    "ZhangDetector",
    "HessianDetector",
    "point_to_plane_jacobian",
    "point_to_plane_hessian",
    "eigen_descending",
    "euler_zyx",
    "euler_rate_matrix",
    "lio_sam_jacobian",
    "lio_sam_directions_to_body_twists",
    "fit_planes",
    "solution_remapping_matrix",
    "remap_update",
    "remapping_matrix_from_basis",
]

LIO_SAM_EIGEN_THRESHOLD = 100.0
"""LIO-SAM's ``eignThre``: absolute bound on the eigenvalues of the raw ``A^T A``."""

HESSIAN_THRESHOLD = 0.003
"""Frozen threshold on per-correspondence eigenvalues of the scaled body-frame Hessian
(dimensionless). An eigenvalue below it is a degenerate direction. Set once on the clean
synthetic shapes, between their largest degenerate and smallest constrained eigenvalue
(``docs/evaluation.md``)."""

MIN_CORRESPONDENCES = 10


# --------------------------------------------------------------------------------------------
# Pure functions
# --------------------------------------------------------------------------------------------


def point_to_plane_jacobian(
    points: np.ndarray,
    normals: np.ndarray,
    pose: np.ndarray | None = None,
    length: float = 1.0,
) -> np.ndarray:
    """Rows ``d r_i / d xi`` of the point-to-plane residuals ``r_i = n_i^T (x_i - q_i)``.

    Args:
        points: (N, 3) scan points already moved into the reference frame, ``x_i = T p_i`` [m].
        normals: (N, 3) unit plane normals in the reference frame.
        pose: the scan pose ``T`` (scan -> reference). None: columns are a *world* twist about
            the reference origin (``exp(xi) T``). Given: a *body* twist at ``T`` (``T exp(xi)``),
            obtained as ``J_world @ Ad_T``.
        length: ``L`` [m]; the rotation columns are divided by it, so that ``J`` acts on the
            scaled twist ``(v, L w)``. 1 gives plain ``(v [m], w [rad])``.

    Returns:
        (N, 6) Jacobian, columns in twist order ``(v, w)``.
    """
    x = np.asarray(points, dtype=float).reshape(-1, 3)
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    J = np.hstack([n, np.cross(x, n)])
    if pose is not None:
        J = J @ adjoint(pose)
    if length != 1.0:
        J = J @ np.linalg.inv(scaling_matrix(length))
    return J


def point_to_plane_hessian(
    points: np.ndarray,
    normals: np.ndarray,
    pose: np.ndarray | None = None,
    length: float = 1.0,
    normalize: bool = False,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """Gauss-Newton Hessian ``A^T A`` of the point-to-plane cost (see ``point_to_plane_jacobian``).

    Args:
        points, normals, pose, length: as in ``point_to_plane_jacobian``.
        normalize: divide by the number of rows (per-correspondence eigenvalues).
        weights: optional (N,) row weights (rows are multiplied by them, ``H = sum w_i^2 a_i a_i^T``).

    Returns:
        (6, 6) symmetric matrix in twist order ``(v, w)``; units m^2 per twist unit squared.
    """
    J = point_to_plane_jacobian(points, normals, pose, length)
    if weights is not None:
        J = J * np.asarray(weights, dtype=float).reshape(-1, 1)
    H = J.T @ J
    if normalize and len(J):
        H /= len(J)
    return 0.5 * (H + H.T)


def eigen_descending(H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigen-decomposition of a symmetric 6x6: (eigenvalues largest first, eigenvectors as rows).

    The row layout matches OpenCV's ``cv::eigen`` used by LIO-SAM (``matV``).
    """
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    order = np.argsort(w)[::-1]
    return w[order], V[:, order].T


def euler_zyx(R: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) [rad] of ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (PCL/LIO-SAM convention)."""
    R = np.asarray(R, dtype=float)
    pitch = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
    roll = np.arctan2(R[2, 1], R[2, 2])
    yaw = np.arctan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def euler_rate_matrix(rpy: np.ndarray) -> np.ndarray:
    """3x3 ``E`` with ``dR = [E d_rpy]_x R``: Euler-angle increments -> world-axes rotation [rad].

    For ``R = Rz(yaw) Ry(pitch) Rx(roll)`` the columns are ``Rz Ry e_x``, ``Rz e_y``, ``e_z``.
    Singular at pitch = +-90 deg (gimbal lock), exactly as LIO-SAM's parameterisation.
    """
    roll, pitch, yaw = np.asarray(rpy, dtype=float)
    Rz, Ry = _rot(2, yaw), _rot(1, pitch)
    return np.column_stack([Rz @ Ry[:, 0], Rz[:, 1], np.array([0.0, 0.0, 1.0])])


def lio_sam_jacobian(
    points_scan: np.ndarray, normals: np.ndarray, pose: np.ndarray
) -> np.ndarray:
    """LIO-SAM's ``matA`` rows: point-to-plane residual w.r.t. ``(roll, pitch, yaw, tx, ty, tz)``.

    Args:
        points_scan: (N, 3) scan points in the scan/sensor frame [m].
        normals: (N, 3) unit plane normals in the reference (world/map) frame.
        pose: 4x4 pose at which to linearise; the rotation is read as ZYX Euler angles.

    Returns:
        (N, 6) unweighted rows ``[(R p x n)^T E, n^T]`` (rotation in rad, translation in m).
    """
    p = np.asarray(points_scan, dtype=float).reshape(-1, 3)
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    R = np.asarray(pose, dtype=float)[:3, :3]
    E = euler_rate_matrix(euler_zyx(R))
    return np.hstack([np.cross(p @ R.T, n) @ E, n])


def lio_sam_directions_to_body_twists(
    directions: np.ndarray, linearisation_pose: np.ndarray, body_pose: np.ndarray
) -> np.ndarray:
    """Map LIO-SAM parameter increments to plain body twists ``(v [m], w [rad])`` at ``body_pose``.

    An increment ``(d_rpy, dt)`` at ``linearisation_pose`` is the rigid motion that rotates by
    ``E d_rpy`` (world axes) about the sensor position and translates by ``dt`` (world axes).
    Expressed at ``body_pose`` (rotation ``R_b``) that is the body twist ``(R_b^T dt,
    R_b^T E d_rpy)``, i.e. ``Ad(T_b^-1)`` of the corresponding world twist about the origin.

    Args:
        directions: (k, 6) increments ``(roll, pitch, yaw, tx, ty, tz)``.
        linearisation_pose: pose whose Euler angles define ``E`` (LIO-SAM: the current estimate).
        body_pose: pose whose body frame the twists are expressed in (P_opt).
    """
    d = np.asarray(directions, dtype=float).reshape(-1, 6)
    E = euler_rate_matrix(euler_zyx(np.asarray(linearisation_pose)[:3, :3]))
    Rb = np.asarray(body_pose, dtype=float)[:3, :3]
    w_world = d[:, 0:3] @ E.T
    v_world = d[:, 3:6]
    return np.hstack([v_world @ Rb, w_world @ Rb])


def fit_planes(
    neighbours: np.ndarray, max_deviation: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares planes through (M, k, 3) neighbourhoods (PCA), validated LIO-SAM style.

    Returns:
        normals (M, 3) unit, centroids (M, 3), valid (M,) bool: every neighbour lies within
        ``max_deviation`` [m] of its plane (LIO-SAM rejects at 0.2 m).
    """
    nb = np.asarray(neighbours, dtype=float)
    c = nb.mean(axis=1)
    d = nb - c[:, None, :]
    cov = np.einsum("mki,mkj->mij", d, d)
    _, vecs = np.linalg.eigh(cov)
    normals = vecs[:, :, 0]
    dev = np.abs(np.einsum("mki,mi->mk", d, normals))
    valid = np.all(dev <= max_deviation, axis=1) & np.all(np.isfinite(normals), axis=1)
    return normals, c, valid


def solution_remapping_matrix(
    hessian: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Zhang's solution remapping ``matP = matV^-1 matV2`` for a Hessian and eigenvalue bound.

    ``matV`` holds the eigenvectors as rows (largest eigenvalue first) and ``matV2`` is ``matV``
    with the rows of eigenvalues below ``threshold`` zeroed. ``matV`` is orthogonal, so
    ``matP = V^T V2`` is the orthogonal projector onto the non-degenerate eigenspace: applied
    to an update it removes exactly the components along degenerate eigenvectors. LIO-SAM
    zeroes rows from the smallest eigenvalue upwards and stops at the first one above the bound,
    which for a sorted spectrum is the same as zeroing every eigenvalue below it.

    Args:
        hessian: (6, 6) symmetric ``A^T A`` in whichever parameter space the updates live in.
        threshold: eigenvalue bound (same units as ``hessian``).

    Returns:
        (matP (6, 6), eigenvalues (6,) largest first, eigenvectors (6, 6) rows,
        degenerate (6,) bool per eigenvalue).
    """
    eigvals, V = eigen_descending(np.asarray(hessian, dtype=float))
    degenerate = eigvals < threshold
    V2 = V.copy()
    V2[degenerate] = 0.0
    P = V.T @ V2  # == inv(V) @ V2 for orthonormal V
    return P, eigvals, V, degenerate


def remap_update(delta: np.ndarray, remapping: np.ndarray) -> np.ndarray:
    """Apply a remapping matrix to one update (6,) or to rows of updates (n, 6)."""
    delta = np.asarray(delta, dtype=float)
    return delta @ np.asarray(remapping, dtype=float).T


def remapping_matrix_from_basis(basis_scaled: np.ndarray, length: float) -> np.ndarray:
    """Remapping matrix for plain body twists ``(v [m], w [rad])`` from a detector's result.

    Removes the components of an update along the degenerate subspace spanned by the orthonormal
    scaled rows ``basis_scaled`` (projection orthogonal in the scaled metric ``(v, L w)``):
    ``P = S^-1 (I - B^T B) S`` with ``S = diag(1, 1, 1, L, L, L)``.
    """
    B = np.asarray(basis_scaled, dtype=float).reshape(-1, 6)
    S = scaling_matrix(length)
    return np.linalg.inv(S) @ (np.eye(6) - B.T @ B) @ S


# --------------------------------------------------------------------------------------------
# Detectors
# --------------------------------------------------------------------------------------------


def _default_registration() -> RegistrationConfig:
    # The same f_opt settings as LiLi's default, so P_opt is the same for every detector.
    return RegistrationConfig(max_iterations=100, convergence=1e-3)


@dataclass
class ZhangConfig:
    """Parameters of ``ZhangDetector``; defaults are LIO-SAM's.

    Attributes:
        eigenvalue_threshold: absolute bound on eigenvalues of the raw ``A^T A`` in LIO-SAM's
            ``(roll, pitch, yaw [rad], tx, ty, tz [m])`` space (LIO-SAM: 100).
        num_neighbors: map points per plane fit (LIO-SAM: 5).
        max_neighbor_distance: the farthest neighbour must be closer than this [m] (LIO-SAM:
            squared distance < 1.0).
        max_plane_deviation: every neighbour within this distance of the fitted plane [m]
            (LIO-SAM: 0.2).
        lio_sam_weights: multiply rows by ``s = 1 - 0.9 |r| / sqrt(range)`` as LIO-SAM does;
            False gives the plain unweighted ``A^T A`` (the ``s > min_weight`` gate stays).
        min_weight: correspondences with ``s <= min_weight`` are dropped (LIO-SAM: 0.1).
        min_correspondences: fewer -> ``ok=False`` (LIO-SAM skips the optimisation below 50).
        registration: f_opt settings for P_opt (default: LiLi's).
    """

    eigenvalue_threshold: float = LIO_SAM_EIGEN_THRESHOLD
    num_neighbors: int = 5
    max_neighbor_distance: float = 1.0
    max_plane_deviation: float = 0.2
    lio_sam_weights: bool = False
    min_weight: float = 0.1
    min_correspondences: int = MIN_CORRESPONDENCES
    registration: RegistrationConfig = field(default_factory=_default_registration)


@dataclass
class HessianConfig:
    """Parameters of ``HessianDetector``.

    Attributes:
        threshold: bound on per-correspondence eigenvalues of the scaled body-frame Hessian
            (dimensionless; default the frozen ``HESSIAN_THRESHOLD``).
        normal_k: neighbours for the PCA normals of the map points.
        min_planarity: drop correspondences whose map normal has a lower planarity
            ``(l2 - l3) / l1`` (see ``ReferenceMap.normals``).
        min_correspondences: fewer -> ``ok=False``.
        registration: f_opt settings for P_opt (default: LiLi's); its correspondence gate is
            also the gate of the Hessian's nearest-neighbour pairs.
    """

    threshold: float = HESSIAN_THRESHOLD
    normal_k: int = 10
    min_planarity: float = 0.1
    min_correspondences: int = MIN_CORRESPONDENCES
    registration: RegistrationConfig = field(default_factory=_default_registration)


def _guess(initial_pose: np.ndarray) -> np.ndarray | None:
    """Re-orthonormalised initial pose, or None when it is not a finite 4x4 rigid transform."""
    try:
        return orthonormalize(initial_pose)
    except ValueError:
        return None


class _Base:
    name = ""

    def _start(self, reference: ReferenceMap, scan: np.ndarray, initial_pose: np.ndarray,
               min_map_points: int, t0: float) -> DegeneracyResult | tuple[np.ndarray, float, np.ndarray]:
        """Common input checks: (finite scan, L, re-orthonormalised guess) or a failed result."""
        scan = finite_points(scan)
        L = usable_length(scan)
        guess = _guess(initial_pose)
        if guess is None:
            return failed_result(self.name, np.eye(4), L, t0, "invalid initial pose")
        if len(scan) < self.config.min_correspondences:
            return failed_result(self.name, guess, L, t0, f"only {len(scan)} finite scan points")
        if reference.voxel_map.empty() or len(reference.points) < min_map_points:
            return failed_result(self.name, guess, L, t0, "reference map is empty or too small")
        return scan, L, guess

    def __init__(self, config, registration: GuardedRegistration | None):
        self.config = config
        rc = config.registration
        self.registration = registration or GuardedRegistration(
            rc.max_iterations, rc.convergence, rc.max_threads
        )

    def _optimum(
        self,
        reference: ReferenceMap,
        scan: np.ndarray,
        guess: np.ndarray,
        optimized_pose: np.ndarray | None,
    ):
        """P_opt = f_opt(guess) (or the caller's ``optimized_pose``) and the correspondence gate."""
        rc = self.config.registration
        gate = rc.gate(reference.voxel_size)
        if optimized_pose is not None:
            try:
                return AlignmentResult(orthonormalize(optimized_pose), True), gate
            except ValueError as exc:
                return AlignmentResult(guess, False, f"invalid optimized pose: {exc}"), gate
        res = self.registration.align(scan, reference, guess, gate, rc.kernel_for(reference.voxel_size))
        if not res.ok:
            res = AlignmentResult(res.pose, False, f"initial alignment failed: {res.reason}")
        return res, gate


class ZhangDetector(_Base):
    """Zhang's Hessian test as LIO-SAM applies it (see the module docstring for the differences).

    ``detect`` returns a ``DegeneracyResult`` whose
      * ``pose`` is KISS-ICP's P_opt (same as LiLi),
      * ``eigenvalues`` are those of the raw first-iteration ``A^T A`` in LIO-SAM's
        ``(roll, pitch, yaw, tx, ty, tz)`` space, largest first, summed over correspondences
        (residuals in m: the rotation block is in m^2 / rad^2, the translation block is
        dimensionless),
      * ``basis_scaled`` spans the motions of the degenerate eigenvectors, as body twists at P_opt,
      * ``details`` holds ``n_correspondences``, ``hessian`` (the raw matrix), ``remapping``
        (LIO-SAM's ``matP`` in its own parameter space), ``linearisation_pose`` and the
        eigenvectors.
    """

    name = "zhang"

    def __init__(
        self, config: ZhangConfig | None = None, registration: GuardedRegistration | None = None
    ):
        super().__init__(config or ZhangConfig(), registration)

    def correspondences(
        self, reference: ReferenceMap, scan: np.ndarray, pose: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """LIO-SAM's surface correspondences of ``scan`` (scan frame) moved by ``pose``.

        Returns:
            indices (n,) of the accepted scan points, normals (n, 3) in the reference frame,
            weights ``s`` (n,).
        """
        cfg = self.config
        mp = reference.points
        k = int(cfg.num_neighbors)
        if len(mp) < max(k, 3) or not len(scan):
            return np.zeros(0, dtype=int), np.zeros((0, 3)), np.zeros(0)
        x = transform_points(pose, scan)
        dist, idx = reference.kdtree.query(x, k=k, workers=kdtree_workers(len(x)))
        dist = dist.reshape(len(x), k)
        idx = idx.reshape(len(x), k)
        near = dist[:, -1] < cfg.max_neighbor_distance
        cand = np.flatnonzero(near)
        normals, centroids, valid = fit_planes(mp[idx[cand]], cfg.max_plane_deviation)
        cand, normals, centroids = cand[valid], normals[valid], centroids[valid]
        r = np.einsum("ij,ij->i", x[cand] - centroids, normals)
        rng = np.linalg.norm(scan[cand], axis=1)
        s = 1.0 - 0.9 * np.abs(r) / np.sqrt(np.maximum(rng, 1e-12))
        keep = s > cfg.min_weight
        return cand[keep], normals[keep], s[keep]

    def detect(
        self,
        reference: ReferenceMap,
        scan: np.ndarray,
        initial_pose: np.ndarray,
        optimized_pose: np.ndarray | None = None,
    ) -> DegeneracyResult:
        """Run Zhang's test at ``initial_pose`` and report it at P_opt.

        Args:
            reference: the map (reference frame).
            scan: (N, 3) scan points in the scan's own frame [m]; non-finite rows are dropped.
            initial_pose: 4x4 initial guess (scan -> reference); the Hessian is linearised here.
            optimized_pose: P_opt when the caller already registered the scan; otherwise
                ``f_opt(initial_pose)`` is computed.
        """
        t0 = time.perf_counter()
        cfg = self.config
        start = self._start(reference, scan, initial_pose, cfg.num_neighbors, t0)
        if isinstance(start, DegeneracyResult):
            return start
        scan, L, guess = start

        # First iteration: correspondences and Hessian at the initial guess.
        sel, normals, s = self.correspondences(reference, scan, guess)
        n = int(len(sel))
        if n < cfg.min_correspondences:
            return failed_result(
                self.name, guess, L, t0, f"only {n} plane correspondences at the initial guess",
                n_correspondences=n,
            )
        A = lio_sam_jacobian(scan[sel], normals, guess)
        if cfg.lio_sam_weights:
            A = A * s[:, None]
        H = A.T @ A
        P, eigvals, V, degenerate = solution_remapping_matrix(H, cfg.eigenvalue_threshold)

        # Pose: the shared f_opt (KISS-ICP), so all detectors report comparable poses.
        aligned, dist = self._optimum(reference, scan, guess, optimized_pose)
        if not aligned.ok:
            return failed_result(self.name, aligned.pose, L, t0, aligned.reason, n_correspondences=n)
        pose = aligned.pose

        twists = lio_sam_directions_to_body_twists(V[degenerate], guess, pose)
        basis = orthonormal_rows(twists * np.array([1, 1, 1, L, L, L]))
        return DegeneracyResult(
            method=self.name,
            pose=pose,
            basis_scaled=basis,
            characteristic_length=L,
            runtime_s=time.perf_counter() - t0,
            eigenvalues=eigvals,
            details={
                "n_correspondences": n,
                "n_scan_points": int(len(scan)),
                "threshold": float(cfg.eigenvalue_threshold),
                "parameter_order": "roll, pitch, yaw [rad], tx, ty, tz [m] (LIO-SAM)",
                "hessian": H,
                "eigenvectors": V,
                "degenerate": degenerate,
                "remapping": P,
                "linearisation_pose": guess,
                "max_correspondence_distance": dist,
            },
        )


class HessianDetector(_Base):
    """Normalised point-to-plane Hessian test at P_opt (see the module docstring).

    ``eigenvalues`` are per-correspondence eigenvalues of the scaled body-frame Hessian
    ``H_s = (1/n) sum_i a_i a_i^T`` with ``a_i = (m_i, (p_i x m_i) / L)``, largest first;
    degenerate directions are its eigenvectors below ``config.threshold``, reported directly as
    ``basis_scaled``. ``details`` holds ``n_correspondences``, ``hessian`` and the threshold.
    """

    name = "hessian"

    def __init__(
        self, config: HessianConfig | None = None, registration: GuardedRegistration | None = None
    ):
        super().__init__(config or HessianConfig(), registration)

    def correspondences(
        self, reference: ReferenceMap, scan: np.ndarray, pose: np.ndarray, max_distance: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nearest-map-point correspondences with PCA normals at ``pose``.

        Returns:
            indices (n,) of the accepted scan points and their normals (n, 3), reference frame.
        """
        mp = reference.points
        if len(mp) < 3 or not len(scan):
            return np.zeros(0, dtype=int), np.zeros((0, 3))
        normals, planarity = reference.normals(self.config.normal_k)
        d, j = reference.kdtree.query(
            transform_points(pose, scan), distance_upper_bound=max_distance,
            workers=kdtree_workers(len(scan))
        )
        ok = np.isfinite(d)
        sel = np.flatnonzero(ok)
        j = j[ok]
        good = (planarity[j] >= self.config.min_planarity) & np.all(np.isfinite(normals[j]), axis=1)
        return sel[good], normals[j[good]]

    def detect(
        self,
        reference: ReferenceMap,
        scan: np.ndarray,
        initial_pose: np.ndarray,
        optimized_pose: np.ndarray | None = None,
    ) -> DegeneracyResult:
        """Test the normalised Hessian at P_opt.

        Args:
            reference: the map (reference frame).
            scan: (N, 3) scan points in the scan's own frame [m]; non-finite rows are dropped.
            initial_pose: 4x4 initial guess (scan -> reference).
            optimized_pose: P_opt when the caller already registered the scan; otherwise
                ``f_opt(initial_pose)`` is computed.
        """
        t0 = time.perf_counter()
        cfg = self.config
        start = self._start(reference, scan, initial_pose, 3, t0)
        if isinstance(start, DegeneracyResult):
            return start
        scan, L, guess = start
        aligned, dist = self._optimum(reference, scan, guess, optimized_pose)
        if not aligned.ok:
            return failed_result(self.name, aligned.pose, L, t0, aligned.reason)
        pose = aligned.pose
        sel, normals = self.correspondences(reference, scan, pose, dist)
        n = int(len(sel))
        if n < cfg.min_correspondences:
            return failed_result(
                self.name, pose, L, t0, f"only {n} correspondences at the optimum",
                n_correspondences=n,
            )
        H = point_to_plane_hessian(
            transform_points(pose, scan[sel]), normals, pose=pose, length=L, normalize=True
        )
        eigvals, V = eigen_descending(H)
        degenerate = eigvals < cfg.threshold
        return DegeneracyResult(
            method=self.name,
            pose=pose,
            basis_scaled=V[degenerate],
            characteristic_length=L,
            runtime_s=time.perf_counter() - t0,
            eigenvalues=eigvals,
            details={
                "n_correspondences": n,
                "n_scan_points": int(len(scan)),
                "threshold": float(cfg.threshold),
                "hessian": H,
                "max_correspondence_distance": dist,
            },
        )
