"""Point-to-plane information and refinement inside a detected subspace."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lili_odom import geometry
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.pipeline.plane_refinement import (PlaneFitCache, PlaneRefinementConfig,
                                                 fit_planes, plane_jacobians,
                                                 refine_in_subspace, returned_directions,
                                                 without_unheld)

AXIS_X = np.array([[1.0, 0, 0, 0, 0, 0]])  # scaled twist: translation along the corridor
AXIS_Y = np.array([[0, 1.0, 0, 0, 0, 0]])


def corridor(length: float, end_walls: bool, step: float = 0.1, width: float = 2.6,
             height: float = 3.0, seed: int = 0) -> np.ndarray:
    """Points on a box corridor x in [0, length], |y| <= width/2, z in [0, height]."""
    rng = np.random.default_rng(seed)
    xs = np.arange(0.0, length, step)
    ys = np.arange(-width / 2, width / 2, step)
    zs = np.arange(0.0, height, step)
    X, Z = np.meshgrid(xs, zs)
    walls = [np.c_[X.ravel(), np.full(X.size, y), Z.ravel()] for y in (-width / 2, width / 2)]
    X, Y = np.meshgrid(xs, ys)
    flats = [np.c_[X.ravel(), Y.ravel(), np.full(X.size, z)] for z in (0.0, height)]
    parts = walls + flats
    if end_walls:
        Y, Z = np.meshgrid(ys, zs)
        parts += [np.c_[np.full(Y.size, x), Y.ravel(), Z.ravel()] for x in (0.0, length)]
    pts = np.vstack(parts)
    return pts + rng.normal(0.0, 0.005, pts.shape)


def scan_at(world: np.ndarray, x0: float, max_range: float = 30.0, n: int = 8000,
            seed: int = 1) -> np.ndarray:
    """World points within range of a sensor at (x0, 0, 1.5), in the sensor frame."""
    rng = np.random.default_rng(seed)
    local = world - np.array([x0, 0.0, 1.5])
    local = local[np.linalg.norm(local, axis=1) < max_range]
    return local[rng.choice(len(local), size=min(n, len(local)), replace=False)]


def pose_at(x: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [x, 0.0, 1.5]
    return T


def test_jacobian_matches_finite_difference():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(5, 3))
    n = rng.normal(size=(5, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    J = plane_jacobians(p, n)  # pose = identity, so n_b = n
    for j in range(6):
        xi = np.zeros(6)
        xi[j] = 1e-6
        moved = geometry.transform_points(geometry.exp(xi), p)
        num = np.einsum("ij,ij->i", n, moved - p) / 1e-6
        assert np.allclose(J[:, j], num, atol=1e-5)


def test_tube_has_no_information_along_its_axis():
    world = corridor(200.0, end_walls=False)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 100.0)
    along = refine_in_subspace(scan, ref, pose_at(100.0), AXIS_X, 10.0)
    across = refine_in_subspace(scan, ref, pose_at(100.0), AXIS_Y, 10.0)
    assert along.ok and across.ok
    assert along.information[0, 0] < 1e-3 * across.information[0, 0]
    assert along.information[0, 0] < 1.0  # sigma above a metre


def test_end_walls_in_range_hold_the_axis():
    world = corridor(40.0, end_walls=True)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 25.0)
    start = pose_at(25.2)  # 20 cm off along the axis
    res = refine_in_subspace(scan, ref, start, AXIS_X, 10.0)
    assert res.ok
    assert abs(res.pose[0, 3] - 25.0) < 0.02
    assert np.allclose(res.pose[1:3, 3], [0.0, 1.5], atol=1e-6)  # only the subspace moved
    assert res.information[0, 0] > 400.0  # sigma below 5 cm
    assert np.allclose(res.information_scaled, AXIS_X.T @ res.information @ AXIS_X)


def test_tube_refinement_stays_at_the_start():
    world = corridor(200.0, end_walls=False)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    res = refine_in_subspace(scan_at(world, 100.0), ref, pose_at(100.3), AXIS_X, 10.0)
    assert abs(res.pose[0, 3] - 100.3) < 0.05


def test_no_subspace_and_empty_map():
    world = corridor(40.0, end_walls=True)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    res = refine_in_subspace(scan_at(world, 20.0), ref, pose_at(20.0), np.zeros((0, 6)), 10.0)
    assert res.ok and res.information.shape == (0, 0)
    far = refine_in_subspace(scan_at(world, 20.0), ref, pose_at(500.0), AXIS_X, 10.0)
    assert not far.ok and np.all(far.information == 0.0)


def test_config_validation():
    with pytest.raises(ValueError, match="plane_refinement.independent_fraction"):
        PlaneRefinementConfig(independent_fraction=0.0).validate()
    PlaneRefinementConfig().validate()


def test_the_odometry_clears_directions_point_to_plane_holds():
    from lili_odom.degeneracy.result import DegeneracyResult
    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
    from lili_odom.pipeline.plane_refinement import PlaneRefinement

    basis = np.vstack([AXIS_X, AXIS_Y])
    det = DegeneracyResult("lili", np.eye(4), basis, 10.0)
    info = np.diag([5000.0, 10.0])  # x held to 1.4 cm, y to 32 cm
    refined = PlaneRefinement(np.eye(4), info, basis.T @ info @ basis, basis)
    pipeline = OdometryPipeline(PipelineConfig())
    left, left_info, (rows, held) = pipeline._clear_held_directions(det, refined)
    assert left.dimension == 1 and np.allclose(np.abs(left.basis_scaled), AXIS_Y)
    assert np.allclose(left_info, 10.0 * AXIS_Y.T @ AXIS_Y)
    assert left.details["cleared"] == 1 and pipeline.counters["directions_cleared"] == 1
    assert np.allclose(np.abs(rows), AXIS_Y) and np.allclose(held, [10.0])
    off = OdometryPipeline(PipelineConfig(plane_refinement=PlaneRefinementConfig(
        clear_information=0.0)))
    same, same_info, (rows, held) = off._clear_held_directions(det, refined)
    assert same.dimension == 2 and np.allclose(same_info, refined.information_scaled)
    assert np.allclose(sorted(held), [10.0, 5000.0]) and rows.shape == (2, 6)


def test_directions_the_lidar_holds_weakly_are_reported_apart_from_degenerate_ones():
    from lili_odom.degeneracy.result import DegeneracyResult
    from lili_odom.pipeline.odometry import reported_bases

    T_base_lidar = np.eye(4)
    T_base_lidar[:3, 3] = [0.2, 0.0, 0.5]
    basis = np.vstack([AXIS_X, AXIS_Y])
    det = DegeneracyResult("lili", np.eye(4), basis, 10.0)
    # x held to 5 cm (400 m^-2), y to 1 m: x weakly constrained, y degenerate at the 100 bar
    degenerate, weak = reported_bases(det, (basis, np.array([400.0, 1.0])), 100.0, T_base_lidar)
    assert np.allclose(np.abs(degenerate), [[0, 1, 0, 0, 0, 0]])
    assert np.allclose(np.abs(weak), [[1, 0, 0, 0, 0, 0]])
    # every direction degenerate with an infinite bar, and without a refinement's measure
    degenerate, weak = reported_bases(det, (basis, np.array([400.0, 1.0])), np.inf,
                                      T_base_lidar)
    assert degenerate.shape == (2, 6) and weak.shape == (0, 6)
    degenerate, weak = reported_bases(det, None, 100.0, T_base_lidar)
    assert degenerate.shape == (2, 6) and weak.shape == (0, 6)
    # a yaw about the LiDAR is a yaw plus a lateral translation of base_link, unit length
    yaw = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])
    degenerate, weak = reported_bases(DegeneracyResult("lili", np.eye(4), yaw, 10.0),
                                      (yaw, np.array([150.0])), 100.0, T_base_lidar)
    assert len(degenerate) == 0 and np.isclose(np.linalg.norm(weak[0]), 1.0)
    assert abs(weak[0, 5]) > 0.9 and abs(weak[0, 1]) > 0.1
    none_left = DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 10.0)
    assert all(b.shape == (0, 6) for b in reported_bases(none_left, None, 100.0, T_base_lidar))


def _pipeline_over(world: np.ndarray, previous_x: float):
    """An odometry pipeline whose local map is ``world`` and whose previous output had the
    LiDAR at ``pose_at(previous_x)``."""
    from types import SimpleNamespace

    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig

    pipeline = OdometryPipeline(PipelineConfig())
    pipeline._matcher = SimpleNamespace(reference=ReferenceMap.from_points(world, 1.0, 200))
    T_lidar_base = np.linalg.inv(pipeline.T_base_lidar)
    pipeline._last_output = SimpleNamespace(pose=pose_at(previous_x) @ T_lidar_base)
    return pipeline


def planes(pipeline, scan: np.ndarray) -> PlaneFitCache:
    """The plane fits of ``scan`` against ``pipeline``'s local map, as one scan shares them."""
    return PlaneFitCache(scan, pipeline._matcher.reference, pipeline.config.plane_refinement)


