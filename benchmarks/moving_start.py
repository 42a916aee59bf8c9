"""Recordings that start while the robot drives: our odometry against the peers.

    python -m benchmarks.moving_start            # four windows at 32x512, about 10 min

A bag recorded mid-drive gives no standstill to start from: the first sweep cannot be
deskewed, the second only with the wheels' speed, and an IMU cannot tell driving at constant
speed from rest. Each window here is a suite scenario (its world, trial, sensor family, error
profile, seed 0) cut to start at a moment the robot moves, simulated at one resolution, and run
by:

* ``lili``: the defaults;
* ``lili, no re-deskew``: ``pipeline.redeskew_start: false`` (the first sweeps stay in the map
  as they were deskewed);
* ``lili, no wheels``: the wheel topic ignored (LiDAR and IMU only);
* the peers ``kiss``, ``genz`` and ``rko`` (as the suite runs them; skipped when not
  installed).

Scored as the suite scores (:func:`lili_odom.suite.scoring.score`): ATE after SE(3) alignment,
and the position error with the estimate anchored at the truth's first pose after 1 s, 5 s and
at the end (what a user sees of the start). Writes ``benchmarks/results/moving_start.{md,json}``
and ``moving_start.png`` (the anchored error over time per window).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, git, write_results
from benchmarks._pieces import format_resolution, parse_resolution, piece_bag

#: (scenario, start [s of its trial]) of every window: the robot drives at that moment.
WINDOWS: tuple[tuple[str, float], ...] = (
    ("building", 30.0), ("parking_lot", 20.0), ("airfield", 30.0), ("long_tunnel", 30.0))

#: label -> (method, overrides)
VARIANTS: dict[str, tuple[str, tuple[tuple[str, str], ...]]] = {
    "lili": ("lili", ()),
    "lili, no re-deskew": ("lili", (("redeskew_start", "false"),)),
    "lili, no wheels": ("lili", (("wheel_topic", "/none"),)),
    "kiss": ("kiss", ()),
    "genz": ("genz", ()),
    "rko": ("rko", ()),
}

CHECKS_S = (1.0, 5.0)


def anchored_errors(est_tum: Path, truth_tum: Path) -> tuple[np.ndarray, np.ndarray]:
    """(times since the first matched pose [s], position error [m]) of the estimate anchored
    at the truth's first matched pose."""
    from evo.core import sync
    from evo.tools import file_interface

    ref = file_interface.read_tum_trajectory_file(str(truth_tum))
    est = file_interface.read_tum_trajectory_file(str(est_tum))
    ref, est = sync.associate_trajectories(ref, est, max_diff=0.02)
    anchor = ref.poses_se3[0] @ np.linalg.inv(est.poses_se3[0])
    err = np.array([np.linalg.norm((anchor @ e)[:3, 3] - r[:3, 3])
                    for e, r in zip(est.poses_se3, ref.poses_se3)])
    return est.timestamps - est.timestamps[0], err


def run_window(scenario: str, start: float, duration: float, resolution: tuple[int, int],
               variants: list[str], tmp: Path, progress: bool) -> tuple[list[dict], dict]:
    from lili_odom.suite.jobs import BagSpec, Job, execute
    from lili_odom.suite.methods import peer_available
    from lili_odom.suite.scenario import load_scenarios

    (sc,) = load_scenarios([scenario], measure=False)
    bag = piece_bag(scenario, start, duration, resolution, 0, progress=progress)
    rows, curves = [], {}
    for label in variants:
        method, overrides = VARIANTS[label]
        if method in ("kiss", "genz", "rko") and not peer_available(method):
            if progress:
                print(f"  {label}: not installed, skipped", flush=True)
            continue
        out = tmp / f"{scenario}_{len(rows)}"
        job = Job(scenario=scenario, split=sc.split, kind=sc.kind, seed=0, method=method,
                  bag=BagSpec(path=str(bag)), out_dir=str(out),
                  truth_path=str(tmp / f"{scenario}_truth.tum"), overrides=overrides)
        row = execute(job)
        row = {"window": f"{scenario} {start:g}-{start + duration:g} s", "variant": label,
               **{k: row.get(k) for k in ("ate_m", "final_m", "distance_m", "scans_per_s",
                                          "error")}}
        est = out / "estimate_base.tum"
        if est.is_file() and row.get("error") is None:
            t, err = anchored_errors(est, Path(job.truth_path))
            for c in CHECKS_S:
                row[f"err_{c:g}s_m"] = float(np.interp(c, t, err))
            curves[label] = (t.tolist(), err.tolist())
        rows.append(row)
        if progress:
            print(f"  {label}: ATE {row.get('ate_m')}, error after 1 s "
                  f"{row.get('err_1s_m')}", flush=True)
    return rows, curves


