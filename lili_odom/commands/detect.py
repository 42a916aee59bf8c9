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
    parser.add_argument("--voxel-size", type=float, help="odometry voxel [m] both clouds are "
                        "downsampled with (default: KISS-ICP's max_range / 100 rule on the scan's "
                        "reach, 1.0 m for a real sensor); with --raw, the reference map's voxel "
                        "(default 10 x the reference's point spacing)")
    parser.add_argument("--raw", action="store_true", help="keep every point of both clouds "
                        "instead of voxelising them as the odometry does")
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object")


def run(args: argparse.Namespace) -> int:
    from lili_odom.degeneracy.detection_input import odometry_detector, prepare
    from lili_odom.degeneracy.factory import make_detector
    from lili_odom.io.cloud_files import load_points, load_pose

    reference = load_points(args.reference)
    scan = load_points(args.scan)
    initial = load_pose(args.initial_pose) if args.initial_pose else np.eye(4)
    if args.voxel_size is not None and not 0 < args.voxel_size < np.inf:
        raise UserError(f"--voxel-size must be finite and > 0, got {args.voxel_size}")
    try:
        inputs = prepare(reference, scan, raw=args.raw, voxel_size=args.voxel_size)
    except ValueError as exc:
        raise UserError(f"{args.reference}, {args.scan}: {exc}") from None
    detector = make_detector(args.method) if args.raw else odometry_detector(args.method)
    result = detector.detect(inputs.reference, inputs.scan, initial)
    if not result.ok:
        raise UserError(f"detection failed: {result.reason}")
    if args.json:
        print(json.dumps({**result.to_json_dict(), "voxel_size": inputs.voxel_size,
                          "scan_points": int(len(inputs.scan))}))
        return 0
    np.set_printoptions(precision=4, suppress=True)
    print(f"method:    {result.method}")
    voxel = "raw clouds" if inputs.voxel_size is None else f"voxel {inputs.voxel_size:.3f} m"
    print(f"input:     {voxel}, {len(inputs.scan)} of {inputs.scan_points_in} scan points")
    print(f"pose (scan -> reference):\n{np.asarray(result.pose)}")
    print(f"dimension: {result.dimension}   (characteristic length L = "
          f"{result.characteristic_length:.3f} m, runtime {result.runtime_s:.3f} s)")
    for i, row in enumerate(result.basis):
        print(f"  b{i + 1}: translation {row[:3]} m   rotation {row[3:]} rad")
    return 0
