"""Split relative-pose information between the LiDAR and the wheels by a degenerate subspace.

The detectors report the degenerate subspace as orthonormal rows ``basis_scaled`` in the
*scaled* twist space of the LiDAR scan body frame: ``s = (v, L w)`` with ``L`` the
characteristic length [m] (see ``lili_odom.degeneracy.result``). The factors of the estimator
are written in the body frame of ``base_link``, plain ``(v [m], w [rad])``.

A base_link twist and a scaled LiDAR twist of the same rigid motion are related by

    xi_base = M s,    M = Ad(T_base_lidar) S^-1,    S = diag(1, 1, 1, L, L, L)

(moving the LiDAR by ``exp(xi_lidar)`` in its body frame moves base_link by
``exp(Ad(T_base_lidar) xi_lidar)``). An information matrix ``Omega_base`` for ``xi_base``
becomes ``M^T Omega_base M`` for ``s``. All splitting happens in the scaled LiDAR coordinates,
where the basis is orthonormal and metres and radians are comparable; results are mapped back
with ``M^-1``.

Two ways of removing directions are offered:

* ``"marginalize"`` (default): the measurement's components along the dropped directions are
  treated as unknown, i.e. marginalised out of the measurement (Schur complement). This is the
  statistically consistent choice when the information has cross terms between the kept and
  the dropped directions.
* ``"project"``: plain ``P Omega P`` with the orthogonal projector ``P`` onto the kept
  directions (drops the cross terms without re-weighting).

Both coincide when the subspace is an eigenspace of the information (e.g. Zhang's method).
The quadratic form of a restricted information depends only on the kept components of the
error, so the factor pulls the estimate only along the kept directions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from lili_odom.geometry import adjoint, exp, log, orthonormalize, scaling_matrix

__all__ = [
    "SubspaceSplit",
    "scaled_lidar_to_base",
    "orthonormal_rows",
    "restrict_information",
    "split_information",
    "sqrt_information",
    "remap_pose",
    "weighted_restriction",
    "degenerate_anchor",
    "planar_directions",
    "snap_basis",
    "covariance_along",
    "inflate_along",
]


def scaled_lidar_to_base(T_base_lidar: np.ndarray, length: float) -> np.ndarray:
    """6x6 ``M`` with ``xi_base = M @ s`` for a scaled LiDAR body twist ``s = (v, L w)``."""
    return adjoint(T_base_lidar) @ np.linalg.inv(scaling_matrix(length))


def orthonormal_rows(basis: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Orthonormal rows spanning the row space of ``basis`` (k, 6); rank-deficient rows dropped."""
    basis = np.asarray(basis, dtype=float).reshape(-1, 6)
    if basis.shape[0] == 0:
        return np.zeros((0, 6))
    _, s, vt = np.linalg.svd(basis, full_matrices=False)
    rank = int(np.count_nonzero(s > tol * max(s[0], 1e-300))) if s.size else 0
    return vt[:rank]


def snap_basis(basis: np.ndarray, threshold: float) -> np.ndarray:
    """Zero the components of each basis row below ``threshold`` times its largest one.

    A detected direction carries small spurious components (a few hundredths in the scaled
    space, from registration noise); under an absolute LiDAR factor they decide where along
    the subspace the estimate settles. Rows are re-orthonormalised afterwards (a row that
    vanishes or repeats another is dropped). ``threshold = 0`` returns the rows unchanged.
    """
    basis = np.asarray(basis, dtype=float).reshape(-1, 6)
    if threshold <= 0.0 or basis.shape[0] == 0:
        return basis
    peak = np.abs(basis).max(axis=1, keepdims=True)
    return orthonormal_rows(np.where(np.abs(basis) >= threshold * peak, basis, 0.0))


def _complement(rows: np.ndarray) -> np.ndarray:
    """Orthonormal rows spanning the orthogonal complement of ``rows`` in R^6."""
    if rows.shape[0] == 0:
        return np.eye(6)
    _, _, vt = np.linalg.svd(rows, full_matrices=True)
    return vt[rows.shape[0]:]


