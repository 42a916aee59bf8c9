"""LiLi pieces: perturbation sizing, PCA threshold, sparsification, and detection on a plane."""
import numpy as np
import pytest
from scipy.stats import special_ortho_group

from conftest import plane_pair
from lili_odom import geometry as g
from lili_odom.degeneracy.factory import reference_for_detection
from lili_odom.degeneracy.lili import LiliConfig, LiliDetector, pca_subspace, perturbation_twists
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.degeneracy.sparsify import _cost_and_gradient, _rotation, sparsify


def test_perturbation_sizing_moves_median_point_k_minus_1_spacings():
    s, L, k = 0.05, 4.0, 5
    deltas = perturbation_twists(s, L, k, both_signs=True)
    assert deltas.shape == (12, 6)
    assert np.allclose(np.abs(deltas[:3]).max(axis=1), (k - 1) * s)
    # a point at range L, perpendicular to the rotation axis, moves (k - 1) s
    p = np.array([0.0, L, 0.0])
    moved = g.transform_points(g.exp(deltas[3]), p[None])[0]
    assert np.linalg.norm(moved - p) == pytest.approx((k - 1) * s, rel=1e-3)
    assert np.allclose(deltas[6:], -deltas[:6])
    assert perturbation_twists(s, L, k, both_signs=False).shape == (6, 6)


def test_pca_threshold_counts_directions_relative_to_perturbation_size():
    d = 0.2
    rng = np.random.default_rng(0)
    free = np.array([[d, 0, 0, 0, 0, 0], [-d, 0, 0, 0, 0, 0], [0, 0, 0, 0, d, 0], [0, 0, 0, 0, -d, 0]])
    pulled_back = rng.normal(scale=0.01 * d, size=(8, 6))
    w, basis = pca_subspace(np.vstack([free, pulled_back]), 2 * d * d, tau_pca=0.25)
    assert basis.shape == (2, 6)
    assert w[0] == pytest.approx(1.0, abs=0.01) and w[2] < 0.01
    # the same twists in other units (mm) give the same eigenvalues: the threshold is unit-free
    w_mm, _ = pca_subspace(1000 * np.vstack([free, pulled_back]), 2 * (1000 * d) ** 2, 0.25)
    assert np.allclose(w, w_mm)


def test_sparsify_recovers_axis_basis_from_rotated_mix():
    E = np.eye(6)[[0, 1, 5]]  # x, y translation and z rotation: a plane z = const
    R = special_ortho_group.rvs(3, random_state=4)
    mixed = R @ E
    out = sparsify(mixed)
    assert np.allclose(np.abs(out), E, atol=1e-4)
    # same row space
    assert np.allclose(out.T @ out, E.T @ E, atol=1e-6)


def test_sparsify_keeps_coupled_direction_intact():
    u = np.array([[0.6, 0, 0, 0, 0.8, 0]])
    assert np.allclose(sparsify(u), u)


@pytest.mark.parametrize("k", [2, 3, 4])
def test_sparsify_rotation_and_gradient_are_exact(k):
    from scipy.linalg import expm
    from scipy.optimize import approx_fprime

    n = k * (k - 1) // 2
    for theta in (np.random.default_rng(k).uniform(-3, 3, n), np.full(n, 1e-5), np.zeros(n)):
        A = np.zeros((k, k))
        A[np.triu_indices(k, 1)] = theta
        assert np.allclose(_rotation(theta, k), expm(A - A.T), atol=1e-12)
    if k <= 3:
        B = special_ortho_group.rvs(6, random_state=k)[:k]
        fun = _cost_and_gradient(B)
        theta = np.random.default_rng(1).uniform(-3, 3, n)
        numeric = approx_fprime(theta, lambda t: fun(t)[0], 1e-7)
        assert np.allclose(fun(theta)[1], numeric, atol=1e-5)


@pytest.mark.parametrize("k", [2, 3, 4])
def test_sparsify_keeps_the_subspace_and_does_not_raise_l1(k):
    for seed in range(5):
        B = special_ortho_group.rvs(6, random_state=seed)[:k]
        out = sparsify(B)
        assert np.allclose(out @ out.T, np.eye(k), atol=1e-9)
        assert np.allclose(out.T @ out, B.T @ B, atol=1e-9)  # same row space
        assert np.abs(out).sum() <= np.abs(B).sum() + 1e-9


def test_sparsify_two_rows_reaches_the_global_minimum():
    # the l1 norm of a rotated pair of rows is minimal at an angle where a component vanishes;
    # compare with a dense scan of the angle
    B = special_ortho_group.rvs(6, random_state=7)[:2]
    t = np.linspace(0, np.pi / 2, 200001)
    c, s = np.cos(t)[:, None], np.sin(t)[:, None]
    dense = (np.abs(c * B[0] + s * B[1]).sum(1) + np.abs(c * B[1] - s * B[0]).sum(1)).min()
    assert np.abs(sparsify(B)).sum() == pytest.approx(dense, abs=1e-6)


