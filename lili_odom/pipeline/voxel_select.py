"""Choose one point per voxel before deskewing, so that only the points kept are deskewed.

The odometry keeps one point per ``0.5 voxel`` cell of a sweep (the map points).
:func:`first_in_voxel` picks the first point of each cell of the *raw* sweep (KISS-ICP's
rule, first point in input order), so the deskew runs on the points kept only
(:meth:`lili_odom.pipeline.scan_matcher.ScanMatcher.preprocess`), instead of on the whole
sweep before voxelising it as KISS-ICP's pipeline does. The cells are those of the raw
positions: each kept point is deskewed exactly, but which point of a cell is kept, and how
many cells there are, follow the raw sweep. Cost and effect: ``docs/performance.md``.

Points (N, 3) in any frame [m]; ``voxel`` [m].
"""
from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["first_in_voxel"]

#: bits per axis of a packed cell index (cells within +-2**20 of the origin are packed exactly)
_BITS = 21
_HALF = 1 << (_BITS - 1)
#: 2**64 / golden ratio, odd: multiplying by it mod 2**64 scatters neighbouring keys
_GOLDEN = 0x9E3779B97F4A7C15


def first_in_voxel(points: np.ndarray, voxel: float) -> np.ndarray | None:
    """Indices of the first point of each ``voxel``-sized cell of ``points``.

    Cells are ``floor(p / voxel)``. The indices come in an order set by a hash of their cells,
    unrelated to the input order, as KISS-ICP's ``voxel_down_sample`` returns its points (from
    its hash map): a later voxelisation that keeps the first point of a coarser cell then
    keeps an arbitrary one, not always the one from the sweep's first rows.

    Returns None (no choice made) for a voxel that is not a positive finite number and for
    points more than 2**20 voxels from the origin (about 500 km at 0.5 m) or not finite,
    whose cells are not packed exactly.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not (np.isfinite(voxel) and voxel > 0):
        return None
    with np.errstate(invalid="ignore", over="ignore"):
        cells = np.floor(points / voxel)  # as KISS-ICP divides (not by the reciprocal)
        if not np.all(np.abs(cells) < _HALF):  # False for NaN too
            return None
    c = cells.astype(np.int64) + _HALF
    key = (c[:, 0] << (2 * _BITS)) | (c[:, 1] << _BITS) | c[:, 2]
    # hash-based first occurrence (pandas), linear in the points
    first = np.flatnonzero(~pd.Series(key, copy=False).duplicated(keep="first").to_numpy())
    # Fibonacci hashing of the cell keys (wrapping uint64 product) sets the order; the keys
    # are distinct and the product by an odd number is a bijection mod 2**64, so the scrambled
    # keys are distinct too and any sort gives the same order (quicksort: the fastest)
    scrambled = key[first].astype(np.uint64) * np.uint64(_GOLDEN)
    return first[np.argsort(scrambled)]
