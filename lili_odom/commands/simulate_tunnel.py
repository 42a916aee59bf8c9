"""``lili-odom simulate tunnel``: write a simulated Husky (OS1-128, IMU, wheels, truth) bag.

Examples::

    lili-odom simulate tunnel --trial 1                      # 260 m pass, cached under data/sim
    lili-odom simulate tunnel --trial 2 --seed 3             # 430 m round trip
    lili-odom simulate tunnel --trial 3 --resolution 32x512 --out bags/x   # explicit output dir
    lili-odom simulate tunnel --world corridor --trial 1 --feature-density 0

Without ``--out`` the bag goes to the cache (``--cache-dir``, default ``data/sim`` of the
checkout or ``$LILI_ODOM_SIM_CACHE``) and an
existing bag with the same parameters and simulator version is reused. The path of the bag is
printed on the last line of stdout.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from lili_odom.errors import UserError
from lili_odom.sim.generator import SimRequest, ensure_trial_bag, simulate_bag
from lili_odom.sim.sensors import parse_resolution

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--trial", type=int, default=1,
                        help="trial of the world: 1 = 260 m pass, 2 = 430 m round trip, 3 = short entrance piece")
    parser.add_argument("--world", default="tunnel",
                        help="world: a name under config/worlds (tunnel, corridor, open_field) or a YAML file")
    parser.add_argument("--out", type=Path, default=None, help="output bag directory (must not exist)")
    parser.add_argument("--cache-dir", type=Path, default=None,
                        help="cache used without --out (default: $LILI_ODOM_SIM_CACHE or data/sim of the checkout)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (trajectory details and all noise)")
    parser.add_argument("--start", type=float, default=0.0, help="start of the piece [s of trial time]")
    parser.add_argument("--duration", type=float, default=None, help="length of the piece [s] (default: to the end)")
    parser.add_argument("--resolution", default="128x1024", help="ROWSxCOLS, e.g. 128x1024, 64x512, 32x512")
    parser.add_argument("--feature-density", type=float, default=None,
                        help="inside features per nominal spacing (0 = featureless tunnel; default: world's)")
    parser.add_argument("--jobs", type=int, default=None, help="ray-casting processes (default: min(2, cores); 1 for pieces under 5 s)")
    parser.add_argument("--zstd-level", type=int, default=None,
                        help="zstd level for the mcap chunks (default 2); 19 for small committed bags")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    world = args.world
    try:
        resolution = parse_resolution(args.resolution)
    except ValueError as exc:
        raise UserError(str(exc)) from exc
    if args.feature_density is not None and args.feature_density < 0:
        raise UserError("--feature-density must be >= 0")
    jobs = args.jobs
    if jobs is None:  # a second process pays off only past its start-up (~2 s)
        short = args.duration is not None and args.duration < 5.0
        jobs = 1 if short else min(2, os.cpu_count() or 1)
    try:
        if args.out is None:
            if args.zstd_level is not None:
                raise UserError("--zstd-level needs --out (cached bags use the default level)")
            path = ensure_trial_bag(args.trial, args.cache_dir, world=world, seed=args.seed, resolution=resolution,
                                    feature_density=args.feature_density, start=args.start, duration=args.duration,
                                    progress=not args.no_progress, jobs=jobs)
        else:
            if args.out.exists():
                raise UserError(f"{args.out} exists already; choose a new --out")
            req = SimRequest(world=world, trial=args.trial, seed=args.seed, resolution=resolution,
                             feature_density=args.feature_density, start=args.start, duration=args.duration)
            kw = {} if args.zstd_level is None else {"zstd_level": args.zstd_level}
            summary = simulate_bag(req, args.out, progress=not args.no_progress, jobs=jobs, **kw)
            path = summary.path
            print(f"{summary.scans} scans in {summary.wall_time:.1f} s ({summary.scans_per_second:.1f} scans/s)")
    except FileNotFoundError as exc:
        raise UserError(str(exc)) from exc
    except ValueError as exc:
        raise UserError(str(exc)) from exc
    print(path)
    return 0
