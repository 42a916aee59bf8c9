"""Subspace helpers for comparing degenerate twist subspaces (pure numpy).

A subspace is given by the *rows* of a (k, n) array (for us n = 6 twists). Angles between
twist subspaces are only meaningful in the *scaled* space ``(v [m], L * w [m])`` (see
``lili_odom.geometry.scale_twist``): pass scaled rows to every function here, e.g. a
detector's ``DegeneracyResult.basis_scaled`` and ``truth_scaled(case.true_basis, L)``.

Conventions:

* An empty subspace is a (0, n) array.
* ``principal_angles_deg`` returns the ``min(kA, kB)`` principal angles in ascending order.
* ``largest_principal_angle_deg`` is the single-number summary used by the benchmarks. For
  subspaces of *different* dimension it is defined as 90 deg (they cannot coincide, and the
  missing direction of the larger one is unmatched); for two *empty* subspaces it is 0 deg
  (both say "no degeneracy", which agrees). One empty and one non-empty subspace therefore
  gives 90 deg.
"""
from __future__ import annotations

import numpy as np

from lili_odom.geometry import scale_twist

__all__ = [
    "RANK_RTOL",
    "orthonormal_rows",
    "projector",
    "principal_angles_deg",
    "largest_principal_angle_deg",
    "truth_scaled",
]

RANK_RTOL = 1e-9
"""Singular values below ``RANK_RTOL * largest`` count as zero when orthonormalising."""


def _as_rows(B: np.ndarray, n: int | None = None) -> np.ndarray:
    B = np.asarray(B, dtype=float)
    if B.ndim == 1:
        B = B.reshape(1, -1) if B.size else B.reshape(0, n or 6)
    if B.ndim != 2:
        raise ValueError(f"expected a (k, n) array of row vectors, got shape {B.shape}")
    return B


def orthonormal_rows(B: np.ndarray, rtol: float = RANK_RTOL) -> np.ndarray:
    """Orthonormal basis of the row space of ``B``.

    Args:
        B: (k, n) rows spanning the subspace (need not be independent or normalised).
        rtol: relative singular value threshold for the rank.

    Returns:
        (r, n) array with orthonormal rows, r = numerical rank of ``B`` (0 for an empty or zero
        input). The rows are the right singular vectors of ``B``, so the result does not depend
        on the order of the input rows.
    """
    B = _as_rows(B)
    n = B.shape[1]
    if B.shape[0] == 0 or not np.any(B):
        return np.zeros((0, n))
    if not np.all(np.isfinite(B)):
        raise ValueError("basis rows must be finite")
    _, S, Vt = np.linalg.svd(B, full_matrices=False)
    rank = int(np.sum(S > rtol * S[0]))
    return Vt[:rank].copy()


def projector(B: np.ndarray) -> np.ndarray:
    """(n, n) orthogonal projector onto the row space of ``B`` (zero matrix when empty)."""
    Q = orthonormal_rows(B)
    return Q.T @ Q


def principal_angles_deg(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Principal angles [deg] between the row spaces of ``A`` and ``B``, ascending.

    Returns ``min(dim A, dim B)`` angles (an empty array when either subspace is empty). Large
    angles come from the cosines (singular values of ``Qa Qb^T``) and small ones (< 45 deg) from
    the sines (singular values of the part of the smaller basis orthogonal to the larger one),
    which keeps nearly identical subspaces accurate to ~1e-12 deg instead of ~1e-6 deg.
    """
    Qa, Qb = orthonormal_rows(A), orthonormal_rows(B)
    if Qa.shape[1] != Qb.shape[1] and Qa.shape[0] and Qb.shape[0]:
        raise ValueError("subspaces live in spaces of different dimension")
    k = min(Qa.shape[0], Qb.shape[0])
    if k == 0:
        return np.zeros(0)
    if Qa.shape[0] < Qb.shape[0]:
        Qa, Qb = Qb, Qa  # Qb is now the smaller one
    cos = np.clip(np.linalg.svd(Qa @ Qb.T, compute_uv=False)[:k], 0.0, 1.0)  # descending
    residual = Qb - (Qb @ Qa.T) @ Qa  # rows of the smaller basis minus their projection
    sin = np.clip(np.sort(np.linalg.svd(residual, compute_uv=False))[:k], 0.0, 1.0)  # ascending
    from_cos = np.arccos(cos)
    from_sin = np.arcsin(sin)
    angles = np.where(from_cos < np.pi / 4, from_sin, from_cos)
    return np.degrees(np.sort(angles))


def largest_principal_angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    """Largest principal angle [deg]; 90 when the dimensions differ, 0 when both are empty."""
    Qa, Qb = orthonormal_rows(A), orthonormal_rows(B)
    if Qa.shape[0] != Qb.shape[0]:
        return 90.0
    if Qa.shape[0] == 0:
        return 0.0
    return float(principal_angles_deg(Qa, Qb)[-1])


def truth_scaled(basis_plain: np.ndarray, length: float) -> np.ndarray:
    """Plain twist rows ``(v [m], w [rad])`` -> orthonormal rows in the scaled space.

    Args:
        basis_plain: (k, 6) twists spanning the subspace, any normalisation.
        length: characteristic length L [m] multiplying the rotation part.

    Returns:
        (k, 6) orthonormal rows spanning ``{(v, L w)}`` (the form of
        ``DegeneracyResult.basis_scaled``).
    """
    B = _as_rows(basis_plain, 6)
    if B.shape[0] == 0:
        return np.zeros((0, 6))
    return orthonormal_rows(scale_twist(B, float(length)))