YAW = np.array([[0, 0, 0, 0, 0, 1.0]])


def test_weak_directions_add_what_point_to_plane_does_not_hold():
    from lili_odom.degeneracy.result import DegeneracyResult

    tube = corridor(200.0, end_walls=False)
    here = pose_at(100.0)
    pipeline = _pipeline_over(tube, 99.9)
    none = DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 10.0)
    scan = planes(pipeline, scan_at(tube, 100.0))
    weak = pipeline._weak_directions(scan, here, here, none)
    assert weak is not None and weak.dimension == 1 and weak.details["weak"] == 1
    assert abs(weak.basis_scaled[0, 0]) > 0.99  # the tube's axis
    # a direction already detected is not added again
    axis = DegeneracyResult("lili", np.eye(4), AXIS_X, 10.0)
    assert pipeline._weak_directions(scan, here, here, axis) is None
    assert scan.queries == 1  # both checks at the same pose: one k-d tree query

    boxed = corridor(40.0, end_walls=True)
    held = _pipeline_over(boxed, 19.9)
    at20 = pose_at(20.0)
    assert held._weak_directions(planes(held, scan_at(boxed, 20.0)), at20, at20, none) is None
    still = _pipeline_over(tube, 100.0)  # no travel since the previous scan: no check
    assert still._weak_directions(planes(still, scan_at(tube, 100.0)), here, here, none) is None
    off = _pipeline_over(tube, 99.9)
    off.config.plane_refinement.weak_information = 0.0
    assert off._weak_directions(planes(off, scan_at(tube, 100.0)), here, here, none) is None


class _NoDetector:
    name = "lili"

    def detect(self, *args, **kwargs):
        raise AssertionError("the detector ran on a screened scan")


def test_a_scan_its_planes_hold_in_every_direction_skips_the_detector():
    room = corridor(12.0, end_walls=True)
    pipeline = _pipeline_over(room, 5.9)
    pipeline._detector = _NoDetector()
    here, scan = pose_at(6.0), scan_at(room, 6.0)
    result = pipeline._detection(scan, here, here, planes(pipeline, scan))
    limit = pipeline.config.plane_refinement.clear_information
    assert result.ok and not result.degenerate and result.details["screened"]
    assert result.details["min_information"] >= limit
    assert pipeline.counters["detections_screened"] == 1
    assert pipeline.counters["detections"] == 0

    tube = corridor(200.0, end_walls=False)  # nothing holds the axis: the detector decides
    open_ended = _pipeline_over(tube, 99.9)
    open_ended._detector = _NoDetector()
    at100, tube_scan = pose_at(100.0), scan_at(tube, 100.0)
    assert open_ended._screen(tube_scan, at100, planes(open_ended, tube_scan)) is None
    off = _pipeline_over(room, 5.9)
    off._detector = _NoDetector()
    off.config.plane_refinement.screen_detections = False
    assert off._screen(scan, here, planes(off, scan)) is None


def test_planes_that_hold_every_direction_weakly_give_the_subspace_themselves():
    """With ``screen_weak_information`` the planes give the subspace (their directions below
    ``clear_information``) where they hold every direction with at least that; below it,
    or with it off, the detector decides."""
    room = corridor(12.0, end_walls=True)
    here, scan = pose_at(6.0), scan_at(room, 6.0)
    probe = _pipeline_over(room, 5.9)
    probe._detector = _NoDetector()
    probe._screen(scan, here, planes(probe, scan))
    w, V = np.linalg.eigh(probe._screen_information[0])
    assert w[0] > 0 and w[2] > w[1] * 1.01  # a clear gap after the second direction

    pipeline = _pipeline_over(room, 5.9)
    pipeline._detector = _NoDetector()
    cfg = pipeline.config.plane_refinement
    cfg.clear_information = 0.5 * (w[1] + w[2])  # the room holds two directions below it
    cfg.screen_weak_information = 0.5 * w[0]
    result = pipeline._detection(scan, here, here, planes(pipeline, scan))
    assert result.ok and result.degenerate and result.details["screened"]
    assert result.dimension == 2 and np.isclose(result.details["min_information"], w[0])
    np.testing.assert_allclose(np.abs(result.basis_scaled @ V[:, :2]), np.eye(2), atol=1e-6)
    assert pipeline.counters["detections_screened_weak"] == 1
    assert pipeline.counters["detections"] == pipeline.counters["detections_screened"] == 0
    from lili_odom.pipeline.odometry import _screened_here
    assert not _screened_here(result)  # the later checks treat it as a detection

    cfg.screen_weak_information = 2.0 * w[0]  # the weakest direction is nearly free
    assert pipeline._screen(scan, here, planes(pipeline, scan)) is None
    cfg.screen_weak_information = 0.0
    assert pipeline._screen(scan, here, planes(pipeline, scan)) is None
    tube = corridor(200.0, end_walls=False)  # nothing holds the axis: the detector decides
    open_ended = _pipeline_over(tube, 99.9)  # the default bar
    assert open_ended.config.plane_refinement.screen_weak_information > 0
    tube_scan = scan_at(tube, 100.0)
    assert open_ended._screen(tube_scan, pose_at(100.0), planes(open_ended, tube_scan)) is None


def _count_refinements(monkeypatch) -> list:
    """A list that gets an entry per call of the odometry's ``refine_in_subspace``."""
    import lili_odom.pipeline.odometry as odometry

    calls = []

    def counted(*args, **kwargs):
        calls.append(1)
        return refine_in_subspace(*args, **kwargs)

    monkeypatch.setattr(odometry, "refine_in_subspace", counted)
    return calls


