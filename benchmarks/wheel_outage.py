"""Wheel outage over several tunnel windows, seeds and repeats, per configuration.

    python -m benchmarks.wheel_outage                       # ~10 min on 2 cores
    python -m benchmarks.wheel_outage --configs default benchmarks/configs/marginalized_wheels.yaml \\
        --seeds 0 1 2 --starts 70 150 --repeats 2
    python -m benchmarks.wheel_outage --threads 1 --repeats 2   # bit-identical repeats

Inside a detected degenerate subspace the wheels carry the motion; when they stop, the
subspace rests on the IMU alone and its error grows with the square of the outage length
(an effective accelerometer bias of 0.01 m/s^2, bias and tilt error together, is 2 m after
20 s). ``benchmarks.faults`` measures one such outage on one window. One window says little:
this runs the outage (the last ``--outage`` seconds of each ``--duration`` s piece, wheel
messages dropped by :class:`lili_odom.evaluation.faults.FaultInjector`) on pieces of Trial
``--trial`` starting at each of ``--starts`` [s], for each simulator seed, configuration and
repeat, with ``lili``. Pieces are simulated once into the simulator cache (``data/sim``).

Repeats of the same run need not be identical by default: KISS-ICP's parallel reductions
(TBB) sum in a thread-dependent order, and the outage amplifies those last-bit differences.
``--threads 1`` runs the native code on one thread, which makes repeats bit-identical (and the
runs slower).

Writes ``benchmarks/results/wheel_outage.{md,json,png}``: ATE (evo, SE(3)-aligned translation
RMSE), largest and final position error [m] of every run, per configuration the mean, median
and worst over all runs, and each configuration against the first, window by window (mean
difference of the final errors and the Wilcoxon signed-rank p-value). ``--reuse`` rewrites
the report from the stored runs of the same arguments.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from benchmarks._common import RESULTS, ROOT, SIM_CACHE
from benchmarks.faults import worker_fault_run
from benchmarks._comparison import matching_runs, paired_table
from benchmarks._comparison import run_label as _label
from lili_odom.sim.generator import ensure_trial_bag


def _run(job: dict) -> dict:
    """One outage run in this worker process (``faults.worker_fault_run``); its row."""
    result = worker_fault_run({
        "case": "wheel_outage", "method": "lili", "seed": 0, "window": None,
        "faults": {"wheel_outage": job["outage"]}, "bag": str(ROOT / job["bag"]),
        "config": job["config"], "threads": job["threads"]})
    m = result["metrics"]
    row = {k: job[k] for k in ("seed", "start", "repeat")}
    row.update(config=_label(job["config"]), ate_m=m["ate_rmse_m"], max_m=m["ate_max_m"],
               final_m=m["final_error_m"], scans=result["accounting"]["outputs"],
               wheel_dropped=result["injector"]["dropped"].get("/platform/odom", 0))
    print(json.dumps(row), flush=True)
    return row


def _summary(rows: list[dict], configs: list[str]) -> list[str]:
    lines = ["| configuration | runs | ATE mean | ATE median | ATE worst | final mean "
             "| final median | final worst |", "|---|---|---|---|---|---|---|---|"]
    for config in map(_label, configs):
        mine = [r for r in rows if r["config"] == config]
        ate, fin = [r["ate_m"] for r in mine], [r["final_m"] for r in mine]
        lines.append(f"| `{config}` | {len(mine)} | {statistics.mean(ate):.3f} | "
                     f"{statistics.median(ate):.3f} | {max(ate):.3f} | "
                     f"{statistics.mean(fin):.2f} | {statistics.median(fin):.2f} | "
                     f"{max(fin):.2f} |")
    return lines


def _per_window(rows: list[dict], configs: list[str]) -> list[str]:
    lines = ["| seed | start [s] | " + " | ".join(f"`{_label(c)}`" for c in configs) + " |",
             "|---|---|" + "---|" * len(configs)]
    windows = sorted({(r["seed"], r["start"]) for r in rows})
    for seed, start in windows:
        cells = []
        for config in map(_label, configs):
            mine = sorted((r for r in rows if (r["seed"], r["start"], r["config"])
                           == (seed, start, config)), key=lambda r: r["repeat"])
            cells.append(", ".join(f"{r['ate_m']:.2f} / {r['final_m']:.2f}" for r in mine))
        lines.append(f"| {seed} | {start:g} | " + " | ".join(cells) + " |")
    return lines


def _plot(rows: list[dict], configs: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    windows = sorted({(r["seed"], r["start"]) for r in rows})
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(windows) + 2.0), 3.6))
    width = 0.8 / max(1, len(configs))
    for j, config in enumerate(map(_label, configs)):
        xs, ys = [], []
        for i, w in enumerate(windows):
            for r in rows:
                if (r["seed"], r["start"], r["config"]) == (*w, config):
                    xs.append(i - 0.4 + width * (j + 0.5))
                    ys.append(r["final_m"])
        ax.plot(xs, ys, "o", alpha=0.8, label=config)
    ax.set_xticks(range(len(windows)), [f"seed {s}\n{t:g} s" for s, t in windows])
    ax.set_ylabel("final position error [m]")
    ax.set_title("wheel outage: error at its end, every run")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trial", type=int, default=1, choices=(1, 2))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--starts", type=float, nargs="+", default=[70.0, 150.0],
                    help="piece starts in the trial [s]")
    ap.add_argument("--duration", type=float, default=40.0, help="piece length [s]")
    ap.add_argument("--outage", type=float, default=20.0,
                    help="no wheels for the last OUTAGE seconds of each piece")
    ap.add_argument("--configs", nargs="+",
                    default=["default", "benchmarks/configs/marginalized_wheels.yaml"],
                    help="'default' or ROS 2 parameter files (relative to the repository)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--threads", type=int, default=0,
                    help="native threads per run (0 = all; 1 = bit-identical repeats)")
    ap.add_argument("--resolution", default="32x256")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--reuse", action="store_true",
                    help="take the runs from OUT/wheel_outage.json (written by the same "
                    "arguments) instead of running them; rewrites the report")
    args = ap.parse_args(argv)
    for config in args.configs:
        if config != "default" and not (ROOT / config).is_file():
            ap.error(f"{config}: no such parameter file")
    if not 0.0 < args.outage <= args.duration:
        ap.error("--outage must be in (0, --duration]")
    if args.repeats < 1:
        ap.error("--repeats must be at least 1")
    if args.reuse:
        return _report(args, _reused_rows(args))
    bags = {}
    for seed in args.seeds:  # one at a time: each generation uses every core
        for start in args.starts:
            bag = ensure_trial_bag(args.trial, SIM_CACHE, resolution=args.resolution,
                                   seed=seed, start=start, duration=args.duration,
                                   progress=False)
            bags[seed, start] = os.path.relpath(bag, ROOT)  # no machine paths in the results
    outage = [args.duration - args.outage, args.duration]
    jobs = [{"bag": bags[s, t], "seed": s, "start": t, "config": c, "repeat": r,
             "outage": outage, "threads": args.threads}
            for s in args.seeds for t in args.starts for c in args.configs
            for r in range(args.repeats)]
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        rows = list(pool.map(_run, jobs))
    return _report(args, rows)


def _reused_rows(args: argparse.Namespace) -> list[dict]:
    """The runs of an earlier invocation with the same arguments (SystemExit otherwise)."""
    path = args.out / "wheel_outage.json"
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f"--reuse: cannot read {path}: {exc}") from None
    wanted = {(s, float(t), _label(c), r) for s in args.seeds for t in args.starts
              for c in args.configs for r in range(args.repeats)}
    rows = matching_runs(stored, {"trial": args.trial, "resolution": args.resolution,
                                  "duration_s": args.duration, "outage_s": args.outage,
                                  "threads": args.threads},
                         wanted, ("seed", "start", "config", "repeat"))
    if rows is None:
        raise SystemExit(f"--reuse: {path} holds other runs than these arguments ask for")
    return rows


def _report(args: argparse.Namespace, rows: list[dict]) -> int:
    """Write wheel_outage.{json,md,png} into ``args.out``."""
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "wheel_outage.json").write_text(json.dumps(
        {"trial": args.trial, "resolution": args.resolution, "duration_s": args.duration,
         "outage_s": args.outage, "threads": args.threads, "runs": rows}, indent=1) + "\n")
    _plot(rows, args.configs, args.out / "wheel_outage.png")
    starts = " ".join(f"{t:g}" for t in args.starts)
    command = (f"python -m benchmarks.wheel_outage --trial {args.trial} --seeds "
               f"{' '.join(map(str, args.seeds))} --starts {starts}"
               f" --duration {args.duration:g} --outage {args.outage:g} --configs "
               f"{' '.join(args.configs)} --repeats {args.repeats} --threads {args.threads} "
               f"--resolution {args.resolution}")
    lines = ["# Wheel outage over windows, seeds and repeats", "",
             f"`{command}`", "",
             f"`lili` on {args.duration:g} s pieces of Trial {args.trial} (OS1 at "
             f"{args.resolution}) starting at the given trial time; no wheel odometry for the "
             f"last {args.outage:g} s of each piece. ATE: evo, SE(3)-aligned translation RMSE "
             "over the piece; final: position error at the piece's (and the outage's) end. "
             "Native threads per run: " + ("all" if not args.threads else str(args.threads))
             + (" (repeats are bit-identical)." if args.threads == 1 else
                " (repeats can differ: parallel reductions in KISS-ICP sum in a thread-dependent "
                "order, and the outage amplifies the last-bit differences)."), "",
             "## Over all runs [m]", "", *_summary(rows, args.configs), "",
             "## Per window: ATE / final [m], one pair per repeat", "",
             *_per_window(rows, args.configs), "",
             "## Paired by window: final error [m]", "",
             "Positive: the first configuration ends further off. A window's final error "
             "(averaged over its repeats) is one draw of a quantity that spreads over metres "
             "(the outage integrates the IMU's noise), so read the p-value, not the means.", "",
             *paired_table(rows, [_label(c) for c in args.configs]), "",
             "![final error per run](wheel_outage.png)", ""]
    (args.out / "wheel_outage.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
