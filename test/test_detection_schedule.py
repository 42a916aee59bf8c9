"""The detection schedule: when a detection is reused, and how it is carried to a new pose."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import closed_room

from lili_odom import geometry
from lili_odom.degeneracy.result import DegeneracyResult, failed_result
from lili_odom.pipeline.detection_schedule import (DetectionSchedule, DetectionScheduleConfig,
                                                   carry_over)
from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig

L = 8.0


def _result(pose, rows) -> DegeneracyResult:
    return DegeneracyResult("lili", np.asarray(pose, float), np.asarray(rows, float), L)


def _pose(x=0.0, yaw_deg=0.0) -> np.ndarray:
    return geometry.exp(np.array([x, 0, 0, 0, 0, np.radians(yaw_deg)]))


def _same_subspace(A, B) -> bool:
    """Row spaces equal (orthonormal rows)."""
    return np.allclose(A.T @ A, B.T @ B, atol=1e-9)


def test_carry_over_keeps_the_motions_fixed_in_the_odometry_frame():
    old = _pose(0.0, 0.0)
    new = _pose(0.2, 20.0)
    # degenerate: translation along world x and rotation about the world z axis through the
    # old origin (in scaled units)
    res = _result(old, [[1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 1]])
    moved = carry_over(res, new, age=1)
    assert moved.details["reused"] and moved.details["reused_age"] == 1
    assert moved.runtime_s == 0.0 and np.allclose(moved.pose, new)
    B = moved.basis_scaled
    assert np.allclose(B @ B.T, np.eye(2), atol=1e-9)  # orthonormal in the scaled space
    # every carried motion, mapped back to the odometry frame, lies in the old subspace
    back = geometry.scale_twist(geometry.unscale_twist(B, L) @ geometry.adjoint(new).T, L)
    P_old = res.basis_scaled.T @ res.basis_scaled
    assert np.allclose(back @ P_old, back, atol=1e-9)
    # the translation along world x seen from a body turned by 20 deg: (cos, -sin, 0), the
    # first row still (Gram-Schmidt keeps the rows' order)
    a = np.radians(20)
    assert np.allclose(B[0], [np.cos(a), -np.sin(a), 0, 0, 0, 0], atol=1e-9)


def test_carry_over_of_an_empty_basis_stays_empty():
    moved = carry_over(_result(_pose(), np.zeros((0, 6))), _pose(0.1), age=2)
    assert moved.dimension == 0 and moved.details["reused_age"] == 2


@pytest.mark.parametrize("pose, reused", [
    (_pose(0.1), True),            # close: reuse
    (_pose(0.5), False),           # moved more than 0.3 m
    (_pose(0.0, 10.0), False),     # turned more than 5 deg
])
def test_reuse_only_close_to_the_detection(pose, reused):
    sched = DetectionSchedule(DetectionScheduleConfig(max_reuse=2, reuse_distance_m=0.3,
                                                      reuse_angle_deg=5.0))
    assert sched.reusable(_pose()) is None  # nothing detected yet
    sched.record(_result(_pose(), [[1, 0, 0, 0, 0, 0]]))
    assert (sched.reusable(pose) is not None) == reused


def test_reuse_at_most_max_reuse_scans_then_detect_again():
    sched = DetectionSchedule(DetectionScheduleConfig(max_reuse=2))
    sched.record(_result(_pose(), [[1, 0, 0, 0, 0, 0]]))
    assert [sched.reusable(_pose(0.01 * i)) is not None for i in range(1, 4)] == \
        [True, True, False]
    sched.record(_result(_pose(0.03), [[1, 0, 0, 0, 0, 0]]))
    assert sched.reusable(_pose(0.04)) is not None


def test_failed_detections_and_resets_are_never_reused():
    sched = DetectionSchedule(DetectionScheduleConfig(max_reuse=5))
    sched.record(failed_result("lili", _pose(), L, 0.0, "no correspondences"))
    assert sched.reusable(_pose()) is None
    sched.record(_result(_pose(), [[1, 0, 0, 0, 0, 0]]))
    sched.reset()
    assert sched.reusable(_pose()) is None


def test_max_reuse_zero_detects_every_scan():
    sched = DetectionSchedule(DetectionScheduleConfig(max_reuse=0))
    sched.record(_result(_pose(), [[1, 0, 0, 0, 0, 0]]))
    assert sched.reusable(_pose()) is None


def test_a_screened_scan_is_carried_over_but_never_reused():
    sched = DetectionSchedule()
    sched.record(_result(_pose(), [[1, 0, 0, 0, 0, 0]]))
    sched.screened(_result(_pose(0.1), np.zeros((0, 6))))  # the detection is within reach
    assert sched.reusable(_pose(0.2)).dimension == 1
    sched.screened(_result(_pose(5.0), np.zeros((0, 6))))  # out of reach: replaced
    assert sched.reusable(_pose(5.0)) is None  # a screened result is never reused ...
    assert sched.has_last and sched.stale(_pose(5.1)).dimension == 0  # ... only carried
    fresh = DetectionSchedule()
    fresh.screened(_result(_pose(), np.zeros((0, 6))))
    assert fresh.has_last and fresh.reusable(_pose()) is None


def test_pipeline_counts_detections_and_reuses():
    """In a closed room at rest: one detection, then ``max_reuse`` reuses (the default
    schedule), then a detection again."""
    room = closed_room(seed=0)
    from lili_odom.pipeline.types import Scan

    cfg = PipelineConfig(method="hessian")
    cfg.detection_schedule.background = False  # every detection serves its own scan
    cfg.plane_refinement.screen_detections = False  # the room's planes hold every direction
    pipe = OdometryPipeline(cfg)
    n = pipe.config.detection_schedule.max_reuse
    assert n >= 1
    outs = [pipe.process_scan(Scan(100.0 + 0.1 * i, room, None)) for i in range(n + 3)]
    assert all(o is not None for o in outs)
    # scan 0 initialises (no detection); then detect, n reuses, detect
    assert pipe.counters["detections"] == 2 and pipe.counters["detections_reused"] == n
    assert [bool(o.degeneracy.details.get("reused")) for o in outs[1:]] == \
        [False] + [True] * n + [False]


def test_invalid_schedule_parameters_are_named():
    cfg = PipelineConfig()
    cfg.detection_schedule.reuse_distance_m = -1.0
    with pytest.raises(ValueError, match="detection_schedule.reuse_distance_m"):
        OdometryPipeline(cfg)


def test_node_parameter_error_names_the_full_dotted_parameter():
    from lili_odom.config import NodeConfig

    cfg = NodeConfig()
    cfg.pipeline.detection_schedule.max_reuse = -1
    with pytest.raises(ValueError, match="pipeline.detection_schedule.max_reuse must be"):
        cfg.validate()


def test_a_held_subspace_fills_in_missed_detections_until_the_hold_distance():
    sched = DetectionSchedule(DetectionScheduleConfig(max_reuse=0, hold_distance_m=1.0))
    axis = [[1.0, 0, 0, 0, 0, 0]]
    sched.record(_result(_pose(0.0), axis))
    # a miss 0.5 m on: the tunnel axis is still degenerate
    miss = _result(_pose(0.5), np.zeros((0, 6)))
    sched.record(miss)
    held = sched.hold(miss, _pose(0.5))
    assert held.dimension == 1 and held.details["held"] == 1
    assert np.allclose(np.abs(held.basis_scaled), axis, atol=1e-9)
    # a fresh result with its own rows keeps them; a held direction already inside is not added
    own = _result(_pose(0.6), [[0.999, 0.0447, 0, 0, 0, 0]])
    own.basis_scaled /= np.linalg.norm(own.basis_scaled)
    assert sched.hold(own, _pose(0.6)) is own
    # a held direction outside the result's subspace is added, orthonormal to its rows
    yaw = _result(_pose(0.7), [[0, 0, 0, 0, 0, 1.0]])
    merged = sched.hold(yaw, _pose(0.7))
    assert merged.dimension == 2 and np.allclose(merged.basis_scaled[0], yaw.basis_scaled[0])
    assert np.allclose(merged.basis_scaled @ merged.basis_scaled.T, np.eye(2), atol=1e-9)
    # failures pass unchanged
    failed = failed_result("lili", _pose(0.8), L, 0.0, "no points")
    assert sched.hold(failed, _pose(0.8)) is failed
    # 1.2 m from the degenerate detection the place is trusted again
    late = _result(_pose(1.2), np.zeros((0, 6)))
    assert sched.hold(late, _pose(1.2)).dimension == 0
    assert sched.hold(miss, _pose(0.5)) is miss  # the hold is over, not resumed
    # without a hold distance nothing is held
    off = DetectionSchedule(DetectionScheduleConfig(hold_distance_m=0.0))
    off.record(_result(_pose(0.0), axis))
    assert off.hold(miss, _pose(0.5)) is miss


def test_hold_distance_is_validated():
    with pytest.raises(ValueError, match="hold_distance_m"):
        DetectionScheduleConfig(hold_distance_m=-1.0).validate()


def test_the_hold_ends_after_the_warm_up_travel_and_restarts_with_a_new_map():
    cfg = DetectionScheduleConfig(max_reuse=0, hold_distance_m=1.0, hold_warmup_m=2.0)
    sched = DetectionSchedule(cfg)
    axis = [[1.0, 0, 0, 0, 0, 0]]
    x = 0.0
    for _ in range(4):  # 1.5 m of travel: detections at 0, 0.5, 1.0 and 1.5 m, misses held
        sched.record(_result(_pose(x), axis))
        assert sched.hold(_result(_pose(x), axis), _pose(x)).dimension == 1
        miss = _result(_pose(x + 0.25), np.zeros((0, 6)))
        assert sched.hold(miss, _pose(x + 0.25)).dimension == 1
        x += 0.5
    # past 2 m of path the held subspace is no longer merged, although the last degenerate
    # detection is only 0.75 m behind
    sched.record(_result(_pose(x), axis))
    sched.hold(_result(_pose(x), axis), _pose(x))
    late = _result(_pose(x + 0.25), np.zeros((0, 6)))
    assert sched.hold(late, _pose(x + 0.25)) is late
    # a failed registration (reset without a new map) does not restart the warm-up ...
    sched.reset()
    sched.record(_result(_pose(x + 0.5), axis))
    late = _result(_pose(x + 0.75), np.zeros((0, 6)))
    assert sched.hold(late, _pose(x + 0.75)) is late
    # ... a new map does
    sched.reset(new_map=True)
    sched.record(_result(_pose(10.0), axis))
    miss = _result(_pose(10.25), np.zeros((0, 6)))
    assert sched.hold(miss, _pose(10.25)).dimension == 1


def test_hold_warmup_is_validated():
    with pytest.raises(ValueError, match="hold_warmup_m"):
        DetectionScheduleConfig(hold_warmup_m=-1.0).validate()