def test_the_planes_subspace_can_skip_the_remapping_and_the_checks(monkeypatch):
    """``screened_subspace_remap`` off and ``check_screened_subspace`` False: a scan whose screen
    gave the planes' subspace is neither remapped nor checked for weak or along-track
    directions; the same subspace carried over to another scan still is."""
    calls = _count_refinements(monkeypatch)
    room = corridor(12.0, end_walls=True)
    pipeline = _pipeline_over(room, 5.9)
    pipeline._detector = _NoDetector()
    cfg = pipeline.config.plane_refinement
    here, scan = pose_at(6.0), scan_at(room, 6.0)
    fits = planes(pipeline, scan)
    pipeline._screen(scan, here, fits)
    w = np.linalg.eigvalsh(pipeline._screen_information[0])
    cfg.clear_information = cfg.weak_information = cfg.constrained_information = w[1] * 1.001
    cfg.screen_weak_information = 0.5 * w[0]
    result = pipeline._screen(scan, here, fits)
    assert result.ok and result.dimension == 2
    behind = pose_at(5.9)
    behind[1, 3] = 0.1  # travel across the room, which the side walls hold well
    carried = replace(result, details={**result.details, "reused": True})
    assert pipeline._remaps(result) and pipeline._remaps(carried)
    calls.clear()
    pipeline._weak_directions(fits, here, behind, result)
    pipeline._along_track(fits, here, behind, result)
    assert len(calls) == 2  # checked by default

    cfg.screened_subspace_remap, cfg.check_screened_subspace = "off", False
    assert not pipeline._remaps(result) and pipeline._remaps(carried)
    calls.clear()
    assert pipeline._weak_directions(fits, here, behind, result) is None
    assert pipeline._along_track(fits, here, behind, result) is None
    assert not calls
    pipeline._weak_directions(fits, here, behind, carried)
    pipeline._along_track(fits, here, behind, carried)
    assert len(calls) == 2
    cfg.weak_information = cfg.clear_information * 2  # outside the subspace may be weaker
    calls.clear()
    pipeline._weak_directions(fits, here, behind, result)
    assert len(calls) == 1

    with pytest.raises(ValueError, match="screened_subspace_remap"):
        replace(cfg, screened_subspace_remap="prediction").validate()  # tried, removed


def test_the_screen_weighs_the_registration_for_the_fusion():
    """With ``weigh_registration`` the fusion gets the screen's information combined with
    the configured sigmas; without it (or before a screen) the configured sigmas."""
    from lili_odom.fusion.measurements import registration_information

    room = corridor(12.0, end_walls=True)
    pipeline = _pipeline_over(room, 5.9)
    pipeline._detector = _NoDetector()
    here, scan = pose_at(6.0), scan_at(room, 6.0)
    assert pipeline._registration_information() is None
    pipeline._detection(scan, here, here, planes(pipeline, scan))
    assert pipeline._registration_information() is None  # off by default
    pipeline.config.plane_refinement.weigh_registration = True
    info = pipeline._registration_information()
    planes_info, length = pipeline._screen_information
    configured = pipeline.config.fusion.lidar.information()
    np.testing.assert_allclose(info, registration_information(configured, planes_info, length))
    assert np.all(np.linalg.eigvalsh(configured - info) >= -1e-6)  # never above the sigmas
    assert np.linalg.eigvalsh(planes_info)[0] > 0


def test_a_screened_scan_passes_the_weak_check_without_computing_it_again(monkeypatch):
    from dataclasses import replace

    calls = _count_refinements(monkeypatch)
    room = corridor(12.0, end_walls=True)
    pipeline = _pipeline_over(room, 5.9)
    pipeline._detector = _NoDetector()
    here, scan = pose_at(6.0), scan_at(room, 6.0)
    fits = planes(pipeline, scan)
    screened = pipeline._screen(scan, here, fits)
    assert screened is not None and len(calls) == 1
    assert pipeline._weak_directions(fits, here, here, screened) is None
    assert len(calls) == 1  # the screen's information already bounds every planar direction
    # carried over to another scan it says nothing about that scan: the check runs, and here
    # it agrees
    carried = replace(screened, details={**screened.details, "reused": True})
    assert pipeline._weak_directions(fits, here, here, carried) is None
    assert len(calls) == 2



def test_a_screened_scan_leaves_the_travel_to_the_constrained_refinement():
    from dataclasses import replace

    room = corridor(12.0, end_walls=True)
    pipeline = _pipeline_over(room, 5.9)
    pipeline._detector = _NoDetector()
    here, scan = pose_at(6.0), scan_at(room, 6.0)
    fits = planes(pipeline, scan)
    behind = pose_at(5.95)  # a registration left 5 cm behind
    screened = pipeline._screen(scan, behind, fits)
    assert screened is not None
    assert pipeline._along_track(fits, behind, here, screened) is None
    refined = pipeline._refine_constrained(fits, behind, screened)
    assert abs(refined[0, 3] - 6.0) < 0.01  # the travel is refined there
    # carried over from another scan, or with the constrained refinement off, it runs
    carried = replace(screened, details={**screened.details, "reused": True})
    assert pipeline._along_track(fits, behind, here, carried).ok
    pipeline.config.plane_refinement.refine_constrained = "off"
    assert pipeline._along_track(fits, behind, here, screened).ok


def test_along_track_covers_the_travel_outside_a_detected_subspace():
    from lili_odom.degeneracy.result import DegeneracyResult

    # yaw detected, the sensor travels along x: the travel is checked, and the end walls
    # move a registration left 20 cm behind back to the truth
    boxed = corridor(40.0, end_walls=True)
    pipeline = _pipeline_over(boxed, 24.9)
    yaw = DegeneracyResult("lili", np.eye(4), YAW, 10.0)
    scan = planes(pipeline, scan_at(boxed, 25.0))
    along = pipeline._along_track(scan, pose_at(24.8), pose_at(25.0), yaw)
    assert along is not None and along.ok
    assert abs(along.pose[0, 3] - 25.0) < 0.03
    # in a tube the travel joins the detected subspace
    tube = corridor(200.0, end_walls=False)
    pipeline = _pipeline_over(tube, 99.9)
    here = pose_at(100.0)
    scan = planes(pipeline, scan_at(tube, 100.0))
    along = pipeline._along_track(scan, here, here, yaw)
    assert along is not None and not along.ok
    assert along.degeneracy.dimension == 2 and along.degeneracy.details["along_track"]
    assert np.allclose(np.abs(along.degeneracy.basis_scaled[1]), AXIS_X[0], atol=1e-9)
    # travel inside the detected subspace: nothing to check
    axis = DegeneracyResult("lili", np.eye(4), AXIS_X, 10.0)
    assert pipeline._along_track(scan, here, here, axis) is None


def test_plane_fits_are_shared_near_their_pose_and_found_again_farther_away():
    boxed = corridor(40.0, end_walls=True)
    ref = ReferenceMap.from_points(boxed, 1.0, 200)
    scan = scan_at(boxed, 20.0)
    cache = PlaneFitCache(scan, ref)
    fits = cache.at(pose_at(20.0))
    assert fits.valid.sum() > 100 and cache.queries == 1
    assert cache.at(pose_at(20.03)) is fits and cache.queries == 1
    assert cache.at(pose_at(20.5)) is not fits and cache.queries == 2
    # a refinement on shared fits is the one that finds its own planes
    start = pose_at(20.2)
    own = refine_in_subspace(scan, ref, start, AXIS_X, 10.0)
    shared = refine_in_subspace(scan, ref, start, AXIS_X, 10.0,
                                fits=fit_planes(scan, ref, pose_at(20.2)))
    np.testing.assert_allclose(shared.pose, own.pose, atol=1e-12)
    np.testing.assert_allclose(shared.information, own.information, rtol=1e-9)
    assert abs(own.pose[0, 3] - 20.0) < 0.03


