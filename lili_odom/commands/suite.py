"""``lili-odom suite``: the scenario suite, our methods and the peers on the same bags, scored
alike.

Examples::

    lili-odom suite --list
    lili-odom suite --preset ci --out suite_ci
    lili-odom suite --scenarios building tunnel --methods none lili --peers genz wheels \\
        --seeds 0 --jobs 2 --out suite_out
    lili-odom suite --bags my_run1 my_run2 --truth-topic /gps/odom --out suite_user
    lili-odom suite --preset ci --backend ray --address HEAD_IP:6379 --out suite_ci

Writes ``OUT/suite.json`` (row by row), ``OUT/suite.md``, ``OUT/NAME.png`` and the runs
under ``OUT/runs/NAME/seedK/METHOD/`` (see :mod:`lili_odom.suite.report`).
"""
from __future__ import annotations

import argparse
import logging
import os
import shlex
import sys
from pathlib import Path

from lili_odom.errors import UserError

help = "run the scenario suite: our methods and peers (KISS-ICP, GenZ-ICP, RKO-LIO, wheels)"

DEFAULT_METHODS = ["none", "zhang", "hessian", "lili"]
DEFAULT_PEERS = ["kiss", "genz", "rko", "wheels"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from lili_odom.suite.backends import BACKENDS
    from lili_odom.suite.methods import OUR_METHODS
    from lili_odom.suite.peers import PEERS

    parser.add_argument("--list", action="store_true",
                        help="list the scenarios (name, split, kind, sensor, distance) and exit")
    parser.add_argument("--scenarios", nargs="+", metavar="NAME", help="scenarios (default: all of the preset)")
    parser.add_argument("--preset", choices=("full", "ci"), default="full",
                        help="full: each scenario's window and sensor; ci: the short CI pieces")
    parser.add_argument("--methods", nargs="*", choices=OUR_METHODS, default=None,
                        help=f"our methods (default: {' '.join(DEFAULT_METHODS)})")
    parser.add_argument("--peers", nargs="*", choices=PEERS, default=None,
                        help=f"peers (default: {' '.join(DEFAULT_PEERS)}, those installed)")
    parser.add_argument("--split", choices=("tuning", "validation", "all"), default="all")
    parser.add_argument("--seeds", nargs="+", type=int, help="seeds (default: each scenario's own; ci: its first)")
    parser.add_argument("--resolution", metavar="RxC", help="LiDAR rows x columns for every scenario")
    parser.add_argument("--bags", nargs="+", type=Path, metavar="BAG",
                        help="also run on these recorded bags (they need a ground-truth topic)")
    parser.add_argument("--truth-topic", default="/ground_truth/odom",
                        help="ground-truth nav_msgs/Odometry topic (default /ground_truth/odom)")
    parser.add_argument("--config", type=Path, help="ROS 2 parameter file for our methods")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a parameter of our methods (e.g. lili.k=3); repeatable")
    parser.add_argument("--rpe-segment", type=float, default=10.0, help="RPE segment [m] (default 10)")
    parser.add_argument("--out", type=Path, default=Path("suite_output"), help="output directory")
    parser.add_argument("--work-dir", type=Path, default=None,
                        help="per-run files: trajectories, our runs' outputs (default OUT/runs)")
    parser.add_argument("--jobs", type=int, default=None,
                        help="jobs at the same time (default: min(2, cores))")
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="local: processes on this machine; ray: one Ray task per job "
                             "(pip install 'lili_odom[cluster]')")
    parser.add_argument("--address", metavar="ADDR",
                        help="with --backend ray: the Ray cluster (HOST:PORT of `ray start --head`, "
                             "or auto); default: a Ray instance on this machine")
    parser.add_argument("--timeout", type=float, default=None, help="stop a job after this many seconds")
    parser.add_argument("--cache-dir", type=Path, help="simulator cache (default $LILI_ODOM_SIM_CACHE or data/sim)")
    parser.add_argument("--resume", action="store_true",
                        help="keep the successful rows of OUT/suite.json and run only the others")
    parser.add_argument("--no-progress", action="store_true")


def _list() -> int:
    from rich.console import Console
    from rich.table import Table

    from lili_odom.suite.scenario import load_scenarios

    table = Table(title="scenarios (config/scenarios)")
    for name in ("scenario", "split", "kind", "sensor", "distance \\[m]", "duration \\[s]", "errors",
                 "ci piece"):
        table.add_column(name, no_wrap=True)
    for sc in load_scenarios():
        ci = f"{sc.ci.duration:.0f} s at {sc.ci.resolution[0]}x{sc.ci.resolution[1]}" if sc.ci else "–"
        table.add_row(sc.name, sc.split, sc.kind, sc.sensor.label,
                      f"{sc.distance:.0f}" if sc.distance is not None else "?",
                      f"{sc.duration_s:.0f}" if sc.duration_s is not None else "?",
                      sc.errors.label(), ci)
    Console(width=200).print(table)
    return 0


