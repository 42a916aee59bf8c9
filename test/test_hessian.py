"""Hessian-based detectors (zhang, hessian), their pure functions and solution remapping."""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom.degeneracy.factory import reference_for_detection
from lili_odom.degeneracy.hessian import (
    HESSIAN_THRESHOLD,
    HessianConfig,
    HessianDetector,
    ZhangConfig,
    ZhangDetector,
    euler_rate_matrix,
    euler_zyx,
    lio_sam_directions_to_body_twists,
    lio_sam_jacobian,
    point_to_plane_hessian,
    point_to_plane_jacobian,
    remap_update,
    remapping_matrix_from_basis,
    solution_remapping_matrix,
)
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.geometry import adjoint, exp, scale_twist, transform_points

G = exp(np.array([1.3, -0.7, 0.45, 0.42, -0.57, 0.81]))  # generic placement of every test scene


def _grid(half_u: float, half_v: float, step: float, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    u = np.arange(-half_u + offset, half_u + 1e-9, step)
    v = np.arange(-half_v + offset, half_v + 1e-9, step)
    U, V = np.meshgrid(u, v)
    return U.ravel(), V.ravel()


def plane(half: float = 2.0, step: float = 0.05, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Points of z = 0 and their normals (shape frame)."""
    u, v = _grid(half, half, step, offset)
    pts = np.c_[u, v, np.zeros_like(u)]
    return pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1))


def box_room(half: float = 1.5, step: float = 0.1, offset: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The six inner faces of a cube (shape frame), each face's open interior only."""
    u, v = _grid(half - step, half - step, step, offset)
    h = np.full_like(u, half)
    pts, nrm = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            cols = [u, v]
            cols.insert(axis, sign * h)
            pts.append(np.column_stack(cols))
            n = np.zeros((len(u), 3))
            n[:, axis] = 1.0
            nrm.append(n)
    return np.vstack(pts), np.vstack(nrm)


def corridor(step: float = 0.05) -> np.ndarray:
    """Floor and two walls along x (free: translation along x). Shape frame."""
    x, y = _grid(3.0, 1.0, step)
    x2, z = _grid(3.0, 0.75, step)
    return np.vstack([
        np.c_[x, y, np.zeros_like(x)],
        np.c_[x2, np.full_like(x2, -1.0), z + 0.75],
        np.c_[x2, np.full_like(x2, 1.0), z + 0.75],
    ])


def world(points: np.ndarray, normals: np.ndarray | None = None):
    p = transform_points(G, points)
    return p if normals is None else (p, normals @ G[:3, :3].T)


def projector(rows: np.ndarray) -> np.ndarray:
    q, _ = np.linalg.qr(np.asarray(rows, dtype=float).T)
    return q @ q.T


# ------------------------------------------------------------------------------- pure functions


def test_jacobians_match_finite_differences():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(7, 3)) * 3.0
    n = rng.normal(size=(7, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    q = rng.normal(size=(7, 3))
    T = exp(rng.normal(size=6))
    L, e = 2.5, 1e-6

    def r(P):
        return np.einsum("ij,ij->i", transform_points(P, p) - q, n)

    Jb = point_to_plane_jacobian(transform_points(T, p), n, pose=T, length=L)
    Jw = point_to_plane_jacobian(transform_points(T, p), n)
    for k in range(6):
        xi = np.zeros(6)
        xi[k] = e / (L if k >= 3 else 1.0)  # scaled unit step
        np.testing.assert_allclose((r(T @ exp(xi)) - r(T @ exp(-xi))) / (2 * e), Jb[:, k], atol=1e-6)
        xi = np.zeros(6)
        xi[k] = e
        np.testing.assert_allclose((r(exp(xi) @ T) - r(exp(-xi) @ T)) / (2 * e), Jw[:, k], atol=1e-6)

    # LIO-SAM's (roll, pitch, yaw, tx, ty, tz) parameterisation and its map to body twists.
    rpy = euler_zyx(T[:3, :3])

    def pose(par):
        c, s = np.cos(par[:3]), np.sin(par[:3])
        Rx = np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
        Ry = np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]])
        Rz = np.array([[c[2], -s[2], 0], [s[2], c[2], 0], [0, 0, 1]])
        P = np.eye(4)
        P[:3, :3] = Rz @ Ry @ Rx
        P[:3, 3] = par[3:]
        return P

    par = np.r_[rpy, T[:3, 3]]
    np.testing.assert_allclose(pose(par), T, atol=1e-12)
    Jl = lio_sam_jacobian(p, n, T)
    twists = lio_sam_directions_to_body_twists(np.eye(6), T, T)
    for k in range(6):
        d = np.zeros(6)
        d[k] = e
        np.testing.assert_allclose((r(pose(par + d)) - r(pose(par - d))) / (2 * e), Jl[:, k], atol=1e-6)
        np.testing.assert_allclose(pose(par + d), T @ exp(e * twists[k]), atol=1e-10)
    assert np.linalg.matrix_rank(euler_rate_matrix(rpy)) == 3


