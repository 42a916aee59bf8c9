"""Synthetic shape cases: sampling, frames, and the analytic degenerate subspaces."""
from __future__ import annotations

import json
from functools import lru_cache

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lili_odom.degeneracy.subspace import orthonormal_rows, projector
from lili_odom.geometry import adjoint, exp, is_valid_pose, log, transform_points, unscale_twist
from lili_odom.sim import shapes
from lili_odom.sim.shapes import (
    DISPLAY_NAMES,
    INITIAL_OFFSET,
    SCENARIOS,
    SPACING,
    T_WORLD_SHAPE,
    ShapeCase,
    load_case,
    make_case,
)

EXPECTED_DIMENSION = {
    "plane": 3,
    "closed_cylinder": 2,
    "sinusoidal_cylinder": 1,
    "open_cylinder": 2,
    "rotating_tunnel": 1,
    "box_room": 0,
}
SLIDE = 1.0  # [m] of scaled motion along the true subspace: twice the Q range
OFF = 0.4  # [m] of scaled motion orthogonal to it


@lru_cache(maxsize=None)
def case(name: str, noisy: bool = False) -> ShapeCase:
    return make_case(name, noisy, seed=0)


@lru_cache(maxsize=None)
def tree(name: str) -> cKDTree:
    return cKDTree(case(name).reference)


def nn_after(name: str, twist_plain: np.ndarray) -> np.ndarray:
    """NN distances [m] of the clean scan moved to ``true_pose @ exp(twist)`` to the reference."""
    c = case(name)
    d, _ = tree(name).query(transform_points(c.true_pose @ exp(twist_plain), c.scan))
    return d


def shape_twist(name: str, xi_shape: np.ndarray) -> np.ndarray:
    """A shape-frame twist expressed in the scan's body frame at the true pose."""
    c = case(name)
    T_C_S = np.linalg.inv(c.true_pose) @ c.shape_pose
    return adjoint(T_C_S) @ xi_shape


def test_scenarios_and_names():
    assert SCENARIOS == tuple(EXPECTED_DIMENSION)
    assert set(DISPLAY_NAMES) == set(SCENARIOS)
    with pytest.raises(ValueError):
        make_case("torus")


@pytest.mark.parametrize("name", SCENARIOS)
def test_case_structure_and_density(name):
    c = case(name)
    assert c.name == name and c.display_name == DISPLAY_NAMES[name]
    assert c.noise == 0.0 and not c.noisy and c.folder_name == f"{name}_clean"
    assert 10_000 <= len(c.reference) <= 20_000
    assert 2_000 <= len(c.scan) <= 12_000
    assert c.true_basis.shape == (EXPECTED_DIMENSION[name], 6) == (c.true_dimension, 6)
    assert is_valid_pose(c.true_pose) and is_valid_pose(c.initial_pose)
    np.testing.assert_allclose(log(np.linalg.inv(c.true_pose) @ c.initial_pose), INITIAL_OFFSET, atol=1e-9)
    # L is the median sensor-frame range of the scan points
    assert c.characteristic_length == pytest.approx(np.median(np.linalg.norm(c.scan, axis=1)))
    # the paper's average neighbour distance of 0.05
    for cloud in (c.reference, c.scan):
        d, _ = cKDTree(cloud).query(cloud, k=2)
        assert abs(d[:, 1].mean() - SPACING) < 0.004
    Bs = c.true_basis_scaled
    np.testing.assert_allclose(Bs @ Bs.T, np.eye(len(Bs)), atol=1e-9)


@pytest.mark.parametrize("name", SCENARIOS)
def test_scan_is_independent_sampling_at_true_pose(name):
    d = nn_after(name, np.zeros(6))
    assert np.median(d) < 0.035 and d.max() < 0.08
    assert np.mean(d < 1e-6) < 0.01  # not the reference's own points


def test_axes_not_aligned_with_reference_frame():
    R = T_WORLD_SHAPE[:3, :3]
    assert np.abs(R).max() < 0.9  # no shape axis close to x, y or z
    assert np.linalg.norm(T_WORLD_SHAPE[:3, 3]) > 0.5


@pytest.mark.parametrize("name", [n for n in SCENARIOS if EXPECTED_DIMENSION[n] > 0])
def test_true_basis_slides_along_the_surface(name):
    """Large motions along each true direction and a random combination stay on the surface
    (also shows the shapes are long enough: no point slides off an end)."""
    c = case(name)
    L = c.characteristic_length
    Bs = c.true_basis_scaled
    rng = np.random.default_rng(7)
    mix = rng.normal(size=len(Bs))
    directions = list(Bs) + [mix / np.linalg.norm(mix) @ Bs]
    for b in directions:
        for sign in (1.0, -1.0):
            d = nn_after(name, unscale_twist(sign * SLIDE * b, L))
            assert np.median(d) < 0.035, (name, b, sign, np.median(d))
            assert np.quantile(d, 0.999) < 0.07, (name, b, sign, d.max())


