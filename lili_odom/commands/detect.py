"""``lili-odom detect``: align one scan to a reference and print its degenerate subspace."""
from __future__ import annotations

import argparse
import json

import numpy as np

from lili_odom.errors import UserError

help = "align a scan to a reference cloud and detect the degenerate subspace"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from lili_odom.degeneracy.factory import METHODS

    parser.add_argument("--reference", required=True, help="reference (map) cloud: .npy Nx3, .ply or .pcd")
    parser.add_argument("--scan", required=True, help="scan cloud in its own frame: .npy, .ply or .pcd")
    parser.add_argument("--initial-pose", help="text 4x4 mapping the scan frame into the reference "
                        "frame (default identity)")
    parser.add_argument("--method", choices=METHODS, default="lili")
    parser.add_argument("--voxel-size", type=float, help="reference voxel size [m] "
                        "(default: 10 x the reference's point spacing)")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object")


def run(args: argparse.Namespace) -> int:
    from lili_odom.degeneracy.factory import make_detector, reference_for_detection
    from lili_odom.io.cloud_files import load_points, load_pose

    reference = load_points(args.reference)
    scan = load_points(args.scan)
    initial = load_pose(args.initial_pose) if args.initial_pose else np.eye(4)
    if args.voxel_size is not None and not 0 < args.voxel_size < np.inf:
        raise UserError(f"--voxel-size must be finite and > 0, got {args.voxel_size}")
    try:
        ref_map = reference_for_detection(reference, args.voxel_size)
    except ValueError as exc:
        raise UserError(f"{args.reference}: {exc}") from None
    result = make_detector(args.method).detect(ref_map, scan, initial)
    if not result.ok:
        raise UserError(f"detection failed: {result.reason}")
    if args.json:
        print(json.dumps(result.to_json_dict()))
        return 0
    np.set_printoptions(precision=4, suppress=True)
    print(f"method:    {result.method}")
    print(f"pose (scan -> reference):\n{np.asarray(result.pose)}")
    print(f"dimension: {result.dimension}   (characteristic length L = "
          f"{result.characteristic_length:.3f} m, runtime {result.runtime_s:.3f} s)")
    for i, row in enumerate(result.basis):
        print(f"  b{i + 1}: translation {row[:3]} m   rotation {row[3:]} rad")
    return 0
