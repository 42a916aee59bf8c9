"""``lili-odom simulate {shapes,tunnel,scenario}``: write the synthetic data sets."""
from __future__ import annotations

import argparse
import importlib

help = "write synthetic data: degenerate shape pairs, Husky-in-a-tunnel or scenario rosbag2 mcap bags"

_KINDS = {
    "shapes": ("lili_odom.commands.simulate_shapes", "shape pairs (reference + local scan) with true subspaces"),
    "tunnel": ("lili_odom.commands.simulate_tunnel", "a simulated OS1-128 / IMU / wheel odometry tunnel bag"),
    "scenario": ("lili_odom.commands.simulate_scenario", "the bag of one scenario of the suite (config/scenarios)"),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="kind", required=True, metavar="KIND")
    for kind, (module_name, text) in _KINDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue
            raise
        p = sub.add_parser(kind, help=text, description=text)
        module.add_arguments(p)
        p.set_defaults(_kind_run=module.run)


def run(args: argparse.Namespace) -> int:
    return int(args._kind_run(args) or 0)
