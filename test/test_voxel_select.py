"""One point per voxel chosen on the raw sweep, and the scan matcher deskewing only those."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from kiss_icp.preprocess import Preprocessor
from kiss_icp.voxelization import voxel_down_sample

from lili_odom import geometry
from lili_odom.pipeline.scan_matcher import ScanMatcher, ScanMatcherConfig
from lili_odom.pipeline.voxel_select import first_in_voxel


def _rows(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a).reshape(-1, 3)
    return a[np.lexsort(a.T[::-1])]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 3000),
       voxel=st.floats(0.05, 3.0), spread=st.floats(0.5, 200.0))
def test_first_in_voxel_keeps_kiss_icps_points(seed, n, voxel, spread):
    """The same points as KISS-ICP's ``voxel_down_sample`` (first point of each cell), one
    per cell."""
    pts = np.random.default_rng(seed).normal(0.0, spread, (n, 3))
    pts[n // 2:] = pts[: n - n // 2] + 0.01 * voxel  # many shared cells
    idx = first_in_voxel(pts, voxel)
    assert len(np.unique(idx)) == len(idx)
    np.testing.assert_array_equal(_rows(pts[idx]), _rows(voxel_down_sample(pts, voxel)))
    cells = np.floor(pts / voxel)
    first = {}
    for i, c in enumerate(map(tuple, cells)):
        first.setdefault(c, i)
    assert sorted(first.values()) == sorted(idx.tolist())


def test_first_in_voxel_order_is_unrelated_to_the_input_order():
    """A coarser voxelisation of the kept points (first point per coarse cell) must not pick
    the points of the sweep's first rows: rows stacked in z, the first row lowest."""
    rows = [np.column_stack([np.arange(0.0, 50.0, 0.5) + 0.25, np.full(100, 0.25),
                             np.full(100, 0.05 + 0.1 * r)]) for r in range(10)]
    pts = np.vstack(rows)  # 10 rows of 0.1 m in z inside one 1 m cell layer; 0.5 m cells in x
    idx = first_in_voxel(pts, 0.1)
    assert len(idx) == len(pts)
    coarse = voxel_down_sample(pts[idx], 1.0)
    # input order would keep row 0 (z = 0.05) in all 50 coarse cells
    assert 0.2 < np.mean(coarse[:, 2]) < 0.8


def test_first_in_voxel_makes_no_choice_where_it_cannot_pack_the_cells():
    pts = np.zeros((5, 3))
    pts[2] = [1e7, 0.0, 0.0]  # 2e7 cells of 0.5 m from the origin: beyond the packed range
    assert first_in_voxel(pts, 0.5) is None
    pts[2] = [np.nan, 0.0, 0.0]
    assert first_in_voxel(pts, 0.5) is None
    assert first_in_voxel(np.zeros((4, 3)), float("nan")) is None
    assert first_in_voxel(np.zeros((4, 3)), 0.0) is None
    assert first_in_voxel(np.zeros((0, 3)), 0.5).shape == (0,)
    np.testing.assert_array_equal(first_in_voxel(np.zeros((4, 3)), 0.5), [0])


def test_preprocess_far_points_voxelise_after_the_deskew():
    """Points beyond the packed range take KISS-ICP's path: deskew all, then voxelise."""
    pts, times = _sweep()
    pts = np.vstack([pts, [[6e5, 0.0, 0.0]]])
    times = np.append(times, 0.05)
    motion = geometry.exp(np.array([0.15, 0.0, 0.0, 0.0, 0.0, 0.05]))
    matcher = ScanMatcher(ScanMatcherConfig(max_range=1e6, min_range=1.0, voxel_size=1.0))
    map_points, source = matcher.preprocess(pts, times, motion)
    whole = np.asarray(Preprocessor(1e6, 1.0, True, 0).preprocess(pts, times, motion))
    expected = voxel_down_sample(whole, 0.5 * matcher.config.voxel)
    np.testing.assert_array_equal(_rows(map_points), _rows(expected))


def _sweep(n_columns: int = 512, n_rows: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A rotating-LiDAR sweep of a 20 x 12 x 4 m room: per-column times over 0.1 s [m, s]."""
    az = np.linspace(-np.pi, np.pi, n_columns, endpoint=False)
    el = np.linspace(-0.3, 0.3, n_rows)
    A, E = np.meshgrid(az, el)  # row-major, as an Ouster cloud
    d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1).reshape(-1, 3)
    half = np.array([10.0, 6.0, 2.0])
    r = np.min(np.where(np.abs(d) > 1e-9, half / np.maximum(np.abs(d), 1e-9), np.inf), axis=1)
    times = np.tile(np.linspace(0.0, 0.1, n_columns, endpoint=False), n_rows)
    return d * r[:, None], times


def test_preprocess_deskews_each_kept_point_as_kiss_icp_deskews_the_sweep():
    pts, times = _sweep()
    motion = geometry.exp(np.array([0.15, 0.02, 0.0, 0.0, 0.01, 0.08]))
    matcher = ScanMatcher(ScanMatcherConfig(max_range=100.0, min_range=1.0))
    map_points, source = matcher.preprocess(pts, times, motion)
    whole = np.asarray(Preprocessor(100.0, 1.0, True, 0).preprocess(pts, times, motion))
    # every map point is the whole sweep's deskewed point
    d = np.min(np.linalg.norm(map_points[:, None, :] - whole[None, :, :], axis=2), axis=1)
    assert np.max(d) < 1e-9
    # one point per 0.5-voxel cell of the raw sweep, about as many as voxelising the deskewed one
    v = matcher.config.voxel
    cells = len(first_in_voxel(pts, 0.5 * v))
    assert cells <= len(map_points) <= cells + 2  # + the points of the first and last time
    reference = len(voxel_down_sample(whole, 0.5 * v))
    assert 0.9 * reference <= len(map_points) <= 1.1 * reference
    assert len(source) == len(voxel_down_sample(map_points, 1.5 * v))


def test_preprocess_normalises_times_over_the_whole_sweep():
    """The kept points' times span less than the sweep's; the deskew still uses the sweep's
    first and last time (a point at the last time does not move)."""
    pts, times = _sweep()
    motion = geometry.exp(np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.2]))
    matcher = ScanMatcher()
    map_points, _ = matcher.preprocess(pts, times, motion)
    last = pts[np.argmax(times)]
    assert np.min(np.linalg.norm(map_points - last, axis=1)) < 1e-12
