"""benchmarks/speed.py on a tiny simulated bag: every method gives every stage column.

Correctness only (the result's shape and plausibility), never speed thresholds.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from _benchmark_module import load_benchmark
from lili_odom.cli import main as cli_main


def _load_speed():
    return load_benchmark("speed")


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("speed") / "bag"
    rc = cli_main(["simulate", "tunnel", "--trial", "3", "--duration", "2", "--resolution", "16x128",
                   "--jobs", "1", "--no-progress", "--out", str(out)])
    assert rc in (0, None)
    return out


def test_speed_benchmark_reports_every_stage(tiny_bag, tmp_path):
    speed = _load_speed()
    report = speed.benchmark(tiny_bag, methods=("none", "kiss"), starts=(0.0,), scans=10, warmup=2,
                             progress=False)
    assert report["machine"]["cores"] >= 1
    assert report["machine"]["commit"]
    (window,) = report["windows"]
    assert set(window["methods"]) == {"none", "kiss"}
    for name, r in window["methods"].items():
        assert r["scans_fed"] == 10, name
        assert r["scans_timed"] == r["scans_processed"] - 2 > 0, name
        assert r["scans_per_s"] > 0 and math.isfinite(r["scans_per_s"]), name
        assert r["rss_peak_mb"] > 0
        assert set(r["stages"]) == set(speed.STAGES), name
        measured = speed.KISS_STAGES if name == "kiss" else speed.STAGES
        for stage in speed.STAGES:
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

    md = speed.markdown(report, "python benchmarks/speed.py")
    assert md.count("| `none` |") == 1 and "KISS-ICP `register_frame`" in md
    header = next(line for line in md.splitlines() if line.startswith("| method"))
    separator = md.splitlines()[md.splitlines().index(header) + 1]
    assert header.count("|") == separator.count("|")


def test_repeats_report_the_median_run():
    speed = _load_speed()
    runs = [{"scans_per_s": v, "tag": i} for i, v in enumerate((3.0, 1.0, 2.0))]
    chosen = speed._median_run(runs)
    assert chosen["tag"] == 2 and chosen["scans_per_s"] == 2.0
    assert chosen["repeats_scans_per_s"] == [3.0, 1.0, 2.0]  # run order kept
    assert speed._median_run(runs[:2])["tag"] == 0  # even count: the upper of the two middle
