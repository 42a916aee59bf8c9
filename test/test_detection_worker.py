"""Detection in a background process: the mirrored map, the schedule's lag and the fall-back
to the main loop when the process is gone."""
from __future__ import annotations

import time
from functools import partial

import numpy as np
import pytest
from conftest import closed_room

from lili_odom import geometry
from lili_odom.degeneracy.hessian import ZhangConfig, ZhangDetector
from lili_odom.degeneracy.lili import LiliConfig, LiliDetector
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.pipeline.detection_schedule import DetectionSchedule, DetectionScheduleConfig
from lili_odom.pipeline.detection_worker import PENDING, DetectionWorker
from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
from lili_odom.pipeline.scan_matcher import insert_scan
from lili_odom.pipeline.types import Scan

VOXEL, MAX_RANGE, PER_VOXEL = 0.5, 50.0, 20


def _corridor(rng, n=6000, length=40.0) -> np.ndarray:
    """Points on the walls, floor and ceiling of a 4 m x 3 m corridor along x (no ends)."""
    x = rng.uniform(-length / 2, length / 2, n)
    side = rng.integers(0, 4, n)
    u = rng.uniform(-1, 1, n)
    y = np.where(side == 0, 2.0, np.where(side == 1, -2.0, 2.0 * u))
    z = np.where(side == 2, 1.5, np.where(side == 3, -1.5, 1.5 * u))
    return np.c_[x, y, z]


def _map(scans, poses) -> ReferenceMap:
    from kiss_icp.mapping import VoxelHashMap

    ref = ReferenceMap(VoxelHashMap(VOXEL, MAX_RANGE, PER_VOXEL), VOXEL, PER_VOXEL)
    for pts, pose in zip(scans, poses):
        insert_scan(ref, pts, pose)
    return ref


@pytest.fixture()
def corridor():
    rng = np.random.default_rng(3)
    poses = [geometry.exp(np.array([0.3 * i, 0, 0, 0, 0, 0])) for i in range(3)]
    scans = [_corridor(rng) for _ in poses]
    return scans, poses, _corridor(rng, 3000)


def test_a_detection_in_the_worker_equals_one_against_the_same_map(corridor):
    scans, poses, scan = corridor
    make = partial(LiliDetector, LiliConfig(return_ratio=0.1))
    worker = DetectionWorker(make, VOXEL, MAX_RANGE, PER_VOXEL, timeout_s=60)
    try:
        for pts, pose in zip(scans, poses):
            worker.update_map(pts, pose)
        guess = poses[-1] @ geometry.exp(np.array([0.05, 0.02, 0, 0, 0, 0.01]))
        local = make().detect(_map(scans, poses), scan, guess, optimized_pose=poses[-1])
        assert worker.submit(7, scan, guess, poses[-1])
        remote = worker.result(7)
    finally:
        worker.close()
    assert remote is not None and remote.ok and local.ok
    assert remote.dimension == local.dimension == 1
    assert abs(remote.basis_scaled[0, 0]) > 0.95  # along the corridor
    assert np.allclose(np.abs(remote.basis_scaled), np.abs(local.basis_scaled), atol=1e-3)
    assert remote.details["spacing"] == pytest.approx(local.details["spacing"])


def test_reset_clears_the_mirrored_map_and_abandoned_results_are_skipped(corridor):
    scans, poses, scan = corridor
    worker = DetectionWorker(partial(ZhangDetector, ZhangConfig()), VOXEL, MAX_RANGE,
                             PER_VOXEL, timeout_s=60)
    try:
        worker.update_map(scans[0], poses[0])
        assert worker.submit(1, scan, poses[0], poses[0])
        worker.reset()
        assert worker.submit(2, scan, poses[0], poses[0])
        first_kept = worker.result(2)  # result 1 was abandoned: skipped
    finally:
        worker.close()
    assert first_kept is not None and not first_kept.ok  # against the emptied map
    assert "too few" in first_kept.reason or "empty" in first_kept.reason


def test_a_dead_worker_reports_and_does_not_block(corridor):
    scans, poses, scan = corridor
    worker = DetectionWorker(partial(ZhangDetector, ZhangConfig()), VOXEL, MAX_RANGE,
                             PER_VOXEL, timeout_s=5)
    assert worker.ready()
    worker._process.kill()
    worker._process.join(5)
    worker.submit(1, scan, poses[0], poses[0])
    assert worker.result(1) is None
    assert not worker.alive and "died" in worker.failure
    assert worker.submit(2, scan, poses[0], poses[0]) is False
    worker.close()


