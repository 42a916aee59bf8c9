"""False detections of the odometry: its degenerate flags where the place is constrained.

    python -m benchmarks.false_detections --runs DIR/runs [--scenarios NAME...] \\
        [--resolution 32x512] [--every 2.0] [--history 3.0|map] [--out DIR]

``--runs`` is the ``runs`` directory of a ``lili-odom suite`` (or ``python -m
benchmarks.tuning``) output: ``RUNS/<scenario>/seed<k>/lili/scans.csv`` holds the subspace
dimension the odometry used on every scan. ``--resolution`` must be the one those runs were
simulated at (default: each scenario's own sensor).

Every ``--every`` seconds of the run (from ``--history`` after its start) one scan is the
judge's sample: the odometry's own detector runs on it against a KISS-ICP local map made of
the previous ``--history`` seconds of scans placed at their *true* poses and deskewed with the
true motion (:mod:`lili_odom.evaluation.truth_map_detection`). ``--history map`` builds the
judge's map as the odometry builds its own: every scan from the run's start, KISS-ICP's
range pruning (samples from ``--every`` after the start). A sample with dimension 0 marks
a constrained place; every scan of the run belongs to its nearest sample. Reported per run:
the share of the scans in constrained places that the odometry flagged degenerate (the
issue's target: at most 5 %), split into standstill and driving (true speed below/above 0.05
m/s), and on constrained stretches only (``STRETCH_SAMPLES`` consecutive constrained
samples); where ``scans.csv`` records them, the share with any subspace (the weakly held
directions included, column ``weakly_held``) and the detector's part of it (without the
directions the weak-direction check added); and the share of the scans in places the judge
finds degenerate that the odometry flagged degenerate too.

Writes ``OUT/false_detections.{md,json}`` and ``false_detections.png`` (default OUT:
``benchmarks/results/false_detections``). Every sweep of the judged span is simulated once
(maps of overlapping samples share their scans).
"""
from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, git, write_results

DEFAULT_OUT = RESULTS / "false_detections"
STANDSTILL_SPEED = 0.05
"""True speed [m/s] below which a scan counts as taken at a standstill."""
TARGET = 0.05
"""Largest share of the scans in constrained places the odometry may flag."""
STRETCH_SAMPLES = 3
"""Consecutive constrained samples that make a constrained stretch (a sample inside one has
constrained neighbours on both sides, or on its one side at a run's end)."""


def stretch_mask(constrained: np.ndarray, n: int = STRETCH_SAMPLES) -> np.ndarray:
    """Samples inside a run of at least ``n`` consecutive ``True`` of ``constrained``."""
    constrained = np.asarray(constrained, dtype=bool)
    out = np.zeros_like(constrained)
    start = None
    for i, c in enumerate([*constrained, False]):
        if c and start is None:
            start = i
        elif not c and start is not None:
            if i - start >= n:
                out[start:i] = True
            start = None
    return out


