"""``lili_odom.evaluation.metrics``: errors in the reference's own body frame after the ATE's
SE(3) alignment, and the distance-indexed error, on hand-built trajectories."""
from __future__ import annotations

import numpy as np

from lili_odom.evaluation.metrics import body_frame_errors, error_along_path


def _arc(n: int, radius: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and poses of a robot driving a quarter circle to the left (yaw = heading)."""
    yaw = np.linspace(0.0, np.pi / 2, n)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 0, 0] = T[:, 1, 1] = np.cos(yaw)
    T[:, 0, 1], T[:, 1, 0] = -np.sin(yaw), np.sin(yaw)
    T[:, 0, 3], T[:, 1, 3] = radius * np.sin(yaw), radius * (1.0 - np.cos(yaw))
    return np.arange(n, dtype=float), T


def test_an_alternating_sideways_error_is_lateral_in_the_body_frame():
    stamps, truth = _arc(40)
    sign = np.where(np.arange(40) % 2 == 0, 1.0, -1.0)
    est = truth.copy()
    est[:, :3, 3] += 0.1 * sign[:, None] * truth[:, :3, 1]  # along each pose's own left axis
    err = body_frame_errors(stamps, est, stamps, truth)
    assert err.shape == (40, 3)
    np.testing.assert_allclose(err[:, 1], 0.1 * sign, atol=0.01)  # lateral, with its sign
    np.testing.assert_allclose(err[:, [0, 2]], 0.0, atol=0.01)  # not forward, not up
    # the same run, seen by the distance-indexed error: 0.1 m everywhere
    dist, norm = error_along_path(stamps, est, stamps, truth)
    assert abs(dist[-1] - np.pi / 2 * 20.0) < 0.2  # chords of the quarter circle
    np.testing.assert_allclose(norm, 0.1, atol=0.01)


def test_a_rigid_offset_is_aligned_away():
    stamps, truth = _arc(20)
    est = truth.copy()
    est[:, :3, 3] += [2.0, -1.0, 0.5]
    np.testing.assert_allclose(body_frame_errors(stamps, est, stamps, truth), 0.0, atol=1e-9)
