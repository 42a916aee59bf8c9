"""``lili-odom run BAG``: offline odometry over a bag, the node's pipeline as fast as possible.

Writes into ``--out DIR`` what :func:`lili_odom.evaluation.runner.run_bag` writes: an outputs
bag (``odometry/``), ``estimate.tum``, ``truth.tum`` (when the bag has truth), ``scans.csv``,
``metrics.json`` (ATE/RPE via evo) and ``trajectory.png``.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from lili_odom.errors import UserError

help = "run the odometry over a rosbag2 bag offline and write outputs, TUM files and metrics"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    parser.add_argument("--method", choices=("lili", "zhang", "hessian", "none"), default=None,
                        help="degeneracy detector (default: the config's, lili)")
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument("--config", type=Path, help="ROS 2 parameter file (default: built-in)")
    parser.add_argument("--max-scans", type=int, default=0, help="stop after N scans (0 = all)")
    parser.add_argument("--rpe-segment", type=float, default=100.0, help="RPE path segment [m]")
    parser.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    from lili_odom.config import load_config
    from lili_odom.evaluation.runner import run_bag, summary_line

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        config = load_config(args.config)
        if args.method:
            config.pipeline.method = args.method
        config.validate()
    except (ValueError, OSError) as exc:
        raise UserError(f"configuration: {exc}") from None
    result = run_bag(args.bag, config, args.out, max_scans=args.max_scans,
                     rpe_segment=args.rpe_segment, progress=not args.no_progress)
    print(summary_line(result.summary))
    return 0
