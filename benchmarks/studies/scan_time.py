#!/usr/bin/env python3
"""Where a scan's time goes in ``lili-odom run``, finer than the pipeline's stages.

Runs :func:`lili_odom.evaluation.runner.run_bag` with the defaults over the speed benchmarks'
piece (:mod:`benchmarks._pieces`: the ``building`` scenario from rest, 30 s) at each
``--resolutions``, one run each in this process, with timers around the main loop's parts:
the messages fed (``MessageFeeder.feed``), the pipeline (``process_scan`` and its stages), the
outputs bag (``write_output``), and inside the detector stage the plane fits (``_planes``: the
k-d query of the scan points' ``normal_neighbors`` nearest map points and the fits), the
screen, the wait for background detections and the constrained refinement. Then it times the
k-d query alone on the plane fits' own inputs, captured during the run (every 30th scan).

Cells are milliseconds per processed scan (wall time in the main thread, so waiting for the
GIL held by the bag-reading thread counts where it happens). Writes
``benchmarks/results/scan_time.md`` and ``.json``.

Usage: ``python -m benchmarks.studies.scan_time [--resolutions 32x512 64x1024] [--out DIR]``
"""
from __future__ import annotations

import argparse
import functools
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import numpy as np

from benchmarks._common import RESULTS, machine_info, write_results
from benchmarks._pieces import add_piece_arguments, piece_bags, piece_command

#: (label, module, owner attribute or None, function) timed in the run, in report order
TIMED = (
    ("messages fed (pipeline included)", "lili_odom.pipeline.feeder", "MessageFeeder", "feed"),
    ("pipeline (process_scan)", "lili_odom.pipeline.odometry", "OdometryPipeline",
     "process_scan"),
    ("input checks", "lili_odom.pipeline.odometry", None, "checked_scan"),
    ("plane fits", "lili_odom.pipeline.plane_refinement", None, "_planes"),
    ("screen (plane fits included)", "lili_odom.pipeline.odometry", "OdometryPipeline",
     "_screen"),
    ("wait for background detections", "lili_odom.pipeline.odometry", "OdometryPipeline",
     "_collect_background"),
    ("constrained refinement", "lili_odom.pipeline.odometry", "OdometryPipeline",
     "_refine_constrained"),
    ("outputs bag", "lili_odom.bagio.writer", "OutputBagWriter", "write_output"),
)


