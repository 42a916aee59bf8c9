"""How should the scan-to-map registration enter the factor graph? Trial 1, one run per variant.

    python -m benchmarks.studies.lidar_factor                       # every variant, 2 at a time
    python -m benchmarks.studies.lidar_factor --variants between hybrid --reuse

Runs ``lili`` over simulated Trial 1 (64 x 512 unless ``--resolution``) once per variant of
the LiDAR factor (``fusion.lidar.factor``: between / prior / hybrid, with and without the
degenerate anchor) and of solution remapping (``remap_iterations``), and writes
``benchmarks/results/lidar_factor.md`` (+ ``.json``): ATE / RPE(100 m) / final error via the
runs' own ``metrics.json`` (evo), and the error by component in the true body frame at a few
times (``lili_odom.evaluation.run_diagnostics``), which tells an along-axis (wheel / IMU velocity) error from
a lateral / yaw (LiDAR) failure. Runs live in ``data/lidar_factor_runs/<variant>``;
``--reuse`` keeps those that already have a ``metrics.json``.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, ROOT, SIM_CACHE
from lili_odom.evaluation.run_diagnostics import errors_in_true_body_frame
from lili_odom import geometry
from lili_odom.sim.generator import ensure_trial_bag

#: the parameters every variant sets (so that a variant does not depend on the defaults)
_NEUTRAL: dict[str, object] = {"fusion.lidar.factor": "between", "fusion.lidar.anchor_sigma": 0.0,
                               "fusion.lidar.basis_snap": 0.0, "remap_iterations": 0,
                               "detection_schedule.hold_distance_m": 0.0}


def _variant(what: str, **overrides: object) -> tuple[dict[str, object], str]:
    return {**_NEUTRAL, **{k.replace("__", "."): v for k, v in overrides.items()}}, what


#: variant -> (pipeline parameter overrides, what it is)
VARIANTS: dict[str, tuple[dict[str, object], str]] = {
    "between": _variant("between factor from the previous fused pose "
                        "(benchmarks/configs/between_factor.yaml)"),
    "between_remap": _variant("between, registration remapped to the wheels",
                              remap_iterations=10),
    "prior": _variant("absolute prior factor", fusion__lidar__factor="prior",
                      fusion__lidar__degenerate_epsilon=1e-9),
    "prior_remap": _variant("prior, registration remapped to the wheels",
                            fusion__lidar__factor="prior", remap_iterations=10),
    "prior_anchor": _variant("prior, degenerate components anchored to the wheels "
                             "(benchmarks/configs/prior_factor.yaml)", fusion__lidar__factor="prior",
                             fusion__lidar__anchor_sigma=0.02, fusion__lidar__basis_snap=0.1),
    "hybrid": _variant("prior in translation and yaw, between in roll and pitch",
                       fusion__lidar__factor="hybrid"),
    "hybrid_remap": _variant("hybrid, registration remapped to the wheels "
                             "(benchmarks/configs/hybrid_factor.yaml; the defaults add the hold)",
                             fusion__lidar__factor="hybrid", remap_iterations=10),
}
SAMPLE_TIMES = (60.0, 120.0, 180.0, 220.0, 240.0, 300.0)


def _parameter_file(overrides: dict[str, object], path: Path) -> Path:
    """A ROS 2 parameter file setting ``pipeline.<key>`` for each override."""
    import yaml

    tree: dict = {}
    for key, value in overrides.items():
        node = tree
        *parents, leaf = ("pipeline." + key).split(".")
        for name in parents:
            node = node.setdefault(name, {})
        node[leaf] = value
    path.write_text(yaml.safe_dump({"lili_odom": {"ros__parameters": tree}}))
    return path


def run_variant(bag: Path, name: str, run_dir: Path, reuse: bool) -> Path:
    if reuse and (run_dir / "metrics.json").exists():
        return run_dir
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    params = _parameter_file(VARIANTS[name][0], run_dir.parent / f"{name}.yaml")
    if run_dir.exists():
        import shutil

        shutil.rmtree(run_dir)
    cmd = [sys.executable, "-m", "lili_odom.cli", "run", str(bag), "--method", "lili",
           "--config", str(params), "--out", str(run_dir), "--no-progress"]
    subprocess.run(cmd, check=True, cwd=ROOT)
    return run_dir


def summarise(name: str, run_dir: Path) -> dict:
    metrics = json.loads((run_dir / "metrics.json").read_text())["metrics"]
    t, err = errors_in_true_body_frame(run_dir)
    samples = {}
    for tq in SAMPLE_TIMES:
        if tq > t[-1]:
            continue
        i = int(np.argmin(np.abs(t - tq)))
        samples[f"{tq:.0f}"] = {
            "along_m": float(err[i, 0, 3]), "lateral_m": float(err[i, 1, 3]),
            "yaw_deg": float(np.degrees(geometry.log(err[i])[5])),
        }
    return {"variant": name, "overrides": VARIANTS[name][0], "what": VARIANTS[name][1],
            "ate_m": metrics.get("ate_rmse_m"), "rpe_m": metrics.get("rpe_rmse_m"),
            "final_error_m": metrics.get("final_error_m"), "errors": samples}


def markdown(rows: list[dict], resolution: str) -> str:
    out = ["# LiDAR factor variants on Trial 1", "",
           f"`lili` on simulated Trial 1 (OS1 at {resolution}, seed 0), one run per variant, "
           "made by `python -m benchmarks.studies.lidar_factor` (two runs at a time on 2 cores). "
           "ATE / RPE(100 m) / final error from each run's `metrics.json` (evo). Error samples: "
           "estimate against truth started at the same pose, no alignment, in the true body "
           "frame (along = tunnel axis).", "",
           "| variant | what | ATE [m] | RPE 100 m [m] | final [m] | "
           + " | ".join(f"t={t:.0f} s along / lateral [m], yaw [deg]" for t in SAMPLE_TIMES)
           + " |", "|---|---|---|---|---|" + "---|" * len(SAMPLE_TIMES)]
    for r in rows:
        cells = []
        for t in SAMPLE_TIMES:
            e = r["errors"].get(f"{t:.0f}")
            cells.append("-" if e is None else
                         f"{e['along_m']:+.2f} / {e['lateral_m']:+.2f}, {e['yaw_deg']:+.2f}")
        fmt = (lambda v: "-" if v is None else f"{v:.3f}")
        out.append(f"| `{r['variant']}` | {r['what']} | {fmt(r['ate_m'])} | {fmt(r['rpe_m'])} | "
                   f"{fmt(r['final_error_m'])} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    ap.add_argument("--resolution", default="64x512")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--reuse", action="store_true", help="keep runs that have metrics.json")
    ap.add_argument("--work-dir", type=Path, default=ROOT / "data" / "lidar_factor_runs")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    rows_, cols = (int(v) for v in args.resolution.lower().split("x"))
    bag = ensure_trial_bag(1, SIM_CACHE, resolution=(rows_, cols), seed=0)
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        dirs = list(pool.map(lambda n: run_variant(bag, n, args.work_dir / n, args.reuse),
                             args.variants))
    rows = [summarise(n, d) for n, d in zip(args.variants, dirs)]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "lidar_factor.json").write_text(json.dumps(rows, indent=2))
    (args.out / "lidar_factor.md").write_text(markdown(rows, args.resolution))
    print(markdown(rows, args.resolution))
    return 0


if __name__ == "__main__":
    sys.exit(main())