def test_reference_spacing_from_probes_matches_all_points():
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-20, 20, (30000, 2)), rng.normal(0, 0.01, 30000)]
    rm = ReferenceMap.from_points(pts, 1.0, 200)
    full = np.median(cKDTree(rm.points).query(rm.points, k=2)[0][:, 1])
    assert rm.spacing == pytest.approx(full, rel=0.02)
    rm.invalidate()
    assert "spacing" not in rm.__dict__ and rm.spacing == pytest.approx(full, rel=0.02)


@pytest.mark.parametrize("rotated", [False, True])
def test_lili_detects_plane_subspace(rotated, generic_rotation):
    R = generic_rotation if rotated else np.eye(3)
    ref, scan, T = plane_pair(seed=1, rotation=R)
    rm = reference_for_detection(ref)
    start = T @ g.exp([0.02, -0.02, 0.01, 0.005, -0.005, 0.01])
    res = LiliDetector().detect(rm, scan, start)
    assert res.ok, res.reason
    assert res.dimension == 3
    # in the scan body frame the plane's normal is z: the subspace is {x, y translation, z rotation}
    truth = np.eye(6)[[0, 1, 5]]
    P_true = truth.T @ truth
    assert np.allclose(res.projector_scaled(), P_true, atol=0.05)
    assert res.twists.shape == (12, 6) and res.kept.sum() >= 6
    # the pose is the optimum: off-plane error removed (z and tilt), in-plane slide is free
    assert abs((np.linalg.inv(T) @ res.pose)[2, 3]) < 0.01


def test_lili_rejects_empty_scan_and_missing_correspondences():
    ref, scan, T = plane_pair(seed=2)
    rm = reference_for_detection(ref)
    det = LiliDetector(LiliConfig())
    res = det.detect(rm, scan[:5], T)
    assert not res.ok and res.dimension == 0
    far = T.copy()
    far[:3, 3] += [0, 0, 100.0]
    res = det.detect(rm, scan, far)
    assert not res.ok and "correspondence" in res.reason
    res = det.detect(rm, np.full((100, 3), np.nan), T)
    assert not res.ok


def test_lili_config_validation():
    with pytest.raises(ValueError):
        LiliConfig(k=1)
    with pytest.raises(ValueError):
        LiliConfig(tau_displacement=1.5)


def test_thinned_capped_perturbation_runs_keep_the_plane_subspace():
    ref, scan, T = plane_pair(seed=1)
    rm = reference_for_detection(ref)
    full = LiliDetector().detect(rm, scan, T)
    fast = LiliDetector(LiliConfig(perturbation_points=300, perturbation_iterations=30)).detect(
        rm, scan, T)
    assert fast.ok and fast.dimension == full.dimension == 3
    assert fast.details["perturbation_points"] <= 300 and full.details["perturbation_points"] == len(scan)
    assert np.allclose(fast.projector_scaled(), full.projector_scaled(), atol=0.05)


def test_thin_gives_at_most_n_evenly_spread_points():
    from lili_odom.degeneracy.lili import thin

    pts = np.arange(3 * 1001, dtype=float).reshape(-1, 3)
    for n in (1, 7, 300, 1001, 5000):
        out = thin(pts, n)
        assert 0 < len(out) <= n and np.array_equal(out[0], pts[0])
    assert len(thin(pts, 5000)) == 1001


def test_perturbation_settings_validation():
    with pytest.raises(ValueError):
        LiliConfig(perturbation_points=-1)
    with pytest.raises(ValueError):
        LiliConfig(perturbation_iterations=-1)
    det = LiliDetector(LiliConfig(perturbation_iterations=20))
    assert det.perturbation_registration.max_iterations == 20
    assert det.registration.max_iterations == 100
    default = LiliDetector()
    assert default.perturbation_registration is default.registration


