"""KISS-ICP's own pipeline (``kiss_icp.kiss_icp.KissICP.register_frame``), LiDAR only.

Settings: KISS-ICP's defaults as its ``load_config`` gives them without a file
(``data.max_range`` 100 m, ``min_range`` 0, ``mapping.voxel_size`` = max_range / 100 = 1 m,
20 points per voxel, adaptive threshold from 2 m, deskewing on) with the cloud's per-point
times. With deskewing, KISS-ICP expresses a scan at the time of its last point, so each pose is
stamped ``header.stamp + max(t)``. Poses are converted to base_link with the bag's extrinsics
(:func:`lili_odom.suite.frames.lidar_to_base`).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from lili_odom.suite.frames import lidar_to_base
from lili_odom.suite.peers.inputs import (Context, Extrinsics, PeerRun, Truth, read_inputs,
                                          truth_arrays)

#: Scans with fewer valid points are skipped (never handed to the native code).
MIN_POINTS = 100


def config():
    """KISS-ICP's default configuration (what its command line uses without ``--config``)."""
    from kiss_icp.config import load_config

    return load_config(None)


def run(bag: Path | str, ctx: Context) -> PeerRun:
    from kiss_icp.kiss_icp import KissICP

    cfg = config()
    if ctx.threads:
        cfg.registration.max_num_threads = ctx.threads
    odometry = KissICP(cfg)
    ext = Extrinsics(ctx.config)
    truth: list[Truth] = []
    stamps, poses, frame = [], [], "os_lidar"
    t0 = time.perf_counter()
    for scan in read_inputs(bag, ctx, extrinsics=ext, truth=truth):
        if len(scan.points) < MIN_POINTS:
            continue
        times = scan.times if scan.has_times else np.zeros(0)
        odometry.register_frame(scan.points, times)
        stamps.append(scan.end)
        poses.append(np.array(odometry.last_pose, dtype=float))
        frame = scan.frame_id or frame
    wall = time.perf_counter() - t0
    ts, tp = truth_arrays(truth)
    base = lidar_to_base(np.array(poses), ext.T_base_lidar(frame)) if poses else np.zeros((0, 4, 4))
    return PeerRun(np.array(stamps), base, ts, tp, scans=len(stamps), wall_s=wall,
                   notes={"voxel_size": cfg.mapping.voxel_size, "max_range": cfg.data.max_range})
