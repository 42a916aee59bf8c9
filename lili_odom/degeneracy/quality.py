"""The paper's quality measure Q of a detected degenerate subspace (Eqs. extended_scan, quality).

The local scan is *extended* by stacking copies of it moved along the detected degenerate
motions, ``S_ext = U_i T_i S_local`` with ``T_i = P_opt @ exp(sum_j c_ij b_j)``, and
``Q = median_p dist(p, S_reference)`` over the extended points (nearest neighbour in the
reference, [m]).

Frames and units: ``scan`` is in the sensor frame, ``pose`` (P_opt) maps it into the reference
frame, the reference points are in the reference frame. The basis rows come in the scaled
space ``(v [m], L w [m])`` (``DegeneracyResult.basis_scaled``); each row is normalised to unit
length there and converted back to a plain body-frame twist ``(v, w / L)``. A coefficient
``c`` [m] therefore moves a point at the characteristic range L by about ``c`` metres,
whatever the mix of translation and rotation.

Coefficients: every vector ``c`` of the grid ``{-R, -R/2, 0, R/2, R}^k`` with ``|c| <= R``
(``R = QUALITY_RANGE``, ``QUALITY_STEPS`` values per dimension; a ball rather than the whole
cube so the largest motion does not grow with k): 5 copies for k = 1, 13 for k = 2, 33 for
k = 3. ``QUALITY_RANGE`` = 0.5 m is ten neighbour spacings (0.05 m) of the synthetic shapes, so
a missing rotational or translational component of a wrongly detected direction moves the
extended copies clearly off the surface (Q grows from ~0.02 m towards ~0.1-0.5 m), while
every synthetic shape extends more than 1 m beyond its local scan along the true degenerate
motions, so a correct subspace keeps the whole extension on the surface.

An empty basis gives a single copy, so Q reduces to the alignment residual of ``pose``: Q does
not penalise *missed* degenerate directions (as in the paper); compare dimensions or principal
angles (``lili_odom.degeneracy.subspace``) for that.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
from scipy.spatial import cKDTree

from lili_odom.geometry import exp, transform_points, unscale_twist

__all__ = [
    "QUALITY_RANGE",
    "QUALITY_STEPS",
    "MAX_EXTENDED_POINTS",
    "coefficient_grid",
    "extension_poses",
    "extended_scan",
    "quality",
]

QUALITY_RANGE = 0.5
"""Largest norm [m] of the scaled-space coefficient vector ``c`` of an extension copy."""
QUALITY_STEPS = 5
"""Grid values per degenerate dimension, evenly spaced on [-QUALITY_RANGE, QUALITY_RANGE]."""
MAX_EXTENDED_POINTS = 200_000
"""Cap on the extended cloud; the scan is thinned by a fixed stride when copies x points exceed it."""


def coefficient_grid(k: int, radius: float = QUALITY_RANGE, steps: int = QUALITY_STEPS) -> np.ndarray:
    """(n, k) coefficient vectors: the ``steps^k`` grid on ``[-radius, radius]^k`` inside the
    ball ``|c| <= radius`` (always contains the zero vector; (1, 0) for k = 0)."""
    if k < 0:
        raise ValueError("k must be >= 0")
    if k == 0:
        return np.zeros((1, 0))
    values = np.linspace(-radius, radius, steps)
    grid = np.array(list(itertools.product(values, repeat=k)), dtype=float)
    return grid[np.linalg.norm(grid, axis=1) <= radius * (1.0 + 1e-9)]


def _unit_plain_basis(basis_scaled: np.ndarray, length: float) -> np.ndarray:
    B = np.asarray(basis_scaled, dtype=float).reshape(-1, 6)
    if B.shape[0] == 0:
        return B
    if not np.all(np.isfinite(B)):
        raise ValueError("basis rows must be finite")
    norms = np.linalg.norm(B, axis=1)
    B = B[norms > 1e-12] / norms[norms > 1e-12, None]
    return unscale_twist(B, length)


def extension_poses(
    pose: np.ndarray,
    basis_scaled: np.ndarray,
    length: float,
    radius: float = QUALITY_RANGE,
    steps: int = QUALITY_STEPS,
) -> np.ndarray:
    """(n, 4, 4) poses ``T_i = pose @ exp(sum_j c_ij b_j)`` of the extension copies.

    Args:
        pose: 4x4 P_opt, scan frame -> reference frame.
        basis_scaled: (k, 6) degenerate directions in the scaled space (rows normalised here).
        length: characteristic length L [m] of the scaling.
    """
    if not (np.isfinite(length) and length > 0):
        raise ValueError("characteristic length must be positive")
    B = _unit_plain_basis(basis_scaled, length)
    coeffs = coefficient_grid(B.shape[0], radius, steps)
    pose = np.asarray(pose, dtype=float)
    return np.stack([pose @ exp(c @ B) if B.shape[0] else pose.copy() for c in coeffs])


def extended_scan(
    scan: np.ndarray,
    pose: np.ndarray,
    basis_scaled: np.ndarray,
    length: float,
    max_points: int = MAX_EXTENDED_POINTS,
) -> np.ndarray:
    """The extended local scan (Eq. extended_scan), (N, 3) points in the reference frame.

    ``scan`` (M, 3) is in the sensor frame. When ``copies * M > max_points`` every copy uses the
    same fixed-stride subset of the scan.
    """
    scan = np.asarray(scan, dtype=float).reshape(-1, 3)
    poses = extension_poses(pose, basis_scaled, length)
    per_copy = max(1, max_points // len(poses))
    stride = max(1, math.ceil(len(scan) / per_copy))
    sub = scan[::stride]
    if len(sub) == 0:
        return np.zeros((0, 3))
    return np.vstack([transform_points(T, sub) for T in poses])


def quality(
    scan: np.ndarray,
    reference: cKDTree | np.ndarray,
    pose: np.ndarray,
    basis_scaled: np.ndarray,
    length: float,
) -> float:
    """Q [m]: median nearest-neighbour distance from the extended scan to the reference.

    Args:
        scan: (M, 3) local scan [m], sensor frame.
        reference: a ``cKDTree`` over the reference points, or the (N, 3) points themselves
            [m], reference frame.
        pose: 4x4 P_opt (scan frame -> reference frame).
        basis_scaled: (k, 6) detected degenerate directions, scaled space ``(v, L w)``; k = 0
            gives the plain alignment residual.
        length: characteristic length L [m] used for the scaling.

    Returns:
        Q in metres (``nan`` for an empty scan or reference).
    """
    tree = reference if isinstance(reference, cKDTree) else cKDTree(np.asarray(reference, dtype=float))
    if tree.n == 0:
        return float("nan")
    points = extended_scan(scan, pose, basis_scaled, length)
    if len(points) == 0:
        return float("nan")
    dist, _ = tree.query(points, k=1)
    return float(np.median(dist))
