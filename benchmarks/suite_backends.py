"""Do the suite's rows depend on the backend? Runs the same `lili-odom suite` request on
`--backend local` and `--backend ray` (a local Ray instance, or `--address` for a cluster) and
compares the rows key by key: every metric's absolute difference per (scenario, seed, method)
and whether the two rows are bit-identical (timings `scans_per_s` / `wall_s` excluded).

With `config/deterministic.yaml` (every native call on one thread) a job's row is a function of
its bag and configuration only, so the two backends must give bit-identical metrics.

    python benchmarks/suite_backends.py --out benchmarks/results/suite_backends
    python benchmarks/suite_backends.py --compare-only --work DIR --out DIR   # reuse DIR/{local,ray}

Writes OUT/suite_backends.json and OUT/suite_backends.md; the suites' own outputs go to
WORK/local and WORK/ray (default: a temporary directory, removed at the end).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

METRICS = ("ate_m", "rpe_pct", "final_m", "distance_m", "degenerate_fraction", "scans")
DEFAULT_ARGS = ["--preset", "ci", "--scenarios", "building", "long_tunnel",
                "--methods", "none", "zhang", "lili", "--peers", "wheels",
                "--config", "config/deterministic.yaml", "--jobs", "2", "--no-progress"]


def run_suite(backend: str, suite_args: list[str], out: Path, address: str | None) -> list[str]:
    cmd = [sys.executable, "-m", "lili_odom.cli", "suite", *suite_args, "--backend", backend,
           "--out", str(out)]
    if address and backend == "ray":
        cmd += ["--address", address]
    print("+", " ".join(shlex.quote(c) for c in cmd), flush=True)
    subprocess.run(cmd, check=True)
    return cmd


def compare(local: dict, ray: dict) -> dict:
    """Per-row differences of two suite documents."""
    key = lambda r: (r["scenario"], r["seed"], r["method"])  # noqa: E731
    a = {key(r): r for r in local["rows"]}
    b = {key(r): r for r in ray["rows"]}
    rows = []
    for k in sorted(set(a) | set(b)):
        ra, rb = a.get(k), b.get(k)
        entry = {"scenario": k[0], "seed": k[1], "method": k[2]}
        if ra is None or rb is None:
            entry["missing"] = "local" if ra is None else "ray"
            rows.append(entry)
            continue
        entry["error_local"], entry["error_ray"] = ra.get("error"), rb.get("error")
        diffs = {}
        for m in METRICS:
            va, vb = ra.get(m), rb.get(m)
            if va is None or vb is None:
                diffs[m] = None if va is vb else math.inf
            else:
                diffs[m] = abs(float(va) - float(vb))
        entry["abs_diff"] = diffs
        entry["ate_m"] = {"local": ra.get("ate_m"), "ray": rb.get("ate_m")}
        entry["identical"] = all(ra.get(m) == rb.get(m) for m in METRICS) and \
            ra.get("error") == rb.get("error") and set(ra) == set(rb)
        rows.append(entry)
    finite = [d for r in rows for d in (r.get("abs_diff") or {}).values() if d is not None]
    return {"rows": rows,
            "identical_rows": sum(bool(r.get("identical")) for r in rows),
            "total_rows": len(rows),
            "max_abs_diff": max(finite) if finite else None,
            "wall_time_s": {"local": local.get("wall_time_s"), "ray": ray.get("wall_time_s")}}


def markdown(result: dict, commands: dict) -> str:
    lines = ["# Suite rows: `--backend local` against `--backend ray`", "",
             "The rows of the two suite runs below, compared by `python benchmarks/suite_backends.py` "
             "(which runs both itself; `--compare-only` compares two existing outputs).", ""]
    for name, cmd in commands.items():
        cmd = re.sub(r"--out \S+", f"--out WORK/{name}", cmd)
        cmd = re.sub(r"^\S*python\S* -m lili_odom.cli ", "lili-odom ", cmd)
        lines.append(f"- {name}: `{cmd}`")
    lines += ["", f"Bit-identical rows (metrics {', '.join(METRICS)}): "
              f"**{result['identical_rows']} of {result['total_rows']}**; largest absolute "
              f"difference of any metric: {result['max_abs_diff']} (timings `scans_per_s`, `wall_s` "
              "are not compared).", "",
              "| scenario | seed | method | ATE local [m] | ATE ray [m] | max abs. diff | identical |",
              "|---|---:|---|---:|---:|---:|---|"]
    for r in result["rows"]:
        if "missing" in r:
            lines.append(f"| {r['scenario']} | {r['seed']} | {r['method']} | | | missing on {r['missing']} | no |")
            continue
        d = [v for v in r["abs_diff"].values() if v is not None]
        ate = r["ate_m"]
        fmt = lambda v: "–" if v is None else f"{v:.6f}"  # noqa: E731
        lines.append(f"| {r['scenario']} | {r['seed']} | {r['method']} | {fmt(ate['local'])} | "
                     f"{fmt(ate['ray'])} | {max(d) if d else '–'} | {'yes' if r['identical'] else 'no'} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/suite_backends"))
    parser.add_argument("--work", type=Path, help="where the two suites write (default: temporary)")
    parser.add_argument("--address", help="Ray cluster for the ray run (default: a local instance)")
    parser.add_argument("--compare-only", action="store_true", help="compare WORK/local and WORK/ray")
    parser.add_argument("suite_args", nargs=argparse.REMAINDER,
                        help="arguments of lili-odom suite after `--` (default: the CI pieces of "
                             "building and long_tunnel, none zhang lili wheels, deterministic)")
    args = parser.parse_args()
    suite_args = [a for a in args.suite_args if a != "--"] or DEFAULT_ARGS
    work = args.work or Path(tempfile.mkdtemp(prefix="suite_backends_"))
    commands = {}
    try:
        if not args.compare_only:
            for backend in ("local", "ray"):
                commands[backend] = " ".join(shlex.quote(c) for c in
                                             run_suite(backend, suite_args, work / backend, args.address))
        docs = {b: json.loads((work / b / "suite.json").read_text()) for b in ("local", "ray")}
        if args.compare_only:
            commands = {b: docs[b].get("command", "") for b in docs}
        result = compare(docs["local"], docs["ray"])
        result["suite_args"] = suite_args
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "suite_backends.json").write_text(json.dumps(result, indent=1) + "\n")
        (args.out / "suite_backends.md").write_text(markdown(result, commands))
        print(f"{result['identical_rows']} of {result['total_rows']} rows bit-identical, "
              f"max abs diff {result['max_abs_diff']}: {args.out / 'suite_backends.md'}")
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
