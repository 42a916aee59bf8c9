"""How much of a tunnel run's along-axis error comes from wheel slip?

    python -m benchmarks.studies.slip_budget data/hybrid_factor_runs/trial1_64x512_seed0/lili --trial 1
    python -m benchmarks.studies.slip_budget RUN_DIR --trial 2 --name slip_budget_t2

The simulator's Husky odometry over-reads its speed by 10-35 % during slip events (Poisson, one
per 40 s on average, 0.3-1.5 s each; ``lili_odom.sim.wheels``). Where the scan matching is
degenerate along the tunnel, the wheels are the only sensor that measures that motion besides
the IMU, so a slip is expected to move the estimate ahead of the truth by part of the
over-read distance. This script regenerates the slip events of ``--trial`` / ``--seed`` (the
simulator is deterministic in its seed; the run must come from a bag of that trial and seed),
and, for a ``lili-odom run`` / ``evaluate`` run directory (``estimate.tum``, ``truth.tum``,
``scans.csv``), tabulates per event: the over-read distance, the share of the run's scans in
the event that were flagged degenerate, and the change of the along-axis error across the
event (error in the true base_link frame, both trajectories started at the same pose, no
alignment; ``lili_odom.evaluation.run_diagnostics.errors_in_true_body_frame``). The change over an event divided by its
over-read is the share of the slip that reached the estimate ("leak").

It also splits the along-axis error's variation between the slip events and the rest of the
run: the error is reduced to its median over each second (scan-to-scan jitter of registration
noise would otherwise dominate), and the absolute changes between consecutive seconds are
summed, inside seconds that overlap an event and outside. Writes
``benchmarks/results/<name>.md`` and a plot of the along-axis error with the events shaded.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS

from lili_odom.evaluation.run_diagnostics import errors_in_true_body_frame

SETTLE_S = 0.5  # the error is read this long after an event ends (the fusion lags the wheels)


def slip_events(trial: int, seed: int) -> tuple[list[tuple[float, float, float]], float]:
    """(start [s], end [s], over-read distance [m]) per slip event in trial time, and the
    trial's wheel scale (1 + e_v)."""
    from lili_odom.sim.generator import SimRequest, Simulation
    from lili_odom.sim.wheels import simulate_wheel_odom

    sim = Simulation(SimRequest(trial=trial, seed=seed))
    w = simulate_wheel_odom(sim.trajectory, sim.sensors.wheels, seed)
    dt = float(w.t[1] - w.t[0])
    events = []
    edges = np.flatnonzero(np.diff(np.r_[0, w.slipping.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):
        # over-read beyond the per-run scale error (which the wheel-scale calibration removes)
        excess = float(np.sum(w.v[a:b] - w.v_true[a:b] * w.scale) * dt)
        events.append((float(w.t[a]), float(w.t[b - 1] + dt), excess))
    return events, float(w.scale)


def budget(run_dir: Path, trial: int, seed: int) -> dict:
    from lili_odom.sim.generator import EPOCH_NS

    t_rel, err = errors_in_true_body_frame(run_dir)
    with open(run_dir / "scans.csv", newline="") as f:
        scans = list(csv.DictReader(f))
    stamps = np.array([float(r["stamp"]) for r in scans])
    scale_est = float(scans[-1]["wheel_scale"]) if scans and "wheel_scale" in scans[0] else None
    degenerate = np.array([int(r["dimension"]) > 0 for r in scans])
    t_trial0 = stamps[0] - EPOCH_NS * 1e-9  # trial time of the first estimate
    t = t_rel + t_trial0
    along = err[:, 0, 3]
    events, scale = slip_events(trial, seed)
    t_scan = stamps - EPOCH_NS * 1e-9
    rows = []
    in_event = np.zeros(len(t), bool)
    for a, b, excess in events:
        if b < t[0] or a > t[-1]:
            continue
        i0 = int(np.searchsorted(t, a - 0.1))
        i1 = min(int(np.searchsorted(t, b + SETTLE_S)), len(t) - 1)
        in_event[i0:i1 + 1] = True
        sel = (t_scan >= a) & (t_scan <= b)
        change = float(along[i1] - along[max(i0 - 1, 0)])
        rows.append({"start_s": a, "end_s": b, "over_read_m": excess,
                     "degenerate_share": float(degenerate[sel].mean()) if sel.any() else None,
                     "along_change_m": change,
                     "leak": change / excess if abs(excess) > 1e-3 else None})
    sec = np.floor(t - t[0]).astype(int)
    keep = np.bincount(sec) > 0
    med = np.array([np.median(along[sec == k]) for k in np.flatnonzero(keep)])
    sec_event = np.array([in_event[sec == k].any() for k in np.flatnonzero(keep)])
    steps = np.abs(np.diff(med))
    inside = float(steps[sec_event[1:] | sec_event[:-1]].sum())
    total = float(steps.sum())
    return {"run": str(run_dir), "trial": trial, "seed": seed, "wheel_scale_truth": scale,
            "wheel_scale_final": scale_est,
            "events": rows, "along_variation_m": total, "along_variation_in_events_m": inside,
            "time_in_events_share": float(sec_event.mean()), "t": t.tolist(),
            "along": along.tolist()}


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 3.5))
    ax.plot(result["t"], result["along"], lw=1.0, label="along-axis error")
    for k, e in enumerate(result["events"]):
        ax.axvspan(e["start_s"], e["end_s"] + SETTLE_S, color="tab:red", alpha=0.25,
                   label="wheel slip" if k == 0 else None)
    ax.set_xlabel("trial time [s]")
    ax.set_ylabel("error along base_link x [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--trial", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--name", default="slip_budget")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    for f in ("estimate.tum", "truth.tum", "scans.csv"):
        if not (args.run_dir / f).is_file():
            print(f"error: {args.run_dir / f} not found (a `lili-odom run` directory)",
                  file=sys.stderr)
            return 2
    r = budget(args.run_dir, args.trial, args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    plot(r, args.out / f"{args.name}.png")
    (args.out / f"{args.name}.json").write_text(json.dumps(
        {k: v for k, v in r.items() if k not in ("t", "along")}, indent=1) + "\n")
    run_name = "/".join(args.run_dir.resolve().parts[-3:])
    lines = [f"# Along-axis error and wheel slip: `{run_name}`", "",
             f"`python -m benchmarks.studies.slip_budget RUN --trial {args.trial} --seed {args.seed}` "
             "(see its docstring). Over-read: wheel distance beyond the truth times the run's "
             f"scale ({r['wheel_scale_truth']:.4f}) during the event; change: along-axis "
             f"error {SETTLE_S} s after the event minus just before it (positive = estimate "
             "ahead); leak = change / over-read.", "",
             "| event [s] | over-read [m] | degenerate scans | along change [m] | leak |",
             "|---|---|---|---|---|"]
    for e in r["events"]:
        share = "-" if e["degenerate_share"] is None else f"{e['degenerate_share']:.0%}"
        leak = "-" if e["leak"] is None else f"{e['leak']:+.2f}"
        lines.append(f"| {e['start_s']:.1f}-{e['end_s']:.1f} | {e['over_read_m']:+.3f} | "
                     f"{share} | {e['along_change_m']:+.3f} | {leak} |")
    over = sum(e["over_read_m"] for e in r["events"])
    change = sum(e["along_change_m"] for e in r["events"])
    lines += ["", f"- {len(r['events'])} events, {over:+.2f} m over-read in total; the along-axis "
              f"error changed by {change:+.2f} m across them.",
              f"- Variation of the along-axis error (sum of changes of its per-second median): "
              f"{r['along_variation_m']:.2f} m, of "
              f"which {r['along_variation_in_events_m']:.2f} m "
              f"({r['along_variation_in_events_m'] / max(r['along_variation_m'], 1e-9):.0%}) "
              f"across the seconds of the events, which are {r['time_in_events_share']:.0%} of "
              "the run's seconds.",
              "", f"![along-axis error]({args.name}.png)", ""]
    if r["wheel_scale_final"] is not None:
        lines[-3:-3] = [f"- Online wheel scale at the end of the run: {r['wheel_scale_final']:.4f} "
                        f"(simulator: {r['wheel_scale_truth']:.4f})."]
    (args.out / f"{args.name}.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
