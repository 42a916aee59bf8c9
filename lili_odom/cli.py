"""``lili-odom`` command line: one sub-command per module in ``lili_odom.commands``.

Each command module exposes ``help: str``, ``add_arguments(parser)`` and ``run(args) -> int``.
Errors a user can cause (bad files, missing topics, corrupt bags) are raised as
``lili_odom.errors.UserError`` and printed as one line, with a non-zero exit code.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from lili_odom.errors import UserError

COMMANDS = ("detect", "simulate", "run", "play", "evaluate", "suite")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser; ``only`` names the one command to import (the others' modules, and
    what they import, are left unloaded so a command starts fast), None imports all."""
    parser = argparse.ArgumentParser(
        prog="lili-odom",
        description="Degeneracy-aware LiDAR-inertial odometry (LiLi) tools.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS if only is None else (only,):
        try:
            module = importlib.import_module(f"lili_odom.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"lili_odom.commands.{name}":
                continue  # command not shipped in this build
            raise
        p = sub.add_parser(name, help=module.help, description=module.help)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None)
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except UserError as exc:
        print(f"lili-odom {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lili-odom {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
