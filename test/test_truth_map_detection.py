"""The detector against a local map from the true poses (the judge of false detections)."""
import numpy as np
import pytest

from lili_odom.evaluation.truth_map_detection import TruthMapDetector
from lili_odom.pipeline.odometry import PipelineConfig
from lili_odom.sim.generator import SimRequest, Simulation


def _judge(world: str, **kwargs) -> TruthMapDetector:
    sim = Simulation(SimRequest(world=world, trial=1, resolution=(32, 256)))
    return TruthMapDetector(sim, history_s=1.0, **kwargs)


def test_constrained_hall_has_dimension_zero():
    """In the building's hall (pillars, cars, crates) the detector finds nothing."""
    d = _judge("building").detect(8.0)
    assert d.map_scans == 10 and d.points > 100
    assert d.dimension == 0
    assert d.t_end == pytest.approx(8.0 + 0.1 * 255 / 256)


def test_bare_tunnel_is_degenerate_along_its_axis():
    """50 m inside the straight bare tunnel the axis (world x, the LiDAR's forward) is free."""
    judge = _judge("long_tunnel")
    d = judge.detect(60.0)
    assert d.pose[0, 3] > 40.0
    assert d.dimension == 1
    axis = d.result.basis_scaled[0] / np.linalg.norm(d.result.basis_scaled[0])
    assert abs(axis[0]) > 0.95


def test_refuses_what_it_cannot_judge():
    with pytest.raises(ValueError, match="needs a detector"):
        _judge("building", config=PipelineConfig(method="none"))
    judge = _judge("building")
    with pytest.raises(ValueError, match="nothing to detect against"):
        judge.detect(judge.sim.window()[0])


def test_constrained_stretches_need_consecutive_samples():
    from benchmarks.false_detections import stretch_mask

    c = np.array([1, 0, 1, 1, 1, 0, 1, 1, 0, 1, 1, 1, 1], dtype=bool)
    expected = np.array([0, 0, 1, 1, 1, 0, 0, 0, 0, 1, 1, 1, 1], dtype=bool)
    np.testing.assert_array_equal(stretch_mask(c, 3), expected)
    assert not stretch_mask(np.zeros(4, dtype=bool)).any()


def test_odometry_flags_read_the_degenerate_and_the_weakly_held_directions(tmp_path):
    from benchmarks.false_detections import odometry_flags

    new = tmp_path / "new.csv"
    new.write_text("stamp,dimension,weak_directions,weakly_held\n"
                   "1.0,0,0,0\n1.1,0,1,1\n1.2,1,0,1\n1.3,1,1,0\n")
    stamps, dims, detected, subspace = odometry_flags(new)
    np.testing.assert_allclose(stamps, [1.0, 1.1, 1.2, 1.3])
    np.testing.assert_array_equal(dims, [0, 0, 1, 1])
    np.testing.assert_array_equal(subspace, [0, 1, 2, 1])
    np.testing.assert_array_equal(detected, [0, 0, 2, 0])  # the subspace less the weak check's
    old = tmp_path / "old.csv"  # runs before the split: dimension was the whole subspace
    old.write_text("stamp,dimension,weak_directions\n1.0,2,1\n1.1,0,0\n")
    _, dims, detected, subspace = odometry_flags(old)
    np.testing.assert_array_equal(dims, [2, 0])
    np.testing.assert_array_equal(detected, [1, 0])
    assert subspace is None


def test_placement_moves_the_map_and_the_guess():
    """Scans placed by another frame's poses (here the truth moved rigidly) give the same
    answer; a scan the placement has no pose for is left out of the map, or refused when it
    is the tested one."""
    sim = Simulation(SimRequest(world="building", trial=1, resolution=(32, 256)))
    shift = np.eye(4)
    shift[:3, 3] = [5.0, -3.0, 1.0]

    def shifted(t):
        return shift @ sim.trajectory.pose(np.array([t]))[0]

    judge = TruthMapDetector(sim, history_s=1.0)
    d = judge.detect(8.0, placement=shifted)
    assert d.dimension == 0
    np.testing.assert_allclose(d.pose[:3, 3] - shift[:3, 3],
                               (sim.trajectory.pose(np.array([d.t_end]))[0]
                                @ sim.sensors.extrinsics.base_to_lidar)[:3, 3], atol=1e-9)

    def gap(t):
        return None if 7.5 < t < 7.95 else shifted(t)

    assert judge.detect(8.0, placement=gap).map_scans < 10
    with pytest.raises(ValueError, match="no placement"):
        judge.detect(8.0, placement=lambda t: None)
    assert judge.detect(8.0).map_scans == 10  # the true poses again, from the kept sweeps
    assert len(judge._sweeps) <= 11


def test_map_in_the_odometrys_extent_grows_in_scan_order():
    """``history_s=None``: one map grows with every scan from the window's start, as the
    odometry's does; up to the first 3 s it holds what a 3 s history holds."""
    sim = Simulation(SimRequest(world="building", trial=1, resolution=(32, 256)))
    w0 = sim.window()[0]
    grown = TruthMapDetector(sim, history_s=None)
    d = grown.detect(w0 + 3.0)
    same = TruthMapDetector(sim, history_s=3.0).detect(w0 + 3.0)
    assert d.map_scans == same.map_scans == 30
    assert d.dimension == same.dimension == 0
    assert grown.detect(w0 + 5.0).map_scans == 50
    with pytest.raises(ValueError, match="scan order"):
        grown.detect(w0 + 4.0)
    assert len(grown._sweeps) <= 2
