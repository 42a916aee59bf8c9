"""``lili-odom simulate scenario NAME``: simulate (or reuse from the cache) one scenario's bag.

Examples::

    lili-odom simulate scenario --list
    lili-odom simulate scenario --list --markdown          # the table of docs/scenarios.md
    lili-odom simulate scenario building                    # seed = the scenario's first seed
    lili-odom simulate scenario building --ci               # its short CI piece
    lili-odom simulate scenario mine --seed 1 --resolution 32x512 --out bags/mine

Without ``--out`` the bag goes to the cache (``--cache-dir``, default ``$LILI_ODOM_SIM_CACHE``
or ``data/sim`` of the checkout). The path of the bag is printed on the last line of stdout.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from lili_odom.errors import UserError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", nargs="?", help="scenario name (config/scenarios/NAME.yaml)")
    parser.add_argument("--list", action="store_true", help="list the scenarios and exit")
    parser.add_argument("--markdown", action="store_true", help="with --list: the markdown table of docs/scenarios.md")
    parser.add_argument("--seed", type=int, default=None, help="seed (default: the scenario's first seed)")
    parser.add_argument("--ci", action="store_true", help="simulate the scenario's short CI piece")
    parser.add_argument("--resolution", default=None, help="ROWSxCOLS override of the sensor profile")
    parser.add_argument("--out", type=Path, default=None, help="output bag directory (must not exist)")
    parser.add_argument("--cache-dir", type=Path, default=None,
                        help="cache used without --out (default: $LILI_ODOM_SIM_CACHE or data/sim of the checkout)")
    parser.add_argument("--jobs", type=int, default=None, help="ray-casting processes (default: min(2, cores))")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from lili_odom.sim.generator import simulate_bag
    from lili_odom.suite.scenario import load_scenarios, scenario_bag, scenario_request, scenario_table

    if args.list and args.markdown:
        print(scenario_table(load_scenarios()), end="")
        return 0
    if args.list:
        for sc in load_scenarios():
            print(f"{sc.name:22s} {sc.split:10s} {sc.kind:10s} {sc.sensor.label:16s} "
                  f"{sc.distance:6.0f} m {sc.duration_s:6.0f} s  {sc.errors.label()}")
        return 0
    if not args.name:
        raise UserError("give a scenario NAME (or --list)")
    try:
        (sc,) = load_scenarios([args.name])
        seed = sc.seeds[0] if args.seed is None else args.seed
        jobs = args.jobs if args.jobs is not None else min(2, os.cpu_count() or 1)
        if args.out is None:
            path = scenario_bag(sc, seed, ci=args.ci, resolution=args.resolution, cache_dir=args.cache_dir,
                                progress=not args.no_progress, jobs=jobs)
        else:
            if args.out.exists():
                raise UserError(f"{args.out} exists already; choose a new --out")
            req = scenario_request(sc, seed, ci=args.ci, resolution=args.resolution)
            summary = simulate_bag(req, args.out, progress=not args.no_progress, jobs=jobs)
            path = summary.path
            print(f"{summary.scans} scans in {summary.wall_time:.1f} s ({summary.scans_per_second:.1f} scans/s)")
    except (ValueError, FileNotFoundError) as exc:
        raise UserError(str(exc)) from exc
    print(path)
    return 0
