"""``lili-odom simulate shapes``: write the synthetic shape benchmark cases to disk.

One folder per case, ``<out>/<scenario>_<clean|noisy>/``, holding ``reference.npy``,
``scan.npy``, ``initial_pose.txt``, ``true_pose.txt`` and ``truth.json`` (see
``lili_odom.sim.shapes.write_case``).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from lili_odom.sim.shapes import all_cases, write_case

DEFAULT_OUT = Path("data") / "shapes"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out", type=Path, default=DEFAULT_OUT, metavar="DIR",
        help=f"output directory (default: {DEFAULT_OUT})",
    )
    parser.add_argument("--seed", type=int, default=0, help="sampling and noise seed (default: 0)")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    seed = int(args.seed)
    folders = []
    for case in all_cases(seed):
        folder = write_case(case, out, seed)
        folders.append(folder)
        print(
            f"{folder}: {len(case.reference)} reference / {len(case.scan)} scan points, "
            f"true dimension {case.true_dimension}, L = {case.characteristic_length:.2f} m"
        )
    print(f"wrote {len(folders)} shape cases to {out}")
    return 0