def test_probed_fits_serve_later_refinements_only_at_the_same_pose():
    boxed = corridor(40.0, end_walls=True)
    ref = ReferenceMap.from_points(boxed, 1.0, 200)
    scan = scan_at(boxed, 20.0)
    here = pose_at(20.0)
    cache = PlaneFitCache(scan, ref)
    probed = cache.probe(here)
    assert cache.at(here.copy()) is probed and cache.queries == 1
    nearby = PlaneFitCache(scan, ref)
    probed = nearby.probe(here)
    fits = nearby.at(pose_at(20.03))  # near enough to share, but planes are found again
    assert fits is not probed and nearby.queries == 2
    np.testing.assert_allclose(fits.pose, pose_at(20.03))
    assert nearby.at(pose_at(20.0)) is fits  # from then on the usual sharing


def test_constrained_directions_are_refined_where_point_to_plane_holds_them():
    from lili_odom.degeneracy.result import DegeneracyResult

    none = DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 10.0)
    off_by = pose_at(5.0)
    off_by[:3, 3] += [0.08, 0.06, 0.0]  # 8 cm along, 6 cm across a short closed corridor
    boxed = corridor(10.0, end_walls=True)
    pipeline = _pipeline_over(boxed, 4.9)
    pipeline.config.plane_refinement.refine_constrained = "all"
    refined = pipeline._refine_constrained(planes(pipeline, scan_at(boxed, 5.0)), off_by, none)
    np.testing.assert_allclose(refined[:3, 3], [5.0, 0.0, 1.5], atol=0.02)
    # in a tube the axis is not held: only the offset across it is removed
    tube = corridor(200.0, end_walls=False)
    pipeline = _pipeline_over(tube, 99.9)
    pipeline.config.plane_refinement.refine_constrained = "all"
    off_by = pose_at(100.0)
    off_by[:3, 3] += [0.08, 0.06, 0.0]
    refined = pipeline._refine_constrained(planes(pipeline, scan_at(tube, 100.0)), off_by, none)
    assert abs(refined[1, 3]) < 0.02 and abs(refined[0, 3] - 100.08) < 1e-3
    # a detected direction is left where it was put, and the option off moves nothing
    across = DegeneracyResult("lili", np.eye(4), AXIS_Y, 10.0)
    refined = pipeline._refine_constrained(planes(pipeline, scan_at(tube, 100.0)), off_by,
                                           across)
    assert abs(refined[1, 3] - 0.06) < 1e-3
    pipeline.config.plane_refinement.refine_constrained = "off"
    assert pipeline._refine_constrained(planes(pipeline, scan_at(tube, 100.0)), off_by,
                                        none) is off_by
    # planar: base_link's forward, lateral and yaw only; a height offset stays
    pipeline.config.plane_refinement.refine_constrained = "planar"
    high = off_by.copy()
    high[2, 3] += 0.05
    refined = pipeline._refine_constrained(planes(pipeline, scan_at(tube, 100.0)), high, none)
    assert abs(refined[1, 3]) < 0.02 and abs(refined[2, 3] - 1.55) < 2e-3
    with pytest.raises(ValueError, match="refine_constrained"):
        PlaneRefinementConfig(refine_constrained="yes").validate()


def _screen_and_detection():
    """A screen's result (held in every direction) and a detection's, both of dimension 0."""
    from lili_odom.degeneracy.result import DegeneracyResult

    screened = DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 10.0,
                                details={"screened": True, "min_information": 2000.0})
    return screened, DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 10.0)


def _off_by(dx: float) -> np.ndarray:
    pose = pose_at(5.0)
    pose[0, 3] += dx
    return pose


def _refined_in_short_corridor(degeneracy, start, rounds, mode="all", prediction=None,
                               from_prediction=False):
    """The constrained refinement from ``start`` of a scan in the middle of a short closed
    corridor, steps capped so a round of three moves at most 12 cm: (pose, counters)."""
    boxed = corridor(10.0, end_walls=True)
    pipeline = _pipeline_over(boxed, 4.9)
    cfg = pipeline.config.plane_refinement
    cfg.refine_constrained, cfg.constrained_rounds = mode, rounds
    cfg.constrained_from_prediction = from_prediction
    cfg.max_step = 0.04
    pose = pipeline._refine_constrained(planes(pipeline, scan_at(boxed, 5.0)), start,
                                        degeneracy, prediction)
    return pose, pipeline.counters


def test_on_a_screened_scan_the_constrained_refinement_goes_on_until_it_settles():
    screened, detected = _screen_and_detection()
    off_by = _off_by(0.25)
    one, counters = _refined_in_short_corridor(screened, off_by, 1)
    assert one[0, 3] - 5.0 > 0.1  # one round: still more than 10 cm off
    assert counters["constrained_rounds_extra"] == 0 and counters["constrained_refined"] == 1
    rounds, counters = _refined_in_short_corridor(screened, off_by, 4)
    np.testing.assert_allclose(rounds[:3, 3], [5.0, 0.0, 1.5], atol=0.02)
    assert 1 <= counters["constrained_rounds_extra"] <= 3
    assert counters["constrained_refined"] == 1  # one scan refined, however many rounds
    # a detection's result (not a screen's) gets one round
    np.testing.assert_allclose(_refined_in_short_corridor(detected, off_by, 4)[0], one,
                               atol=1e-9)
    # already where the planes hold it: one round, no more
    boxed = corridor(10.0, end_walls=True)
    pipeline = _pipeline_over(boxed, 4.9)
    pipeline.config.plane_refinement.refine_constrained = "all"
    pipeline._refine_constrained(planes(pipeline, scan_at(boxed, 5.0)), pose_at(5.0), screened)
    assert pipeline.counters["constrained_rounds_extra"] == 0
    with pytest.raises(ValueError, match="constrained_rounds"):
        PlaneRefinementConfig(constrained_rounds=0).validate()


def test_a_screened_scan_is_also_refined_from_the_prediction_and_the_better_fit_kept():
    screened, detected = _screen_and_detection()
    registration = _off_by(0.25)

    def refined(degeneracy, on, prediction=_off_by(0.01)):
        return _refined_in_short_corridor(degeneracy, registration, 1, "planar", prediction, on)

    alone, counters = refined(screened, False)
    assert alone[0, 3] - 5.0 > 0.1 and counters["constrained_from_prediction"] == 0
    both, counters = refined(screened, True)
    assert abs(both[0, 3] - 5.0) < 0.02 and counters["constrained_from_prediction"] == 1
    # a prediction that fits worse is not taken; a detection's result is not refined from it
    np.testing.assert_allclose(refined(screened, True, _off_by(0.6))[0], alone, atol=1e-9)
    np.testing.assert_allclose(refined(detected, True)[0], alone, atol=1e-9)


