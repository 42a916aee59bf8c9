"""Compare configurations of our odometry on the suite's tuning split, the only place defaults
are chosen.

Each configuration (``default`` or a parameter overlay such as ``benchmarks/configs/X.yaml``)
runs one method over the tuning scenarios through the scenario suite (same bags, same scoring);
the wheel odometry runs once beside them. Validation scenarios are refused.

    python -m benchmarks.tuning --configs default benchmarks/configs/no_weak_directions.yaml \
        [--preset full|ci] [--scenarios NAME...] [--resolution 32x512] [--max-seeds 1] \
        [--method lili] [--repeats 1] [--jobs 2] [--out benchmarks/results/tuning]

Writes ``OUT/tuning.md`` (ATE per scenario and configuration, in metres and in % of the
distance, best per row in bold, the mean of the % over the rows) and ``OUT/tuning.json``; each
configuration's suite report is in ``OUT/<config>/`` (with ``--repeats`` N > 1 in
``OUT/<config>/r<k>/``). The registration's parallel reductions make two runs of one bag
differ (``config/deterministic.yaml``); with repeats each cell is the median over them with
their range, and the mean of the % is taken over the medians.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

from benchmarks._common import ROOT, RESULTS, git


def _rows_by_key(doc: dict, method: str) -> dict[tuple[str, int], dict]:
    return {(r["scenario"], r["seed"]): r for r in doc["rows"] if r["method"] == method}


def _cell(row: dict | None) -> tuple[float, float]:
    """(ATE [m], ATE [% of distance]); NaN when the run failed."""
    if row is None or "error" in row or row.get("ate_m") is None:
        return math.nan, math.nan
    ate, dist = float(row["ate_m"]), float(row.get("distance_m") or math.nan)
    return ate, 100.0 * ate / dist if dist > 0 else math.nan


def _repeated_cell(rows: list[dict | None]) -> tuple[float, float, float, float]:
    """(median ATE [m], its % of the distance, smallest, largest ATE [m]) over the repeats'
    rows; NaN when any of them failed."""
    ates = sorted(_cell(r)[0] for r in rows)
    if not ates or not all(math.isfinite(a) for a in ates):
        return (math.nan,) * 4
    median = statistics.median(ates)
    dist = float(rows[0].get("distance_m") or math.nan)
    return median, 100.0 * median / dist if dist > 0 else math.nan, ates[0], ates[-1]


def report(results: dict[str, dict | list[dict]], wheels: dict, method: str,
           command: str) -> str:
    """The markdown table of ``results`` (label -> suite document, or one per repeat)."""
    results = {l: docs if isinstance(docs, list) else [docs] for l, docs in results.items()}
    repeats = max(len(docs) for docs in results.values())
    labels = list(results)
    keys = sorted({k for docs in results.values() for doc in docs
                   for k in _rows_by_key(doc, method)})
    lines = [
        f"# Tuning split: `{method}` per configuration",
        "",
        f"Command: `{command}`  ",
        f"Commit: {git('rev-parse', '--short', 'HEAD') or '-'}, "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}.",
        "",
        "ATE after SE(3) alignment [m] (in brackets: % of the distance); best per row in bold. "
        "`wheels`: the wheel odometry alone on the same bag."
        + (f" {repeats} runs per configuration: the median, in square brackets the smallest "
           "and largest ATE; the mean of the % is over the medians." if repeats > 1 else ""),
        "",
        "| scenario | seed | distance [m] | " + " | ".join(f"`{l}`" for l in labels) + " | wheels |",
        "|---|---:|---:|" + "---:|" * (len(labels) + 1),
    ]
    pct_sums = {l: [] for l in labels}
    for key in keys:
        cells = {l: _repeated_cell([_rows_by_key(doc, method).get(key) for doc in results[l]])
                 for l in labels}
        best = min((c[0] for c in cells.values() if math.isfinite(c[0])), default=math.nan)
        dist = next((r.get("distance_m") for l in labels for doc in results[l]
                     for r in [_rows_by_key(doc, method).get(key)] if r), None)
        parts = []
        for l in labels:
            ate, pct, lo, hi = cells[l]
            pct_sums[l].append(pct)
            text = "–" if not math.isfinite(ate) else f"{ate:.3f} ({pct:.2f} %)"
            if math.isfinite(ate) and ate == best:
                text = f"**{text}**"
            if math.isfinite(ate) and len(results[l]) > 1:
                text += f" [{lo:.3f}-{hi:.3f}]"
            parts.append(text)
        w_ate, w_pct = _cell(_rows_by_key(wheels, "wheels").get(key)) if wheels else (math.nan,) * 2
        w_text = "–" if not math.isfinite(w_ate) else f"{w_ate:.3f} ({w_pct:.2f} %)"
        lines.append(f"| {key[0]} | {key[1]} | {dist or math.nan:.0f} | " + " | ".join(parts)
                     + f" | {w_text} |")
    means = []
    for l in labels:
        vals = [v for v in pct_sums[l] if math.isfinite(v)]
        means.append(f"{sum(vals) / len(vals):.2f} %" if len(vals) == len(pct_sums[l]) and vals
                     else "– (a run failed)")
    lines.append("| **mean of the %** | | | " + " | ".join(means) + " | |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.tuning", description=__doc__.split("\n\n")[0])
    parser.add_argument("--configs", nargs="+", default=["default"],
                        help="'default' and/or parameter overlays (YAML, relative to the repository)")
    parser.add_argument("--preset", choices=["full", "ci"], default="full")
    parser.add_argument("--scenarios", nargs="+", default=None, help="tuning scenarios (default: all)")
    parser.add_argument("--resolution", default=None, help="RxC for every scenario (default: each one's own)")
    parser.add_argument("--max-seeds", type=int, default=1)
    parser.add_argument("--method", default="lili", choices=["lili", "zhang", "hessian", "none"])
    parser.add_argument("--repeats", type=int, default=1,
                        help="runs per configuration (default 1); cells are their median")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "tuning")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)

    from benchmarks._comparison import run_label
    from lili_odom.suite.backends import LocalBackend
    from lili_odom.suite.runner import SuiteRequest, run_suite
    from lili_odom.suite.scenario import load_scenarios

    prog = "benchmarks.tuning"
    if args.scenarios:
        try:
            chosen = load_scenarios(args.scenarios)
        except (ValueError, OSError) as exc:
            raise SystemExit(f"{prog}: {exc}") from None
        held_out = [s.name for s in chosen if s.split != "tuning"]
        if held_out:
            raise SystemExit(f"{prog}: {', '.join(held_out)} not in the tuning split; defaults "
                             "are never chosen on validation scenarios")
    for config in args.configs:
        if config != "default" and not (ROOT / config).is_file() and not Path(config).is_file():
            raise SystemExit(f"{prog}: no such configuration file: {config}")
    if args.repeats < 1:
        raise SystemExit(f"{prog}: --repeats must be at least 1")
    labels = [run_label(c) for c in args.configs]
    if len(set(labels)) != len(labels):
        raise SystemExit(f"{prog}: two configurations share the name {labels}")

    command = "python -m benchmarks.tuning " + " ".join(argv if argv is not None else sys.argv[1:])
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, list[dict]] = {}
    wheels: dict = {}
    for i, (config, label) in enumerate(zip(args.configs, labels)):
        path = None if config == "default" else str(ROOT / config if (ROOT / config).is_file() else config)
        results[label] = []
        for k in range(args.repeats):
            methods = [args.method] + (["wheels"] if i == 0 and k == 0 else [])
            out = args.out / label / f"r{k + 1}" if args.repeats > 1 else args.out / label
            print(f"[{i + 1}/{len(labels)}] {label}"
                  + (f" run {k + 1}/{args.repeats}" if args.repeats > 1 else ""), flush=True)
            request = SuiteRequest(out=out, scenarios=args.scenarios, preset=args.preset,
                                   methods=methods, split="tuning", max_seeds=args.max_seeds,
                                   resolution=args.resolution, config_path=path,
                                   command=command)
            doc = run_suite(request, LocalBackend(jobs=args.jobs), progress=not args.no_progress)
            results[label].append(doc)
            if i == 0 and k == 0:
                wheels = doc
    text = report(results, wheels, args.method, command)
    (args.out / "tuning.md").write_text(text)
    (args.out / "tuning.json").write_text(json.dumps(
        {"command": command, "method": args.method,
         "configs": dict(zip(labels, args.configs)),
         "repeats": args.repeats,
         "rows": [dict(r, config=l, run=k + 1) for l, docs in results.items()
                  for k, doc in enumerate(docs) for r in doc["rows"]]},
        indent=1))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
