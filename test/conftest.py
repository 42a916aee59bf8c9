"""Shared test fixtures: small synthetic clouds that run in well under a second each."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import special_ortho_group


@pytest.fixture
def generic_rotation() -> np.ndarray:
    """A fixed rotation with no axis aligned to x, y or z."""
    return special_ortho_group.rvs(3, random_state=3)


def plane_pair(seed: int = 0, rotation: np.ndarray | None = None):
    """(reference Nx3, scan Mx3 in its sensor frame, true pose) for a plane seen from 1 m above.

    The plane is z = 0 in a frame rotated by ``rotation``; the sensor sits 1 m above the plane
    with an identity orientation relative to the plane frame.
    """
    rng = np.random.default_rng(seed)
    R = np.eye(3) if rotation is None else rotation
    ref = np.c_[rng.uniform(-5, 5, (30000, 2)), np.zeros(30000)]
    scan_plane = np.c_[rng.uniform(-2, 2, (4000, 2)), np.zeros(4000)]
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = R @ np.array([0.0, 0.0, 1.0])
    scan = scan_plane - [0.0, 0.0, 1.0]
    return ref @ R.T, scan, T


def closed_room(seed: int = 0, per_face: int = 1500,
                half: tuple[float, float, float] = (6.0, 5.0, 3.0)) -> np.ndarray:
    """Points on the six faces of a closed room of half-extents ``half`` [m] centred on the
    sensor (every direction constrained); default 12 m x 10 m x 6 m."""
    from lili_odom.fuzz.api import room

    return room(np.random.default_rng(seed), per_face, half)
