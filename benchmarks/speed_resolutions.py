"""Whole-run speed of ``lili`` against KISS-ICP's own pipeline at every suite resolution.

Writes benchmarks/results/speed_resolutions.{md,json}.

    python -m benchmarks.speed_resolutions                # building 0-30 s, 8 resolutions, 2 rounds
    python -m benchmarks.speed_resolutions --resolutions 32x512 128x1024 --duration 5 --repeats 1

For each resolution the same window of one scenario (default: ``building`` from 0 s for 30 s:
2 s at rest, the parking hall, into the corridor) is simulated with the suite's scenario code
(the scenario's world, sensor family, error profile and seed; rows x cols replaced) and cached
in the simulator cache (:mod:`benchmarks._pieces`). The default resolutions are 32 x 512,
32 x 1024, 64 x 1024, 64 x 2048, 128 x 1024, 128 x 2048 and every other mode a shipped
scenario uses. The bag is read once before the timings, so every run finds it in the page
cache. Then, each in its own fresh process, back to back, the first of the two alternating
from round to round, over ``--repeats`` rounds:

* ``lili``: the whole offline run, :func:`lili_odom.evaluation.runner.run_bag` with the default
  configuration (``pipeline.method`` lili), as ``lili-odom run`` does it: reading and decoding
  the bag, the pipeline, writing the outputs bag, ``estimate.tum`` / ``truth.tum``,
  ``scans.csv``, ``metrics.json`` (ATE / RPE with evo) and ``trajectory.png``;
* ``kiss``: KISS-ICP's own pipeline as the suite runs it, :func:`lili_odom.suite.peers.kiss.run`
  (reading and decoding the bag, parsing the clouds, ``KissICP.register_frame`` with KISS-ICP's
  default configuration, the poses into base_link).

* ``none`` (with ``--with-none``, after the two): the same offline run with
  ``pipeline.method`` none, no degeneracy detection and nothing built on it (no plane fits):
  the floor of our pipeline (deskew, registration, fusion, inputs and outputs) against which
  ``lili``'s own share shows.

Timed is that one call; not timed are the interpreter's start-up and the imports (the modules
the call uses are imported first; the modules still imported inside the timing are counted).

Per resolution: scans, wall time [s] and scans/s of each (median over the rounds), the ratio of
``lili``'s wall time to KISS-ICP's within each round and its median (target: at most 1.5), the
peak RSS of each (the child's ``getrusage`` peak or the sampled sum over it and its own
processes, such as ``lili``'s background detector, whichever is larger; largest over the
rounds), the cores other
processes used while each ran (from ``/proc/stat``, as :mod:`benchmarks.speed`), and the mean
per-stage times [ms] of ``lili`` (its ``metrics.json``, the run with the median wall time).
The machine, the commit and the load are recorded with the figures.
"""
from __future__ import annotations

import argparse
import importlib
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import RESULTS, ROOT, machine_info, write_results
from benchmarks._process_tree import ProcessTreeRss, descendants_cpu_s
from benchmarks._pieces import (add_piece_arguments, format_resolution, piece_bags,
                                piece_command, suite_resolutions, warm_file_cache)
from benchmarks.speed import (LoadMeter, _cpu_busy_jiffies, _fmt, _other_load, _rss_mb,
                              machine_load_lines)
from lili_odom.evaluation.timing import median_run

METHODS = ("lili", "kiss")
#: The optional floor: our pipeline without degeneracy detection (``--with-none``).
FLOOR = "none"
TARGET_RATIO = 1.5
#: Stages of the pipeline in the order of its per-scan work (metrics.json ``timings_mean_s``).
STAGE_ORDER = ("predict", "deskew", "icp", "detector", "refine", "remap", "fusion", "map",
               "total")

#: Modules both timed calls use to read a bag (optional ones may be absent).
_BAG_IMPORTS = ("lili_odom.bagio.reader", "lili_odom.bagio.factory", "lili_odom.pointcloud2",
                "lili_odom.messages", "lili_odom.pipeline.feeder", "rosbags.highlevel",
                "rosbags.rosbag2", "rosbags.serde", "rosbags.typesys.stores.ros2_jazzy",
                "ruamel.yaml", "sqlite3", "lz4.frame", "backports.zstd")