@pytest.mark.parametrize("name", SCENARIOS)
def test_orthogonal_motions_leave_the_surface(name):
    c = case(name)
    L = c.characteristic_length
    complement = orthonormal_rows(np.eye(6) - projector(c.true_basis_scaled))
    assert len(complement) == 6 - EXPECTED_DIMENSION[name]
    rng = np.random.default_rng(11)
    mix = rng.normal(size=len(complement))
    for b in list(complement) + [mix / np.linalg.norm(mix) @ complement]:
        for sign in (1.0, -1.0):
            d = nn_after(name, unscale_twist(sign * OFF * b, L))
            assert np.median(d) > 0.06, (name, b, sign, np.median(d))


@pytest.mark.parametrize(
    ("name", "xi_shape"),
    [
        # pure axial translation is not the screw of the rotating tunnel
        ("rotating_tunnel", np.array([0, 0, 0.5, 0, 0, 0.0])),
        # nor is pure rotation about its axis
        ("rotating_tunnel", np.array([0, 0, 0, 0, 0, 0.35])),
        # the lobes constrain rotation about the sinusoidal cylinder's axis
        ("sinusoidal_cylinder", np.array([0, 0, 0, 0, 0, 0.3])),
    ],
)
def test_near_miss_motions_leave_the_surface(name, xi_shape):
    assert np.median(nn_after(name, shape_twist(name, xi_shape))) > 0.06


def test_open_cylinder_rotation_is_coupled_in_the_scan_frame():
    """Rotating the open cylinder scan about its own origin (same direction as the axis) is
    wrong: the degenerate rotation needs the translation part v = c x a of the axis line."""
    c = case("open_cylinder")
    axis_body = shape_twist("open_cylinder", np.array([0, 0, 0, 0, 0, 1.0]))
    assert np.linalg.norm(axis_body[:3]) > 0.8  # the sensor is ~0.9 m off the axis
    pure_rotation = np.concatenate([np.zeros(3), axis_body[3:]]) * 0.3
    assert np.median(nn_after("open_cylinder", pure_rotation)) > 0.1
    assert np.median(nn_after("open_cylinder", 0.3 * axis_body)) < 0.035
    # and the true subspace contains the coupled twist
    P = projector(c.true_basis)
    np.testing.assert_allclose(P @ axis_body, axis_body, atol=1e-9)


def test_noisy_variant_shares_samples_plus_noise():
    clean, noisy = case("closed_cylinder"), case("closed_cylinder", True)
    assert noisy.noisy and noisy.noise == shapes.NOISE_SIGMA and noisy.folder_name == "closed_cylinder_noisy"
    for a, b in ((clean.reference, noisy.reference), (clean.scan, noisy.scan)):
        assert a.shape == b.shape
        assert abs(np.std(b - a) - shapes.NOISE_SIGMA) < 0.002
    np.testing.assert_array_equal(clean.true_pose, noisy.true_pose)
    np.testing.assert_allclose(clean.true_basis, noisy.true_basis)


def test_seeds_are_deterministic_and_distinct():
    a, b, other = make_case("plane", False, 3), make_case("plane", False, 3), make_case("plane", False, 4)
    np.testing.assert_array_equal(a.reference, b.reference)
    np.testing.assert_array_equal(a.scan, b.scan)
    assert a.reference.shape != other.reference.shape or not np.array_equal(a.reference, other.reference)


def test_all_cases_order():
    cases = shapes.all_cases(seed=0)
    assert [(c.name, c.noisy) for c in cases] == [(n, v) for n in SCENARIOS for v in (False, True)]


def test_cli_writes_every_case(tmp_path, capsys):
    from lili_odom.cli import main

    out = tmp_path / "shapes"
    assert main(["simulate", "shapes", "--out", str(out), "--seed", "2"]) == 0
    assert str(out) in capsys.readouterr().out
    folders = sorted(p.name for p in out.iterdir())
    assert folders == sorted(f"{n}_{v}" for n in SCENARIOS for v in ("clean", "noisy"))
    folder = out / "open_cylinder_noisy"
    for f in ("reference.npy", "scan.npy", "initial_pose.txt", "true_pose.txt", "truth.json"):
        assert (folder / f).is_file()
    truth = json.loads((folder / "truth.json").read_text())
    assert truth["scenario"] == "open_cylinder" and truth["noise"] == shapes.NOISE_SIGMA
    assert truth["true_dimension"] == 2 and len(truth["true_basis_scaled"]) == 2
    loaded, fresh = load_case(folder), make_case("open_cylinder", True, 2)
    np.testing.assert_allclose(loaded.scan, fresh.scan)
    np.testing.assert_allclose(loaded.true_pose, fresh.true_pose)
    np.testing.assert_allclose(np.loadtxt(folder / "initial_pose.txt"), fresh.initial_pose)
    np.testing.assert_allclose(loaded.true_basis, fresh.true_basis)
    assert loaded.characteristic_length == pytest.approx(truth["characteristic_length"])
