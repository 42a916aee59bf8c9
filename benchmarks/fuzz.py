"""Fuzz campaign over every public input door (package :mod:`lili_odom.fuzz`).

Runs the seeded cases of each door in worker subprocesses (native aborts and hangs are caught
and counted per case), writes ``benchmarks/results/fuzz.json`` and ``fuzz.md`` and, for every
finding, a reproducer script under ``benchmarks/results/fuzz_reproducers/``.

    python -m benchmarks.fuzz                   # the full campaign (10,374 cases)
    python -m benchmarks.fuzz --scale 0.05      # a quick slice
    python -m benchmarks.fuzz --doors api bags  # some doors only
"""
from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from benchmarks._common import RESULTS

#: Cases per door of the full campaign.
FULL = {"clouds": 7700, "api": 1200, "feeder": 1000, "bags": 150, "detect": 300,
        "sequences": 24}


def main(argv: list[str] | None = None) -> int:
    from lili_odom.fuzz.campaign import DoorPlan, run_campaign
    from lili_odom.fuzz.report import render

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--scale", type=float, default=1.0, help="fraction of the full case counts")
    p.add_argument("--doors", nargs="+", choices=sorted(FULL), default=list(FULL))
    p.add_argument("--jobs", type=int, default=1, help="worker processes at a time")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--name", default="fuzz", help="result file stem")
    p.add_argument("--no-progress", action="store_true")
    args = p.parse_args(argv)

    plans = [DoorPlan(door, max(1, round(FULL[door] * args.scale))) for door in args.doors]
    args.out.mkdir(parents=True, exist_ok=True)
    repro = args.out / f"{args.name}_reproducers"
    report = run_campaign(plans, args.seed, jobs=args.jobs, reproducer_dir=repro,
                          progress=not args.no_progress)
    command = "python -m benchmarks.fuzz " + " ".join(
        shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    (args.out / f"{args.name}.json").write_text(json.dumps(report, indent=1) + "\n")
    (args.out / f"{args.name}.md").write_text(render(report, command.strip()))
    t = report["totals"]
    print(f"{report['cases']} cases in {report['wall_s']:.0f} s: "
          + ", ".join(f"{k} {v}" for k, v in t.items()))
    return 0 if not report["findings"] else 1


if __name__ == "__main__":
    sys.exit(main())
