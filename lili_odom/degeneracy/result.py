"""The detectors' common output.

Frames and units: ``pose`` maps the scan's own (sensor) frame into the reference frame. Basis
twists live in the scan's *body* frame at ``pose``: the degenerate motions are
``pose @ exp(sum_j c_j b_j)``. Twist order is ``(v, w)`` (see ``lili_odom.geometry``).
``basis_scaled`` rows are orthonormal in the scaled space ``(v [m], L * w [m])`` with
``L = characteristic_length`` [m] (median range of the scan points from the sensor origin).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lili_odom.geometry import unscale_twist


@dataclass
class DegeneracyResult:
    """Detected degenerate subspace of one scan-to-reference alignment.

    Attributes:
        method: detector name (``lili``, ``zhang``, ``hessian``).
        pose: 4x4 optimised pose P_opt (scan frame -> reference frame).
        basis_scaled: (k, 6) orthonormal rows spanning the degenerate subspace, scaled space.
        characteristic_length: L [m] used for scaling rotations.
        runtime_s: wall time of the detection including its own registrations [s].
        eigenvalues: the spectrum the method thresholded (method-specific meaning, see the
            detector's docstring), largest first.
        twists: (n, 6) plain twists ``log(P_opt^-1 P_pert)`` of every perturbation (LiLi only).
        ratios: (n,) median point displacement ratios of every perturbation (LiLi only).
        kept: (n,) bool, which perturbation twists entered the PCA (LiLi only).
        ok: False when the detection could not run (no correspondences, too few points); the
            basis is then empty and ``reason`` says why.
        reason: human-readable explanation when ``ok`` is False.
        details: free-form extra numbers for logs and benchmarks.
    """

    method: str
    pose: np.ndarray
    basis_scaled: np.ndarray
    characteristic_length: float
    runtime_s: float = 0.0
    eigenvalues: np.ndarray = field(default_factory=lambda: np.zeros(0))
    twists: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    ratios: np.ndarray = field(default_factory=lambda: np.zeros(0))
    kept: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    ok: bool = True
    reason: str = ""
    details: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.basis_scaled = np.asarray(self.basis_scaled, dtype=float).reshape(-1, 6)

    @property
    def dimension(self) -> int:
        """Number of degenerate directions (0 = fully constrained)."""
        return int(self.basis_scaled.shape[0])

    @property
    def degenerate(self) -> bool:
        return self.dimension > 0

    @property
    def basis(self) -> np.ndarray:
        """(k, 6) plain twists ``(v [m], w [rad])``: the scaled unit rows with ``w`` divided by L.

        Each moves a point at the characteristic range by about one metre per unit coefficient.
        """
        return unscale_twist(self.basis_scaled, self.characteristic_length)

    def projector_scaled(self) -> np.ndarray:
        """6x6 orthogonal projector onto the degenerate subspace in the scaled space."""
        B = self.basis_scaled
        return B.T @ B

    def to_json_dict(self) -> dict[str, Any]:
        """The ``lili-odom detect --json`` object (design.md contract)."""
        return {
            "method": self.method,
            "pose": np.asarray(self.pose, dtype=float).tolist(),
            "dimension": self.dimension,
            "basis": [
                {"translation": row[:3].tolist(), "rotation": row[3:].tolist()} for row in self.basis
            ],
            "basis_scaled": self.basis_scaled.tolist(),
            "characteristic_length": float(self.characteristic_length),
            "runtime_s": float(self.runtime_s),
            "ok": self.ok,
            "reason": self.reason,
        }


def failed_result(method: str, pose: np.ndarray, length: float, started: float, reason: str,
                  **details: Any) -> DegeneracyResult:
    """An ``ok=False`` result with an empty basis; ``started`` is the ``perf_counter`` start."""
    return DegeneracyResult(
        method=method,
        pose=np.asarray(pose, dtype=float),
        basis_scaled=np.zeros((0, 6)),
        characteristic_length=length,
        runtime_s=time.perf_counter() - started,
        ok=False,
        reason=reason,
        details=dict(details),
    )
