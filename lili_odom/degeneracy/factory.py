"""Build detectors by name, and a reference map sized for detection from raw points."""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from lili_odom.degeneracy.reference import ReferenceMap

METHODS = ("lili", "zhang", "hessian")

# Voxel edge in units of the raw reference spacing. KISS-ICP searches the 27 neighbouring voxels
# only, so one voxel must exceed LiLi's perturbation ((k - 1) spacings at the median range) plus
# the rotational lever arm of the farther points (about twice that): 10 spacings for k = 5.
VOXEL_IN_SPACINGS = 10.0


def raw_spacing(points: np.ndarray, sample: int = 4000, seed: int = 0) -> float:
    """Median nearest-neighbour distance [m] of (a random sample of) ``points``."""
    points = np.asarray(points, dtype=float)
    if len(points) < 2:
        return float("nan")
    rng = np.random.default_rng(seed)
    probe = points[rng.choice(len(points), size=min(sample, len(points)), replace=False)]
    d, _ = cKDTree(points).query(probe, k=2, workers=-1)
    return float(np.median(d[:, 1]))


def reference_for_detection(
    points: np.ndarray, voxel_size: float | None = None, max_points_per_voxel: int | None = None
) -> ReferenceMap:
    """A ``ReferenceMap`` whose voxel size and capacity keep the reference's full density.

    Defaults: ``voxel = VOXEL_IN_SPACINGS * s_raw`` and room for twice the points a surface
    crossing the voxel holds at that spacing (KISS-ICP thins a voxel to its capacity).
    """
    if voxel_size is None:
        s = raw_spacing(points)
        if not (np.isfinite(s) and s > 0):
            raise ValueError("reference cloud too small or degenerate to size a voxel map")
        voxel_size = VOXEL_IN_SPACINGS * s
        if max_points_per_voxel is None:
            max_points_per_voxel = int(math.ceil(2.0 * VOXEL_IN_SPACINGS**2))
    return ReferenceMap.from_points(points, voxel_size, max_points_per_voxel or 200)


def make_detector(method: str):
    """Detector object with ``.name`` and ``.detect(reference, scan, initial_pose)``."""
    if method == "lili":
        from lili_odom.degeneracy.lili import LiliDetector

        return LiliDetector()
    if method == "zhang":
        from lili_odom.degeneracy.hessian import ZhangDetector

        return ZhangDetector()
    if method == "hessian":
        from lili_odom.degeneracy.hessian import HessianDetector

        return HessianDetector()
    raise ValueError(f"unknown method '{method}', choose one of {', '.join(METHODS)}")