def restrict_information(
    omega: np.ndarray, keep: np.ndarray, drop: np.ndarray, mode: str = "marginalize"
) -> np.ndarray:
    """Information left about the ``keep`` directions once the ``drop`` ones are discarded.

    Args:
        omega: 6x6 PSD information in coordinates where ``keep`` and ``drop`` are orthonormal.
        keep: (k, 6) orthonormal rows; drop: (6 - k, 6) orthonormal rows, complementary.
        mode: ``"marginalize"`` (Schur complement) or ``"project"`` (``P omega P``).

    Returns:
        6x6 PSD information of rank <= k supported on span(keep).
    """
    if keep.shape[0] == 0:
        return np.zeros((6, 6))
    o_kk = keep @ omega @ keep.T
    if mode == "marginalize" and drop.shape[0] > 0:
        o_kd = keep @ omega @ drop.T
        o_dd = drop @ omega @ drop.T
        o_kk = o_kk - o_kd @ np.linalg.pinv(o_dd, rcond=1e-10, hermitian=True) @ o_kd.T
    elif mode not in ("marginalize", "project"):
        raise ValueError(f"unknown restriction mode {mode!r}")
    o_kk = 0.5 * (o_kk + o_kk.T)
    w, v = np.linalg.eigh(o_kk)
    o_kk = (v * np.clip(w, 0.0, None)) @ v.T
    return keep.T @ o_kk @ keep