class _SlowDetector:
    """Zhang's detector after a pause (a detection that comes late)."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds

    def detect(self, reference, scan, initial_pose, optimized_pose=None):
        time.sleep(self.seconds)
        return ZhangDetector(ZhangConfig()).detect(reference, scan, initial_pose,
                                                   optimized_pose=optimized_pose)


def test_a_late_result_is_pending_within_the_wait_and_arrives_later(corridor):
    scans, poses, scan = corridor
    worker = DetectionWorker(partial(_SlowDetector, 1.0), VOXEL, MAX_RANGE, PER_VOXEL,
                             timeout_s=30)
    try:
        worker.update_map(scans[0], poses[0])
        assert worker.submit(1, scan, poses[0], poses[0])
        assert worker.result(1, wait_s=0.05) is PENDING
        assert worker.alive
        late = worker.result(1)
    finally:
        worker.close()
    assert late is not None and late is not PENDING and late.ok


def test_a_late_background_result_is_applied_when_it_arrives():
    """As the test above, with a wait limit and every result late: the scan at which the
    first is due and the next carry the old detection over, the scan 2 x lag after the
    request waits for it and applies it with its age. The next one, late like the one
    before, is waited for at the scan it is due."""
    room = closed_room(seed=0)
    cfg = PipelineConfig(method="hessian")
    cfg.detection_schedule.max_reuse = 4
    cfg.plane_refinement.screen_detections = False  # the room would skip the detector
    cfg.detection_schedule.background_lag = 2
    pipe = OdometryPipeline(cfg, max_detection_wait_s=0.0)
    waits = []
    try:
        outs = [pipe.process_scan(Scan(100.0, room, None))]
        worker = pipe._worker
        result = worker.result

        def late(seq, wait_s=None):
            waits.append(wait_s)
            return PENDING if wait_s is not None else result(seq)

        worker.result = late
        outs += [pipe.process_scan(Scan(100.0 + 0.1 * i, room, None)) for i in range(1, 14)]
    finally:
        pipe.close()
    ages = [o.degeneracy.details.get("reused_age", 0) for o in outs[1:]]
    assert ages == [0, 1, 2, 3, 4, 5, 6, 7, 8, 4, 5, 6, 2], (ages, waits)
    assert waits == [0.0, 0.0, 0.0, None, 0.0, None]
    assert pipe.counters["background_detections_late"] == 2
    with pytest.raises(ValueError, match="max_detection_wait_s"):
        OdometryPipeline(cfg, max_detection_wait_s=-1.0)


def test_a_worker_closed_while_its_process_starts_leaves_no_process():
    worker = DetectionWorker(partial(ZhangDetector, ZhangConfig()), VOXEL, MAX_RANGE,
                             PER_VOXEL, timeout_s=5)
    worker.update_map(np.zeros((10, 3)), np.eye(4))  # queued while the child starts
    worker.close()
    assert worker._process is not None and not worker._process.is_alive()
    worker.close()  # idempotent


def test_an_unpicklable_detector_factory_leaves_no_process():
    worker = DetectionWorker(lambda: None, VOXEL, MAX_RANGE, PER_VOXEL)
    assert not worker.alive and "could not start" in worker.failure
    assert worker.submit(1, np.zeros((10, 3)), np.eye(4), np.eye(4)) is False
    worker.close()


def test_a_background_result_counts_its_age_from_its_own_scan():
    cfg = DetectionScheduleConfig(max_reuse=3)
    sched = DetectionSchedule(cfg)
    from lili_odom.degeneracy.result import DegeneracyResult

    res = DegeneracyResult("lili", np.eye(4), np.zeros((0, 6)), 8.0)
    sched.record(res, age=2)  # asked for two scans ago, applied now
    ages = []
    for _ in range(3):
        r = sched.reusable(np.eye(4))
        ages.append(None if r is None else r.details["reused_age"])
    assert ages == [2, 3, None]
    assert sched.has_last and sched.stale(np.eye(4)).details["reused_age"] == 4


def test_the_pipeline_applies_background_results_lag_scans_later():
    """Closed room at rest, ``max_reuse`` 4, lag 2: scan 1 detects in the main loop, scans
    2-4 reuse it; at scan 5 it has run out: scan 5 asks the background and, like scan 6,
    carries the old result over past the bound; scan 7 applies the result of scan 5 (age 2),
    scans 8-9 reuse it."""
    room = closed_room(seed=0)
    cfg = PipelineConfig(method="hessian")
    cfg.detection_schedule.max_reuse = 4
    cfg.plane_refinement.screen_detections = False  # the room would skip the detector
    cfg.detection_schedule.background_lag = 2
    pipe = OdometryPipeline(cfg)
    try:
        outs = [pipe.process_scan(Scan(100.0 + 0.1 * i, room, None)) for i in range(10)]
    finally:
        pipe.close()
    ages = [o.degeneracy.details.get("reused_age", 0) for o in outs[1:]]
    #        scan 1  2  3  4  5  6  7  8  9
    assert ages == [0, 1, 2, 3, 4, 5, 6, 2, 3], ages
    assert pipe.counters["detections_background"] == 1  # asked at scan 5
    assert pipe.counters["detections"] == 2


def test_the_pipeline_detects_in_its_main_loop_when_the_worker_is_gone():
    """Lag 2, a detection due every other scan: whether the child answered scan 2's request
    before it was killed or not, its death is noticed by scan 7 at the latest, and scans 5-9
    hold at least two detections of the main loop."""
    room = closed_room(seed=1)
    cfg = PipelineConfig(method="hessian")
    cfg.detection_schedule.max_reuse = 1
    cfg.plane_refinement.screen_detections = False  # the room would skip the detector
    cfg.detection_schedule.background_lag = 2
    cfg.detection_schedule.background_timeout_s = 5
    pipe = OdometryPipeline(cfg)
    outs = [pipe.process_scan(Scan(100.0 + 0.1 * i, room, None)) for i in range(4)]
    assert pipe.counters["detections_background"] == 1
    assert pipe._worker.ready()
    pipe._worker._process.kill()
    outs += [pipe.process_scan(Scan(100.0 + 0.1 * i, room, None)) for i in range(4, 10)]
    assert all(o is not None and o.degeneracy.ok for o in outs[1:])
    assert pipe.counters["background_detection_failures"] == 1
    # from then on every due detection runs in the main loop: fresh results, no stale ones
    assert pipe._worker is None
    fresh = [not o.degeneracy.details.get("reused") for o in outs[5:]]
    assert fresh.count(True) >= 2
    pipe.close()


def test_a_started_pipeline_has_its_worker_before_the_first_scan_and_the_same_results():
    """``start()`` starts the detector process up front; the outputs are those of a pipeline
    that starts it at its first map update. Once the map holds scans, ``start()`` does not
    start a process whose mirror would miss them."""
    room = closed_room(seed=2)
    cfg = PipelineConfig(method="hessian")
    cfg.detection_schedule.max_reuse = 2
    cfg.plane_refinement.screen_detections = False  # the room would skip the detector
    poses = {}
    for started in (False, True):
        pipe = OdometryPipeline(cfg)
        try:
            if started:
                pipe.start()
                assert pipe._worker is not None and pipe._worker.alive
            else:
                assert pipe._worker is None
            outs = [pipe.process_scan(Scan(100.0 + 0.1 * i, room, None)) for i in range(8)]
            assert pipe.counters["detections_background"] >= 1
            poses[started] = np.array([o.pose for o in outs])
        finally:
            pipe.close()
    np.testing.assert_allclose(poses[True], poses[False], atol=1e-9)

    late = OdometryPipeline(PipelineConfig(method="hessian"))
    late._background = False  # the first scans fill the map without a process
    late.process_scan(Scan(100.0, room, None))
    late._background = True
    late.start()
    assert late._worker is None
    late.close()


def test_the_node_provider_hands_its_wait_limit_to_the_pipeline():
    from lili_odom.ros.provider import OdometryPipelineProvider

    provider = OdometryPipelineProvider()
    assert provider.create({"pipeline.method": "none"}).max_detection_wait_s == 0.02
    assert provider.create({"pipeline.method": "none",
                            "detection_max_wait_s": 0.05}).max_detection_wait_s == 0.05
    assert provider.create({"pipeline.method": "none",
                            "detection_max_wait_s": 0.0}).max_detection_wait_s is None
    with pytest.raises(ValueError, match="detection_max_wait_s"):
        provider.create({"pipeline.method": "none", "detection_max_wait_s": -1.0})
