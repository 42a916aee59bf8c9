"""Deskewing only the points kept: its time, its points and the order they come in.

    python -m benchmarks.studies.voxel_select                     # building, 0-30 s, 128x1024
    python -m benchmarks.studies.voxel_select --resolution 32x512 --scenario long_tunnel

On every 10th sweep of a window of a suite scenario (simulated with the suite's scenario code,
:mod:`benchmarks._pieces`), with a sweep motion of 0.1 m forward and 0.05 rad of yaw, compares
three ways to get the map points (one per 0.5-voxel cell) and the registration source (those
at 1.5 voxel) of the odometry's default voxel (1 m):

- ``whole sweep``: KISS-ICP's order of work, the ``Preprocessor`` on every point, then
  ``voxel_down_sample`` at 0.5 and 1.5 voxel;
- ``kept, sweep order``: one point per cell of the raw sweep
  (:func:`lili_odom.pipeline.voxel_select.first_in_voxel`) in the sweep's order, only those
  deskewed;
- ``kept, hash order``: :meth:`lili_odom.pipeline.scan_matcher.ScanMatcher.preprocess`, the
  odometry's own (the same points in the cell-hash order ``first_in_voxel`` returns).

Reports per way the mean time [ms] (median of 5 repeats per sweep, this process, one core of
contention at most), the map and source points, and the mean height of the source points in
the LiDAR frame [m] (a source that favours some of the sensor's rows sits higher or lower).
Writes ``benchmarks/results/voxel_select.{md,json}``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import RESULTS, machine_info, write_results
from benchmarks._pieces import (add_window_arguments, format_resolution, window_bag,
                                window_command)

VOXEL = 1.0
WAYS = ("whole sweep", "kept, sweep order", "kept, hash order")


def sweeps(bag, every: int = 10) -> list[tuple[np.ndarray, np.ndarray]]:
    """(points, times) of every ``every``-th cloud of the bag, parsed as the odometry does."""
    from lili_odom.bagio.reader import BagReader
    from lili_odom.messages import default_cloud_parser, scan_from_msg

    parse = default_cloud_parser(1.0, 100.0)
    out = []
    with BagReader(bag, topics=["/ouster/points"]) as reader:
        for k, item in enumerate(reader):
            if k % every == 0:
                scan = scan_from_msg(item.msg, parse)
                if scan.times is not None and len(scan.points):
                    out.append((scan.points, scan.times))
    return out


def compare(points: np.ndarray, times: np.ndarray, repeats: int = 5) -> dict[str, dict]:
    """The three ways on one sweep: time [ms], map and source points, source mean height."""
    from kiss_icp.preprocess import Preprocessor
    from kiss_icp.voxelization import voxel_down_sample

    from lili_odom import geometry
    from lili_odom.pipeline.scan_matcher import ScanMatcher, ScanMatcherConfig
    from lili_odom.pipeline.voxel_select import first_in_voxel

    pre = Preprocessor(100.0, 1.0, True, 0)
    matcher = ScanMatcher(ScanMatcherConfig(max_range=100.0, min_range=1.0, voxel_size=VOXEL))
    motion = geometry.exp(np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.05]))

    def with_source(map_points):
        return map_points, np.asarray(voxel_down_sample(map_points, 1.5 * VOXEL))

    def whole():
        frame = np.asarray(pre.preprocess(points, times, motion))
        return with_source(np.asarray(voxel_down_sample(frame, 0.5 * VOXEL)))

    def sweep_order():
        keep = np.sort(first_in_voxel(points, 0.5 * VOXEL))
        return with_source(np.asarray(pre.preprocess(points[keep], times[keep], motion)))

    ways = {WAYS[0]: whole, WAYS[1]: sweep_order,
            WAYS[2]: lambda: matcher.preprocess(points, times, motion)}
    out = {}
    for name, fn in ways.items():
        seconds = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            map_points, source = fn()
            seconds.append(time.perf_counter() - t0)
        out[name] = {"ms": 1e3 * float(np.median(seconds)), "map_points": len(map_points),
                     "source_points": len(source), "source_mean_z_m": float(source[:, 2].mean())}
    return out


def summarise(per_sweep: list[dict[str, dict]]) -> dict[str, dict]:
    return {w: {k: float(np.mean([s[w][k] for s in per_sweep])) for k in per_sweep[0][w]}
            for w in WAYS}


def markdown(report: dict, command: str) -> str:
    p, m = report["piece"], report["machine"]
    lines = ["# Deskewing only the points kept", "",
             f"`{command}`: {p['scenario']} from {p['start_s']:g} s for {p['duration_s']:g} s "
             f"(seed {p['seed']}) at {p['resolution']}, {report['sweeps']} sweeps (every 10th), "
             "sweep motion 0.1 m forward and 0.05 rad of yaw, voxel 1 m. Means over the sweeps; "
             "times are medians of 5 repeats per sweep.", "",
             f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}; commit "
             f"`{m['commit']}`.", "",
             "| way | time [ms] | map points | source points | source mean height [m] |",
             "|---|---:|---:|---:|---:|"]
    for w, r in report["summary"].items():
        lines.append(f"| {w} | {r['ms']:.1f} | {r['map_points']:.0f} | {r['source_points']:.0f} "
                     f"| {r['source_mean_z_m']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_window_arguments(ap, "building", 30.0, "128x1024")
    ap.add_argument("--out", default=RESULTS)
    args = ap.parse_args(argv)
    _, res, bag = window_bag(ap, args)
    per_sweep = [compare(points, times) for points, times in sweeps(bag)]
    if not per_sweep:
        ap.error("no sweep with per-point times in the window")
    report = {"piece": {"scenario": args.scenario, "start_s": args.start,
                        "duration_s": args.duration, "seed": args.seed,
                        "resolution": format_resolution(res)},
              "machine": machine_info(), "sweeps": len(per_sweep),
              "summary": summarise(per_sweep)}
    command = window_command("benchmarks.studies.voxel_select", args, "building", 30.0,
                             "128x1024")
    print(f"wrote {write_results(args.out, 'voxel_select', markdown(report, command), report)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
