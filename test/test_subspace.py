"""Subspace metrics (principal angles, projectors) and the quality measure Q."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from lili_odom.degeneracy.quality import QUALITY_RANGE, coefficient_grid, extended_scan, quality
from lili_odom.degeneracy.subspace import (
    largest_principal_angle_deg,
    orthonormal_rows,
    principal_angles_deg,
    projector,
    truth_scaled,
)
from lili_odom.geometry import exp, scale_twist, transform_points
from lili_odom.sim.shapes import SCENARIOS, make_case

E = np.eye(6)


def test_orthonormal_rows_drops_dependent_rows():
    B = np.array([[1.0, 1, 0, 0, 0, 0], [2, 2, 0, 0, 0, 0], [0, 0, 3, 0, 0, 0]])
    Q = orthonormal_rows(B)
    assert Q.shape == (2, 6)
    np.testing.assert_allclose(Q @ Q.T, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(projector(Q) @ B.T, B.T, atol=1e-12)
    assert orthonormal_rows(np.zeros((0, 6))).shape == (0, 6)
    assert orthonormal_rows(np.zeros((2, 6))).shape == (0, 6)


def test_projector_properties():
    P = projector(E[[0, 4]] + 0.3 * E[[2, 5]])
    np.testing.assert_allclose(P @ P, P, atol=1e-12)
    np.testing.assert_allclose(P, P.T, atol=1e-12)
    assert np.trace(P) == pytest.approx(2.0)
    np.testing.assert_array_equal(projector(np.zeros((0, 6))), np.zeros((6, 6)))


def test_principal_angles_known_cases():
    A = E[[0, 1]]
    same_space = np.array([[1.0, 1, 0, 0, 0, 0], [3, -1, 0, 0, 0, 0]])
    np.testing.assert_allclose(principal_angles_deg(A, same_space), [0, 0], atol=1e-9)
    np.testing.assert_allclose(principal_angles_deg(A, E[[2, 3]]), [90, 90], atol=1e-9)
    for theta in (1e-4, 0.5, 17.0, 60.0, 89.0):
        t = np.radians(theta)
        B = np.array([E[0], np.cos(t) * E[1] + np.sin(t) * E[5]])
        np.testing.assert_allclose(principal_angles_deg(A, B), [0.0, theta], atol=1e-9)
        assert largest_principal_angle_deg(A, B) == pytest.approx(theta, abs=1e-9)
    # different dimensions: min(kA, kB) angles from principal_angles_deg
    np.testing.assert_allclose(principal_angles_deg(A, E[[1]]), [0.0], atol=1e-12)


def test_largest_angle_conventions():
    empty = np.zeros((0, 6))
    assert largest_principal_angle_deg(empty, empty) == 0.0
    assert largest_principal_angle_deg(empty, E[[0]]) == 90.0
    assert largest_principal_angle_deg(E[[0, 1]], E[[0]]) == 90.0  # dimensions differ
    assert principal_angles_deg(empty, E[[0]]).shape == (0,)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 5))
def test_angles_invariant_to_basis_change(seed, k):
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(k, 6)), rng.normal(size=(k, 6))
    mix = rng.normal(size=(k, k)) + 3 * np.eye(k)
    np.testing.assert_allclose(principal_angles_deg(A, B), principal_angles_deg(mix @ A, B), atol=1e-6)
    np.testing.assert_allclose(principal_angles_deg(A, B), principal_angles_deg(B, A), atol=1e-6)
    assert largest_principal_angle_deg(A, mix @ A) < 1e-5


def test_truth_scaled():
    L = 2.5
    plain = np.array([[0.0, 0, 1, 0, 0, 0], [0.3, -0.2, 0, 0, 0, 1]])
    T = truth_scaled(plain, L)
    np.testing.assert_allclose(T @ T.T, np.eye(2), atol=1e-12)
    assert largest_principal_angle_deg(T, scale_twist(plain, L)) < 1e-9
    assert truth_scaled(np.zeros((0, 6)), L).shape == (0, 6)


def test_coefficient_grid():
    assert [len(coefficient_grid(k)) for k in range(4)] == [1, 5, 13, 33]
    g = coefficient_grid(3)
    assert np.linalg.norm(g, axis=1).max() == pytest.approx(QUALITY_RANGE)
    assert np.any(np.all(g == 0, axis=1))


@lru_cache(maxsize=None)
def _case(name):
    return make_case(name, False, 0)


@pytest.mark.parametrize("name", [n for n in SCENARIOS if n != "box_room"])
def test_quality_true_basis_beats_wrong_basis(name):
    c = _case(name)
    L = c.characteristic_length
    ref = cKDTree(c.reference)
    true_s = c.true_basis_scaled
    q_true = quality(c.scan, ref, c.true_pose, true_s, L)
    assert q_true < 0.035
    # a wrong subspace of the same dimension: the orthogonal complement's first directions
    wrong = orthonormal_rows(np.eye(6) - projector(true_s))[: len(true_s)]
    assert quality(c.scan, ref, c.true_pose, wrong, L) > 2.5 * q_true
    # the truth tilted by 30 degrees towards constrained directions (largest angle 30 deg)
    t = np.radians(30.0)
    tilted = np.cos(t) * true_s + np.sin(t) * wrong
    assert largest_principal_angle_deg(tilted, true_s) == pytest.approx(30.0)
    assert quality(c.scan, ref, c.true_pose, tilted, L) > 2.0 * q_true
    # Q is blind to a missed direction (as in the paper): dropping one keeps Q small
    assert quality(c.scan, ref, c.true_pose, true_s[1:], L) < 1.1 * q_true


def test_quality_empty_basis_is_alignment_residual():
    c = _case("box_room")
    L = c.characteristic_length
    residual = np.median(cKDTree(c.reference).query(transform_points(c.true_pose, c.scan))[0])
    assert quality(c.scan, c.reference, c.true_pose, np.zeros((0, 6)), L) == pytest.approx(residual)
    # a spurious degenerate direction in a constrained room is penalised
    assert quality(c.scan, c.reference, c.true_pose, E[[0]], L) > 3 * residual
    # a misaligned pose is penalised even with an empty basis
    off = c.true_pose @ exp(np.array([0.2, 0, 0, 0, 0, 0]))
    assert quality(c.scan, c.reference, off, np.zeros((0, 6)), L) > 3 * residual


def test_extended_scan_size_and_inputs():
    c = _case("plane")
    L = c.characteristic_length
    ext = extended_scan(c.scan, c.true_pose, c.true_basis_scaled, L)
    assert ext.shape == (33 * len(c.scan), 3)
    # unnormalised rows are normalised; the KD-tree and point inputs agree
    q1 = quality(c.scan, c.reference, c.true_pose, 3.0 * c.true_basis_scaled, L)
    q2 = quality(c.scan, cKDTree(c.reference), c.true_pose, c.true_basis_scaled, L)
    assert q1 == pytest.approx(q2)
    capped = extended_scan(c.scan, c.true_pose, c.true_basis_scaled, L, max_points=10_000)
    assert len(capped) <= 10_000 + 33
    with pytest.raises(ValueError):
        quality(c.scan, c.reference, c.true_pose, c.true_basis_scaled, 0.0)
