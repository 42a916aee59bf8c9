"""Odometry that keeps the LiDAR's point-to-plane information: before/after on given bags.

    python -m benchmarks.fusion_generalisation --bag building=BAG --bag trial1=BAG \\
        [--configs default benchmarks/configs/point_to_point_only.yaml] \\
        [--peers genz wheels] [--reuse]

Each bag is run by ``lili`` with every configuration (``default`` = the built-in defaults;
``benchmarks/configs/point_to_point_only.yaml`` switches off the perturbation cap, the
point-to-plane refinements, the LiDAR's information inside the detected subspace and the wheel scale from
partially constrained registrations), and, when the suite's peer runners are importable
(``lili_odom.suite.peers``), by the named peers. Runs go to ``RUNS/<bag>_<config>`` (default
``data/fusion_generalisation``) and are reused with ``--reuse``. Reported per run: ATE (evo, SE(3)-aligned translation RMSE) and its
share of the distance travelled, the fraction of scans with a degenerate subspace over the
whole run and over the first ``--start-m`` metres of travel (the feature-rich start of the
building; the standalone detector finds dimension 0 there), and the online wheel scale after
10, 20 m and at the end against the simulator's (bag sidecar ``wheel_scale``). Writes
``OUT/fusion_generalisation.{json,md}`` (default OUT: ``benchmarks/results/fusion_generalisation``).
"""
from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, ROOT
from lili_odom.config import load_config
from benchmarks._comparison import run_label
from lili_odom.evaluation.runner import run_bag

DEFAULT_OUT = RESULTS / "fusion_generalisation"


def _sidecar(bag: Path) -> dict:
    side = bag.with_name(bag.name + ".json")
    return json.loads(side.read_text()) if side.exists() else {}