class Timers:
    """Wraps functions with wall-clock accumulators; :meth:`undo` restores them."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._undo: list[Callable[[], None]] = []

    def wrap(self, label: str, owner: Any, name: str) -> None:
        original = getattr(owner, name)

        @functools.wraps(original)
        def timed(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                self.seconds[label] += time.perf_counter() - t0
                self.calls[label] += 1

        setattr(owner, name, timed)
        self._undo.append(lambda: setattr(owner, name, original))

    def undo(self) -> None:
        while self._undo:
            self._undo.pop()()


def measure(bag: Path, capture_every: int = 30) -> dict[str, Any]:
    """One ``run_bag`` over ``bag`` with the timers; the per-scan figures and the k-d query
    timed again on the captured plane-fit inputs."""
    import importlib

    from lili_odom.config import NodeConfig
    from lili_odom.evaluation.runner import run_bag
    from lili_odom.pipeline import plane_refinement

    timers = Timers()
    for label, module, owner, name in TIMED:
        mod = importlib.import_module(module)
        timers.wrap(label, getattr(mod, owner) if owner else mod, name)
    captured: list[tuple[np.ndarray, np.ndarray, Any]] = []
    fits = plane_refinement._planes  # the timed one

    def capturing(reference, q, cfg):
        if timers.calls["plane fits"] % capture_every == 0:
            captured.append((reference.points, np.array(q), cfg))
        return fits(reference, q, cfg)

    plane_refinement._planes = capturing
    try:
        with tempfile.TemporaryDirectory(prefix="lili_scan_time_") as tmp:
            t0 = time.perf_counter()
            run = run_bag(bag, NodeConfig(), Path(tmp) / "run", progress=False)
            wall = time.perf_counter() - t0
    finally:
        plane_refinement._planes = fits
        timers.undo()
    n = len(run.estimates)
    parts = {label: 1000.0 * timers.seconds[label] / n for label, *_ in TIMED}
    stages = {k: 1000.0 * v for k, v in run.summary["timings_mean_s"].items()}
    return {"scans": n, "wall_s": wall, "loop_s": run.summary["wall_time_s"],
            "ms_per_scan": parts, "stages_ms": stages,
            "query": query_cost(captured),
            "ate_m": (run.summary.get("metrics") or {}).get("ate_rmse_m")}


def query_cost(captured: list[tuple[np.ndarray, np.ndarray, Any]], repeats: int = 5
               ) -> dict[str, float]:
    """The plane fits' k-d query alone on captured inputs: mean ms per query call, scan
    points and map points per call, and microseconds per scan point."""
    from scipy.spatial import cKDTree

    from lili_odom.degeneracy.reference import kdtree_workers

    if not captured:
        return {}
    total, points = 0.0, 0
    for map_points, q, cfg in captured:
        tree = cKDTree(map_points, balanced_tree=False, compact_nodes=False)
        k = min(cfg.normal_neighbors, len(map_points))
        for _ in range(repeats):
            t0 = time.perf_counter()
            tree.query(q, k=k, distance_upper_bound=cfg.max_neighbor_distance,
                       workers=kdtree_workers(len(q)))
            total += time.perf_counter() - t0
        points += repeats * len(q)
    calls = repeats * len(captured)
    return {"ms_per_call": 1000.0 * total / calls,
            "scan_points_per_call": points / calls,
            "map_points_mean": float(np.mean([len(m) for m, _, _ in captured])),
            "us_per_point": 1e6 * total / points}


def markdown(results: dict[str, dict[str, Any]], command: str, machine: dict[str, Any]) -> str:
    res = list(results)
    lines = ["# Where a scan's time goes in `lili-odom run`", "",
             f"`{command}`: `run_bag` with the defaults over the speed benchmarks' `building` "
             "piece, one run per resolution with timers around the main loop's parts "
             "(module docstring of `benchmarks/studies/scan_time.py`). Milliseconds per "
             "processed scan, main-thread wall time.", "",
             f"Machine: {machine['cpu']}, {machine['cores']} cores, Python {machine['python']}; "
             f"commit `{machine['commit']}`.", "",
             "| part | " + " | ".join(res) + " |", "|---|" + "---:|" * len(res)]
    first = results[res[0]]
    rows = [("whole run / scans [ms]", lambda r: 1000.0 * r["wall_s"] / r["scans"])]
    rows += [(label, (lambda lab: lambda r: r["ms_per_scan"][lab])(label))
             for label in first["ms_per_scan"]]
    rows += [(f"stage `{k}`", (lambda key: lambda r: r["stages_ms"].get(key, float("nan")))(k))
             for k in first["stages_ms"]]
    rows += [("k-d query alone [ms per plane fit]",
              lambda r: r["query"].get("ms_per_call", float("nan"))),
             ("k-d query [us per scan point]",
              lambda r: r["query"].get("us_per_point", float("nan"))),
             ("scan points per plane fit", lambda r: r["query"].get("scan_points_per_call",
                                                                    float("nan"))),
             ("map points (mean)", lambda r: r["query"].get("map_points_mean", float("nan"))),
             ("ATE [m]", lambda r: r["ate_m"] if r["ate_m"] is not None else float("nan"))]
    for label, get in rows:
        lines.append(f"| {label} | " + " | ".join(f"{get(results[x]):.3g}" for x in res) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_piece_arguments(ap)
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--name", default="scan_time")
    args = ap.parse_args(argv)
    if not args.resolutions:
        args.resolutions = ["32x512", "64x1024"]
    _, bags = piece_bags(ap, args)
    results = {}
    for res, bag in bags.items():
        print(f"[{res}] run ...", flush=True)
        results[res] = measure(bag)
    machine = machine_info()
    command = piece_command("benchmarks.studies.scan_time", args)
    path = write_results(args.out, args.name, markdown(results, command, machine),
                         {"machine": machine, "command": command, "resolutions": results})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
