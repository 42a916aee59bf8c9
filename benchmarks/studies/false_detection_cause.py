"""Is a false detection the detector's, or the map's? The same scans on a map from the true
poses and on one from the run's own estimate.

    python -m benchmarks.studies.false_detection_cause --runs DIR/runs --scenario tunnel_trial1 \\
        [--seed 0] [--resolution 32x512] [--every 10] [--history 10]

For one ``lili`` run of a suite or tuning output (``RUNS/<scenario>/seed<k>/lili``), every
``--every`` seconds one scan goes to the odometry's detector twice
(:mod:`lili_odom.evaluation.truth_map_detection`): against a local map of the previous
``--history`` seconds of scans inserted at their true poses, and against the same scans
inserted where the run's estimate (``estimate_base.tum``, base_link in the odometry frame) put
them, the tested scan guessed at its estimated pose. Both are deskewed with the true motion,
so only the placement differs. Where the true-pose map finds the place constrained and the
estimate's map does not, the odometry's drift (features smeared along the unconstrained
direction) makes the flag; where both find it constrained and the odometry flagged it, the
odometry's own detection (its map's extent, a detection carried over from an earlier scan)
does. Appends a section to ``benchmarks/results/false_detection_cause.md`` (``--out``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, git

DEFAULT_OUT = RESULTS / "false_detection_cause.md"
MAX_STAMP_GAP_S = 0.02


def estimate_placement(run_dir: Path, epoch_s: float):
    """``f(trial time)`` -> the run's estimated ``T_odom_base`` at that scan (None when the run
    has no pose within ``MAX_STAMP_GAP_S``)."""
    from lili_odom.bagio.tum import read_tum

    stamps, poses = read_tum(run_dir / "estimate_base.tum")
    t_trial = stamps - epoch_s

    def placement(t: float):
        i = int(np.argmin(np.abs(t_trial - t)))
        return poses[i] if abs(t_trial[i] - t) <= MAX_STAMP_GAP_S else None

    return placement


def odometry_dimension(run_dir: Path, epoch_s: float):
    """``f(trial time)`` -> the subspace dimension the odometry used at that scan (or None)."""
    from benchmarks.false_detections import odometry_flags

    stamps, dims, _, _ = odometry_flags(run_dir / "scans.csv")
    t = stamps - epoch_s

    def dim(tq: float):
        i = int(np.argmin(np.abs(t - tq)))
        return int(dims[i]) if abs(t[i] - tq) <= MAX_STAMP_GAP_S else None

    return dim


def study(runs: Path, scenario_name: str, seed: int, resolution: str | None, every: float,
          history: float) -> list[str]:
    from lili_odom.evaluation.truth_map_detection import TruthMapDetector
    from lili_odom.sim.generator import EPOCH_NS, Simulation
    from lili_odom.suite.scenario import load_scenarios, scenario_request

    run_dir = runs / scenario_name / f"seed{seed}" / "lili"
    if not (run_dir / "estimate_base.tum").is_file():
        raise ValueError(f"{run_dir}: no estimate_base.tum (not a suite run of lili)")
    scenario = load_scenarios([scenario_name], measure=False)[0]
    sim = Simulation(scenario_request(scenario, seed, resolution=resolution))
    epoch_s = EPOCH_NS * 1e-9
    judge = TruthMapDetector(sim, history_s=history)
    placement = estimate_placement(run_dir, epoch_s)
    odometry = odometry_dimension(run_dir, epoch_s)
    starts = sim.scan_starts()
    lines = [f"## {scenario_name}, seed {seed} ({resolution or 'own sensor'}, every {every:g} s, "
             f"{history:g} s of history; commit {git('rev-parse', '--short', 'HEAD') or '?'})",
             "", "| t [s] | true-pose map | estimate's map | odometry |", "|---:|---:|---:|---:|"]
    counts = {"constrained": 0, "flagged": 0, "estimate_map_flags": 0}
    for tq in np.arange(starts[0] + history, starts[-1] + 1e-9, every):
        t = float(starts[np.argmin(np.abs(starts - tq))])
        try:
            truth = judge.detect(t)
            est = judge.detect(t, placement=placement)
        except ValueError as exc:
            print(f"  t={t:.1f} s skipped: {exc}", file=sys.stderr)
            continue
        odo = odometry(truth.t_end)
        lines.append(f"| {t:.1f} | {truth.dimension} | {est.dimension} | "
                     f"{'–' if odo is None else odo} |")
        print(lines[-1], flush=True)
        if truth.dimension == 0:
            counts["constrained"] += 1
            if odo:
                counts["flagged"] += 1
                counts["estimate_map_flags"] += int(est.dimension > 0)
    lines += ["", f"Samples the true-pose map finds constrained: {counts['constrained']}; the "
                  f"odometry flagged {counts['flagged']} of them; the estimate's map flags "
                  f"{counts['estimate_map_flags']} of those {counts['flagged']}.", ""]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.studies.false_detection_cause",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True)
    parser.add_argument("--scenario", required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--resolution")
    parser.add_argument("--every", type=float, default=10.0)
    parser.add_argument("--history", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    try:
        lines = study(args.runs, args.scenario, args.seed, args.resolution, args.every,
                      args.history)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    head = "" if args.out.exists() else (
        "# False detections: the detector's or the map's?\n\nProduced by "
        "`benchmarks/studies/false_detection_cause.py` (see its docstring); one section per "
        "invocation.\n\n")
    with open(args.out, "a") as f:
        f.write(head + "\n".join(lines) + "\n")
    print(f"appended to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