def test_plane_has_exactly_the_three_in_plane_directions():
    pts, nrm = plane()
    x, n = world(pts, nrm)
    T_S_C = exp(np.array([0.2, -0.3, 1.5, 0.3, -0.2, 0.4]))  # sensor above the plane
    T = G @ T_S_C
    L = 1.7
    H = point_to_plane_hessian(x, n, pose=T, length=L, normalize=True)
    w, V = np.linalg.eigh(H)
    assert np.all(w[:3] < 1e-12) and np.all(w[3:] > 0.05)
    # shape-frame generators vx, vy, wz -> body twists Ad(T^-1 G) xi, scaled
    gens = np.eye(6)[[0, 1, 5]]
    expected = scale_twist((adjoint(np.linalg.inv(T_S_C)) @ gens.T).T, L)
    np.testing.assert_allclose(projector(V[:, :3].T), projector(expected), atol=1e-9)
    assert np.trace(H[:3, :3]) == pytest.approx(1.0)  # unit normals, per correspondence


def test_box_room_has_no_degenerate_direction():
    pts, nrm = box_room()
    x, n = world(pts, nrm)
    T = G @ exp(np.array([0.3, -0.2, 0.1, 0.3, -0.35, 0.5]))
    w = np.linalg.eigvalsh(point_to_plane_hessian(x, n, pose=T, length=1.5, normalize=True))
    assert w.min() > 0.05 > HESSIAN_THRESHOLD


def test_body_frame_hessian_is_invariant_to_a_rigid_transform_of_the_problem():
    pts, nrm = box_room()
    T = exp(np.array([0.3, -0.2, 0.1, 0.3, -0.35, 0.5]))
    H0 = point_to_plane_hessian(transform_points(T, pts), nrm, pose=T, length=1.5)
    x, n = world(transform_points(T, pts), nrm)
    H1 = point_to_plane_hessian(x, n, pose=G @ T, length=1.5)
    np.testing.assert_allclose(H1, H0, rtol=1e-9, atol=1e-6)
    # the world-frame (reference origin) Hessian is not invariant; the adjoint links the two
    Hw = point_to_plane_hessian(x, n)
    Ad = adjoint(G @ T)
    np.testing.assert_allclose(Ad.T @ Hw @ Ad, point_to_plane_hessian(x, n, pose=G @ T), atol=1e-6)


