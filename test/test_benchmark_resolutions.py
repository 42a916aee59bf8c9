"""``benchmarks.speed_resolutions`` and ``benchmarks.node_latency``: resolutions, rounds,
figures and reports from synthetic runs (no simulation, no timing)."""
from __future__ import annotations

import argparse

import pytest

from benchmarks import node_latency as nl
from benchmarks import speed_resolutions as sr
from benchmarks._pieces import (DEFAULT_RESOLUTIONS, add_piece_arguments, default_resolutions,
                                format_resolution, parse_resolution, piece_command,
                                suite_resolutions)

MACHINE = {"cpu": "test CPU", "cores": 2, "python": "3.11", "commit": "abc1234",
           "uncommitted_lili_odom": []}
LOAD = {"loadavg_before": [0.1, 0, 0], "loadavg_after": [0.2, 0, 0], "wall_s": 60.0,
        "other_processes_cores": 0.01, "other_processes_at_start": []}
PIECE = {"scenario": "building", "kind": "building", "start_s": 0.0, "duration_s": 30.0,
         "seed": 0}


def test_default_resolutions_cover_the_suite_and_the_ouster_modes():
    suite = suite_resolutions()
    assert (32, 512) in suite and "building (CI)" in suite[(32, 512)]
    assert set(suite) <= set(default_resolutions())
    assert set(DEFAULT_RESOLUTIONS) <= set(default_resolutions())
    rows = {r for r, _ in default_resolutions()}
    cols = {c for _, c in default_resolutions()}
    assert rows == {32, 64, 128} and cols == {512, 1024, 2048}
    points = [r * c for r, c in default_resolutions()]
    assert points == sorted(points)
    assert parse_resolution("64x2048") == (64, 2048) and format_resolution((64, 2048)) == "64x2048"
    with pytest.raises(ValueError):
        parse_resolution("64-2048")


def test_piece_options_and_the_command_that_reproduces_them():
    import argparse

    ap = argparse.ArgumentParser()
    add_piece_arguments(ap)
    defaults = ap.parse_args([])
    assert (defaults.scenario, defaults.start, defaults.duration, defaults.seed) == (
        "building", 0.0, 30.0, 0)
    assert piece_command("benchmarks.x", defaults) == "python -m benchmarks.x"
    args = ap.parse_args(["--scenario", "mine", "--start", "5", "--duration", "12.5",
                          "--seed", "2", "--resolutions", "32x512", "64x1024"])
    assert piece_command("benchmarks.x", args, " --rate 2") == (
        "python -m benchmarks.x --scenario mine --start 5 --duration 12.5 --seed 2"
        " --resolutions 32x512 64x1024 --rate 2")


def test_rounds_alternate_which_method_goes_first():
    assert [sr.round_order(r) for r in range(3)] == [("lili", "kiss"), ("kiss", "lili"),
                                                      ("lili", "kiss")]


def _lili(wall, total_ms=50.0, rss=250.0):
    return {"method": "lili", "scans": 300, "wall_s": wall, "scans_per_s": 300 / wall,
            "rss_peak_mb": rss, "other_load_cores": 0.02, "degenerate_fraction": 0.1,
            "ate_m": 0.02, "modules_imported_in_timing": 0,
            "stages_mean_ms": {"deskew": 10.0, "icp": 8.0, "detector": 15.0, "fusion": 4.0,
                               "along_track": 2.0, "total": total_ms}}


def _kiss(wall, rss=200.0):
    return {"method": "kiss", "scans": 300, "wall_s": wall, "scans_per_s": 300 / wall,
            "rss_peak_mb": rss, "other_load_cores": 0.01, "modules_imported_in_timing": 2}


def test_summary_takes_the_ratio_within_each_round_and_its_median():
    runs = {"lili": [_lili(20.0, rss=260.0), _lili(24.0, total_ms=60.0)],
            "kiss": [_kiss(10.0), _kiss(20.0, rss=210.0)]}
    s = sr.summarise(runs)
    assert s["rounds_ratio"] == pytest.approx([2.0, 1.2])
    assert s["ratio"] == pytest.approx(1.6)  # median of the rounds' ratios, not of the walls
    assert s["lili"]["wall_s"] == pytest.approx(22.0) and s["kiss"]["wall_s"] == 15.0
    assert s["lili"]["scans_per_s"] == pytest.approx(300 / 22.0)
    assert s["lili"]["rss_peak_mb"] == 260.0 and s["kiss"]["rss_peak_mb"] == 210.0
    assert s["lili"]["stages_mean_ms"]["total"] == 60.0  # the run with the median wall time
    assert s["target"] == {"value": pytest.approx(1.6), "target": 1.5, "met": False}
    fast = sr.summarise({"lili": [_lili(14.0)], "kiss": [_kiss(10.0)]})
    assert fast["target"]["met"] and fast["rounds_ratio"] == pytest.approx([1.4])