def _fmt(v) -> str:
    return "–" if v is None else f"{v:.3f}"


def markdown(report: dict, command: str) -> str:
    lines = ["# Recordings that start while driving", "",
             f"`{command}`: suite scenarios cut to start while the robot moves (seed 0, "
             f"{report['resolution']}, {report['duration_s']:g} s each), commit "
             f"`{report['commit']}`. ATE after SE(3) alignment; the anchored errors are the "
             "position error with the estimate anchored at the truth's first pose, after 1 s, "
             "5 s and at the end.", "",
             "| window | method | ATE [m] | anchored 1 s [m] | anchored 5 s [m] | "
             "anchored end [m] | distance [m] |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in report["rows"]:
        if r.get("error"):
            lines.append(f"| {r['window']} | {r['variant']} | failed: {r['error'][:60]} "
                         "| | | | |")
            continue
        lines.append(f"| {r['window']} | {r['variant']} | {_fmt(r['ate_m'])} | "
                     f"{_fmt(r.get('err_1s_m'))} | {_fmt(r.get('err_5s_m'))} | "
                     f"{_fmt(r['final_m'])} | {_fmt(r['distance_m'])} |")
    lines += ["", "![anchored error over time](moving_start.png)", ""]
    return "\n".join(lines)


def plot(curves: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(curves), figsize=(4.2 * len(curves), 3.6), squeeze=False)
    for ax, (window, by_label) in zip(axes[0], curves.items()):
        for label, (t, err) in by_label.items():
            ax.plot(t, err, label=label, lw=1.2)
        ax.set_title(window, fontsize=9)
        ax.set_xlabel("time since the first scan [s]")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("anchored position error [m]")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="32x512", help="ROWSxCOLS (default 32x512)")
    ap.add_argument("--duration", type=float, default=20.0, help="window length [s] (20)")
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), metavar="VARIANT",
                    default=list(VARIANTS), help="default: all (" + ", ".join(VARIANTS) + ")")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    try:
        resolution = parse_resolution(args.resolution)
    except ValueError as exc:
        ap.error(str(exc))
    progress = not args.no_progress
    rows, curves = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for scenario, start in WINDOWS:
            if progress:
                print(f"[{scenario} from {start:g} s]", flush=True)
            r, c = run_window(scenario, start, args.duration, resolution, args.variants,
                              Path(tmp), progress)
            rows += r
            curves[f"{scenario} {start:g}-{start + args.duration:g} s"] = c
    report = {"commit": git("rev-parse", "--short", "HEAD"),
              "resolution": format_resolution(resolution), "duration_s": args.duration,
              "rows": rows}
    command = ("python -m benchmarks.moving_start"
               + (f" --resolution {args.resolution}" if args.resolution != "32x512" else "")
               + (f" --duration {args.duration:g}" if args.duration != 20.0 else "")
               + (f" --variants {' '.join(repr(v) for v in args.variants)}"
                  if args.variants != list(VARIANTS) else ""))
    args.out.mkdir(parents=True, exist_ok=True)
    plot(curves, args.out / "moving_start.png")
    path = write_results(args.out, "moving_start", markdown(report, command), report)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
