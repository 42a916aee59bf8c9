"""``python -m benchmarks.speed`` on a tiny simulated bag: every method gives every stage
column. Correctness only (the result's shape and plausibility), never speed thresholds.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from lili_odom.cli import main as cli_main
from lili_odom.evaluation.timing import median_run, stage_stats

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("parse", "predict", "deskew", "icp", "detector", "fusion", "map", "total")
KISS_STAGES = ("parse", "deskew", "icp", "map", "total")


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("speed") / "bag"
    rc = cli_main(["simulate", "tunnel", "--trial", "3", "--duration", "2", "--resolution", "16x128",
                   "--jobs", "1", "--no-progress", "--out", str(out)])
    assert rc in (0, None)
    return out


def test_speed_benchmark_reports_every_stage(tiny_bag, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "benchmarks.speed", "--bag", str(tiny_bag),
                           "--methods", "none", "kiss", "--start", "0", "--scans", "10",
                           "--warmup", "2", "--no-progress", "--out", str(tmp_path),
                           "--name", "speed"], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads((tmp_path / "speed.json").read_text())
    assert report["machine"]["cores"] >= 1
    assert report["machine"]["commit"]
    (window,) = report["windows"]
    assert set(window["methods"]) == {"none", "kiss"}
    for name, r in window["methods"].items():
        assert r["scans_fed"] == 10, name
        assert r["scans_timed"] == r["scans_processed"] - 2 > 0, name
        assert r["scans_per_s"] > 0 and math.isfinite(r["scans_per_s"]), name
        assert r["rss_peak_mb"] > 0
        assert set(r["stages"]) == set(STAGES), name
        measured = KISS_STAGES if name == "kiss" else STAGES
        for stage in STAGES:
            s = r["stages"][stage]
            if stage in measured:
                assert s is not None and 0 <= s["mean_ms"] <= s["p95_ms"] <= s["max_ms"], (name, stage)
            else:
                assert s is None, (name, stage)
        total = r["stages"]["total"]["mean_ms"]
        parts = sum(r["stages"][k]["mean_ms"] for k in measured if k != "total")
        assert parts <= total * 1.001 + 1e-6, name  # the stages are inside the total
    assert window["methods"]["kiss"]["time_vs_kiss"] == pytest.approx(1.0)
    assert window["methods"]["none"]["counters"]["processed"] == 10
    assert window["targets"] == {}  # no lili in this run

    md = (tmp_path / "speed.md").read_text()
    assert md.count("| `none` |") == 1 and "KISS-ICP `register_frame`" in md
    header = next(line for line in md.splitlines() if line.startswith("| method"))
    separator = md.splitlines()[md.splitlines().index(header) + 1]
    assert header.count("|") == separator.count("|")


def test_repeats_report_the_median_run():
    runs = [{"scans_per_s": v, "tag": i} for i, v in enumerate((3.0, 1.0, 2.0))]
    chosen = median_run(runs)
    assert chosen["tag"] == 2 and chosen["scans_per_s"] == 2.0
    assert chosen["repeats_scans_per_s"] == [3.0, 1.0, 2.0]  # run order kept
    assert median_run(runs[:2])["tag"] == 0  # even count: the upper of the two middle


def test_stage_stats_leave_unmeasured_stages_empty():
    stats = stage_stats({"parse": [0.001, 0.003], "icp": []}, ("parse", "icp", "map"),
                        measured=("parse", "icp"))
    assert stats["parse"]["mean_ms"] == pytest.approx(2.0)
    assert stats["parse"]["max_ms"] == pytest.approx(3.0)
    assert stats["icp"] is None and stats["map"] is None


def test_process_tree_rss_counts_a_child_process():
    import subprocess
    import sys
    import time

    from benchmarks._process_tree import tree_rss_mb

    alone = tree_rss_mb()
    child = subprocess.Popen([sys.executable, "-c",
                              "import time; b = b'x' * (200 * 2**20); time.sleep(30)"])
    try:
        deadline = time.monotonic() + 20
        while tree_rss_mb() < alone + 150 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert tree_rss_mb() >= alone + 150  # the child's 200 MB
        assert tree_rss_mb(child.pid) >= 150
    finally:
        child.kill()
        child.wait()