def test_only_directions_held_to_constrained_information_take_the_refined_step():
    from dataclasses import replace

    from lili_odom.degeneracy.result import DegeneracyResult

    none = DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 10.0)
    boxed = corridor(40.0, end_walls=True)  # far end walls: the axis is held, but weakly
    pipeline = _pipeline_over(boxed, 19.9)
    cfg = pipeline.config.plane_refinement
    cfg.refine_constrained = "all"
    off_by = pose_at(20.0)
    off_by[:3, 3] += [0.08, 0.06, 0.0]
    fits = planes(pipeline, scan_at(boxed, 20.0))
    info = refine_in_subspace(fits.points, fits.reference, pose_at(20.0), np.eye(6)[:2], 10.0,
                              replace(cfg, iterations=0), fits=fits.at(pose_at(20.0)))
    along, across = np.diag(info.information)
    assert 0 < along < 0.1 * across  # the axis is held, far less than across it
    cfg.constrained_information = 0.5 * along
    refined = pipeline._refine_constrained(fits, off_by, none)
    assert abs(refined[0, 3] - 20.0) < 0.03 and abs(refined[1, 3]) < 0.02
    cfg.constrained_information = float(np.sqrt(along * across))  # between the two
    refined = pipeline._refine_constrained(fits, off_by, none)
    assert abs(refined[0, 3] - 20.08) < 2e-3 and abs(refined[1, 3]) < 0.02
    with pytest.raises(ValueError, match="constrained_information"):
        PlaneRefinementConfig(constrained_information=0.0).validate()


def test_closed_form_eigen_matches_numpy_on_planar_and_generic_neighbourhoods():
    from lili_odom.pipeline.plane_refinement import symmetric_eigen3

    rng = np.random.default_rng(5)
    m = 2000
    R = np.linalg.qr(rng.normal(size=(m, 3, 3)))[0]
    spread = np.c_[rng.uniform(0.1, 2, m), rng.uniform(0.05, 1, m),
                   np.where(np.arange(m) % 2, rng.uniform(1e-4, 1e-2, m), rng.uniform(0.05, 1, m))]
    pts = rng.normal(size=(m, 10, 3)) * spread[:, None, :] @ R.transpose(0, 2, 1)
    d = pts - pts.mean(axis=1, keepdims=True)
    A = d.transpose(0, 2, 1) @ d / 10
    w, v = symmetric_eigen3(A)
    W, V = np.linalg.eigh(A)
    assert np.allclose(w, W, rtol=0, atol=1e-12 * W[:, 2:].max())
    planar = (W[:, 1] - W[:, 0]) / W[:, 2] > 0.3
    assert planar.sum() > m // 4
    assert np.allclose(np.abs(np.einsum("ij,ij->i", v, V[:, :, 0]))[planar], 1.0, atol=1e-9)
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0)
    # isotropic and zero matrices: equal eigenvalues, some unit vector, no NaN
    w0, v0 = symmetric_eigen3(np.stack([np.eye(3), np.zeros((3, 3))]))
    assert np.allclose(w0, [[1, 1, 1], [0, 0, 0]]) and np.all(np.isfinite(v0))


def test_the_fit_noise_term_equals_its_per_point_sum():
    """``_debiased`` subtracts ``sum_m w_m A_m^T A_m`` (``A_m = Tv - [p_m]x Tw``) from the
    information; its closed form from the points' moments equals the sum written out."""
    from lili_odom.pipeline.plane_refinement import _debiased

    rng = np.random.default_rng(3)
    points = rng.normal(size=(200, 3)) * 4.0
    weights = rng.uniform(0.0, 1.0, 200)
    to_twist = rng.normal(size=(6, 2))
    Tv, Tw = to_twist[:3], to_twist[3:]
    noise = sum(w * (Tv - geometry.hat(p) @ Tw).T @ (Tv - geometry.hat(p) @ Tw)
                for p, w in zip(points, weights))
    H = noise + np.diag([50.0, 3.0])  # PSD after the subtraction: nothing clipped
    np.testing.assert_allclose(_debiased(H, points, to_twist, weights), np.diag([50.0, 3.0]),
                               atol=1e-8)
    np.testing.assert_allclose(geometry.hat([1.0, 2.0, 3.0]) @ [-2.0, 0.5, 4.0],
                               np.cross([1.0, 2.0, 3.0], [-2.0, 0.5, 4.0]))


def test_a_tree_built_ahead_is_the_tree_of_the_current_map():
    from lili_odom.pipeline.scan_matcher import insert_scan

    rng = np.random.default_rng(3)
    ref = ReferenceMap.from_points(rng.uniform(-10, 10, (3000, 3)), 1.0, 20)
    q = rng.uniform(-10, 10, (200, 3))
    ref.build_kdtree_ahead()
    assert "_kdtree_future" in ref.__dict__
    _, i_ahead = ref.kdtree.query(q, k=5)
    _, i_now = cKDTree(ref.points).query(q, k=5)
    np.testing.assert_array_equal(i_ahead, i_now)
    # a map change discards the tree (and one started ahead): the next one has the new points
    ref.build_kdtree_ahead()
    insert_scan(ref, rng.uniform(10, 20, (500, 3)), np.eye(4))
    ref.build_kdtree_ahead()
    assert ref.kdtree.n == len(ref.points) > 3000
    empty = ReferenceMap.from_points(np.zeros((0, 3)), 1.0, 20)
    empty.build_kdtree_ahead()  # nothing to build: no thread, and no error
    assert "_kdtree_future" not in empty.__dict__


def _tree_in_forked_child(ref: ReferenceMap, queue) -> None:
    ref.build_kdtree_ahead()  # inherited from the parent: a tree the child cannot wait for
    fresh = ReferenceMap.from_points(ref.points + 1.0, 1.0, 20)
    fresh.build_kdtree_ahead()  # the parent's builder thread does not exist in the child
    queue.put((ref.kdtree.n, fresh.kdtree.n))


def test_a_forked_child_builds_its_own_trees():
    """A process forked while a tree was being built ahead (a process pool's worker) neither
    waits for the parent's thread nor uses its half-built tree."""
    import multiprocessing as mp

    if "fork" not in mp.get_all_start_methods():
        pytest.skip("no fork on this platform")
    rng = np.random.default_rng(4)
    ref = ReferenceMap.from_points(rng.uniform(-10, 10, (3000, 3)), 1.0, 20)
    ReferenceMap.from_points(rng.uniform(-10, 10, (100, 3)), 1.0, 20).build_kdtree_ahead()
    ref.build_kdtree_ahead()
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_tree_in_forked_child, args=(ref, queue), daemon=True)
    child.start()
    try:
        got = queue.get(timeout=60)
        child.join(timeout=10)
    finally:
        if child.is_alive():
            child.terminate()
    assert child.exitcode == 0
    assert got == (len(ref.points), len(ref.points))
    assert ref.kdtree.n == len(ref.points)


def test_plane_cost_is_lower_at_the_pose_that_fits():
    from lili_odom.pipeline.plane_refinement import plane_cost

    world = corridor(40.0, end_walls=True)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 25.0)
    fits = fit_planes(scan, ref, pose_at(25.2))
    assert plane_cost(fits, pose_at(25.0)) < 0.5 * plane_cost(fits, pose_at(25.2))
    assert plane_cost(fits, pose_at(25.0)) < plane_cost(fits, pose_at(24.9))
    empty = fit_planes(scan, ReferenceMap.from_points(world[:3], 1.0, 200), pose_at(25.0))
    assert plane_cost(empty, pose_at(25.0)) == float("inf")


