"""Wheel odometry alone: the bag's ``/platform/odom`` poses (base_link in the wheel
odometry frame, as the robot integrated them), every message."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from lili_odom.suite.peers.inputs import Context, PeerRun, Truth, read_inputs, truth_arrays


def run(bag: Path | str, ctx: Context) -> PeerRun:
    truth: list[Truth] = []
    stamps, poses = [], []
    t0 = time.perf_counter()
    for sample in read_inputs(bag, ctx, lidar=False, wheels=True, truth=truth):
        stamps.append(sample.stamp)
        poses.append(sample.pose)
    wall = time.perf_counter() - t0
    ts, tp = truth_arrays(truth)
    order = np.argsort(stamps, kind="stable")
    return PeerRun(np.array(stamps)[order], np.array(poses).reshape(-1, 4, 4)[order], ts, tp,
                   scans=0, wall_s=wall)