def odometry_flags(scans_csv: Path
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(stamps [s], degenerate dimension per scan, the detector's part of the subspace or
    None, the subspace's dimension or None) of a run's ``scans.csv``.

    The subspace is what the fusion took from the detection: the degenerate directions and
    those the LiDAR still holds weakly (column ``weakly_held``; in older runs, without it,
    ``dimension`` was the whole subspace, and None is returned for it). The detector's part
    is the subspace less the weak directions the odometry added (column
    ``weak_directions``, absent in older runs)."""
    with open(scans_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    stamps = np.array([float(r["stamp"]) for r in rows])
    dims = np.array([int(float(r["dimension"])) for r in rows])

    def column(name: str) -> np.ndarray | None:
        if not rows or name not in rows[0]:
            return None
        return np.array([int(float(r[name])) for r in rows])

    held = column("weakly_held")
    subspace = None if held is None else dims + held
    weak = column("weak_directions")
    detected = None if weak is None else np.maximum(
        (dims if subspace is None else subspace) - weak, 0)
    return stamps, dims, detected, subspace


def _share(flags: np.ndarray) -> float | None:
    return float(np.mean(flags)) if len(flags) else None


def judge_run(scenario, seed: int, scans_csv: Path, resolution, every: float,
              history: float | None) -> dict:
    """The judge's samples of one run and the odometry's flags in their places (``history``
    None: the judge's map in the odometry's extent)."""
    from lili_odom.evaluation.truth_map_detection import TruthMapDetector
    from lili_odom.sim.generator import EPOCH_NS, Simulation
    from lili_odom.suite.scenario import scenario_request

    sim = Simulation(scenario_request(scenario, seed, resolution=resolution))
    judge = TruthMapDetector(sim, history_s=history)
    stamps, dims, detected, subspace = odometry_flags(scans_csv)
    t_scans = stamps - EPOCH_NS * 1e-9  # trial time of each scan's last column
    starts = sim.scan_starts()
    first = starts[0] + (every if history is None else history)
    samples = []
    for t in np.arange(first, starts[-1] + 1e-9, every):
        t = float(starts[np.argmin(np.abs(starts - t))])
        try:
            d = judge.detect(t)
        except ValueError as exc:
            print(f"  {scenario.name} seed {seed} t={t:.1f} s skipped: {exc}", file=sys.stderr)
            continue
        samples.append((d.t_end, d.dimension))
    if not samples:
        raise ValueError(f"{scenario.name} seed {seed}: no sample could be judged")
    t_samples = np.array([s[0] for s in samples])
    ref_dims = np.array([s[1] for s in samples])
    in_range = (t_scans >= t_samples[0] - every / 2) & (t_scans <= t_samples[-1] + every / 2)
    nearest = np.argmin(np.abs(t_scans[:, None] - t_samples[None, :]), axis=1)
    constrained = in_range & (ref_dims[nearest] == 0)
    on_stretch = in_range & stretch_mask(ref_dims == 0)[nearest]
    degenerate = in_range & (ref_dims[nearest] > 0)
    speed = _speeds(sim, t_scans)
    still = speed < STANDSTILL_SPEED
    flagged = dims > 0
    travelled = _travelled(sim, t_scans)
    return {
        "scenario": scenario.name, "seed": int(seed), "samples": len(samples),
        "samples_constrained": int(np.sum(ref_dims == 0)),
        "scans_constrained": int(np.sum(constrained)),
        "false_share": _share(flagged[constrained]),
        "scans_on_stretches": int(np.sum(on_stretch)),
        "false_share_stretches": _share(flagged[on_stretch]),
        "false_share_standstill": _share(flagged[constrained & still]),
        "false_share_driving": _share(flagged[constrained & ~still]),
        "false_share_detector": (None if detected is None
                                 else _share(detected[constrained] > 0)),
        "false_share_subspace": (None if subspace is None
                                 else _share(subspace[constrained] > 0)),
        "scans_degenerate": int(np.sum(degenerate)),
        "flag_share_degenerate": _share(flagged[degenerate]),
        "series": {"distance_m": travelled.round(2).tolist(), "odometry_dim": dims.tolist(),
                   "sample_distance_m": np.interp(t_samples, t_scans, travelled).round(2).tolist(),
                   "sample_dim": ref_dims.tolist()},
    }


def _speeds(sim, t: np.ndarray) -> np.ndarray:
    """True speed of base_link [m/s] at trial times ``t`` (central differences, 0.05 s)."""
    dt = 0.05
    a = sim.trajectory.pose(t - dt)[:, :3, 3]
    b = sim.trajectory.pose(t + dt)[:, :3, 3]
    return np.linalg.norm(b - a, axis=1) / (2 * dt)


def _travelled(sim, t: np.ndarray) -> np.ndarray:
    """True distance travelled [m] from the first of the times ``t``."""
    p = sim.trajectory.pose(t)[:, :3, 3]
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100 * v:.1f} %"


def markdown(rows: list[dict], command: str) -> str:
    lines = ["# False detections: the odometry's flags where the place is constrained", "",
             f"Command: `{command}`  ", f"Commit: {git('rev-parse', '--short', 'HEAD') or '?'}.",
             "",
             "Judge: the odometry's own detector on one scan every few seconds against a local "
             "map of the scans before it placed at their true poses "
             "(`lili_odom/evaluation/truth_map_detection.py`). Constrained scans: those whose "
             "nearest sample the judge finds of dimension 0. False: the share of them the "
             f"odometry flagged as degenerate (target at most {TARGET:.0%}); standstill below "
             f"{STANDSTILL_SPEED} m/s true speed. 'Subspace': the share in whose subspace the "
             "fusion took the LiDAR's measured weight, the directions it holds weakly "
             "(`plane_refinement.held_information` up to `clear_information`, "
             "`OdometryOutput.weak_basis`) included; '–' for runs that did not record them, "
             "where 'false' is that share. 'Detector': the subspace's share without the "
             "directions the weak-direction check added (`plane_refinement.weak_information`). "
             "Last column: the share of the scans in places the judge finds degenerate that "
             "the odometry flagged as degenerate too.", "",
             f"Stretches: runs of at least {STRETCH_SAMPLES} consecutive samples the judge finds "
             "constrained (a single constrained sample between degenerate ones is often a "
             "feature passing by, which a detection that serves several scans cannot follow).",
             "",
             "| scenario | seed | samples (constrained) | constrained scans | false | "
             "false at standstill | false driving | subspace | subspace, detector | "
             f"scans on stretches of {STRETCH_SAMPLES}+ samples | false there | "
             "degenerate scans | flagged there |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['scenario']} | {r['seed']} | {r['samples']} ({r['samples_constrained']}) | "
            f"{r['scans_constrained']} | {_pct(r['false_share'])} | "
            f"{_pct(r['false_share_standstill'])} | {_pct(r['false_share_driving'])} | "
            f"{_pct(r.get('false_share_subspace'))} | "
            f"{_pct(r.get('false_share_detector'))} | {r['scans_on_stretches']} | "
            f"{_pct(r['false_share_stretches'])} | {r['scans_degenerate']} | {_pct(r['flag_share_degenerate'])} |")
    total_c = sum(r["scans_constrained"] for r in rows)
    if total_c:
        false_all = sum((r["false_share"] or 0.0) * r["scans_constrained"] for r in rows) / total_c
        within = sum(1 for r in rows if r["false_share"] is not None and r["false_share"] <= TARGET)
        judged = sum(1 for r in rows if r["false_share"] is not None)
        lines += ["", f"All runs: {_pct(false_all)} of {total_c} constrained scans flagged; "
                      f"{within} of {judged} runs within {TARGET:.0%}."]
        if all(r.get("false_share_subspace") is not None for r in rows):
            sub = sum(r["false_share_subspace"] * r["scans_constrained"] for r in rows) / total_c
            lines.append(f"With the weakly held directions: {_pct(sub)} of them had a "
                         "subspace.")
        flagged = {}
        for r in rows:
            n = round((r["false_share"] or 0.0) * r["scans_constrained"])
            flagged[r["scenario"]] = flagged.get(r["scenario"], 0) + n
        total_f = sum(flagged.values())
        if total_f:
            lines.append("Where the flagged constrained scans are: " + ", ".join(
                f"{name} {n} ({n / total_f:.0%})" for name, n in flagged.items()) + ".")
    return "\n".join(lines + ["", "![false detections](false_detections.png)", ""])


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(rows), 1, figsize=(9, 1.3 * len(rows) + 0.6), sharex=False,
                             squeeze=False)
    for ax, r in zip(axes[:, 0], rows):
        s = r["series"]
        ax.step(s["distance_m"], s["odometry_dim"], where="post", lw=0.8, label="odometry")
        ax.plot(s["sample_distance_m"], s["sample_dim"], "o", ms=3, color="tab:red",
                label="judge (true-pose map)")
        ax.set_ylabel(f"{r['scenario']}\nseed {r['seed']}", fontsize=7)
        ax.set_ylim(-0.3, max(3, max(s["odometry_dim"] + s["sample_dim"])) + 0.3)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("distance travelled [m]")
    fig.suptitle("degenerate dimension: odometry against the judge", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def find_runs(runs: Path, names: list[str] | None) -> list[tuple[str, int, Path]]:
    """(scenario, seed, scans.csv) of every ``lili`` run under ``runs``."""
    found = []
    for scans in sorted(Path(runs).glob("*/seed*/lili/scans.csv")):
        scenario, seed_dir = scans.parts[-4], scans.parts[-3]
        if names and scenario not in names:
            continue
        found.append((scenario, int(seed_dir[len("seed"):]), scans))
    return found


def main(argv: list[str] | None = None) -> int:
    from lili_odom.suite.scenario import load_scenarios

    parser = argparse.ArgumentParser(prog="python -m benchmarks.false_detections",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True,
                        help="the runs directory of a suite or tuning output")
    parser.add_argument("--scenarios", nargs="+")
    parser.add_argument("--resolution", help="RxC the runs were simulated at "
                        "(default: each scenario's own)")
    parser.add_argument("--every", type=float, default=2.0, help="seconds between samples")
    parser.add_argument("--history", default="3.0",
                        help="seconds of scans in the judge's map, or 'map': every scan from "
                        "the run's start with KISS-ICP's range pruning, as the odometry's map")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    try:
        history = None if args.history == "map" else float(args.history)
    except ValueError:
        parser.error(f"--history: a number of seconds or 'map', not {args.history!r}")
    if not args.every > 0 or not (history is None or history > 0):
        parser.error("--every and --history must be positive")
    runs = find_runs(args.runs, args.scenarios)
    if not runs:
        parser.error(f"no <scenario>/seed<k>/lili/scans.csv under {args.runs}")
    scenarios = {s.name: s for s in load_scenarios(sorted({r[0] for r in runs}), measure=False)}
    rows = []
    for i, (name, seed, scans) in enumerate(runs, 1):
        print(f"[{i}/{len(runs)}] {name} seed {seed}", flush=True)
        try:
            rows.append(judge_run(scenarios[name], seed, scans, args.resolution, args.every,
                                  history))
        except (ValueError, OSError, KeyError) as exc:
            print(f"  skipped: {exc}", file=sys.stderr)
            continue
        r = rows[-1]
        print(f"  {r['samples']} samples, {r['scans_constrained']} constrained scans, "
              f"false {_pct(r['false_share'])}", flush=True)
    if not rows:
        print("error: no run could be judged", file=sys.stderr)
        return 1
    command = "python -m benchmarks.false_detections " + " ".join(
        a if not a.startswith("/") else Path(a).name for a in (argv if argv is not None else sys.argv[1:]))
    args.out.mkdir(parents=True, exist_ok=True)
    figure(rows, args.out / "false_detections.png")
    write_results(args.out, "false_detections", markdown(rows, command), {"rows": rows})
    print(f"wrote {args.out / 'false_detections.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