def _refined_from(pipeline, world, scan_x, measured_x, guess_x):
    from lili_odom.degeneracy.result import DegeneracyResult

    det = DegeneracyResult("lili", np.eye(4), AXIS_X, 10.0)
    fits = planes(pipeline, scan_at(world, scan_x))
    measured = pose_at(measured_x)
    first = refine_in_subspace(fits.points, fits.reference, measured, AXIS_X, 10.0,
                               pipeline.config.plane_refinement, fits=fits.at(measured))
    return first, pipeline._refined_from_prediction(fits, first, measured, pose_at(guess_x),
                                                    det, check_return=True)


def test_without_wheels_the_refinement_also_starts_at_the_prediction():
    # a registration dragged 0.5 m back: the end wall's planes are beyond the refinement's
    # residual gate from there, and the refinement started at the prediction finds them
    closed = corridor(40.0, end_walls=True)
    pipeline = _pipeline_over(closed, 24.8)
    first, chosen = _refined_from(pipeline, closed, 25.0, 24.5, 25.05)
    assert abs(first.pose[0, 3] - 25.0) > 0.2
    assert abs(chosen.pose[0, 3] - 25.0) < 0.02
    assert pipeline.counters["refined_from_prediction"] == 1
    # in a tube the planes hold nothing along the axis: the registration's refinement stays
    tube = corridor(200.0, end_walls=False)
    pipeline = _pipeline_over(tube, 99.8)
    first, chosen = _refined_from(pipeline, tube, 100.0, 99.7, 100.05)
    assert chosen is first and pipeline.counters["refined_from_prediction"] == 0
    # a prediction within 2 cm of the registration is not refined twice
    pipeline = _pipeline_over(closed, 24.8)
    first, chosen = _refined_from(pipeline, closed, 25.0, 25.0, 25.01)
    assert chosen is first and pipeline.counters["refined_from_prediction"] == 0


def poles_on_ground(seed: int = 0) -> np.ndarray:
    """Flat ground (z = 0, 40 x 40 m) with six thin vertical poles (radius 0.1 m, 4 m high),
    each sampled on the half facing the origin (what a sensor near it sees)."""
    rng = np.random.default_rng(seed)
    g = np.arange(-20.0, 20.0, 0.4)
    X, Y = np.meshgrid(g, g)
    ground = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    poles = []
    for cx, cy in ((6.0, 4.0), (-5.0, 7.0), (9.0, -6.0), (-8.0, -5.0), (2.0, -9.0), (12.0, 1.0)):
        z = np.arange(0.0, 4.0, 0.05)
        a = np.arctan2(-cy, -cx) + rng.uniform(-0.5 * np.pi, 0.5 * np.pi, len(z))
        poles.append(np.c_[cx + 0.1 * np.cos(a), cy + 0.1 * np.sin(a), z])
    pts = np.vstack([ground] + poles)
    return pts + rng.normal(0.0, 0.005, pts.shape)


@pytest.mark.parametrize("axis", [AXIS_X, AXIS_Y])
def test_vertical_lines_hold_open_ground_across_the_poles(axis):
    world = poles_on_ground()
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 0.0, n=20000)
    truth = pose_at(0.0)
    start = truth.copy()
    start[:3, 3] += 0.1 * axis[0, :3]  # 10 cm off across the poles
    with_lines = refine_in_subspace(scan, ref, start, axis, 1.0,
                                    PlaneRefinementConfig(points=20000, vertical_lines=True))
    planes_only = refine_in_subspace(scan, ref, start, axis, 1.0,
                                     PlaneRefinementConfig(points=20000))
    assert with_lines.ok and with_lines.information[0, 0] > 1000.0
    assert np.linalg.norm(with_lines.pose[:3, 3] - truth[:3, 3]) < 0.02
    # the ground's normals say nothing across the poles, the few planar patches of the
    # poles' surface little: the pose stays far off
    assert planes_only.information[0, 0] < 0.5 * with_lines.information[0, 0]
    assert np.linalg.norm(planes_only.pose[:3, 3] - truth[:3, 3]) > 0.04


@pytest.mark.parametrize("tilt_deg, used", [(0.0, True), (15.0, True), (45.0, False),
                                             (90.0, False)])
def test_only_near_vertical_lines_are_used(tilt_deg, used):
    """A pole is a vertical line; a sparse scan's ring on the ground or a wall is a
    horizontal one that moves with the sensor and must not become a constraint."""
    u = np.array([np.sin(np.deg2rad(tilt_deg)), 0.0, np.cos(np.deg2rad(tilt_deg))])
    t = np.arange(-3.0, 3.0, 0.05)
    lines = np.vstack([np.array([4.0, y, 2.0]) + t[:, None] * u for y in (-3.0, 3.0)])
    ref = ReferenceMap.from_points(lines, 1.0, 200)
    scan = lines[10:-10:3] - [0.0, 0.0, 1.5]  # sensor frame at pose_at(0)
    fits = fit_planes(scan, ref, pose_at(0.0),
                      PlaneRefinementConfig(points=20000, vertical_lines=True))
    if not used:
        assert not fits.valid.any() and len(fits.points) == len(scan)
        return
    assert fits.valid.all() and len(fits.points) == 2 * len(scan)  # two planes per point
    assert not fit_planes(scan, ref, pose_at(0.0), PlaneRefinementConfig(points=20000)).valid.any()
    n = len(scan)
    normals = fits.normals
    assert np.allclose(np.abs(normals @ u), 0.0, atol=0.05)  # both across the line
    assert np.allclose(np.einsum("ij,ij->i", normals[:n], normals[n:]), 0.0, atol=1e-9)


def test_strips_of_a_wall_are_not_lines():
    """A sparse sensor driving towards a wall leaves vertical strips of map points at its
    columns' bearings: the nearest ten points of a strip form a vertical line, the wider
    neighbourhood (``line_neighbors``) the wall's plane, which the point gets. Only without
    that check do the strips count as poles."""
    z = np.arange(0.0, 4.0, 0.1)
    wall = np.vstack([np.c_[np.full_like(z, 4.0), np.full_like(z, y), z]
                      for y in np.arange(-6.0, 6.0, 0.8)])
    ref = ReferenceMap.from_points(wall, 1.0, 200)
    scan = wall[::3] - [0.0, 0.0, 1.5]  # sensor frame at pose_at(0)
    checked = fit_planes(scan, ref, pose_at(0.0),
                         PlaneRefinementConfig(points=20000, vertical_lines=True))
    assert PlaneRefinementConfig().line_neighbors == 30  # the default checks
    unchecked = fit_planes(scan, ref, pose_at(0.0), PlaneRefinementConfig(
        points=20000, vertical_lines=True, line_neighbors=0))
    assert unchecked.valid.mean() > 0.5  # most strip points became two planes each
    assert len(unchecked.points) > len(scan)
    assert len(checked.points) == len(scan)  # no point on a line
    # the strip points get the wall's plane from their wider neighbourhood (a few near the
    # strips' ends, whose wider neighbourhood is neither line nor plane, get none)
    assert checked.valid.mean() > 0.8
    assert np.allclose(np.abs(checked.normals[checked.valid, 0]), 1.0, atol=1e-6)
    # a pole stays a line with the check: its wider neighbourhood is the pole too
    world = poles_on_ground()
    pole = world[world[:, 2] > 1.0]
    ref = ReferenceMap.from_points(world, 1.0, 200)
    lines = [len(fit_planes(pole, ref, np.eye(4), PlaneRefinementConfig(
        points=20000, vertical_lines=True, line_neighbors=n)).points) - len(pole)
        for n in (30, 0)]
    assert lines[1] > 0.8 * len(pole) and lines[0] > 0.9 * lines[1]