def weighted_restriction(omega: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """The information of a measurement's own estimate of its ``keep`` components.

    ``omega D^T (D omega D^T)^-1 D omega`` with ``D = keep``: the factor penalises the
    measurement's weighted least-squares fit of the residual inside span(keep), so its
    components along the subspace are decided by what the measurement measures well. A
    detected tunnel axis mixes a little roll or pitch into the translation; restricted with
    ``"project"``, the wheels' "no tilt change" (which they do not measure) would move the
    position along the axis; restricted with ``"marginalize"``, their weak tilt makes them
    weak along the whole direction (information more than 50 times lower for 0.39 of scaled
    pitch, ``test/test_fusion.py``), and the IMU then decides the distance. The information
    along span(keep) equals ``"project"``'s; it has rank ``len(keep)`` but is not supported
    on span(keep).

    Args:
        omega: 6x6 PSD information in coordinates where ``keep`` is orthonormal.
        keep: (k, 6) orthonormal rows.
    """
    if keep.shape[0] == 0:
        return np.zeros((6, 6))
    normal = keep @ omega @ keep.T
    inv = np.linalg.pinv(0.5 * (normal + normal.T), rcond=1e-12, hermitian=True)
    out = omega @ keep.T @ inv @ keep @ omega
    return 0.5 * (out + out.T)


@dataclass
class SubspaceSplit:
    """LiDAR and wheel information of one increment, both 6x6 ``(v, w)`` in base_link.

    Attributes:
        lidar: positive definite information of the LiDAR factor (degenerate directions
            removed, ``epsilon`` kept there), or None when the LiDAR constrains nothing.
        wheel: PSD information of the wheel factor, supported on the degenerate subspace (plus
            the optional weak part elsewhere), or None when it is zero.
        dimension: degenerate dimension used.
        projector_scaled: 6x6 projector onto the degenerate subspace, scaled LiDAR coordinates.
    """

    lidar: np.ndarray | None
    wheel: np.ndarray | None
    dimension: int
    projector_scaled: np.ndarray


def split_information(
    omega_lidar: np.ndarray,
    omega_wheel: np.ndarray | None,
    basis_scaled: np.ndarray,
    length: float,
    T_base_lidar: np.ndarray,
    *,
    epsilon: float = 1e-6,
    wheel_weak_scale: float = 0.0,
    mode: str = "marginalize",
    wheel_mode: str = "same",
) -> SubspaceSplit:
    """Remove the degenerate directions from the LiDAR information and give them to the wheels.

    Args:
        omega_lidar: 6x6 information ``(v, w)`` of the LiDAR increment in the **LiDAR** body
            frame.
        omega_wheel: 6x6 information ``(v, w)`` of the wheel increment in **base_link**, or None.
        basis_scaled: (k, 6) degenerate directions, scaled LiDAR body twists (need not be
            exactly orthonormal; re-orthonormalised).
        length: characteristic length L [m] of the scaling.
        T_base_lidar: 4x4 pose of the LiDAR in base_link.
        epsilon: information kept along the degenerate directions, relative to the largest
            eigenvalue of the scaled LiDAR information (keeps it positive definite).
        wheel_weak_scale: factor on the wheel information *outside* the degenerate subspace
            (0 = none: the wheels then only act inside it).
        mode: ``"marginalize"`` or ``"project"`` (see module docstring).
        wheel_mode: how the wheel information is restricted to the subspace: ``"same"`` as
            the LiDAR's (``mode``), ``"marginalize"``, ``"project"``, or ``"weighted"``
            (:func:`weighted_restriction`).
    """
    M = scaled_lidar_to_base(T_base_lidar, length)
    Minv = np.linalg.inv(M)
    S_inv = np.linalg.inv(scaling_matrix(length))
    deg = orthonormal_rows(basis_scaled)
    ok = _complement(deg)
    P_deg = deg.T @ deg

    lidar = None
    if ok.shape[0] > 0:
        om_s = S_inv @ omega_lidar @ S_inv  # xi_lidar = S^-1 s
        om_s = 0.5 * (om_s + om_s.T)
        kept = restrict_information(om_s, ok, deg, mode)
        scale = float(np.linalg.eigvalsh(om_s).max())
        kept = kept + epsilon * max(scale, 1e-12) * P_deg
        lidar = Minv.T @ kept @ Minv
        lidar = 0.5 * (lidar + lidar.T)

    wheel = None
    if omega_wheel is not None:
        om_w = M.T @ omega_wheel @ M
        om_w = 0.5 * (om_w + om_w.T)
        if not deg.shape[0]:
            part = np.zeros((6, 6))
        elif wheel_mode == "weighted":
            part = weighted_restriction(om_w, deg)
        else:
            part = restrict_information(om_w, deg, ok,
                                        mode if wheel_mode == "same" else wheel_mode)
        if wheel_weak_scale > 0.0 and ok.shape[0] > 0:
            part = part + wheel_weak_scale * restrict_information(om_w, ok, deg, mode)
        if np.any(part != 0.0):
            wheel = Minv.T @ part @ Minv
            wheel = 0.5 * (wheel + wheel.T)
    return SubspaceSplit(lidar, wheel, int(deg.shape[0]), P_deg)


def sqrt_information(omega: np.ndarray, rel_tol: float = 1e-12) -> np.ndarray:
    """6x6 ``R`` with ``R^T R = omega`` for a PSD ``omega`` (zero rows for null directions).

    Used for rank-deficient informations, where a Cholesky factorisation does not exist.
    """
    omega = 0.5 * (np.asarray(omega, dtype=float) + np.asarray(omega, dtype=float).T)
    w, v = np.linalg.eigh(omega)
    top = max(float(w.max()), 0.0)
    w = np.where(w > rel_tol * top, w, 0.0)
    return (np.sqrt(w)[:, None] * v.T)


def remap_pose(T: np.ndarray, T_ref: np.ndarray, basis_scaled: np.ndarray, length: float,
               iterations: int = 3, weight: np.ndarray | None = None) -> np.ndarray:
    """LiDAR pose ``T`` (4x4) moved along the degenerate subspace onto ``T_ref``'s degenerate
    components (solution remapping of a pose).

    ``basis_scaled`` rows are scaled twists ``(v, L w)`` in the LiDAR body frame. Without
    ``weight``, solves ``B S log((T exp(xi))^-1 T_ref) = 0`` for ``xi`` in the subspace by
    fixed-point steps (one is exact when ``T`` and ``T_ref`` differ by a motion inside the
    subspace). With ``weight`` (6x6 PSD metric on scaled LiDAR twists, e.g. the reference's
    information), the step along the subspace is the weighted least-squares fit of the
    difference ``S log(T^-1 T_ref)``: a detected direction mixes a little rotation into the
    translation, and a reference that does not know that rotation (wheel odometry knows no
    roll or pitch) must not decide the position along the direction through it.
    """
    B = orthonormal_rows(basis_scaled)
    T = orthonormalize(np.asarray(T, dtype=float))
    if B.shape[0] == 0:
        return T
    S = scaling_matrix(length)
    Sinv = np.linalg.inv(S)
    W = np.eye(6) if weight is None else np.asarray(weight, dtype=float)
    W = 0.5 * (W + W.T)
    normal = B @ W @ B.T
    if not np.all(np.isfinite(normal)) or np.linalg.cond(normal) > 1e12:
        W, normal = np.eye(6), np.eye(B.shape[0])  # the weight does not see the subspace
    for _ in range(max(1, iterations)):
        d = S @ log(np.linalg.inv(T) @ T_ref)
        c = np.linalg.solve(normal, B @ W @ d)
        T = orthonormalize(T @ exp(Sinv @ B.T @ c))
    return T


def degenerate_anchor(
    T_meas: np.ndarray,
    T_ref: np.ndarray,
    basis_scaled: np.ndarray,
    length: float,
    T_base_lidar: np.ndarray,
    sigma: float,
    reference_covariance: np.ndarray | None = None,
    iterations: int = 3,
    reference_information: np.ndarray | None = None,
    min_planar_share: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A registration pose whose degenerate components are taken from a reference pose.

    With an *absolute* LiDAR factor and nothing but relative wheel/IMU factors along the
    degenerate subspace, the position along it is decided by what little information the
    restricted factor keeps near the subspace, which small spurious components of the detected
    basis can move along the axis against the wheels. Replacing the measurement's degenerate
    components by a reference pose (the wheel prediction: Zhang & Singh's solution remapping)
    and holding them with ``sigma`` gives that direction to the wheels.

    Args:
        T_meas: 4x4 registered pose of base_link in the odometry frame.
        T_ref: 4x4 reference pose of base_link (e.g. previous pose composed with the wheel
            increment).
        basis_scaled: (k, 6) degenerate directions, scaled LiDAR body twists.
        length: characteristic length L [m].
        T_base_lidar: 4x4 pose of the LiDAR in base_link.
        sigma: 1-sigma of the anchor along each degenerate direction, scaled units [m].
        reference_covariance: 6x6 ``(v, w)`` base_link covariance of ``T_ref`` [m^2, rad^2]
            (the previous pose's marginal); its part along the subspace is added to
            ``sigma^2``, so the anchor never claims more than the reference knows and the
            reported covariance along the subspace keeps growing like the wheel random walk.
        iterations: Gauss-Newton steps making the degenerate components of
            ``log(T_target^-1 T_ref)`` vanish (one is exact for small differences).
        reference_information: 6x6 ``(v, w)`` base_link information of the reference's own
            increment (the wheel increment). The position along the subspace is then the
            reference's weighted least-squares fit (:func:`remap_pose`), so a rotation the
            reference does not measure (roll, pitch from wheels) cannot move it: a detected
            tunnel axis carries some roll, and without the weight 0.02 rad of roll
            disagreement moves the target by more than 5 cm along the axis
            (``test/test_fusion_prior_factor.py``).
        min_planar_share: the target takes the reference's components only along the
            directions of the subspace that are at least this share planar motion of
            base_link (:func:`planar_directions`) and keeps ``T_meas``'s along the rest
            (mostly height, roll and pitch, which planar wheel odometry does not measure);
            ``omega`` covers the whole subspace either way. 0 (default): every direction from
            the reference.

    Returns:
        ``(T_target, omega)``: ``T_meas`` moved along the degenerate subspace onto ``T_ref``'s
        degenerate components, and the 6x6 ``(v, w)`` base_link information (body frame at
        ``T_target``) supported on that subspace.
    """
    M = scaled_lidar_to_base(T_base_lidar, length)
    Minv = np.linalg.inv(M)
    deg = orthonormal_rows(basis_scaled)
    weight = None if reference_information is None else M.T @ reference_information @ M
    moved = deg
    if min_planar_share > 0.0 and len(deg):
        moved = planar_directions(deg, length, T_base_lidar, min_planar_share)
    T_target = np.asarray(T_meas, dtype=float)
    if len(moved):
        T_target = remap_pose(T_target @ T_base_lidar,
                              np.asarray(T_ref, dtype=float) @ T_base_lidar, moved, length,
                              iterations, weight=weight) @ np.linalg.inv(T_base_lidar)
    cov_deg = np.eye(len(deg)) * sigma**2
    if reference_covariance is not None:
        cov_deg = cov_deg + covariance_along(reference_covariance, deg, length, T_base_lidar)
    omega = Minv.T @ (deg.T @ np.linalg.inv(cov_deg) @ deg) @ Minv
    return T_target, 0.5 * (omega + omega.T)


#: base_link twist components ``(v, w)`` of planar motion: x, y and yaw
_PLANAR = np.diag([1.0, 1.0, 0.0, 0.0, 0.0, 1.0])


def planar_directions(basis_scaled: np.ndarray, length: float, T_base_lidar: np.ndarray,
                      min_share: float) -> np.ndarray:
    """Orthonormal rows (m, 6, scaled LiDAR twists) spanning the directions of the subspace
    ``basis_scaled`` (k, 6) that are at least ``min_share`` planar motion of base_link: the
    share of x, y and yaw in the direction as a scaled base_link twist ``(v, L w)``
    (the generalised eigenvectors of the subspace, m <= k).

    A detected direction of travel or a yaw is planar motion, which wheel odometry measures;
    a roll about a distant axis (a corridor's floor edge) carries only a little lateral
    translation, and height, roll and pitch are what it does not measure. The share depends
    on the geometry alone, not on how long the wheel increment is. A non-finite length or
    mount, or a numerically singular subspace, gives the whole subspace back."""
    deg = orthonormal_rows(basis_scaled)
    if not len(deg):
        return deg
    # scaled base_link twist (v, L w) of each row
    with np.errstate(all="ignore"):
        B = scaling_matrix(length) @ scaled_lidar_to_base(T_base_lidar, length) @ deg.T
    if not np.all(np.isfinite(B)):
        return deg
    try:
        share, C = scipy.linalg.eigh(B.T @ _PLANAR @ B, B.T @ B)
    except (np.linalg.LinAlgError, ValueError):  # numerically singular: keep every direction
        return deg
    return orthonormal_rows(C[:, share >= min_share].T @ deg)


def covariance_along(cov_base: np.ndarray, basis_scaled: np.ndarray, length: float,
                     T_base_lidar: np.ndarray) -> np.ndarray:
    """(k, k) covariance of a base_link ``(v, w)`` covariance along the degenerate directions
    (scaled LiDAR coordinates, m^2)."""
    Minv = np.linalg.inv(scaled_lidar_to_base(T_base_lidar, length))
    deg = orthonormal_rows(basis_scaled)
    cov_s = Minv @ np.asarray(cov_base, dtype=float) @ Minv.T
    return deg @ (0.5 * (cov_s + cov_s.T)) @ deg.T


def inflate_along(cov_base: np.ndarray, basis_scaled: np.ndarray, variance: float,
                  length: float, T_base_lidar: np.ndarray) -> np.ndarray:
    """``cov_base`` (6x6 ``(v, w)`` base_link) plus ``variance`` [m^2, scaled units] along each
    degenerate direction."""
    M = scaled_lidar_to_base(T_base_lidar, length)
    deg = orthonormal_rows(basis_scaled)
    out = np.asarray(cov_base, dtype=float) + variance * (M @ deg.T @ deg @ M.T)
    return 0.5 * (out + out.T)