def test_return_check_settings_validation():
    for bad in ({"return_ratio": -0.1}, {"return_ratio": 0.2}, {"return_ratio": 0.5},
                {"return_check_iterations": 0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            LiliConfig(**bad)
    LiliConfig(return_ratio=0.0, return_check_iterations=1)


def test_return_check_keeps_the_plane_subspace():
    """Stopping the runs that came back: same kept twists and subspace as running every
    perturbed re-registration to convergence (the paper)."""
    ref, scan, T = plane_pair(seed=1)
    rm = reference_for_detection(ref)
    paper = LiliDetector().detect(rm, scan, T)
    fast = LiliDetector(LiliConfig(return_ratio=0.1)).detect(rm, scan, T)
    assert paper.ok and fast.ok and fast.dimension == paper.dimension == 3
    assert np.array_equal(fast.kept, paper.kept)
    assert paper.details["returned_early"] == 0 and fast.details["returned_early"] > 0
    assert fast.details["returned_early"] <= int((~paper.kept).sum())
    assert np.allclose(fast.projector_scaled(), paper.projector_scaled(), atol=0.02)


def test_return_check_records_the_ratio_at_every_check():
    """details["check_ratios"]: per perturbed run the ratios seen at its checks; a run that
    came back stopped at its first check below return_ratio, the others never went below."""
    ref, scan, T = plane_pair(seed=1)
    rm = reference_for_detection(ref)
    paper = LiliDetector().detect(rm, scan, T)
    assert paper.details["check_ratios"] == [[]] * len(paper.ratios)  # no checks in one call
    fast = LiliDetector(LiliConfig(return_ratio=0.1)).detect(rm, scan, T)
    checks = fast.details["check_ratios"]
    assert len(checks) == len(fast.ratios)
    stopped = [c for c in checks if c and c[-1] < 0.1]
    assert len(stopped) == fast.details["returned_early"] > 0
    for c in checks:
        assert all(r >= 0.1 for r in c[:-1])  # the run went on while above the ratio
    for c, final in zip(checks, fast.ratios):
        if c and c[-1] < 0.1:
            assert final == pytest.approx(c[-1])  # stopped there: its final ratio


def test_return_check_in_the_node_parameter_table():
    from lili_odom.config import NodeConfig

    cfg = NodeConfig()
    cfg.pipeline.lili.return_check_iterations = 0
    with pytest.raises(ValueError, match="pipeline.lili.return_check_iterations"):
        cfg.validate()


def _box_surfaces(centre, size, step, rng) -> np.ndarray:
    """Points on the six faces of an axis-aligned box [m], 1 cm noise."""
    centre, size = np.asarray(centre, float), np.asarray(size, float)
    faces = []
    for ax in range(3):
        o = [a for a in range(3) if a != ax]
        U, V = np.meshgrid(np.arange(-size[o[0]] / 2, size[o[0]] / 2, step),
                           np.arange(-size[o[1]] / 2, size[o[1]] / 2, step))
        for sign in (-1, 1):
            P = np.zeros((U.size, 3))
            P[:, o[0]], P[:, o[1]], P[:, ax] = U.ravel(), V.ravel(), sign * size[ax] / 2
            faces.append(P + centre)
    P = np.vstack(faces)
    return P + rng.normal(0.0, 0.01, P.shape)


def _hall(step: float, seed: int) -> np.ndarray:
    """A 30 x 20 x 4 m hall with crates and pillars, in the frame of a sensor 0.7 m up."""
    rng = np.random.default_rng(seed)
    parts = [_box_surfaces((0, 0, 2.0), (30, 20, 4), step, rng)]
    parts += [_box_surfaces(c, (1.5, 2.5, 1.5), step, rng)
              for c in ((4, 3, 0.75), (-6, -4, 0.75), (8, -5, 0.75), (-3, 6, 0.75))]
    parts += [_box_surfaces((x, y, 2.0), (0.4, 0.4, 4.0), step, rng)
              for x, y in ((2, -2), (-5, 2), (7, 4))]
    return np.vstack(parts) - np.array([0.0, 0.0, 0.7])


def test_a_young_sparse_map_does_not_make_a_constrained_hall_degenerate():
    """The odometry's local map after one scan: 1 m voxels holding points ~0.4 m apart, so
    ``(k - 1) s`` exceeds the 1 m correspondence gate. Capped at 0.75 of the gate the
    perturbations come back (dimension 0); uncapped the translations cannot."""
    reference = ReferenceMap.from_points(_hall(0.4, 0), 1.0, 20)
    scan = _hall(0.3, 1)
    assert 4 * reference.spacing > reference.voxel_size  # (k - 1) s beyond the gate
    capped = LiliDetector(LiliConfig()).detect(reference, scan, np.eye(4))
    assert capped.ok and capped.dimension == 0
    assert capped.details["perturbation_m"] == pytest.approx(0.75)
    uncapped = LiliDetector(LiliConfig(max_perturbation_gate=0.0)).detect(reference, scan,
                                                                         np.eye(4))
    assert uncapped.dimension >= 2


def test_perturbation_cap_validation():
    with pytest.raises(ValueError, match="max_perturbation_gate"):
        LiliConfig(max_perturbation_gate=-1.0)