def toothed_tube(length: float = 200.0, period: float = 0.12, depth: float = 0.04,
                 width: float = 2.6, height: float = 3.0, seed: int = 0) -> np.ndarray:
    """A corridor without end walls whose side walls are a fine sawtooth along x (teeth of
    ``period`` [m], ``depth`` [m] deep): every tooth holds a point along the axis, but only to
    within one period."""
    rng = np.random.default_rng(seed)
    X, Z = np.meshgrid(np.arange(0.0, length, 0.02), np.arange(0.0, height, 0.1))
    X, Z = X.ravel(), Z.ravel()
    tooth = depth * (X % period) / period
    walls = [np.c_[X, side * (width / 2 + tooth), Z] for side in (-1, 1)]
    Xf, Yf = np.meshgrid(np.arange(0.0, length, 0.1), np.arange(-width / 2, width / 2, 0.1))
    flats = [np.c_[Xf.ravel(), Yf.ravel(), np.full(Xf.size, z)] for z in (0.0, height)]
    pts = np.vstack(walls + flats)
    return pts + rng.normal(0.0, 0.002, pts.shape)


def test_end_walls_bring_a_moved_refinement_back():
    world = corridor(40.0, end_walls=True)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 25.0)
    res = refine_in_subspace(scan, ref, pose_at(25.01), AXIS_X, 10.0)
    rows, ratios = returned_directions(scan, ref, res, 10.0)
    assert np.allclose(np.abs(rows), AXIS_X)
    assert abs(ratios[0]) < 0.1  # back from 10 cm to within 1 cm
    assert without_unheld(res, rows, ratios, 0.5) is res


def test_information_a_moved_refinement_does_not_come_back_along_is_dropped():
    # the teeth give the axis point-to-plane information, but a refinement moved by 10 cm
    # settles on the next tooth (12 cm on) instead of coming back
    world = toothed_tube()
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 100.0)
    res = refine_in_subspace(scan, ref, pose_at(100.01), AXIS_X, 10.0)
    assert res.information[0, 0] > 100.0  # claims better than 10 cm
    rows, ratios = returned_directions(scan, ref, res, 10.0)
    assert ratios[0] > 0.5
    held = without_unheld(res, rows, ratios, 0.5)
    assert held is not res and held.details["unheld"] == 1
    assert np.allclose(held.information, 0.0) and np.allclose(held.information_scaled, 0.0)
    assert np.array_equal(held.pose, res.pose)


def test_only_the_directions_that_did_not_come_back_lose_their_information():
    from lili_odom.pipeline.plane_refinement import PlaneRefinement

    B = np.vstack([AXIS_X, AXIS_Y])
    info = np.diag([400.0, 900.0])
    res = PlaneRefinement(np.eye(4), info, B.T @ info @ B, B)
    rows = np.vstack([AXIS_Y, AXIS_X])  # eigen-directions in another order
    held = without_unheld(res, rows, np.array([0.1, 2.0]), 0.5)
    assert np.allclose(held.information, np.diag([0.0, 900.0]))
    assert np.allclose(held.information_scaled, AXIS_Y.T @ AXIS_Y * 900.0)
    assert without_unheld(res, rows, np.array([0.1, -0.4]), 0.5) is res
    # a moved refinement that found too few planes (inf) did not come back either
    assert np.allclose(without_unheld(res, rows, np.array([np.inf, 0.0]), 0.5).information,
                       np.diag([400.0, 0.0]))


def test_bounds_cap_an_unheld_direction_instead_of_dropping_it():
    from lili_odom.pipeline.plane_refinement import PlaneRefinement

    B = np.vstack([AXIS_X, AXIS_Y])
    info = np.array([[400.0, 30.0], [30.0, 900.0]])
    res = PlaneRefinement(np.eye(4), info, B.T @ info @ B, B)
    rows = np.vstack([AXIS_Y, AXIS_X])
    ratios = np.array([2.0, 0.1])  # y did not come back, x did
    held = without_unheld(res, rows, ratios, 0.5, bounds=np.array([100.0, 5.0]))
    # y capped at 100 m^-2 (a 10 cm sigma), its coupling to x gone, x untouched
    assert np.allclose(held.information, np.diag([400.0, 100.0]))
    assert np.allclose(held.information_scaled, B.T @ held.information @ B)
    # a bound above what the direction had leaves its own information, without the coupling
    loose = without_unheld(res, rows, ratios, 0.5, bounds=np.array([1e6, 1e6]))
    assert np.allclose(loose.information, np.diag([400.0, 900.0]))
    assert np.allclose(without_unheld(res, rows, ratios, 0.5, bounds=np.zeros(2)).information,
                       without_unheld(res, rows, ratios, 0.5).information)


def test_a_direction_without_information_is_not_tested(monkeypatch):
    import lili_odom.pipeline.plane_refinement as plane_refinement

    world = corridor(200.0, end_walls=False)
    ref = ReferenceMap.from_points(world, 1.0, 200)
    scan = scan_at(world, 100.0)
    res = refine_in_subspace(scan, ref, pose_at(100.0), AXIS_X, 10.0)
    assert res.information[0, 0] < 1.0
    calls = []
    monkeypatch.setattr(plane_refinement, "refine_in_subspace",
                        lambda *a, **k: calls.append(a) or res)
    rows, ratios = returned_directions(scan, ref, res, 10.0)
    assert ratios.tolist() == [0.0] and not calls


def test_without_wheels_the_pipeline_drops_information_that_does_not_come_back():
    from lili_odom.degeneracy.result import DegeneracyResult

    det = DegeneracyResult("lili", np.eye(4), AXIS_X, 10.0)
    for world, x, kept in ((corridor(40.0, end_walls=True), 25.0, True),
                           (toothed_tube(), 100.0, False)):
        pipeline = _pipeline_over(world, x - 0.1)
        fits = planes(pipeline, scan_at(world, x))
        start = pose_at(x + 0.01)
        res = refine_in_subspace(fits.points, fits.reference, start, AXIS_X, 10.0,
                                 pipeline.config.plane_refinement, fits=fits.at(start))
        held = pipeline._checked_by_offset(fits, res, det)
        assert pipeline.counters["return_checks"] == 1
        assert (held is res) == kept
        assert pipeline.counters["unheld_directions"] == (0 if kept else 1)


def test_without_wheels_a_direction_the_prediction_does_not_come_back_along_is_dropped():
    # the registration 10 cm behind the prediction: between end walls the refinement from the
    # prediction comes back to the registration's; on the sawtooth it stays on its own tooth
    closed = corridor(40.0, end_walls=True)
    pipeline = _pipeline_over(closed, 24.9)
    first, chosen = _refined_from(pipeline, closed, 25.0, 24.99, 25.09)
    assert pipeline.counters["return_checks"] == 1 and pipeline.counters["unheld_directions"] == 0
    assert chosen is first and chosen.information[0, 0] > 100.0
    toothed = toothed_tube()
    pipeline = _pipeline_over(toothed, 99.9)
    first, chosen = _refined_from(pipeline, toothed, 100.0, 100.0, 100.1)
    assert first.information[0, 0] > 100.0
    assert pipeline.counters["return_checks"] == 1 and pipeline.counters["unheld_directions"] == 1
    assert np.allclose(chosen.information, 0.0) and np.array_equal(chosen.pose, first.pose)
    # with the check off the information stays
    pipeline = _pipeline_over(toothed, 99.9)
    pipeline.config.plane_refinement.return_check = "off"
    first, chosen = _refined_from(pipeline, toothed, 100.0, 100.0, 100.1)
    assert chosen is first and pipeline.counters["return_checks"] == 0


