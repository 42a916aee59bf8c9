"""The pipeline never hands KISS-ICP input that aborts the process (run in a subprocess so a
native abort fails the test instead of killing the test runner)."""
import subprocess
import sys
import textwrap


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, timeout=240)


def test_clouds_without_or_with_degenerate_times_do_not_abort():
    proc = _run("""
        import numpy as np
        from lili_odom.pipeline.odometry import OdometryPipeline, PipelineConfig
        from lili_odom.pipeline.types import Scan
        rng = np.random.default_rng(0)
        # a closed room, 6 faces
        pts = []
        for ax in range(3):
            for s in (-1, 1):
                p = rng.uniform(-1, 1, (3000, 3)) * [6, 5, 3]
                p[:, ax] = s * [6, 5, 3][ax]
                pts.append(p)
        room = np.vstack(pts)
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
