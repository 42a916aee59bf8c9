"""GenZ-ICP (PyPI ``genz-icp``), LiDAR only, with one of its pre-tuned presets.

The preset is chosen once per kind of scene, never per scenario (:data:`PRESETS`):
enclosed scenes (tunnels, corridors, buildings, mines, warehouses: walls within range on
most sides) use GenZ-ICP's ``corridor`` preset; open scenes (fields, parking lots, anything
outdoors) its ``outdoor`` preset; an unknown kind uses ``indoor``. The presets are used as
shipped (they all set ``deskew: false``); each pose is stamped at the middle of its sweep,
the time a rigid, undeskewed scan represents. Poses are converted to base_link with the
bag's extrinsics (:func:`lili_odom.suite.frames.lidar_to_base`).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from lili_odom.suite.frames import lidar_to_base
from lili_odom.suite.peers.inputs import (Context, Extrinsics, PeerRun, Truth, read_inputs,
                                          truth_arrays)

#: kind of scene -> GenZ-ICP preset (``genz_icp/config/pretuned/<name>.yaml``)
PRESETS: dict[str, str] = {
    "tunnel": "corridor",
    "corridor": "corridor",
    "building": "corridor",
    "indoor": "corridor",
    "mine": "corridor",
    "warehouse": "corridor",
    "field": "outdoor",
    "parking": "outdoor",
    "open": "outdoor",
    "outdoor": "outdoor",
}
DEFAULT_PRESET = "indoor"
MIN_POINTS = 100


def preset_for(kind: str) -> str:
    """The preset of a kind of scene (matched on the kind's words, e.g. ``parking_lot``)."""
    kind = (kind or "").lower()
    if kind in PRESETS:
        return PRESETS[kind]
    for word in kind.replace("-", "_").split("_"):
        if word in PRESETS:
            return PRESETS[word]
    return DEFAULT_PRESET


def config(kind: str):
    from genz_icp.config import load_config

    return load_config(Path(preset_for(kind)))


def run(bag: Path | str, ctx: Context) -> PeerRun:
    from genz_icp.genz_icp import GenZICP

    cfg = config(ctx.kind)
    odometry = GenZICP(cfg)
    ext = Extrinsics(ctx.config)
    truth: list[Truth] = []
    stamps, poses, frame = [], [], "os_lidar"
    t0 = time.perf_counter()
    for scan in read_inputs(bag, ctx, extrinsics=ext, truth=truth):
        if len(scan.points) < MIN_POINTS:
            continue
        if scan.has_times:
            odometry.register_frame(scan.points, scan.times)
            mid = scan.stamp + 0.5 * float(scan.times.min() + scan.times.max())
        else:
            odometry.register_frame(scan.points, None)
            mid = scan.stamp
        stamps.append(mid if not cfg.data.deskew else scan.end)
        poses.append(np.array(odometry.last_pose, dtype=float))
        frame = scan.frame_id or frame
    wall = time.perf_counter() - t0
    ts, tp = truth_arrays(truth)
    base = lidar_to_base(np.array(poses), ext.T_base_lidar(frame)) if poses else np.zeros((0, 4, 4))
    return PeerRun(np.array(stamps), base, ts, tp, scans=len(stamps), wall_s=wall,
                   notes={"preset": preset_for(ctx.kind)})