#: Modules each timed call uses, imported before the timing.
IMPORTS = {
    "lili": _BAG_IMPORTS + (
        "lili_odom.evaluation.runner", "lili_odom.evaluation.replay",
        "lili_odom.evaluation.metrics", "lili_odom.evaluation.plots", "lili_odom.bagio.tum",
        "lili_odom.bagio.writer", "lili_odom.pipeline.odometry", "evo.core.trajectory",
        "evo.core.metrics", "evo.core.sync", "matplotlib.pyplot",
        "matplotlib.backends.backend_agg", "PIL.PngImagePlugin", "rich.progress",
        "scipy.spatial.transform"),
    "kiss": _BAG_IMPORTS + ("lili_odom.suite.peers.kiss", "lili_odom.suite.peers.inputs",
                            "lili_odom.suite.frames", "kiss_icp.kiss_icp", "kiss_icp.config"),
}
IMPORTS[FLOOR] = IMPORTS["lili"]


# ----------------------------------------------------------------------------- one timed run

def _preimport(method: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    for name in IMPORTS[method]:
        try:
            importlib.import_module(name)
        except ImportError:  # an optional dependency of a dependency
            pass


def run_lili(bag: Path | str, method: str = "lili") -> dict[str, Any]:
    """``run_bag`` over ``bag`` with the defaults and ``pipeline.method`` ``method`` (lili or
    none), in this process; the outputs go to a temporary directory (removed after the
    timing)."""
    from lili_odom.config import load_config
    from lili_odom.evaluation.runner import run_bag

    config = load_config(None)
    config.pipeline.method = method
    config.validate()
    with tempfile.TemporaryDirectory(prefix="lili_speed_res_") as tmp:
        modules0, rss0 = set(sys.modules), _rss_mb()
        with ProcessTreeRss() as tree:
            t0 = time.perf_counter()
            run = run_bag(bag, config, Path(tmp) / "run", progress=False)
            wall = time.perf_counter() - t0
        own_children_s = descendants_cpu_s()  # the background detector, reaped or not
        imported = sorted(set(sys.modules) - modules0)
        summary = json.loads((Path(tmp) / "run" / "metrics.json").read_text())
    metrics = summary.get("metrics") or {}
    return {"method": method, "scans": len(run.estimates), "wall_s": wall,
            "scans_per_s": len(run.estimates) / wall if wall > 0 else float("nan"),
            "run_bag_loop_s": summary["wall_time_s"],
            "stages_mean_ms": {k: 1e3 * v for k, v in summary["timings_mean_s"].items()},
            "degenerate_fraction": summary["degenerate_fraction"],
            "ate_m": metrics.get("ate_rmse_m"), "counters": summary["counters"],
            "rss_peak_mb": max(_rss_mb(), tree.peak_mb), "rss_before_mb": rss0,
            "descendants_cpu_s": own_children_s,
            "modules_imported_in_timing": len(imported),
            "packages_imported_in_timing": sorted({m.split(".")[0] for m in imported})}


def run_kiss(bag: Path | str, kind: str = "") -> dict[str, Any]:
    """:func:`lili_odom.suite.peers.kiss.run` over ``bag`` as the suite calls it (its
    ``Context`` from the default configuration, scene ``kind``), in this process."""
    from lili_odom.config import load_config
    from lili_odom.suite.peers import kiss
    from lili_odom.suite.peers.inputs import Context

    ctx = Context(config=load_config(None), kind=kind)
    modules0, rss0 = set(sys.modules), _rss_mb()
    with ProcessTreeRss() as tree:
        t0 = time.perf_counter()
        run = kiss.run(bag, ctx)
        wall = time.perf_counter() - t0
    imported = sorted(set(sys.modules) - modules0)
    return {"method": "kiss", "scans": int(run.scans), "wall_s": wall,
            "scans_per_s": run.scans / wall if wall > 0 else float("nan"),
            "loop_s": run.wall_s, "notes": dict(run.notes),
            "rss_peak_mb": max(_rss_mb(), tree.peak_mb), "rss_before_mb": rss0,
            "modules_imported_in_timing": len(imported),
            "packages_imported_in_timing": sorted({m.split(".")[0] for m in imported})}


def _run_in_fresh_process(bag: Path, method: str, kind: str) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="lili_speed_res_") as tmp:
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, "-m", "benchmarks.speed_resolutions", "--worker", str(out),
               "--bag", str(bag), "--method", method, "--kind", kind]
        proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
        if proc.returncode != 0 or not out.exists():
            raise RuntimeError(f"{method} on {Path(bag).name} failed (exit {proc.returncode}):"
                               f" {proc.stderr[-2000:]}")
        return json.loads(out.read_text())


