"""SE(3) helpers shared by the whole package, built on ``gtsam.Pose3``.

Conventions (used everywhere in lili_odom):

* Poses are 4x4 homogeneous float64 matrices. ``T_a_b`` maps points from frame ``b`` into ``a``.
* Twists are 6-vectors in **our order** ``(v, w)`` = (translation [m], rotation [rad]).
  GTSAM orders its tangent space ``(w, v)``; KISS-ICP/Sophus use ``(v, w)`` like us. The
  conversion to GTSAM happens only inside this module.
* ``exp(xi)`` / ``log(T)`` are the true SE(3) exponential and logarithm (``Pose3.Expmap`` /
  ``Pose3.Logmap``), so ``T @ exp(xi)`` is a motion expressed in the body frame of ``T``.
* A *scaled* twist multiplies the rotation part by a characteristic length ``L`` [m], so that
  both halves are in metres and a Euclidean angle between twists is meaningful.
"""
from __future__ import annotations

import gtsam
import numpy as np

__all__ = [
    "to_gtsam_order",
    "from_gtsam_order",
    "orthonormalize",
    "is_valid_pose",
    "exp",
    "log",
    "adjoint",
    "hat",
    "scale_twist",
    "unscale_twist",
    "scaling_matrix",
    "transform_points",
    "nonfinite_rows",
    "drop_nonfinite_rows",
    "pose3",
    "matrix",
]


def to_gtsam_order(xi: np.ndarray) -> np.ndarray:
    """(v, w) -> (w, v); works on a 6-vector or on the last axis of an array of twists."""
    xi = np.asarray(xi, dtype=float)
    return np.concatenate([xi[..., 3:6], xi[..., 0:3]], axis=-1)


def from_gtsam_order(xi: np.ndarray) -> np.ndarray:
    """(w, v) -> (v, w)."""
    return to_gtsam_order(xi)  # the swap is its own inverse


def _det3(R: np.ndarray) -> float:
    """Determinant of a 3x3 matrix, written out (``np.linalg.det`` costs ~10x more on 3x3)."""
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def is_valid_pose(T: np.ndarray, tol: float = 1e-6) -> bool:
    """True when ``T`` is a finite 4x4 rigid transform (rotation orthonormal within ``tol``)."""
    T = np.asarray(T)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        return False
    R = T[:3, :3]
    # np.allclose(a, b, atol=tol) written out (|a - b| <= tol + 1e-5 |b|): this runs several
    # times per ICP call, and allclose's generality costs more than the check itself
    E = np.abs(R.T @ R - _EYE3)
    if E.max() > tol and not (E <= tol + 1e-5 * _EYE3).all():
        return False
    if not abs(_det3(R) - 1.0) < tol:
        return False
    a, b, c, d = T[3].tolist()
    return abs(a) <= tol and abs(b) <= tol and abs(c) <= tol and abs(d - 1.0) <= tol + 1e-5


_EYE3 = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])
#: largest |R^T R - I| entry taken as a rotation as it is (Sophus rejects about 1e-10)
_ORTHONORMAL = 1e-13


def orthonormalize(T: np.ndarray) -> np.ndarray:
    """Return ``T`` with its rotation projected onto SO(3) (SVD) and an exact last row.

    Native code (Sophus inside KISS-ICP) aborts the process on a rotation that is off-orthogonal
    by as little as 1e-9, so every pose handed to it goes through here first.

    Raises:
        ValueError: when ``T`` is not a finite 4x4 matrix or its rotation part is degenerate.
    """
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError("pose must be a finite 4x4 matrix")
    R = T[:3, :3]
    if np.abs(R.T @ R - _EYE3).max() < _ORTHONORMAL and _det3(R) > 0.0:
        # already a rotation to rounding (most poses: GTSAM's, KISS-ICP's): no SVD, which
        # would only move the last bits; far inside what Sophus accepts
        out = T.copy()
        out[3] = _LAST_ROW
        return out
    U, S, Vt = np.linalg.svd(R)
    if S[-1] < 1e-6 * max(S[0], 1e-300):
        raise ValueError("pose rotation is singular")
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    out = np.eye(4)
    out[:3, :3] = U @ D @ Vt
    out[:3, 3] = T[:3, 3]
    return out


def pose3(T: np.ndarray) -> gtsam.Pose3:
    """4x4 matrix -> ``gtsam.Pose3`` (re-orthonormalised)."""
    return gtsam.Pose3(orthonormalize(T))


def matrix(P: gtsam.Pose3) -> np.ndarray:
    """``gtsam.Pose3`` -> 4x4 float64 matrix."""
    return np.asarray(P.matrix(), dtype=np.float64)


def exp(xi: np.ndarray) -> np.ndarray:
    """SE(3) exponential of a twist ``(v, w)`` -> 4x4 matrix."""
    return matrix(gtsam.Pose3.Expmap(to_gtsam_order(xi)))


def log(T: np.ndarray) -> np.ndarray:
    """SE(3) logarithm of a 4x4 matrix -> twist ``(v, w)``."""
    return from_gtsam_order(gtsam.Pose3.Logmap(pose3(T)))


def hat(v: np.ndarray) -> np.ndarray:
    """3x3 skew-symmetric matrix of a 3-vector: ``hat(v) @ u == np.cross(v, u)``."""
    return np.asarray(gtsam.Rot3.Hat(np.asarray(v, dtype=float).reshape(3)))


def adjoint(T: np.ndarray) -> np.ndarray:
    """6x6 adjoint of ``T`` in our ``(v, w)`` order: ``T exp(xi) T^-1 = exp(Ad_T xi)``."""
    A = np.asarray(pose3(T).AdjointMap())  # gtsam order (w, v)
    P = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])
    return P @ A @ P


def scaling_matrix(length: float) -> np.ndarray:
    """Diagonal 6x6 ``S`` with ``S @ (v, w) = (v, L w)``."""
    return np.diag([1.0, 1.0, 1.0, length, length, length])


def scale_twist(xi: np.ndarray, length: float) -> np.ndarray:
    """Plain twist(s) ``(v [m], w [rad])`` -> scaled ``(v, L w)`` [m]; last axis has size 6."""
    xi = np.array(xi, dtype=float)
    xi[..., 3:6] *= length
    return xi


def unscale_twist(xi: np.ndarray, length: float) -> np.ndarray:
    """Scaled twist(s) ``(v, L w)`` -> plain ``(v, w)``."""
    xi = np.array(xi, dtype=float)
    xi[..., 3:6] /= length
    return xi


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply the 4x4 ``T`` to an (N, 3) array of points."""
    points = np.asarray(points, dtype=np.float64)
    return points @ T[:3, :3].T + T[:3, 3]


def nonfinite_rows(points: np.ndarray) -> np.ndarray | None:
    """Boolean mask of the rows of the 2-D ``points`` that hold a NaN or inf, or None when
    every entry is finite.

    The all-finite case (every well-formed scan) is decided by one flat reduction, much
    cheaper on an (N, 3) array than the per-row ``np.isfinite(points).all(axis=1)``, which is
    built only when a row is bad.
    """
    finite = np.isfinite(points)
    return None if finite.all() else ~finite.all(axis=1)


def drop_nonfinite_rows(points: np.ndarray) -> np.ndarray:
    """``points`` without the rows that hold a NaN or inf (the same array when there is none)."""
    bad = nonfinite_rows(points)
    return points if bad is None else points[~bad]
