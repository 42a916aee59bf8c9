"""Odometry started while the robot drives through the featureless tunnel, per LiDAR factor.

    python -m benchmarks.studies.start_while_moving     # 3 windows x 4 settings, ~6 min on 2 cores

``test/test_degenerate_odometry.py`` checks one such start (Trial 1 at 100 s, 8 s, 32 x 256).
Its scenario is sensitive to detector misses in the first scans after a start while moving.
This script repeats it at other start times of Trial 1, over 30 s, for the between factor,
for the hybrid factor + remapping without a detection hold, with the hold
(``detection_schedule.hold_distance_m`` = 1 m) for the whole run, and with the hold limited
to the first 10 m after the start (``hold_warmup_m``). It writes
``benchmarks/results/start_while_moving.{md,json}``: ATE (evo, SE(3)-aligned) and the share of
scans flagged degenerate, per window and setting. The windows are simulated once and cached in
``data/sim``.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from benchmarks._common import RESULTS, SIM_CACHE, config_with, write_results
from lili_odom.evaluation.runner import run_bag
from lili_odom.sim.generator import ensure_trial_bag

HYBRID = {"remap_iterations": 10, "fusion.lidar.factor": "hybrid", "fusion.lidar.anchor_sigma": 0.0}
HOLD = {"detection_schedule.hold_distance_m": 1.0}
SETTINGS: dict[str, dict[str, object]] = {
    "between factor": {"remap_iterations": 0, "fusion.lidar.factor": "between",
                       "fusion.lidar.anchor_sigma": 0.02, "detection_schedule.hold_warmup_m": 0.0,
                       "detection_schedule.hold_distance_m": 0.0},
    "hybrid, no hold": {**HYBRID, "detection_schedule.hold_distance_m": 0.0},
    "hybrid + hold 1 m": {**HYBRID, **HOLD, "detection_schedule.hold_warmup_m": 0.0},
    "hybrid + hold 1 m, first 10 m": {**HYBRID, **HOLD, "detection_schedule.hold_warmup_m": 10.0},
}
# (start, duration) [s] in Trial 1; the first is the test's window
WINDOWS = ((100.0, 8.0), (60.0, 30.0), (230.0, 30.0))


def run_window(bag: Path, overrides: dict[str, object]) -> dict:
    config = config_with(overrides, prog="start_while_moving")
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_bag(bag, config, Path(tmp), rpe_segment=5.0, progress=False).summary
    return {"ate_m": summary["metrics"]["ate_rmse_m"], "scans": summary["scans_processed"],
            "degenerate_share": summary["degenerate_fraction"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", default="32x256")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    rows = []
    for start, duration in WINDOWS:
        bag = ensure_trial_bag(1, SIM_CACHE, resolution=args.resolution, start=start,
                               duration=duration, progress=False)
        for name, overrides in SETTINGS.items():
            r = {"start_s": start, "duration_s": duration, "setting": name,
                 **run_window(bag, overrides)}
            print(json.dumps(r), flush=True)
            rows.append(r)
    lines = ["# Odometry started while moving (featureless tunnel)", "",
             f"`python -m benchmarks.studies.start_while_moving` (Trial 1, OS1 at {args.resolution}, "
             "seed 0, `lili`). Each cell: ATE [m] (evo, SE(3)-aligned translation RMSE) and, in "
             "brackets, the share of scans flagged degenerate.", "",
             "| window | " + " | ".join(SETTINGS) + " |", "|---|" + "---|" * len(SETTINGS)]
    for start, duration in WINDOWS:
        cells = [f"{r['ate_m']:.3f} ({r['degenerate_share']:.0%})" for r in rows
                 if r["start_s"] == start]
        lines.append(f"| {start:.0f}-{start + duration:.0f} s | " + " | ".join(cells) + " |")
    write_results(args.out, "start_while_moving", "\n".join(lines) + "\n", rows)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
