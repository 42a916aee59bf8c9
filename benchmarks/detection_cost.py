"""What the detector's cost savings do to the detected subspace and to the odometry.

    python -m benchmarks.detection_cost                  # LiLi, two 40 s pieces of Trial 1
    python -m benchmarks.detection_cost --variant reuse6 detection_schedule.max_reuse=6

For each piece of the simulated tunnel Trial 1 (default 64x512: the cluttered entrance from 0 s
and the featureless stretch from 70 s, 40 s each) the odometry runs once with the *reference*
detector settings (the paper's: every scan, every scan point up to ``detection_points``, 100
ICP iterations per perturbed re-registration, each run to convergence) and once per *variant*
(pipeline parameters overridden, dotted names as in ``config/lili_odom.yaml`` below
``pipeline``). Per run: ATE /
RPE / final error (evo), the share of scans on which the detector ran, the mean detector time
per scan [ms], scans/s, and against the reference, scan by scan: the share of scans with the
same detected dimension and the largest principal angle between the two subspaces (scaled
space, sensor body frame) where both are degenerate with equal dimension (mean, p95). The
reference row holds, in those columns, the detector's own scan-to-scan spread. Writes
``benchmarks/results/detection_cost.{md,json}``.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, apply_set, parse_set, write_results
from lili_odom.config import load_config
from lili_odom.evaluation.runner import run_bag
from lili_odom.sim.generator import ensure_trial_bag

PIECES = {"entrance": 0.0, "featureless": 70.0}
RESOLUTION = "64x512"
DEFAULT_OUT = RESULTS


def largest_angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    """Largest principal angle [deg] between the row spaces of orthonormal A and B (same k)."""
    s = np.linalg.svd(A @ B.T, compute_uv=False)
    return float(np.degrees(np.arccos(np.clip(s.min(), -1.0, 1.0))))


def agreement(pairs: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """Share of basis pairs with equal dimension, and the largest principal angles [deg]
    (mean, p95) of the pairs that are degenerate with equal dimension."""
    same = [(A, B) for A, B in pairs if len(A) == len(B)]
    a = np.asarray([largest_angle_deg(A, B) for A, B in same if len(A)])
    return {"matched_scans": len(pairs),
            "same_dimension": len(same) / len(pairs) if pairs else float("nan"),
            "angle_mean_deg": float(a.mean()) if len(a) else 0.0,
            "angle_p95_deg": float(np.percentile(a, 95)) if len(a) else 0.0}


def compare(ref, run) -> dict:
    """Scan-by-scan agreement of ``run``'s subspaces with ``ref``'s (matched by stamp)."""
    ref_idx = {round(t, 6): i for i, t in enumerate(ref.stamps)}
    pairs = [(ref.bases_scaled[ref_idx[round(t, 6)]], run.bases_scaled[j])
             for j, t in enumerate(run.stamps) if round(t, 6) in ref_idx]
    return agreement(pairs)


def self_consistency(ref) -> dict:
    """The reference against itself one scan later: the detector's own scan-to-scan spread,
    the scale on which to judge a carried-over subspace."""
    return agreement(list(zip(ref.bases_scaled[:-1], ref.bases_scaled[1:])))


#: the paper's LiLi settings, every scan
REFERENCE = {"detection_schedule.max_reuse": 0, "lili.perturbation_points": 0,
             "lili.perturbation_iterations": 0, "lili.return_ratio": 0.0}
#: variants measured by default (each overrides the reference)
VARIANTS = {
    "reuse2": {"detection_schedule.max_reuse": 2, "detection_schedule.reuse_distance_m": 0.3},
    "return0.1": {"lili.return_ratio": 0.1},
    "reuse4+return0.1": {"detection_schedule.max_reuse": 4,
                         "detection_schedule.reuse_distance_m": 0.5, "lili.return_ratio": 0.1},
}


def one_run(bag: Path, method: str, name: str, overrides: dict, work: Path, label: str):
    config = load_config(None)
    config.pipeline.method = method
    apply_set(config, {**REFERENCE, **overrides}, "detection_cost")
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    run = run_bag(bag, config, work / f"{label}_{name}", progress=False)
    s, m = run.summary, run.summary.get("metrics") or {}
    det = np.asarray(run.timings.get("detector", [0.0]))
    row = {"variant": name, "overrides": overrides, "scans": s["scans_processed"],
           "detector_share": 1.0 - float(np.mean(run.reused)) if run.reused else float("nan"),
           "detector_ms": 1e3 * float(det.mean()), "scans_per_second": s["scans_per_second"],
           "ate_rmse_m": m.get("ate_rmse_m"), "rpe_rmse_m": m.get("rpe_rmse_m"),
           "rpe_segment_m": m.get("rpe_segment_m"), "final_error_m": m.get("final_error_m"),
           "degenerate_fraction": s["degenerate_fraction"], "mean_dimension": s["mean_dimension"],
           "wall_s": time.perf_counter() - t0,
           "load_average": 0.5 * (load0 + os.getloadavg()[0])}
    print(f"{label:12s} {name:18s}: {row['scans']} scans, detector on "
          f"{100 * row['detector_share']:.0f} %, {row['detector_ms']:.0f} ms/scan, "
          f"{row['scans_per_second']:.1f} scans/s, ATE {row['ate_rmse_m']:.3f} m", flush=True)
    return run, row


def markdown(report: dict) -> str:
    lines = [
        "# Detector cost savings: subspace and odometry against the paper's settings",
        "",
        f"Generated by `{report.get('command', 'python -m benchmarks.detection_cost')}` "
        f"(method `{report['method']}`, tunnel Trial 1 at {report['resolution']}, "
        f"{report['duration']:g} s pieces). "
        "Reference: the paper's settings, the detector on every scan. Variants: "
        + "; ".join(f"`{n}` = " + ", ".join(f"`{k}={v}`" for k, v in o.items())
                    for n, o in report["variants"].items())
        + ". Reuse carries a detection over to at most `max_reuse` following scans within "
        f"`reuse_distance_m` (default {report['reuse_distance_m']:g} m) and "
        f"{report['reuse_angle_deg']:g} deg of it; `return_ratio` stops a perturbed "
        "re-registration once it came back (ratio below it; 0 = every run to convergence). "
        "Same dim: scans whose detected dimension equals the reference's on the same scan; "
        "angle: largest principal angle to the reference's subspace where both are degenerate "
        "with equal dimension (scaled space). The reference's row gives, in those two columns, "
        "the detector's own spread: each scan of the reference against the next one. "
        "Detector time is the mean over all scans, reused ones included; load: the machine's "
        "1-min load average (mean of the run's start and end; 2 cores): detector times and "
        "scans/s of runs under different load do not compare.",
        "",
        "| piece | settings | detector runs | detector [ms/scan] | scans/s | ATE [m] | RPE [m] "
        "(segment) | final [m] | degenerate | mean dim | same dim | angle mean / p95 [deg] "
        "| load |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for piece, rows in report["pieces"].items():
        for r in rows:
            c = r.get("vs_reference") or r.get("scan_to_scan")
            tag = " (scan to scan)" if "scan_to_scan" in r else ""
            tail = (f"{100 * c['same_dimension']:.0f} %{tag} | {c['angle_mean_deg']:.1f} / "
                    f"{c['angle_p95_deg']:.1f} |") if c else "- | - |"
            lines.append(
                f"| {piece} | {r['variant']} | {100 * r['detector_share']:.0f} % | "
                f"{r['detector_ms']:.0f} | {r['scans_per_second']:.1f} | {r['ate_rmse_m']:.3f} | "
                f"{r['rpe_rmse_m']:.3f} ({r['rpe_segment_m']:.0f} m) | {r['final_error_m']:.3f} | "
                f"{100 * r['degenerate_fraction']:.0f} % | {r['mean_dimension']:.2f} | " + tail
                + (f" {r['load_average']:.1f} |" if "load_average" in r else " - |"))
    lines += ["", f"Machine: {report['machine']}.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    import platform

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--method", default="lili", choices=("lili", "zhang", "hessian"))
    ap.add_argument("--variant", nargs="+", action="append", metavar=("NAME", "KEY=VALUE"),
                    help="a variant (repeatable): a name and pipeline overrides; replaces the "
                    "default variants")
    ap.add_argument("--resolution", default=RESOLUTION)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--pieces", nargs="+", default=list(PIECES), choices=list(PIECES))
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = ap.parse_args(argv)
    variants = VARIANTS
    if args.variant:
        variants = {}
        for name, *pairs in args.variant:
            variants[name] = parse_set(pairs, f"detection_cost: --variant {name}")
    logging.basicConfig(level=logging.ERROR)
    defaults = load_config(None).pipeline.detection_schedule
    command = ("python -m benchmarks.detection_cost"
               + (f" --method {args.method}" if args.method != "lili" else "")
               + (f" --resolution {args.resolution}" if args.resolution != RESOLUTION else "")
               + (f" --duration {args.duration:g}" if args.duration != 40.0 else "")
               + (f" --pieces {' '.join(args.pieces)}" if args.pieces != list(PIECES) else "")
               + "".join(f" --variant {name} " + " ".join(f"{k}={v}" for k, v in o.items())
                         for name, o in (variants.items() if args.variant else ()))
               + (f" --out {args.out}" if args.out != DEFAULT_OUT else ""))
    report = {"method": args.method, "resolution": args.resolution, "duration": args.duration,
              "command": command,
              "reuse_distance_m": defaults.reuse_distance_m,
              "reuse_angle_deg": defaults.reuse_angle_deg, "variants": variants,
              "machine": f"{platform.machine()}, {__import__('os').cpu_count()} cores, "
                         f"Python {platform.python_version()}",
              "pieces": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for piece in args.pieces:
            bag = ensure_trial_bag(1, resolution=args.resolution, start=PIECES[piece],
                                   duration=args.duration, progress=False)
            ref, row = one_run(bag, args.method, "reference", {}, Path(tmp), piece)
            row["scan_to_scan"] = self_consistency(ref)
            rows = [row]
            for name, overrides in variants.items():
                run, row = one_run(bag, args.method, name, overrides, Path(tmp), piece)
                row["vs_reference"] = compare(ref, run)
                rows.append(row)
            report["pieces"][piece] = rows
    write_results(args.out, "detection_cost", markdown(report), report)
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
