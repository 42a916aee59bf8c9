"""Solution remapping: a registration held at the prediction along the degenerate subspace.

Scan-to-map ICP in a degenerate place slides along the free directions by whatever the few
features and the noise dictate. Removing those directions from the LiDAR factor's information
is not enough: the detected basis never matches the slide exactly (a tunnel's axis comes out
mixed with a little roll or yaw), so part of the slide lands in the *kept* components of the
registered pose, and an absolute LiDAR factor then pins the position along the axis to the
slide through them. Zhang & Singh's solution remapping removes the slide at its source: each
Gauss-Newton update of the registration is projected onto the well-constrained directions, so
the registered pose keeps the prediction's components along the degenerate subspace and its
other components are the registration's optimum given those.

KISS-ICP has no constrained solver, so the constrained registration is run as single KISS-ICP
iterations (points re-associate at each one), each update projected out of the degenerate
subspace before it is applied. The registration starts from the unconstrained optimum with its
degenerate components replaced by the prediction's, which is already close.

Frames and units: poses are 4x4 ``T_odom_lidar`` [m]; twists ``(v [m], w [rad])`` in the LiDAR
body frame; ``basis_scaled`` rows are orthonormal-ish twists of the scaled space ``(v, L w)``
with ``L`` the characteristic length [m] (:mod:`lili_odom.degeneracy.result`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from lili_odom import geometry
from lili_odom.degeneracy.hessian import remapping_matrix_from_basis
from lili_odom.degeneracy.subspace import orthonormal_rows
from lili_odom.fusion.subspace import remap_pose

__all__ = ["RemapResult", "project_out", "constrained_registration"]


def project_out(xi: np.ndarray, basis_scaled: np.ndarray, length: float) -> np.ndarray:
    """Plain twist ``xi`` (6,) without its components along the degenerate subspace.

    The projection is orthogonal in the scaled space, where the basis is orthonormal (Zhang's
    remapping matrix, :func:`lili_odom.degeneracy.hessian.remapping_matrix_from_basis`).
    """
    return remapping_matrix_from_basis(orthonormal_rows(basis_scaled), length) @ np.asarray(xi)


@dataclass
class RemapResult:
    """Attributes:
        pose: 4x4 constrained registration ``T_odom_lidar``.
        iterations: single ICP iterations run.
        converged: the last projected update was below the tolerance.
        ok: False when an ICP iteration failed (``pose`` is then the last good one).
    """

    pose: np.ndarray
    iterations: int
    converged: bool
    ok: bool = True


def constrained_registration(
    step: Callable[[np.ndarray], np.ndarray | None],
    registered: np.ndarray,
    prediction: np.ndarray,
    basis_scaled: np.ndarray,
    length: float,
    max_iterations: int = 10,
    tolerance: float = 1e-4,
) -> RemapResult:
    """Registration restricted to the complement of the degenerate subspace.

    Args:
        step: one ICP iteration: pose (4x4) -> pose after one re-association and update, or
            None when it failed.
        registered: the unconstrained optimum (4x4).
        prediction: the predicted pose (4x4) whose degenerate components are kept.
        basis_scaled: (k, 6) degenerate directions, scaled LiDAR body twists.
        length: characteristic length L [m].
        max_iterations: single ICP iterations at most.
        tolerance: stop when the projected update's norm (scaled space, m) is below this.
    """
    B = orthonormal_rows(basis_scaled)
    if B.shape[0] == 0:
        return RemapResult(geometry.orthonormalize(registered), 0, True)
    keep = remapping_matrix_from_basis(B, length)  # projects plain twists out of the subspace
    pose = remap_pose(registered, prediction, B, length)
    for n in range(1, max_iterations + 1):
        moved = step(pose)
        if moved is None:
            return RemapResult(pose, n, False, ok=False)
        update = keep @ geometry.log(np.linalg.inv(pose) @ moved)
        pose = geometry.orthonormalize(pose @ geometry.exp(update))
        if np.linalg.norm(geometry.scale_twist(update, length)) < tolerance:
            return RemapResult(pose, n, True)
    return RemapResult(pose, max_iterations, False)
