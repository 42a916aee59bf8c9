"""When the online wheel scale is learned after a start, and what holds it back.

    python -m benchmarks.studies.wheel_scale_start                  # parking_lot, 0-40 s, 32x512
    python -m benchmarks.studies.wheel_scale_start --scenario building --duration 30
    python -m benchmarks.studies.wheel_scale_start --set fusion.wheel_scale.max_lidar_sigma=0.05 \
        --name wheel_scale_start_sigma5

Runs ``lili`` (the defaults) over a window of a suite scenario (simulated with the suite's
scenario code, :mod:`benchmarks._pieces`) and records for every scan, against the distance the
robot truly travelled since the start [m]: whether the registration had a degenerate
direction, whether the wheel-scale estimator was chaining increments into a segment
(:attr:`lili_odom.fusion.wheel_scale.WheelScaleEstimator.chaining`), the segments used and
rejected so far, and the scale applied. Reports the distance of the first chained scan, of
the first used segment (the scale applies from then on), the scale every 5 m and its error
against the scenario's true wheel scale (``1 + wheel_scale_error``). ``--set`` runs other
parameters. Writes ``benchmarks/results/<name>.{md,json}`` (default ``wheel_scale_start``).
"""
from __future__ import annotations

import argparse

import numpy as np

from benchmarks._common import (RESULTS, SET_HELP, config_with, machine_info, parse_set,
                                write_results)
from benchmarks._pieces import (add_window_arguments, format_resolution, window_bag,
                                window_command)


def trace(bag, overrides: dict | None = None) -> dict:
    """Per scan: stamp, degenerate (bool), chaining, used, rejected, scale; and the truth."""
    from lili_odom.bagio.reader import BagReader
    from lili_odom.evaluation.replay import Replay

    config = config_with({"method": "lili", **(overrides or {})}, prog="wheel_scale_start")
    rows: list[tuple] = []

    def record(out, pipeline) -> None:
        ws = pipeline.estimator.wheel_scale
        dim = out.degeneracy.dimension if out.degeneracy is not None else 0
        rows.append((out.stamp, dim > 0, ws.chaining, ws.used, ws.rejected, ws.scale))

    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic,
              config.ground_truth_topic, "/tf_static"]
    with BagReader(bag, topics=topics, required=[config.lidar_topic]) as reader:
        replay = Replay(config, on_output=record)
        replay.pipeline.start()
        try:
            replay.run(reader)
        finally:
            replay.pipeline.close()
    return {"rows": rows, "truth": replay.truth}


def travelled(stamps: np.ndarray, truth: list) -> np.ndarray:
    """True path length [m] from the first truth sample to each stamp (nearest sample)."""
    ts = np.array([s for s, _ in truth])
    xyz = np.array([T[:3, 3] for _, T in truth])
    path = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(xyz, axis=0), axis=1))]
    return path[np.clip(np.searchsorted(ts, stamps), 0, len(ts) - 1)]


def summarise(result: dict, true_scale: float | None, step_m: float = 5.0) -> dict:
    rows = result["rows"]
    stamps = np.array([r[0] for r in rows])
    dist = travelled(stamps, result["truth"])
    chaining = np.array([r[2] for r in rows])
    used = np.array([r[3] for r in rows])
    scale = np.array([r[5] for r in rows])

    def first(mask: np.ndarray) -> float | None:
        return float(dist[np.argmax(mask)]) if mask.any() else None

    marks = []
    for m in np.arange(step_m, dist[-1] + 1e-9, step_m):
        i = min(int(np.searchsorted(dist, m)), len(rows) - 1)
        s = float(scale[i])
        err = None if true_scale is None else 100.0 * (s / true_scale - 1.0)
        marks.append({"distance_m": float(m), "scale": s, "error_pct": err,
                      "degenerate_share_so_far": float(np.mean([r[1] for r in rows[:i + 1]])),
                      "segments_used": int(used[i])})
    return {"scans": len(rows), "distance_m": float(dist[-1]),
            "first_chained_m": first(chaining), "first_segment_m": first(used > 0),
            "segments_used": int(used[-1]), "segments_rejected": int(rows[-1][4]),
            "true_scale": true_scale, "marks": marks}


def markdown(report: dict, command: str) -> str:
    p, s = report["piece"], report["summary"]
    settings = ", ".join(f"`{k}` = {v}" for k, v in report.get("overrides", {}).items()) \
        or "defaults"

    def m(v):
        return "never" if v is None else f"{v:.1f} m"

    lines = [
        "# The wheel scale after a start", "",
        f"`{command}`: `lili` ({settings}) over `{p['scenario']}` (seed {p['seed']}) from "
        f"{p['start_s']:g} s for {p['duration_s']:g} s at {p['resolution']} "
        "(`benchmarks/studies/wheel_scale_start.py`). Distances are the true path since the "
        "window's start.", "",
        f"Commit `{report['machine']['commit']}`.", "",
        f"{s['scans']} scans over {s['distance_m']:.1f} m; true wheel scale "
        + ("unknown" if s["true_scale"] is None else f"{s['true_scale']:.4f}")
        + f". First scan chained into a segment: {m(s['first_chained_m'])}; first segment "
        f"used (the scale applies): {m(s['first_segment_m'])}; segments used / rejected: "
        f"{s['segments_used']} / {s['segments_rejected']}.", "",
        "| distance [m] | scale | error [%] | scans with a degenerate direction so far | "
        "segments used |",
        "|---:|---:|---:|---:|---:|",
    ]
    for k in s["marks"]:
        err = "–" if k["error_pct"] is None else f"{k['error_pct']:+.2f}"
        lines.append(f"| {k['distance_m']:.0f} | {k['scale']:.4f} | {err} | "
                     f"{100 * k['degenerate_share_so_far']:.0f} % | {k['segments_used']} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_window_arguments(ap, "parking_lot", 40.0)
    ap.add_argument("--out", default=RESULTS)
    ap.add_argument("--name", default="wheel_scale_start",
                    help="file name of the results without .md/.json")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP)
    args = ap.parse_args(argv)
    overrides = parse_set(args.set, "wheel_scale_start")
    scenario, res, bag = window_bag(ap, args)
    error = scenario.errors.wheel_scale_error
    true_scale = None if error is None else 1.0 + float(error)
    report = {"piece": {"scenario": args.scenario, "start_s": args.start,
                        "duration_s": args.duration, "seed": args.seed,
                        "resolution": format_resolution(res)},
              "machine": machine_info(),
              "overrides": overrides,
              "summary": summarise(trace(bag, overrides), true_scale)}
    command = (window_command("benchmarks.studies.wheel_scale_start", args, "parking_lot", 40.0)
               + "".join(f" --set {k}={v}" for k, v in overrides.items())
               + (f" --name {args.name}" if args.name != "wheel_scale_start" else ""))
    print(f"wrote {write_results(args.out, args.name, markdown(report, command), report)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