# ----------------------------------------------------------------------------- driver

def round_order(round_index: int) -> tuple[str, str]:
    """Which method runs first in round ``round_index`` (0-based): ``lili`` in even rounds."""
    return METHODS if round_index % 2 == 0 else METHODS[::-1]


def summarise(runs: dict[str, list[dict[str, Any]]]) -> dict[str, Any]:
    """One resolution's figures from its runs (``{"lili": [...], "kiss": [...]}``, one per
    round, in round order): medians over the rounds, the ratio per round and its median,
    peak RSS (largest over the rounds) and the target."""
    out: dict[str, Any] = {}
    for m in METHODS:
        rs = runs[m]
        wall = float(np.median([r["wall_s"] for r in rs]))
        out[m] = {"scans": rs[0]["scans"], "wall_s": wall,
                  "scans_per_s": rs[0]["scans"] / wall if wall > 0 else float("nan"),
                  "rounds_wall_s": [r["wall_s"] for r in rs],
                  "rss_peak_mb": max(r["rss_peak_mb"] for r in rs),
                  "other_load_cores": [r.get("other_load_cores") for r in rs]}
    per_round = [a["wall_s"] / b["wall_s"] for a, b in zip(runs["lili"], runs["kiss"])]
    ratio = float(np.median(per_round))
    median_lili = median_run(runs["lili"], key="wall_s")
    out["lili"]["stages_mean_ms"] = median_lili["stages_mean_ms"]
    out["lili"]["degenerate_fraction"] = median_lili["degenerate_fraction"]
    out["lili"]["ate_m"] = median_lili.get("ate_m")
    out["ratio"] = ratio
    out["rounds_ratio"] = per_round
    if runs.get(FLOOR):
        rs = runs[FLOOR]
        wall = float(np.median([r["wall_s"] for r in rs]))
        floor_kiss = [a["wall_s"] / b["wall_s"] for a, b in zip(rs, runs["kiss"])]
        lili_floor = [a["wall_s"] / b["wall_s"] for a, b in zip(runs["lili"], rs)]
        median_floor = median_run(rs, key="wall_s")
        out[FLOOR] = {"scans": rs[0]["scans"], "wall_s": wall,
                      "scans_per_s": rs[0]["scans"] / wall if wall > 0 else float("nan"),
                      "rounds_wall_s": [r["wall_s"] for r in rs],
                      "rss_peak_mb": max(r["rss_peak_mb"] for r in rs),
                      "ratio_kiss": float(np.median(floor_kiss)), "rounds_ratio_kiss": floor_kiss,
                      "lili_ratio": float(np.median(lili_floor)), "rounds_lili_ratio": lili_floor,
                      "stages_mean_ms": median_floor["stages_mean_ms"]}
    out["target"] = {"value": ratio, "target": TARGET_RATIO, "met": ratio <= TARGET_RATIO}
    return out


def benchmark(bags: dict[str, Path], kind: str, repeats: int = 2, progress: bool = True,
              with_none: bool = False) -> dict[str, Any]:
    """Every method on every bag (``{"ROWSxCOLS": bag}``) ``repeats`` rounds, each run in a
    fresh process (``none`` after the two with ``with_none``); the JSON-ready
    per-resolution results and the load."""
    meter = LoadMeter()
    rows: dict[str, Any] = {}
    for res, bag in bags.items():
        warm_file_cache(bag)
        runs: dict[str, list[dict]] = {m: [] for m in METHODS + ((FLOOR,) if with_none else ())}
        for r in range(repeats):
            for method in round_order(r) + ((FLOOR,) if with_none else ()):
                tag = f"[{res}] round {r + 1}/{repeats} {method}"
                if progress:
                    print(f"{tag} ...", flush=True)
                b0, _ = _cpu_busy_jiffies()
                c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                w0 = time.monotonic()
                result = _run_in_fresh_process(bag, method, kind)
                wall = time.monotonic() - w0
                # the run's own processes that it does not wait for are not "other"
                result["other_load_cores"] = max(0.0, _other_load(b0, c0, wall)
                                                 - result.get("descendants_cpu_s", 0.0) / wall)
                runs[method].append(result)
                if progress:
                    print(f"{tag}: {result['scans']} scans in {result['wall_s']:.1f} s "
                          f"({result['scans_per_s']:.1f} scans/s), peak RSS "
                          f"{result['rss_peak_mb']:.0f} MB, other load "
                          f"{result['other_load_cores']:.2f} cores", flush=True)
        rows[res] = {"bag": Path(bag).name, **summarise(runs), "runs": runs}
        if progress:
            print(f"[{res}] lili / KISS-ICP: {rows[res]['ratio']:.2f}x (rounds "
                  + ", ".join(f"{x:.2f}" for x in rows[res]["rounds_ratio"]) + ")", flush=True)
    return {"machine": machine_info(), "repeats": repeats, "target_ratio": TARGET_RATIO,
            "load": meter.report(),
            "resolutions": rows}