def _truth_path_length(truth: np.ndarray) -> np.ndarray:
    """Cumulative path length [m] of (n, 3) positions."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(truth, axis=0), axis=1))])


def _scan_stats(run_dir: Path, start_m: float) -> dict:
    """Degenerate fractions and the wheel scale over travelled distance from a run's files."""
    with open(run_dir / "scans.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    stamps = np.array([float(r["stamp"]) for r in rows])
    dims = np.array([int(float(r["dimension"])) for r in rows])
    scale = np.array([float(r["wheel_scale"]) for r in rows])
    truth = np.loadtxt(run_dir / "truth.tum", ndmin=2)
    s_truth = _truth_path_length(truth[:, 1:4])
    travelled = np.interp(stamps, truth[:, 0], s_truth)
    start = travelled <= start_m
    out = {"distance_m": float(s_truth[-1]),
           "degenerate_fraction": float(np.mean(dims > 0)),
           "degenerate_fraction_start": float(np.mean(dims[start] > 0)) if start.any() else None,
           "wheel_scale_final": float(scale[-1])}
    for d in (10.0, 20.0):
        i = np.searchsorted(travelled, d)
        out[f"wheel_scale_at_{int(d)}m"] = float(scale[i]) if i < len(scale) else None
    return out


def run_ours(bag: Path, config: str, out_dir: Path, reuse: bool, start_m: float) -> dict:
    if not (reuse and (out_dir / "metrics.json").exists()):
        if out_dir.exists():
            import shutil

            shutil.rmtree(out_dir)
        cfg = load_config(None if config == "default" else ROOT / config)
        cfg.pipeline.method = "lili"
        run_bag(bag, cfg, out_dir, progress=False)
    metrics = json.loads((out_dir / "metrics.json").read_text())
    row = {"ate_m": metrics["metrics"]["ate_rmse_m"], **_scan_stats(out_dir, start_m),
           "scans_per_s": metrics["scans_per_second"]}
    row["ate_pct_distance"] = 100.0 * row["ate_m"] / row["distance_m"]
    return row


def run_peer(bag: Path, peer: str, kind: str) -> dict | None:
    try:
        import importlib

        from lili_odom.evaluation.metrics import evaluate
        from lili_odom.suite.peers.inputs import Context
        module = importlib.import_module(f"lili_odom.suite.peers.{peer}")
    except ImportError as exc:
        print(f"peer {peer} skipped: {exc}", flush=True)
        return None
    r = module.run(bag, Context(load_config(None), kind=kind))
    m = evaluate(r.stamps, r.poses, r.truth_stamps, r.truth_poses, segment_m=100.0).to_dict()
    return {"ate_m": m["ate_rmse_m"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bag", action="append", required=True, metavar="NAME=BAG",
                    help="a bag to run (repeatable); NAME labels it")
    ap.add_argument("--kind", action="append", default=[], metavar="NAME=KIND",
                    help="kind of scene of a bag for the peers' presets (default: NAME)")
    ap.add_argument("--configs", nargs="+",
                    default=["default", "benchmarks/configs/point_to_point_only.yaml"])
    ap.add_argument("--peers", nargs="*", default=[])
    ap.add_argument("--start-m", type=float, default=20.0,
                    help="travel [m] counted as the start of each run")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--runs", type=Path, default=ROOT / "data" / "fusion_generalisation")
    ap.add_argument("--reuse", action="store_true")
    args = ap.parse_args(argv)
    kinds = dict(k.split("=", 1) for k in args.kind)
    args.out.mkdir(parents=True, exist_ok=True)
    result_file = args.out / "fusion_generalisation.json"
    results = json.loads(result_file.read_text()) if result_file.exists() else {}
    for spec in args.bag:
        name, bag = spec.split("=", 1)
        bag = Path(bag)
        entry = results.setdefault(name, {})
        entry["bag"] = bag.name
        entry["true_wheel_scale"] = _sidecar(bag).get("wheel_scale")
        for config in args.configs:
            label = run_label(config)
            print(f"{name}: lili {label} ...", flush=True)
            entry[label] = run_ours(bag, config, args.runs / f"{name}_{label}",
                                    args.reuse, args.start_m)
            print(f"  {entry[label]}", flush=True)
            result_file.write_text(json.dumps(results, indent=1) + "\n")
        for peer in args.peers:
            print(f"{name}: {peer} ...", flush=True)
            row = run_peer(bag, peer, kinds.get(name, name))
            if row is not None:
                entry[peer] = row
                print(f"  {row}", flush=True)
            result_file.write_text(json.dumps(results, indent=1) + "\n")
    (args.out / "fusion_generalisation.md").write_text(report(results))
    print(report(results))
    return 0


def report(results: dict) -> str:
    lines = ["# Fusion generalisation: before/after", "",
             "`python -m benchmarks.fusion_generalisation` (see its docstring); ATE = evo "
             "SE(3)-aligned translation RMSE; degenerate % = scans with a detected subspace "
             "(whole run / first metres of travel); wheel scale = online estimate after "
             "10 m / 20 m / at the end (the simulator's in the heading).", ""]
    for name, entry in results.items():
        lines += [f"## {name} (`{entry.get('bag')}`, true wheel scale "
                  f"{entry.get('true_wheel_scale') or float('nan'):.4f})", "",
                  "| run | ATE [m] | ATE [% dist] | degenerate [%] | start degenerate [%] | "
                  "wheel scale 10 m / 20 m / end |", "|---|---|---|---|---|---|"]
        for label, row in entry.items():
            if not isinstance(row, dict):
                continue
            if "distance_m" not in row:
                lines.append(f"| {label} | {row['ate_m']:.3f} | | | | |")
                continue
            ws = " / ".join("-" if row.get(k) is None else f"{row[k]:.4f}"
                            for k in ("wheel_scale_at_10m", "wheel_scale_at_20m",
                                      "wheel_scale_final"))
            start = row.get("degenerate_fraction_start")
            lines.append(f"| lili {label} | {row['ate_m']:.3f} | {row['ate_pct_distance']:.2f} | "
                         f"{100 * row['degenerate_fraction']:.1f} | "
                         f"{'-' if start is None else f'{100 * start:.1f}'} | {ws} |")
        lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
