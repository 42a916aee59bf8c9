"""Registration settings shared by all detectors (the f_opt of the paper).

All detectors align with the same KISS-ICP point-to-point ICP against the same voxel map, so
their poses are comparable and LiLi's perturbed re-registrations use exactly the odometry's
matcher. Lengths in metres.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lili_odom.geometry import drop_nonfinite_rows


@dataclass
class RegistrationConfig:
    """KISS-ICP alignment parameters.

    Attributes:
        max_iterations: ICP iteration cap per alignment.
        convergence: KISS-ICP convergence criterion (norm of the last update, m / rad).
        max_correspondence_distance: correspondence gate [m]; 0 -> the map's voxel size
            (KISS-ICP searches the 27 neighbouring voxels only, so a larger gate has no effect).
        kernel: Geman-McClure kernel scale on the *squared* residual; 0 ->
            ``max_correspondence_distance / 3`` (KISS-ICP's own ratio of gate to kernel).
        max_threads: TBB threads for the native code, 0 = all (set once per process).
    """

    max_iterations: int = 500
    convergence: float = 1e-4
    max_correspondence_distance: float = 0.0
    kernel: float = 0.0
    max_threads: int = 0

    def gate(self, voxel_size: float) -> float:
        d = self.max_correspondence_distance
        return float(voxel_size if not d or d <= 0 else d)

    def kernel_for(self, voxel_size: float) -> float:
        return float(self.gate(voxel_size) / 3.0 if not self.kernel or self.kernel <= 0 else self.kernel)

    def __post_init__(self) -> None:
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if not (np.isfinite(self.convergence) and self.convergence > 0):
            raise ValueError(f"convergence must be > 0, got {self.convergence}")


def characteristic_length(scan: np.ndarray) -> float:
    """Median range [m] of scan points from the sensor origin (the L of the scaled twist space)."""
    r = np.linalg.norm(np.asarray(scan, dtype=float).reshape(-1, 3), axis=1)
    r = r[np.isfinite(r)]
    return float(np.median(r)) if len(r) else float("nan")


def finite_points(scan: np.ndarray) -> np.ndarray:
    """(N, 3) float64 copy of ``scan`` without non-finite rows."""
    return drop_nonfinite_rows(np.array(scan, dtype=np.float64).reshape(-1, 3))


def usable_length(scan: np.ndarray) -> float:
    """``characteristic_length`` or 1 m when it is undefined (empty or all-zero scan)."""
    L = characteristic_length(scan)
    return L if np.isfinite(L) and L > 1e-9 else 1.0