# ----------------------------------------------------------------------------- report

def markdown(report: dict[str, Any], command: str) -> str:
    m, load = report["machine"], report["load"]
    piece = report["piece"]
    lines = [
        "# Whole-run speed against KISS-ICP at every suite resolution",
        "",
        f"`{command}`: the `{piece['scenario']}` scenario from {piece['start_s']:g} s for "
        f"{piece['duration_s']:g} s (seed {piece['seed']}), simulated at each resolution with "
        "the scenario's sensor family and error profile. Each run in its own fresh process, the "
        f"two methods back to back, the first alternating, {report['repeats']} round(s). "
        "`lili`: `run_bag` with the defaults, as `lili-odom run` (reading the bag, the "
        "pipeline, writing the outputs bag, TUM files, scans.csv, metrics.json with evo's "
        "ATE / RPE, the plot). KISS-ICP: `lili_odom.suite.peers.kiss.run`, as the suite runs "
        "it (reading the bag, parsing, `register_frame` with KISS-ICP's defaults). Not timed: "
        "interpreter start-up and imports; the bag was read once before, so every run found it "
        "in the page cache.",
        "",
        *machine_load_lines(m, load),
        "",
        "Wall [s] and scans/s: median over the rounds. lili / KISS: `lili`'s wall time over "
        "KISS-ICP's within each round (in brackets), and their median. Peak RSS: of the run's "
        "process with its own child processes (the background detector), largest over the "
        "rounds. Other load: cores other processes used while `lili` / KISS-ICP ran, per "
        "round.",
        "",
        "| resolution | used by | scans | `lili` wall [s] | `lili` scans/s | KISS-ICP wall [s] | "
        "KISS-ICP scans/s | lili / KISS (rounds) | <= " + f"{report['target_ratio']:g}x"
        + " | `lili` peak RSS [MB] | KISS-ICP peak RSS [MB] | other load [cores] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---|",
    ]
    for res, row in report["resolutions"].items():
        li, ki = row["lili"], row["kiss"]
        users = ", ".join(report.get("suite_resolutions", {}).get(res, [])) or "–"
        loads = " / ".join(
            ", ".join(_fmt(x, 2) for x in row[k]["other_load_cores"]) for k in METHODS)
        scans = f"{li['scans']}" + (f" / {ki['scans']}" if ki["scans"] != li["scans"] else "")
        lines.append(
            f"| {res} | {users} | {scans} | {_fmt(li['wall_s'])} | {_fmt(li['scans_per_s'])} | "
            f"{_fmt(ki['wall_s'])} | {_fmt(ki['scans_per_s'])} | **{_fmt(row['ratio'], 2)}** ("
            + ", ".join(_fmt(x, 2) for x in row["rounds_ratio"]) + ") | "
            f"{'met' if row['target']['met'] else '**missed**'} | {_fmt(li['rss_peak_mb'], 0)} | "
            f"{_fmt(ki['rss_peak_mb'], 0)} | {loads} |")
    met = [res for res, row in report["resolutions"].items() if row["target"]["met"]]
    missed = [res for res in report["resolutions"] if res not in met]
    lines += ["", f"Target (`lili` at most {report['target_ratio']:g}x KISS-ICP's wall time): "
              + (f"met at {', '.join(met)}" if met else "met at no resolution")
              + (f"; missed at {', '.join(missed)}" if missed else "") + "."]
    floors = {res: row[FLOOR] for res, row in report["resolutions"].items() if FLOOR in row}
    if floors:
        lines += ["", "## The floor: our pipeline without degeneracy detection", "",
                  "`none`: the same run with `pipeline.method` none (no detection, no plane "
                  "fits, nothing built on them), after the two in each round. none / KISS and "
                  "lili / none: wall time ratios within each round (in brackets), and their "
                  "median; `none` total: its pipeline's own mean time per scan [ms].", "",
                  "| resolution | `none` wall [s] | `none` scans/s | none / KISS (rounds) | "
                  "lili / none (rounds) | `none` total [ms] | `none` peak RSS [MB] |",
                  "|---|---:|---:|---:|---:|---:|---:|"]
        for res, fl in floors.items():
            lines.append(
                f"| {res} | {_fmt(fl['wall_s'])} | {_fmt(fl['scans_per_s'])} | "
                f"{_fmt(fl['ratio_kiss'], 2)} ("
                + ", ".join(_fmt(x, 2) for x in fl["rounds_ratio_kiss"]) + ") | "
                f"{_fmt(fl['lili_ratio'], 2)} ("
                + ", ".join(_fmt(x, 2) for x in fl["rounds_lili_ratio"]) + ") | "
                f"{_fmt(fl['stages_mean_ms'].get('total'))} | {_fmt(fl['rss_peak_mb'], 0)} |")
    stages = [k for k in STAGE_ORDER
              if any(k in row["lili"]["stages_mean_ms"] for row in report["resolutions"].values())]
    extra = sorted({k for row in report["resolutions"].values()
                    for k in row["lili"]["stages_mean_ms"]} - set(stages))
    stages = [k for k in stages if k != "total"] + extra + (["total"] if "total" in stages else [])
    lines += ["", "## `lili`: mean time per scan and stage [ms]", "",
              "The run with the median wall time, from its `metrics.json`; `total` is the "
              "pipeline's own time per scan (without reading the bag and writing the outputs).",
              "", "| resolution | " + " | ".join(stages) + " | degenerate | ATE [m] |",
              "|---|" + "---:|" * (len(stages) + 2)]
    for res, row in report["resolutions"].items():
        st = row["lili"]["stages_mean_ms"]
        lines.append(f"| {res} | " + " | ".join(_fmt(st.get(k)) for k in stages)
                     + f" | {100 * row['lili']['degenerate_fraction']:.0f} % | "
                     f"{_fmt(row['lili'].get('ate_m'), 3)} |")
    imports = {f"{res} {r['method']}": r["modules_imported_in_timing"]
               for res, row in report["resolutions"].items()
               for rs in row["runs"].values() for r in rs if r["modules_imported_in_timing"]}
    if imports:
        lines += ["", "Modules still imported inside the timing: "
                  + ", ".join(f"{k}: {v}" for k, v in sorted(imports.items())) + "."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_piece_arguments(ap)
    ap.add_argument("--repeats", type=int, default=2, help="rounds (default 2)")
    ap.add_argument("--out", type=Path, default=RESULTS,
                    help="directory for the results (default benchmarks/results)")
    ap.add_argument("--name", default="speed_resolutions",
                    help="file name of the results without .md/.json (default speed_resolutions)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--with-none", action="store_true",
                    help="also time the pipeline without degeneracy detection (method none)")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--bag", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--method", choices=METHODS + (FLOOR,), help=argparse.SUPPRESS)
    ap.add_argument("--kind", default="", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:  # one timed run in this (fresh) process
        _preimport(args.method)
        r = (run_kiss(args.bag, args.kind) if args.method == "kiss"
             else run_lili(args.bag, args.method))
        args.worker.write_text(json.dumps(r))
        return 0
    if args.repeats < 1:
        ap.error("--repeats must be at least 1")
    scenario, bags = piece_bags(ap, args, progress=not args.no_progress)
    report = benchmark(bags, scenario.kind, repeats=args.repeats,
                       progress=not args.no_progress, with_none=args.with_none)
    report["piece"] = {"scenario": scenario.name, "kind": scenario.kind,
                       "start_s": args.start, "duration_s": args.duration, "seed": args.seed}
    report["suite_resolutions"] = {format_resolution(r): names
                                   for r, names in suite_resolutions().items()}
    command = piece_command(
        "benchmarks.speed_resolutions", args,
        (f" --repeats {args.repeats}" if args.repeats != 2 else "")
        + (f" --name {args.name}" if args.name != "speed_resolutions" else "")
        + (" --with-none" if args.with_none else ""))
    path = write_results(args.out, args.name, markdown(report, command), report)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