def lamps(xs: np.ndarray, points: int, seed: int, half: float = 0.1) -> np.ndarray:
    """Small lamps under a ceiling: ``points`` random points on the faces of a cube of edge
    ``2 half`` [m] at x = each of ``xs``, y = 0, z = 2.7 (a sparse scan of a fitting: its
    nearest map points span several faces)."""
    rng = np.random.default_rng(seed)
    out = []
    for x in xs:
        p = rng.uniform(-half, half, (points, 3))
        p[np.arange(points), rng.integers(0, 3, points)] = rng.choice([-half, half], points)
        out.append(p + [x, 0.0, 2.7])
    return np.vstack(out)


def test_blobs_bring_a_tube_with_lamps_back_along_its_axis():
    """In a corridor without end walls whose only features are small lamps, the lamps'
    neighbourhoods are neither planes nor lines: as blobs they hold the axis."""
    tube = corridor(60.0, end_walls=False, step=0.1)
    xs = np.arange(2.0, 60.0, 4.0)
    ref = ReferenceMap.from_points(np.vstack([tube, lamps(xs, 100, seed=0)]), 1.0, 400)
    seen = np.vstack([tube[::7], lamps(xs, 38, seed=1)]) - [30.0, 0.0, 1.5]
    scan = seen[np.linalg.norm(seen, axis=1) < 30.0]
    start = pose_at(30.0)
    start[0, 3] += 0.1  # 10 cm off along the axis
    cfg = PlaneRefinementConfig(points=40000, blobs=True, iterations=10)
    refined = refine_in_subspace(scan, ref, start, AXIS_X, 1.0, cfg)
    fits = fit_planes(scan, ref, start, cfg)
    assert len(fits.points) > len(scan)  # blob rows were added
    assert refined.ok and refined.information[0, 0] > 1000.0
    assert abs(refined.pose[0, 3] - 30.0) < 0.02


def test_a_blob_gets_three_rows_along_its_weighted_axes():
    """Each point in a blob gets three residuals through its neighbourhood's centroid,
    along the neighbourhood's principal axes, weighted by ``sigma / sqrt(l + sigma^2)``;
    planes and lines (a sparse scan's ring, which moves with the sensor) are no blobs."""
    from lili_odom.pipeline.plane_refinement import _blob_axes

    lam, axes = _blob_axes(np.array([np.diag([0.09, 1e-4, 0.01])]), 0.03)
    assert np.allclose(lam, [[1e-4, 0.01, 0.09]])
    axes = axes[0]
    # ascending variance: y (1e-4 m^2), z (0.01), x (0.09)
    expected = np.array([[0.0, 0.03 / np.sqrt(1e-4 + 9e-4), 0.0],
                         [0.0, 0.0, 0.03 / np.sqrt(0.01 + 9e-4)],
                         [0.03 / np.sqrt(0.09 + 9e-4), 0.0, 0.0]])
    assert np.allclose(np.abs(axes), expected)
    rng = np.random.default_rng(3)
    blob = rng.normal([4.0, 0.0, 2.0], 0.1, (500, 3))
    ref = ReferenceMap.from_points(blob, 1.0, 1000)
    scan = blob[::10] - [0.0, 0.0, 1.5]
    cfg = PlaneRefinementConfig(points=20000, blobs=True, normal_neighbors=50, max_blob_spread=1.0)
    fits = fit_planes(scan, ref, pose_at(0.0), cfg)
    n = len(scan)
    m = (len(fits.points) - n) // 2  # points in a blob: two further rows each
    assert len(fits.points) == n + 2 * m and m > 0.6 * n
    first = np.array([np.flatnonzero((fits.points[:n] == p).all(axis=1))[0]
                      for p in fits.points[n:n + m]])
    assert np.array_equal(fits.points[n + m:], fits.points[n:n + m])
    assert fits.valid[first].all()
    assert np.allclose(fits.centroids[n:n + m], fits.centroids[first])
    N = np.stack([fits.normals[first], fits.normals[n:n + m], fits.normals[n + m:]], axis=1)
    gram = np.einsum("nij,nkj->nik", N, N)
    assert np.allclose(gram - np.einsum("nii->ni", gram)[:, :, None] * np.eye(3), 0.0,
                       atol=1e-9)  # orthogonal axes
    assert np.all(np.linalg.norm(N, axis=2) <= 1.0)
    # without blobs those points have no residual (the few planar neighbourhoods keep theirs)
    planes_only = fit_planes(scan, ref, pose_at(0.0), replace(cfg, blobs=False))
    assert len(planes_only.points) == n and not planes_only.valid[first].any()
    assert planes_only.valid.sum() == fits.valid[:n].sum() - m
    t = np.arange(-3.0, 3.0, 0.05)
    ring = np.c_[np.full_like(t, 4.0), t, np.zeros_like(t)]  # a horizontal line
    flat = np.c_[rng.uniform(-3, 3, (2000, 2)), np.zeros(2000)] + [6.0, 0.0, 0.0]
    for cloud in (ring, flat):
        ref = ReferenceMap.from_points(cloud, 1.0, 1000)
        fits = fit_planes(cloud[::5] - [0, 0, 1.5], ref, pose_at(0.0),
                          PlaneRefinementConfig(points=20000, blobs=True))
        assert len(fits.points) == len(cloud[::5])  # no blob rows


def test_blob_axes_the_search_cut_off_hold_the_pose_where_it_was_put():
    """Lamps that are clusters of points with no surface: along an axis where a blob's ten
    nearest map points are cut off by the search, their centroid follows the point, so with
    every axis (``max_blob_spread`` 1) the refinement stays near where it started, claiming
    information; with only the closed axes (the default) it comes back as planes alone do."""
    rng = np.random.default_rng(0)
    tube = corridor(60.0, end_walls=False, step=0.1)
    xs = np.arange(2.0, 60.0, 4.0)
    ref = ReferenceMap.from_points(
        np.vstack([tube] + [rng.normal([x, 0.0, 2.7], 0.1, (30, 3)) for x in xs]), 1.0, 400)
    seen = np.vstack([tube[::7]] + [rng.normal([x, 0.0, 2.7], 0.1, (15, 3)) for x in xs])
    scan = seen - [30.0, 0.0, 1.5]
    scan = scan[np.linalg.norm(scan, axis=1) < 30.0]
    start = pose_at(30.0)
    start[0, 3] += 0.1  # 10 cm off along the axis

    def left(**kw) -> float:
        cfg = PlaneRefinementConfig(points=40000, iterations=10, **kw)
        return abs(refine_in_subspace(scan, ref, start, AXIS_X, 1.0, cfg).pose[0, 3] - 30.0)

    planes = left()
    assert left(blobs=True, max_blob_spread=1.0) > 0.05 > planes
    assert left(blobs=True) < planes + 0.01