def _overrides(items: list[str]) -> list[tuple[str, str]]:
    out = []
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UserError(f"--set expects KEY=VALUE, got {item!r}")
        out.append((key.strip(), value))
    return out


def run(args: argparse.Namespace) -> int:
    from lili_odom.suite.backends import make_backend
    from lili_odom.suite.methods import node_config, peer_available
    from lili_odom.suite.runner import SuiteRequest, run_suite

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        if args.list:
            return _list()
    except (ValueError, OSError) as exc:
        raise UserError(f"scenarios: {exc}") from None
    methods = DEFAULT_METHODS if args.methods is None else list(args.methods)
    if args.peers is None:
        peers = [p for p in DEFAULT_PEERS if peer_available(p)]
        skipped = [p for p in DEFAULT_PEERS if p not in peers]
        if skipped:
            print(f"peers not installed, skipped: {' '.join(skipped)} "
                  f"(pip install 'lili_odom[peers]')", file=sys.stderr)
    else:
        peers = list(args.peers)
    if not methods and not peers:
        raise UserError("nothing to run: no method and no peer")
    jobs = args.jobs if args.jobs is not None else min(2, os.cpu_count() or 1)
    if jobs < 1:
        raise UserError("--jobs must be >= 1")
    if args.resolution:
        from lili_odom.sim.sensors import parse_resolution

        try:
            parse_resolution(args.resolution)
        except ValueError as exc:
            raise UserError(f"--resolution: {exc}") from None
    for bag in args.bags or []:
        if not bag.exists():
            raise UserError(f"{bag}: no such bag")
    overrides = _overrides(args.set)
    try:  # a bad parameter fails here once, not in every job
        node_config(str(args.config) if args.config else None, tuple(overrides), args.truth_topic)
    except (ValueError, OSError) as exc:
        raise UserError(f"configuration: {exc}") from None
    command = "lili-odom suite " + " ".join(shlex.quote(a) for a in sys.argv[2:]) \
        if len(sys.argv) > 1 and sys.argv[1] == "suite" else "lili-odom suite " + _describe(args, methods, peers)
    request = SuiteRequest(
        out=args.out, scenarios=args.scenarios, preset=args.preset, methods=methods + peers,
        split=args.split, seeds=args.seeds, resolution=args.resolution, bags=list(args.bags or []),
        truth_topic=args.truth_topic, config_path=str(args.config) if args.config else None,
        overrides=overrides, rpe_segment_m=args.rpe_segment,
        cache_dir=str(args.cache_dir) if args.cache_dir else None, resume=args.resume,
        work_dir=args.work_dir,
        command=command)
    if args.backend != "ray" and args.address:
        raise UserError("--address needs --backend ray")
    if args.backend == "ray" and args.timeout is not None:
        raise UserError("--timeout is not supported with --backend ray")
    # on a cluster without --jobs, Ray schedules one task per free CPU of its nodes
    backend_jobs = None if args.backend == "ray" and args.address and args.jobs is None else jobs
    try:
        backend = make_backend(args.backend, backend_jobs, timeout_s=args.timeout, address=args.address)
    except (RuntimeError, ConnectionError) as exc:
        raise UserError(f"--backend {args.backend}: {exc}") from None
    try:
        doc = run_suite(request, backend, progress=not args.no_progress)
    except ValueError as exc:
        backend.shutdown(cancel=True)
        raise UserError(str(exc)) from None
    rows = doc["rows"]
    failed = [r for r in rows if r.get("error")]
    print(f"{len(rows)} rows ({len(failed)} failed) in {doc['wall_time_s']:.0f} s: "
          f"{args.out / 'suite.json'}, {args.out / 'suite.md'}")
    for r in failed:
        print(f"  failed: {r['scenario']} seed {r['seed']} {r['method']}: {r['error']}", file=sys.stderr)
    return 0


def _describe(args: argparse.Namespace, methods: list[str], peers: list[str]) -> str:
    """The options of a programmatic call, as a command line."""
    parts = []
    if args.scenarios:
        parts += ["--scenarios", *args.scenarios]
    parts += ["--preset", args.preset, "--methods", *methods, "--peers", *peers]
    if args.split != "all":
        parts += ["--split", args.split]
    if args.seeds:
        parts += ["--seeds", *map(str, args.seeds)]
    if args.resolution:
        parts += ["--resolution", args.resolution]
    for s in args.set:
        parts += ["--set", s]
    if args.config:
        parts += ["--config", str(args.config)]
    parts += ["--out", str(args.out)]
    if args.work_dir:
        parts += ["--work-dir", str(args.work_dir)]
    return " ".join(shlex.quote(p) for p in parts)
