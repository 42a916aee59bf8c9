"""``lili-odom evaluate``: the tunnel evaluation (Table II): every method on Trials 1 and 2."""
from __future__ import annotations

import argparse
from pathlib import Path

from lili_odom.errors import UserError

help = "run none/zhang/hessian/lili on the simulated tunnel trials; ATE/RPE table and plots"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from lili_odom.evaluation.tunnel import METHODS, TRIALS

    parser.add_argument("--trials", type=int, nargs="+", default=list(TRIALS),
                        choices=(1, 2, 3),
                        help="tunnel trials (1: 260 m pass, 2: 430 m round trip, 3: entrance piece)")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--resolution", default="128x1024", help="OS1 ROWSxCOLS of the bags")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed")
    parser.add_argument("--start", type=float, default=0.0,
                        help="start of the piece of each trial [s] (default: its beginning)")
    parser.add_argument("--duration", type=float, default=None,
                        help="only N seconds of each trial (default: to its end)")
    parser.add_argument("--out", type=Path, default=Path("tunnel_evaluation"),
                        help="report directory (tunnel.md, tunnel.json, figures)")
    parser.add_argument("--work-dir", type=Path, default=None,
                        help="per-run outputs (default: OUT/runs)")
    parser.add_argument("--cache-dir", type=Path, default=None,
                        help="simulator bag cache (default: $LILI_ODOM_SIM_CACHE or data/sim)")
    parser.add_argument("--config", type=Path, help="ROS 2 parameter file for the odometry")
    parser.add_argument("--jobs", type=int, default=1, help="runs in parallel")
    parser.add_argument("--reuse", action="store_true",
                        help="keep runs whose metrics.json already exists")
    parser.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    from lili_odom.evaluation.tunnel import TunnelEvaluation, evaluate_tunnel

    if args.jobs < 1:
        raise UserError("--jobs must be >= 1")
    if args.duration is not None and not args.duration > 0:
        raise UserError("--duration must be > 0 s")
    if not args.start >= 0:
        raise UserError("--start must be >= 0 s")
    if args.config is not None and not args.config.is_file():
        raise UserError(f"{args.config}: no such parameter file")
    ev = TunnelEvaluation(out_dir=args.out, work_dir=args.work_dir or args.out / "runs",
                          trials=tuple(args.trials), methods=tuple(args.methods),
                          resolution=args.resolution, seed=args.seed, jobs=args.jobs,
                          start=args.start, duration=args.duration,
                          reuse=args.reuse, progress=not args.no_progress,
                          cache_dir=args.cache_dir, config=args.config)
    report = evaluate_tunnel(ev)
    print((args.out / "tunnel.md").read_text())
    return 0 if report["rows"] else 1