def test_solution_remapping_zeroes_degenerate_directions_and_keeps_the_rest():
    rng = np.random.default_rng(3)
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    eig = np.array([900.0, 500.0, 300.0, 120.0, 40.0, 1.0])
    H = Q @ np.diag(eig) @ Q.T
    P, w, V, degenerate = solution_remapping_matrix(H, 100.0)
    np.testing.assert_allclose(w, eig, rtol=1e-10)
    assert degenerate.tolist() == [False, False, False, False, True, True]
    V2 = V.copy()
    V2[degenerate] = 0.0
    np.testing.assert_allclose(P, np.linalg.inv(V) @ V2, atol=1e-12)  # LIO-SAM's matP
    np.testing.assert_allclose(P @ P, P, atol=1e-12)
    for i in range(6):
        out = remap_update(V[i], P)
        np.testing.assert_allclose(out, 0.0 if degenerate[i] else V[i], atol=1e-12)
    deltas = rng.normal(size=(5, 6))
    np.testing.assert_allclose(remap_update(deltas, P), deltas @ P.T)

    # the same from a detector's scaled basis, acting on plain (v, w) body twists
    L = 2.0
    B = np.array([[1.0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 1.0]])  # vx and (scaled) wz
    M = remapping_matrix_from_basis(B, L)
    np.testing.assert_allclose(M @ [0.3, 0, 0, 0, 0, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(M @ [0, 0, 0, 0, 0, 0.2], 0.0, atol=1e-12)
    keep = np.array([0, 0.4, -0.1, 0.05, 0.02, 0])
    np.testing.assert_allclose(M @ keep, keep, atol=1e-12)


# ------------------------------------------------------------------------------------ detectors


@pytest.fixture(scope="module")
def plane_case():
    ref, _ = plane(offset=0.0)
    scan_s, _ = plane(half=1.2, offset=0.025)  # an independent sampling under the sensor
    T_S_C = exp(np.array([0.2, -0.3, 1.5, 0.3, -0.2, 0.4]))
    scan = transform_points(np.linalg.inv(T_S_C), scan_s)
    return reference_for_detection(world(ref)), scan, G @ T_S_C, T_S_C


@pytest.mark.parametrize("detector", [ZhangDetector(), HessianDetector()], ids=lambda d: d.name)
def test_detectors_find_the_plane_subspace_in_the_body_frame(detector, plane_case):
    reference, scan, true_pose, T_S_C = plane_case
    guess = true_pose @ exp(np.array([0.02, -0.01, 0.03, 0.01, -0.008, 0.01]))
    res = detector.detect(reference, scan, guess)
    assert res.ok and res.method == detector.name
    assert res.dimension == 3
    assert np.all(np.diff(res.eigenvalues) <= 1e-12)  # largest first
    assert res.details["n_correspondences"] > 1000
    np.testing.assert_allclose(res.basis_scaled @ res.basis_scaled.T, np.eye(3), atol=1e-9)
    gens = np.eye(6)[[0, 1, 5]]
    expected = scale_twist((adjoint(np.linalg.inv(T_S_C)) @ gens.T).T, res.characteristic_length)
    # zhang linearises at the guess (1 deg off): its subspace is tilted by about that much
    tol = 0.05 if detector.name == "zhang" else 1e-3
    assert np.abs(projector(res.basis_scaled) - projector(expected)).max() < tol
    # P_opt is KISS-ICP's: normal offset and tilt removed
    rel = np.linalg.inv(true_pose) @ res.pose
    n_body = np.linalg.inv(T_S_C)[:3, 2]
    assert abs(n_body @ rel[:3, 3]) < 5e-3


def test_hessian_detector_is_invariant_to_a_rigid_transform_of_the_problem():
    ref = corridor()
    T_S_C = exp(np.array([0.1, 0.2, 0.6, 0.1, -0.05, 0.3]))
    scan = transform_points(np.linalg.inv(T_S_C), ref[np.linalg.norm(ref - T_S_C[:3, 3], axis=1) < 1.8])
    guess = exp(np.array([0.02, -0.01, 0.01, 0.005, -0.005, 0.008]))
    det = HessianDetector()
    a = det.detect(reference_for_detection(ref), scan, T_S_C @ guess)
    b = det.detect(reference_for_detection(world(ref)), scan, G @ T_S_C @ guess)
    assert a.ok and b.ok and a.dimension == b.dimension == 1
    np.testing.assert_allclose(a.eigenvalues, b.eigenvalues, rtol=0.02, atol=1e-4)
    assert np.abs(projector(a.basis_scaled) - projector(b.basis_scaled)).max() < 1e-2
    # the free direction is the translation along the corridor axis (x of the shape frame),
    # seen from the body frame at P_opt
    expected = (adjoint(np.linalg.inv(a.pose)) @ np.eye(6)[0])[None]
    assert np.abs(projector(a.basis_scaled) - projector(expected)).max() < 5e-3


def test_zhang_absolute_threshold_depends_on_point_count_and_scale():
    """Fully constrained cube rooms. Zhang's raw eigenvalues (absolute bound 100) flag the small or
    sparsely sampled rooms as degenerate in rotation (few points, short lever arms) and pass the
    same room sampled more densely; the normalised test finds no degeneracy in any of them."""
    T_S_C = exp(np.array([0.05, -0.04, 0.03, 0.3, -0.35, 0.5]))
    out = {}
    for half, step in ((0.5, 0.1), (1.0, 0.1), (1.0, 0.05)):
        ref, _ = box_room(half=half, step=step)
        scan_s, _ = box_room(half=half, step=step, offset=step / 2)
        scan = transform_points(np.linalg.inv(T_S_C), scan_s)
        reference = reference_for_detection(world(ref))
        guess = G @ T_S_C @ exp(np.array([0.005, -0.004, 0.003, 0.004, 0.003, -0.004]))
        z = ZhangDetector().detect(reference, scan, guess)
        h = HessianDetector().detect(reference, scan, guess)
        assert z.ok and h.ok
        out[half, step] = (z, h, z.details["n_correspondences"])
    (z_tiny, h_tiny, n_tiny) = out[0.5, 0.1]
    (z_sparse, h_sparse, n_sparse) = out[1.0, 0.1]
    (z_dense, h_dense, n_dense) = out[1.0, 0.05]
    assert n_tiny < 500 and n_dense > 4 * n_sparse
    assert z_tiny.dimension >= 1 and z_tiny.eigenvalues[-1] < 100.0
    assert z_sparse.dimension >= 1  # same room as z_dense, a quarter of the points
    assert z_dense.dimension == 0
    assert h_tiny.dimension == h_sparse.dimension == h_dense.dimension == 0
    # raw eigenvalues grow with the number of correspondences, normalised ones do not
    assert z_dense.eigenvalues[-1] / z_sparse.eigenvalues[-1] > 3.0
    assert h_dense.eigenvalues[-1] / h_sparse.eigenvalues[-1] == pytest.approx(1.0, rel=0.3)


@pytest.mark.parametrize("detector", [ZhangDetector(), HessianDetector()], ids=lambda d: d.name)
def test_detectors_fail_cleanly(detector, plane_case):
    reference, scan, true_pose, _ = plane_case
    empty = ReferenceMap.from_points(np.zeros((0, 3)), voxel_size=0.5)
    res = detector.detect(empty, scan, true_pose)
    assert not res.ok and res.dimension == 0 and res.reason

    far = true_pose.copy()
    far[:3, 3] += 100.0  # nothing within reach
    res = detector.detect(reference, scan, far)
    assert not res.ok and res.dimension == 0 and res.reason

    res = detector.detect(reference, np.full((50, 3), np.nan), true_pose)
    assert not res.ok and res.reason

    res = detector.detect(reference, scan[:5], true_pose)
    assert not res.ok

    bad_pose = np.full((4, 4), np.nan)
    res = detector.detect(reference, scan, bad_pose)  # must not reach native code with NaNs
    assert not res.ok and "pose" in res.reason
    res = detector.detect(reference, scan, true_pose, optimized_pose=bad_pose)
    assert not res.ok


def test_non_finite_points_are_dropped(plane_case):
    reference, scan, true_pose, _ = plane_case
    dirty = scan.copy()
    dirty[::7] = np.nan
    dirty[1::11] = np.inf
    clean = dirty[np.all(np.isfinite(dirty), axis=1)]
    for det in (ZhangDetector(), HessianDetector()):
        a = det.detect(reference, dirty, true_pose)
        b = det.detect(reference, clean, true_pose)
        assert a.ok and b.ok and a.dimension == b.dimension == 3
        np.testing.assert_allclose(a.eigenvalues, b.eigenvalues, rtol=1e-9, atol=1e-9)


def test_configs_have_documented_defaults():
    z, h = ZhangConfig(), HessianConfig()
    assert z.eigenvalue_threshold == 100.0 and z.num_neighbors == 5
    assert z.max_neighbor_distance == 1.0 and z.max_plane_deviation == 0.2
    assert h.threshold == HESSIAN_THRESHOLD
    assert ZhangDetector().name == "zhang" and HessianDetector().name == "hessian"
