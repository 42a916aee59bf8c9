"""The pipeline API validates its inputs before any native call and never hands KISS-ICP or
GTSAM input that aborts the process. Cases that could abort run in a subprocess, so a native
abort fails the test instead of killing the test runner."""
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from lili_odom.pipeline.types import Scan
from lili_odom.pipeline.validation import MAX_SWEEP_S, PipelineInputError, checked_scan

ROOT = Path(__file__).resolve().parents[1]

ROOM = """
import numpy as np
from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
from lili_odom.pipeline.types import Scan
rng = np.random.default_rng(0)
pts = []
for ax in range(3):
    for s in (-1, 1):
        p = rng.uniform(-1, 1, (600, 3)) * [6, 5, 3]
        p[:, ax] = s * [6, 5, 3][ax]
        pts.append(p)
room = np.vstack(pts)
T = np.linspace(0.0, 0.1, len(room))
def moved(k):
    return room - 0.05 * (k + T / 0.1)[:, None] * [1.0, 0.0, 0.0]
"""


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(ROOM) + textwrap.dedent(code)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)


def test_clouds_without_or_with_degenerate_times_do_not_abort():
    proc = _run("""
        pipe = OdometryPipeline(PipelineConfig(method="none"))
        outs = []
        for i, times in enumerate([None, np.zeros(len(room)), np.full(len(room), np.nan),
                                   np.full(len(room), 0.05), None]):
            out = pipe.process_scan(Scan(100.0 + 0.1 * i, room, times))
            outs.append(out is not None)
        empty = pipe.process_scan(Scan(101.0, np.zeros((0, 3)), None))
        nan = pipe.process_scan(Scan(101.1, np.full((500, 3), np.nan), None))
        print("OK", outs, empty, nan, dict(pipe.counters))
    """)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "OK [True, True, True, True, True] None None" in proc.stdout, proc.stdout


@pytest.mark.parametrize("method", ["none", "lili"])
def test_finite_but_huge_point_times_do_not_abort(method):
    """Times of +-1e308 or alternating +-max float used to make KISS-ICP's deskew compute an
    infinite span and abort in Sophus (``SO3::exp failed``) once the pipeline had a motion."""
    proc = _run(f"""
        pipe = OdometryPipeline(PipelineConfig(method="{method}"))
        for k in range(3):
            assert pipe.process_scan(Scan(100.0 + 0.1 * k, moved(k), T)) is not None
        first_last = T.copy(); first_last[0], first_last[-1] = -1e308, 1e308
        alternating = np.where(np.arange(len(T)) % 2 == 0, 1.0, -1.0) * np.finfo(float).max
        outs = []
        for k, times in enumerate([first_last, alternating, T * 1e300, T], start=3):
            out = pipe.process_scan(Scan(100.0 + 0.1 * k, moved(k), times))
            outs.append(out is not None and bool(np.all(np.isfinite(out.pose))))
        print("OK", outs, pipe.counters["scan_times_ignored"])
    """)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    assert "OK [True, True, True, True] 3" in proc.stdout, proc.stdout


def test_deskew_guard_rejects_an_overflowing_time_span():
    """The scan matcher itself never hands KISS-ICP times whose span overflows (defence in depth
    behind the pipeline's validation)."""
    proc = _run("""
        from lili_odom.pipeline.scan_matcher import ScanMatcher
        from lili_odom import geometry
        m = ScanMatcher()
        motion = geometry.exp(np.array([0.05, 0, 0, 0, 0, 0.02]))
        times = T.copy(); times[0], times[-1] = -1e308, 1e308
        from kiss_icp.voxelization import voxel_down_sample
        map_points, source = m.preprocess(room, times, motion)
        cells = len(voxel_down_sample(room, 0.5 * m.config.voxel))  # no deskew: the raw cells
        print("OK", len(map_points) == cells, bool(np.all(np.isfinite(map_points))))
    """)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-2000:]}"
    assert "OK True True" in proc.stdout, proc.stdout


def _room_scan(k: int = 0, n: int = 600) -> Scan:
    rng = np.random.default_rng(0)
    pts = []
    for ax in range(3):
        for s in (-1, 1):
            p = rng.uniform(-1, 1, (n, 3)) * [6, 5, 3]
            p[:, ax] = s * [6, 5, 3][ax]
            pts.append(p)
    room = np.vstack(pts) - [0.05 * k, 0.0, 0.0]
    return Scan(100.0 + 0.1 * k, room, np.linspace(0.0, 0.1, len(room)))


def test_times_as_a_list_are_accepted():
    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig

    pipe = OdometryPipeline(PipelineConfig(method="none"))
    outs = []
    for k in range(3):
        s = _room_scan(k)
        outs.append(pipe.process_scan(Scan(s.stamp, s.points.tolist(), s.times.tolist())))
    assert all(o is not None for o in outs)


@pytest.mark.parametrize("change, message", [
    (lambda s: Scan(s.stamp, s.points, s.times[:-1]), "scan times must have shape"),
    (lambda s: Scan(s.stamp, np.vstack([s.points, [np.nan] * 3]), s.times), "scan times"),
    (lambda s: Scan(s.stamp, s.points[:, :2], None), "shape (N, 3)"),
    (lambda s: Scan(s.stamp, s.points.astype(str), None), "real numbers"),
    (lambda s: Scan("100.0", s.points, None), "scan stamp must be a number"),
    (lambda s: Scan(None, s.points, None), "scan stamp must be a number"),
    (lambda s: Scan(s.stamp, s.points, s.times[:, None]), "scan times must have shape"),
    (lambda s: Scan(s.stamp, s.points, s.times.astype(complex)), "real numbers"),
    (lambda s: Scan(s.stamp, None, None), "real numbers"),
])
def test_malformed_scans_raise_pipeline_input_error_and_change_nothing(change, message):
    from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig

    pipe = OdometryPipeline(PipelineConfig(method="none"))
    assert pipe.process_scan(_room_scan(0)) is not None
    with pytest.raises(PipelineInputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        pipe.process_scan(change(_room_scan(1)))
    assert isinstance(PipelineInputError("x"), ValueError)
    assert pipe.counters["scans"] == 1  # the malformed scan was not counted as a scan
    assert pipe.process_scan(_room_scan(2)) is not None


@settings(max_examples=200, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(points=hnp.arrays(st.sampled_from([np.float64, np.float32, np.int32, np.bool_,
                                          np.complex64, np.dtype("U3")]),
                         hnp.array_shapes(min_dims=1, max_dims=3, max_side=6),
                         elements=None),
       times=st.one_of(st.none(), hnp.arrays(np.float64, hnp.array_shapes(max_dims=2,
                                                                          max_side=8))),
       stamp=st.one_of(st.floats(), st.text(max_size=2), st.none(), st.integers()))
def test_checked_scan_returns_a_safe_scan_or_raises_pipeline_input_error(points, times, stamp):
    counters: dict = {}
    try:
        s = checked_scan(Scan(stamp, points, times), counters)
    except PipelineInputError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert s.points.ndim == 2 and s.points.shape[1] == 3 and s.points.dtype == np.float64
    assert np.all(np.isfinite(s.points))
    if s.times is not None:
        assert s.times.shape == (len(s.points),)
        assert np.all(np.isfinite(s.times))
        assert len(s.times) == 0 or np.ptp(s.times) <= MAX_SWEEP_S
    assert isinstance(s.stamp, float)
