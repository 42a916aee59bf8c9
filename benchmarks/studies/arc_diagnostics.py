"""Where does the tunnel error come from: the detector, or the estimate it is fed?

    python -m benchmarks.studies.arc_diagnostics probe --times 60 130 150 200 250 300
    python -m benchmarks.studies.arc_diagnostics jumps data/tunnel_runs/trial1_64x512_seed0/lili
    python -m benchmarks.studies.arc_diagnostics errors data/tunnel_runs/trial1_64x512_seed0/lili
    python -m benchmarks.studies.arc_diagnostics tilt RUN_DIR --trial 2 --seed 2

``probe`` runs LiLi on simulated Trial 1 scans registered against a local map built from the
*true* poses (the previous ``--history`` seconds of scans, each column placed with its true
pose, so no deskew or odometry error enters). Whatever LiLi reports there is the detector's
own answer for that place; anything more it reports in the odometry comes from the estimate.
The map and scan go through the odometry's own preprocessing with the true sweep motion
(:mod:`lili_odom.evaluation.truth_map_detection`; ``benchmarks/false_detections.py`` uses the
same judge on whole runs).

``jumps`` reads ``estimate.tum`` and ``truth.tum`` of a ``lili-odom run`` / ``evaluate`` run
directory and counts scan-to-scan changes of the lateral position error (in the true body
frame) above ``--threshold``: a registration that is stable to centimetres cannot produce
them, an estimator that oscillates does.

``errors`` tabulates the error of such a run by component (along the tunnel, lateral,
vertical, roll, pitch, yaw) in the true body frame, without alignment: slow drift and sudden
failures look different there, and so do along-axis (wheel) and lateral/yaw (LiDAR) errors.

``tilt`` follows a run's roll/pitch against gravity: the world-frame tilt error of the fused
pose and of the scan-to-map registration (the odometry frame is gravity-aligned at the start,
so only the start yaw and position are aligned), with the accelerometer bias the estimator
holds (``scans.csv``) and, for a simulated bag (``--trial``/``--seed``), the true one. At rest
the accelerometer cannot tell a bias from a tilt, so the start's gravity alignment takes a
bias ``b`` as a tilt of about ``b / g``; the local map is built in that frame. The
registration-minus-fused column is the map's tilt against the fused estimate, averaged over
the row's period (single registrations scatter by tenths of a degree).

All four append a section to ``benchmarks/results/arc_diagnostics.md`` (``--out`` to change).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks._common import RESULTS
from lili_odom.evaluation.run_diagnostics import error_table, jump_table, tilt_table

DEFAULT_OUT = RESULTS / "arc_diagnostics.md"


def probe(times: list[float], resolution: tuple[int, int], history: float) -> list[str]:
    from lili_odom.evaluation.truth_map_detection import TruthMapDetector
    from lili_odom.sim.generator import SimRequest, Simulation

    judge = TruthMapDetector(Simulation(SimRequest(trial=1, resolution=resolution)),
                             history_s=history)
    lines = [f"## LiLi on a map from the true poses (Trial 1, {resolution[0]}x{resolution[1]}, "
             f"{history:g} s of history)", "",
             "| t [s] | x [m] | points | L [m] | dimension | PCA eigenvalues | basis (scaled, v / L w) |",
             "|---|---|---|---|---|---|---|"]
    for t in times:
        d = judge.detect(t)
        res = d.result
        basis = "; ".join("(" + ", ".join(f"{v:+.2f}" for v in row) + ")" for row in res.basis_scaled)
        eig = ", ".join(f"{v:.2f}" for v in res.eigenvalues[:3]) if res.eigenvalues is not None else ""
        lines.append(f"| {t:g} | {d.pose[0, 3]:.1f} | {d.points} | {res.characteristic_length:.1f} | "
                     f"{res.dimension} | {eig} | {basis or '-'} |")
        print(lines[-1], flush=True)
    return lines + [""]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("probe", help="LiLi against a map from the true poses")
    p.add_argument("--times", type=float, nargs="+", default=[60, 130, 150, 200, 211, 250, 300])
    p.add_argument("--resolution", default="64x512")
    p.add_argument("--history", type=float, default=5.0, help="seconds of scans in the map")
    j = sub.add_parser("jumps", help="lateral error jumps of a run directory")
    j.add_argument("run_dir", type=Path)
    j.add_argument("--threshold", type=float, default=0.05, help="[m]")
    e = sub.add_parser("errors", help="error by component of a run directory")
    e.add_argument("run_dir", type=Path)
    e.add_argument("--period", type=float, default=20.0, help="table row every N s")
    g = sub.add_parser("tilt", help="roll/pitch against gravity, with the accelerometer bias")
    g.add_argument("run_dir", type=Path)
    g.add_argument("--period", type=float, default=20.0, help="table row every N s")
    g.add_argument("--trial", type=int, help="simulated trial of the bag (true bias)")
    g.add_argument("--seed", type=int, help="simulator seed of the bag (true bias)")
    for q in (p, j, e, g):
        q.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.command == "probe":
        rows, cols = (int(v) for v in args.resolution.lower().split("x"))
        lines = probe(args.times, (rows, cols), args.history)
    else:
        if not (args.run_dir / "estimate.tum").exists() or not (args.run_dir / "truth.tum").exists():
            print(f"error: {args.run_dir}: needs estimate.tum and truth.tum", file=sys.stderr)
            return 2
        if args.command == "jumps":
            lines = jump_table(args.run_dir, args.threshold)
        elif args.command == "errors":
            lines = error_table(args.run_dir, args.period)
        else:
            try:
                lines = tilt_table(args.run_dir, args.period, args.trial, args.seed)
            except ValueError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 2
        print("\n".join(lines))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    header = "" if args.out.exists() else (
        "# Tunnel diagnostics\n\nProduced by `python -m benchmarks.studies.arc_diagnostics` "
        "(see its docstring); one section per invocation.\n\n")
    with open(args.out, "a") as f:
        f.write(header + "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
