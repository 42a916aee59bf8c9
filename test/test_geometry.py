"""Lie group helpers: round trips, twist order and frame conventions against gtsam."""
import gtsam
import numpy as np
import pytest

from lili_odom import geometry as g


def test_exp_log_round_trip():
    rng = np.random.default_rng(1)
    for _ in range(50):
        xi = rng.normal(size=6) * [1, 1, 1, 0.5, 0.5, 0.5]
        assert np.allclose(g.log(g.exp(xi)), xi, atol=1e-9)


def test_twist_order_is_translation_first():
    T = g.exp([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    assert np.allclose(T[:3, 3], [1, 2, 3]) and np.allclose(T[:3, :3], np.eye(3))
    T = g.exp([0.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2])
    assert np.allclose(T[:3, :3] @ [1, 0, 0], [0, 1, 0])
    # gtsam orders (w, v): the conversion is the only place that knows
    assert np.allclose(gtsam.Pose3.Expmap(g.to_gtsam_order([1, 2, 3, 0, 0, 0])).translation(), [1, 2, 3])


def test_body_frame_perturbation_and_adjoint():
    rng = np.random.default_rng(2)
    P = g.exp(rng.normal(size=6))
    xi = rng.normal(size=6) * 0.1
    # a body-frame motion P exp(xi) equals the world-frame motion exp(Ad_P xi) P
    assert np.allclose(P @ g.exp(xi), g.exp(g.adjoint(P) @ xi) @ P, atol=1e-9)


def test_orthonormalize_repairs_and_rejects():
    T = g.exp([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    noisy = T.copy()
    noisy[:3, :3] += 1e-7
    fixed = g.orthonormalize(noisy)
    assert g.is_valid_pose(fixed, tol=1e-12)
    assert np.allclose(fixed, T, atol=1e-6)
    bad = T.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError):
        g.orthonormalize(bad)
    with pytest.raises(ValueError):
        g.orthonormalize(np.zeros((4, 4)))


def test_orthonormalize_keeps_rotations_and_repairs_the_rest():
    T = g.exp([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    T[3] = [0.0, 0.0, 1e-9, 1.0]  # a sloppy last row is always made exact
    kept = g.orthonormalize(T)
    assert np.array_equal(kept[:3], T[:3]) and np.array_equal(kept[3], [0, 0, 0, 1])
    assert kept is not T
    off = T.copy()
    off[:3, :3] *= 1.0 + 1e-11  # too far off for Sophus: projected
    fixed = g.orthonormalize(off)
    R = fixed[:3, :3]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-14
    mirrored = T.copy()
    mirrored[:3, 0] *= -1.0  # orthonormal, but a reflection
    R = g.orthonormalize(mirrored)[:3, :3]
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_det3_matches_numpy():
    rng = np.random.default_rng(0)
    for _ in range(20):
        M = rng.normal(size=(3, 3))
        assert g._det3(M) == pytest.approx(np.linalg.det(M), rel=1e-12, abs=1e-12)


def test_scaling_round_trip():
    xi = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    s = g.scale_twist(xi, 10.0)
    assert np.allclose(s, [1, 2, 3, 1, 2, 3])
    assert np.allclose(g.unscale_twist(s, 10.0), xi)
    assert np.allclose(g.scaling_matrix(10.0) @ xi, s)


def test_nonfinite_rows_marks_exactly_the_bad_rows():
    points = np.arange(30, dtype=float).reshape(10, 3)
    assert g.nonfinite_rows(points) is None
    points[2, 1], points[7, 0], points[7, 2], points[9, 2] = np.nan, np.inf, -np.inf, np.nan
    np.testing.assert_array_equal(np.flatnonzero(g.nonfinite_rows(points)), [2, 7, 9])
    assert g.nonfinite_rows(np.empty((0, 3))) is None
    np.testing.assert_array_equal(g.drop_nonfinite_rows(points), points[[0, 1, 3, 4, 5, 6, 8]])
