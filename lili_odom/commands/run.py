"""``lili-odom run BAG``: offline odometry over a bag, the node's pipeline as fast as possible.

Writes into ``--out DIR`` what :func:`lili_odom.evaluation.runner.run_bag` writes: an outputs
bag (``odometry/``), ``estimate.tum``, ``truth.tum`` (when the bag has truth), ``scans.csv``,
``metrics.json`` (ATE/RPE via evo) and ``trajectory.png``; with ``--save-map FILE`` also the
accumulated map (``.pcd`` or ``.ply``).

``lili-odom run RECORDING.pcap --metadata META.json`` (or ``RECORDING.osf``) runs the same
pipeline straight from an Ouster recording (:class:`lili_odom.io.ouster.OusterRecording`,
needs ``pip install ouster-sdk``): the clouds as ouster-ros would publish them, the IMU when
recorded, no wheels. ``base_link`` is then the sensor's ``os_sensor`` frame; the lidar and IMU
extrinsics come from the metadata.
"""
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from lili_odom.errors import UserError

help = "run the odometry over a rosbag2 bag offline and write outputs, TUM files and metrics"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file, or an "
                        "Ouster recording (.pcap with --metadata, .osf)")
    parser.add_argument("--method", choices=("lili", "zhang", "hessian", "none"), default=None,
                        help="degeneracy detector (default: the config's, lili)")
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument("--config", type=Path, help="ROS 2 parameter file (default: built-in)")
    parser.add_argument("--max-scans", type=int, default=0, help="stop after N scans (0 = all)")
    parser.add_argument("--rpe-segment", type=float, default=100.0, help="RPE path segment [m]")
    parser.add_argument("--no-progress", action="store_true")
    parser.add_argument("--save-map", type=Path, metavar="FILE",
                        help="also write the accumulated map to FILE (.pcd or .ply)")
    parser.add_argument("--map-voxel", type=float, default=0.2,
                        help="voxel size of the saved map [m] (default 0.2)")
    parser.add_argument("--metadata", type=Path, metavar="META.json",
                        help="sensor metadata of an Ouster .pcap recording")


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
    if not args.map_voxel > 0:
        raise UserError(f"--map-voxel must be > 0, got {args.map_voxel}")
    reader = None
    if Path(args.bag).suffix.lower() in OUSTER_SUFFIXES:
        reader = ouster_source(args.bag, args.metadata, config)
    elif args.metadata is not None:
        raise UserError("--metadata is for Ouster recordings (.pcap, .osf)")
    result = run_bag(args.bag, config, args.out, max_scans=args.max_scans,
                     rpe_segment=args.rpe_segment, progress=not args.no_progress,
                     reader=reader, save_map=args.save_map, map_voxel=args.map_voxel)
    print(summary_line(result.summary))
    if result.map_path:
        print(f"map: {result.map_path}")
    return 0


OUSTER_SUFFIXES = (".pcap", ".osf")


def ouster_source(path: Path, metadata: Path | None, config):
    """The recording as a message source; ``config`` gets its topics and extrinsics
    (``base_link`` = ``os_sensor``, no wheels, no /tf_static)."""
    from lili_odom.io.ouster import OusterRecording

    rec = OusterRecording(path, metadata, lidar_topic=config.lidar_topic,
                          imu_topic=config.imu_topic)
    config.extrinsics.base_to_sensor = [0.0] * 6
    config.extrinsics.sensor_to_lidar = xyz_rpy(rec.T_sensor_lidar)
    config.extrinsics.sensor_to_imu = xyz_rpy(rec.T_sensor_imu)
    config.extrinsics.use_tf_static = False
    config.validate()
    config.apply_extrinsics()
    return rec


def xyz_rpy(T) -> list[float]:
    """4x4 -> ``[x, y, z, roll, pitch, yaw]`` (the inverse of ``config.pose_from_xyz_rpy``)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    T = np.asarray(T, dtype=float)
    yaw, pitch, roll = Rotation.from_matrix(T[:3, :3]).as_euler("ZYX")
    return [float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), float(roll), float(pitch),
            float(yaw)]