def test_the_floor_is_reported_against_kiss_and_lili_within_each_round():
    runs = {"lili": [_lili(20.0), _lili(24.0)], "kiss": [_kiss(10.0), _kiss(20.0)],
            "none": [{**_lili(15.0, total_ms=30.0), "method": "none"},
                     {**_lili(16.0, total_ms=32.0), "method": "none"}]}
    s = sr.summarise(runs)
    floor = s["none"]
    assert floor["rounds_ratio_kiss"] == pytest.approx([1.5, 0.8])
    assert floor["ratio_kiss"] == pytest.approx(1.15)
    assert floor["rounds_lili_ratio"] == pytest.approx([20 / 15, 24 / 16])
    assert floor["wall_s"] == pytest.approx(15.5)
    assert s["ratio"] == pytest.approx(1.6)  # lili / KISS as without the floor
    report = {"machine": MACHINE, "load": LOAD, "piece": PIECE, "repeats": 2,
              "target_ratio": 1.5, "resolutions": {"32x512": {"bag": "b", **s, "runs": runs}},
              "suite_resolutions": {}}
    md = sr.markdown(report, "python -m benchmarks.speed_resolutions --with-none")
    row = next(line for line in md.splitlines() if line.startswith("| 32x512 | 15.5"))
    assert "1.15 (1.50, 0.80)" in row and "1.42 (1.33, 1.50)" in row
    assert "floor" not in sr.markdown({**report, "resolutions": {
        "32x512": {"bag": "b", **sr.summarise({k: runs[k] for k in ("lili", "kiss")}),
                   "runs": runs}}}, "cmd")


def test_speed_report_has_a_row_and_a_verdict_per_resolution():
    rows = {"32x512": {"bag": "b1", **sr.summarise({"lili": [_lili(14.0)], "kiss": [_kiss(10.0)]}),
                       "runs": {"lili": [_lili(14.0)], "kiss": [_kiss(10.0)]}},
            "128x1024": {"bag": "b2", **sr.summarise({"lili": [_lili(40.0)],
                                                      "kiss": [_kiss(20.0)]}),
                         "runs": {"lili": [_lili(40.0)], "kiss": [_kiss(20.0)]}}}
    report = {"machine": MACHINE, "load": LOAD, "piece": PIECE, "repeats": 1,
              "target_ratio": 1.5, "resolutions": rows,
              "suite_resolutions": {"32x512": ["airfield"], "128x1024": ["warehouse"]}}
    md = sr.markdown(report, "python -m benchmarks.speed_resolutions --repeats 1")
    assert "`python -m benchmarks.speed_resolutions --repeats 1`" in md
    row32 = next(line for line in md.splitlines() if line.startswith("| 32x512 | airfield"))
    row128 = next(line for line in md.splitlines() if line.startswith("| 128x1024 | warehouse"))
    assert "**1.40** (1.40)" in row32 and "| met |" in row32
    assert "**2.00** (2.00)" in row128 and "**missed**" in row128
    assert "met at 32x512; missed at 128x1024" in md
    stage_header = next(line for line in md.splitlines() if line.startswith("| resolution | deskew"))
    assert stage_header.split(" | ")[-3:] == ["total", "degenerate", "ATE [m] |"]
    assert "along_track" in stage_header
    assert "128x1024 kiss: 2" in md  # modules imported inside the timing are shown


