"""On a featureless tunnel stretch, ``lili`` and ``none`` differ the way the degeneracy says.

A simulated piece of Trial 1 deep inside the tunnel (no features in range): scan matching alone
cannot see motion along the tunnel axis. ``none`` trusts the registration there and loses the
distance travelled; ``lili`` detects the one-dimensional degenerate subspace along the axis in
most scans, takes that direction from the wheels and stays close to the truth.
"""
from __future__ import annotations

import numpy as np
import pytest

from lili_odom.bagio.reader import BagReader
from lili_odom.cli import main as cli_main
from lili_odom.config import NodeConfig
from lili_odom.evaluation.metrics import evaluate
from lili_odom.evaluation.replay import Replay


@pytest.fixture(scope="module")
def featureless_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "featureless"
    assert cli_main(["simulate", "tunnel", "--trial", "1", "--start", "100", "--duration", "8",
                     "--resolution", "32x256", "--seed", "0", "--out", str(out),
                     "--no-progress"]) == 0
    return out


def _run(bag, method):
    config = NodeConfig()
    config.pipeline.method = method
    outputs = []
    replay = Replay(config, on_output=lambda out, _pipeline: outputs.append(out))
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic, "/tf_static",
              config.ground_truth_topic]
    with BagReader(bag, topics=topics) as reader:
        replay.run(reader)
    truth = replay.truth
    metrics = evaluate(np.array([o.stamp for o in outputs]), np.array([o.pose for o in outputs]),
                       np.array([s for s, _ in truth]), np.array([T for _, T in truth]))
    return outputs, metrics


def _replay_first_scans(bag, config, wheels: bool, max_scans: int = 30) -> Replay:
    """``config`` replayed over the first ``max_scans`` scans of ``bag`` with its LiDAR, IMU
    and extrinsics, and its wheel odometry only with ``wheels``."""
    topics = [config.lidar_topic, config.imu_topic, "/tf_static"]
    if wheels:
        topics.append(config.wheel_topic)
    replay = Replay(config)
    with BagReader(bag, topics=topics) as reader:
        replay.run(reader, max_scans=max_scans)
    return replay


def test_lili_follows_the_wheels_where_none_slides(featureless_bag):
    none_out, none_m = _run(featureless_bag, "none")
    lili_out, lili_m = _run(featureless_bag, "lili")
    assert len(none_out) == len(lili_out) == 80
    assert none_m.path_length_m > 5.0  # the robot really drives ~7.7 m
    # lili: degenerate along the tunnel axis (base_link x) in most scans
    dims = np.array([o.degeneracy.dimension if o.degeneracy else 0 for o in lili_out])
    assert np.mean(dims > 0) >= 0.6, dims
    axis_share = [np.abs(o.degenerate_basis[:, 0]).max() for o in lili_out
                  if len(o.degenerate_basis)]
    assert np.median(axis_share) > 0.9
    # and that is what decides the accuracy
    assert lili_m.ate_rmse_m < 0.3, lili_m
    assert none_m.ate_rmse_m > 0.5 and none_m.ate_rmse_m > 4 * lili_m.ate_rmse_m, (none_m, lili_m)


def test_without_wheel_data_the_subspace_information_takes_its_factor(featureless_bag,
                                                                      monkeypatch):
    """``plane_refinement.information_without_wheels`` scales the refinement's information
    on scans without wheel data, and only there."""
    from lili_odom.fusion.estimator import FusionEstimator

    def first_subspace_information(factor, wheels):
        config = NodeConfig()
        config.pipeline.method = "lili"
        config.pipeline.plane_refinement.information_without_wheels = factor
        seen = []
        update = FusionEstimator.update

        def recording(self, t, T_icp_base, degeneracy, subspace=None, **kwargs):
            if subspace is not None and np.abs(subspace.information_scaled).max() > 0:
                seen.append(np.array(subspace.information_scaled))  # the runs part after it
            return update(self, t, T_icp_base, degeneracy, subspace=subspace, **kwargs)

        monkeypatch.setattr(FusionEstimator, "update", recording)
        _replay_first_scans(featureless_bag, config, wheels)
        monkeypatch.setattr(FusionEstimator, "update", update)
        assert seen, "no scan had a subspace measurement with information"
        return seen[0]

    full = first_subspace_information(1.0, wheels=False)
    np.testing.assert_allclose(first_subspace_information(0.25, wheels=False), 0.25 * full)
    with_wheels = first_subspace_information(1.0, wheels=True)
    np.testing.assert_allclose(first_subspace_information(0.25, wheels=True), with_wheels)


@pytest.mark.parametrize("wheels, recent, checked", [(True, True, False), (False, False, False),
                                                     (False, True, True)])
def test_the_return_check_runs_without_wheel_data_within_its_window(featureless_bag, wheels,
                                                                   recent, checked,
                                                                   monkeypatch):
    """``plane_refinement.return_check`` tests the subspace information of scans without
    wheel data while the newest wheel data is recent (``return_check_window_s``, as in an
    outage); with wheels the refinement starts at their prediction, and without any wheel
    data the LiDAR keeps its information (the IMU was never calibrated against wheels) and
    the plane fits use vertical lines (``vertical_lines_without_wheels``)."""
    import lili_odom.pipeline.odometry as odometry

    if recent and not wheels:  # an outage: wheel data before, none on these scans
        monkeypatch.setattr(odometry.OdometryPipeline, "_wheels_recent", lambda self, t: True)
    lines = []

    class RecordingCache(odometry.PlaneFitCache):
        def __init__(self, points, reference, config=None):
            super().__init__(points, reference, config)
            lines.append(self.config.vertical_lines)

    monkeypatch.setattr(odometry, "PlaneFitCache", RecordingCache)
    config = NodeConfig()
    config.pipeline.method = "lili"
    counters = _replay_first_scans(featureless_bag, config, wheels).pipeline.counters
    assert (counters["return_checks"] > 0) == checked
    assert lines and all(used == (not recent) for used in lines)


def test_the_return_check_window_counts_from_the_newest_wheel_data():
    from lili_odom.pipeline.odometry import OdometryPipeline

    pipeline = OdometryPipeline(NodeConfig().pipeline)
    assert not pipeline._wheels_recent(100.0)  # no wheel data yet
    pipeline.estimator.wheels.add(100.0, np.eye(4))
    assert pipeline._wheels_recent(100.0) and pipeline._wheels_recent(130.0)
    assert not pipeline._wheels_recent(130.5)


def test_vertical_lines_on_scans_long_without_wheel_data_only():
    from lili_odom.pipeline.odometry import OdometryPipeline

    config = NodeConfig()
    pipeline = OdometryPipeline(config.pipeline)
    assert pipeline._plane_config(True).vertical_lines  # the default
    assert pipeline._plane_config(False) is config.pipeline.plane_refinement
    assert not pipeline._plane_config(False).vertical_lines
    config.pipeline.plane_refinement.vertical_lines_without_wheels = False
    assert not OdometryPipeline(config.pipeline)._plane_config(True).vertical_lines
    assert not pipeline._plane_config(True).blobs
    config.pipeline.plane_refinement.blobs_without_wheels = True
    blobs = OdometryPipeline(config.pipeline)
    assert blobs._plane_config(True).blobs and not blobs._plane_config(False).blobs