def test_node_latency_targets_and_report():
    job = nl.play_job("some/bag", rate=1.0, duration=30.0)
    assert "--restamp" in job["play_args"] and job["play_timeout"] >= 600
    assert job["parameters"] == {}
    ap = argparse.ArgumentParser()
    params = nl.parse_parameters(ap, ["pipeline.detection_schedule.max_reuse=16",
                                      "pipeline.detection_schedule.reuse_distance_m=2"])
    assert params == {"pipeline.detection_schedule.max_reuse": 16,
                      "pipeline.detection_schedule.reuse_distance_m": 2.0}
    # the node declares a float parameter as DOUBLE: an integer written for it becomes a float
    assert isinstance(params["pipeline.detection_schedule.reuse_distance_m"], float)
    assert nl.play_job("some/bag", parameters=params)["parameters"] == params
    for bad in (["no_such.parameter=1"], ["pipeline.detection_schedule.max_reuse"],
                ["pipeline.detection_schedule.max_reuse=1.5"],
                ["pipeline.detection_schedule.reuse_distance_m=-1"]):
        with pytest.raises(SystemExit):
            nl.parse_parameters(ap, bad)
    ok = {"status": "ok", "nothing_lost": 1, "published": 300, "received": 300,
          "processed": 300, "dropped": 0, "missing": 0, "odometry": 300,
          "latency_p50_s": 0.05, "latency_p99_s": 0.09, "latency_max_s": 0.12,
          "mean_processing_s": 0.045, "other_load_cores": 0.01}
    slow = {**ok, "nothing_lost": 0, "processed": 280, "dropped": 20, "odometry": 280,
            "latency_p99_s": 0.31, "latency_max_s": 0.4}
    assert nl.evaluate(ok, "32x512") == {"no_drops": {"met": True}}
    assert nl.evaluate(ok, "128x1024")["p99"]["met"]
    assert not nl.evaluate(slow, "128x1024")["p99"]["met"]
    assert not nl.evaluate({**ok, "status": "crash"}, "32x512")["no_drops"]["met"]
    sub = nl.received_summary([0.5] + [0.05] * 9 + [0.04] * 99 + [0.2])
    assert sub["first_max_s"] == 0.5 and sub["max_s"] == 0.2
    assert sub["p50_s"] == pytest.approx(0.04)
    assert nl.received_summary([0.1])["p99_s"] is None
    rows = {}
    for res, r in (("32x512", ok), ("128x1024", slow)):
        rows[res] = {**r, "targets": nl.evaluate(r, res),
                     "subscriber": nl.received_summary([0.05] * 20)}
    report = {"machine": MACHINE, "load": LOAD, "piece": PIECE, "method": "lili", "rate": 1.0,
              "target_p99_s": 0.1, "target_resolution": "128x1024", "resolutions": rows}
    md = nl.markdown(report, "python -m benchmarks.node_latency")
    row128 = next(line for line in md.splitlines() if line.startswith("| 128x1024"))
    assert "50 / 310 / 400" in row128 and "**missed** (target)" in row128 and "**no**" in row128
    assert "**missed** at 128x1024" in md
    assert "latency p99 <= 100 ms at 128x1024: 310 ms, **missed**" in md
    md32 = nl.markdown({**report, "resolutions": {"32x512": rows["32x512"]}}, "cmd")
    assert "**met** at every resolution measured" in md32 and "not measured in this run" in md32
    assert "mean time per scan and pipeline stage" not in md32  # no stage figures, no table
    rows["32x512"]["stage_ms"] = {"deskew": 2.5, "icp": 6.0, "total": 40.0}
    rows["128x1024"]["stage_ms"] = {"deskew": 19.0, "icp": 9.5, "along_track": 15.0,
                                    "total": 64.0}
    md = nl.markdown(report, "cmd")
    assert "| resolution | deskew | icp | total | along_track |" in md
    assert "| 32x512 | 2.5 | 6.0 | 40.0 | – |" in md
    assert "| 128x1024 | 19.0 | 9.5 | 64.0 | 15.0 |" in md


def test_node_latency_repeats_report_the_median_run():
    runs = [{"latency_p50_s": 0.08, "latency_p99_s": p99, "dropped": d, "steal_cores": s,
             "run": i} for i, (p99, d, s) in enumerate([(0.30, 5, 0.2), (0.12, 0, 0.0),
                                                          (None, 0, 0.0), (0.14, 0, 0.01)])]
    row = nl.median_run(runs)
    assert row["run"] == 0  # p99 0.12, 0.14, 0.30, none: the upper middle one
    assert [r["latency_p99_s"] for r in row["repeats"]] == [0.30, 0.12, None, 0.14]
    assert nl.median_run(runs[1:2]) == runs[1] and "repeats" not in nl.median_run(runs[1:2])
    assert nl.median_run(runs[:3])["run"] == 0  # 0.12, 0.30, none
    row = {**row, "status": "ok", "nothing_lost": 1, "targets": nl.evaluate(row, "128x1024")}
    report = {"machine": MACHINE, "load": LOAD, "piece": PIECE, "method": "lili", "rate": 1.0,
              "target_p99_s": 0.1, "target_resolution": "128x1024",
              "resolutions": {"128x1024": row}}
    md = nl.markdown(report, "python -m benchmarks.node_latency --repeats 4")
    assert ("- 128x1024: 300 ms, 5 dropped, 0.20; 120 ms, 0 dropped, 0.00; – ms, 0 dropped, "
            "0.00; 140 ms, 0 dropped, 0.01") in md
    assert "latency p99 <= 100 ms at 128x1024: 300 ms, **missed**" in md


def test_long_runs_at_several_resolutions_are_reported_with_the_rss_target():
    from benchmarks.faults import render

    def long_run(bag, peak):
        return {"bag": bag, "method": "lili", "scans": 5601, "every": 20, "path_length_m": 430.4,
                "ate_rmse_m": 0.9, "wall_time_s": 600.0, "peak_rss_mb": peak,
                "max_sampled_rss_mb": peak - 1, "first_rss_mb": 180.0,
                "trend_mb_per_100_scans": 0.0, "second_half_from": 2800}

    md = render({"long_run": long_run("Trial 2 (32x256)", 197.0),
                 "long_run_128x1024": long_run("Trial 2 (128x1024)", 1500.0)})
    small = md[md.index("## Long run (memory): Trial 2 (32x256)"):]
    large = md[md.index("## Long run (memory): Trial 2 (128x1024)"):]
    assert "under 1.5 GB (1431 MB of 2^20 bytes): **met**" in small.split("##")[1]
    assert "**missed**" in large and "(long_run_128x1024_memory.png)" in large
