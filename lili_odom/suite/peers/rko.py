"""RKO-LIO (PyPI ``rko-lio``) through its Python API (``rko_lio.lio.LIO``), LiDAR + IMU.

Settings: RKO-LIO's defaults (``rko_lio.config.LIOConfig()``: deskewing on, voxel 1 m,
range 1-100 m), which its authors present as working across sensors without tuning; the
IMU-to-base and LiDAR-to-base extrinsics are the bag's (``/tf_static``, else the configured
ones). Messages are fed as RKO-LIO's own ``LidarIMUSequencer`` does: a scan is registered
once an IMU sample newer than its last point has arrived, after every IMU sample older than
that point. Per-point times are absolute nanoseconds (``header.stamp`` + ``t``). RKO-LIO
estimates base_link directly; its own stamped poses (``poses_with_timestamps``) are used.
Scans it rejects (``InputError``) are counted in the notes.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lili_odom.suite.peers.inputs import (Context, Extrinsics, Imu, ParsedScan, PeerRun, Truth,
                                          read_inputs, truth_arrays)

MIN_POINTS = 100


def config():
    from rko_lio.config import LIOConfig

    return LIOConfig()


def _ns(t: float) -> int:
    return int(round(t * 1e9))


def run(bag: Path | str, ctx: Context) -> PeerRun:
    from rko_lio.lio import LIO
    from rko_lio.rko_lio_pybind import InputError

    cfg = config()
    if ctx.threads:
        cfg.max_num_threads = ctx.threads
    lio = LIO(cfg)
    ext = Extrinsics(ctx.config)
    truth: list[Truth] = []
    scans: list[ParsedScan] = []
    imus: list[Imu] = []
    counts = {"registered": 0, "rejected": 0}
    T_bl = T_bi = None

    def register(scan: ParsedScan) -> None:
        nonlocal T_bl
        if T_bl is None:
            T_bl = ext.T_base_lidar(scan.frame_id or "os_lidar")
        if scan.has_times:
            abs_ns = (_ns(scan.stamp) + np.round(scan.times * 1e9)).astype(np.int64)
        else:
            abs_ns = np.full(len(scan.points), _ns(scan.stamp), dtype=np.int64)
        try:
            lio.register_scan(scan.points, abs_ns, extrinsic_lidar2base=T_bl,
                              start_time_ns=int(abs_ns.min()), end_time_ns=int(abs_ns.max()))
            counts["registered"] += 1
        except InputError:
            counts["rejected"] += 1

    def drain(force: bool) -> None:
        nonlocal T_bi
        while scans and (force or (imus and imus[-1].stamp > scans[0].end)):
            scan = scans.pop(0)
            while imus and imus[0].stamp < scan.end:
                imu = imus.pop(0)
                if T_bi is None:
                    T_bi = ext.T_base_imu(imu.frame_id or "os_imu")
                lio.add_imu_measurement(imu.acceleration, imu.angular_velocity, _ns(imu.stamp),
                                        extrinsic_imu2base=T_bi)
            register(scan)

    t0 = time.perf_counter()
    for item in read_inputs(bag, ctx, imu=True, extrinsics=ext, truth=truth):
        if isinstance(item, ParsedScan):
            if len(item.points) >= MIN_POINTS:
                scans.append(item)
        else:
            imus.append(item)
        drain(force=False)
    drain(force=True)
    wall = time.perf_counter() - t0
    stamps_ns, values = lio.poses_with_timestamps()
    values = np.asarray(values, dtype=float).reshape(-1, 7)
    poses = np.tile(np.eye(4), (len(values), 1, 1))
    if len(values):
        poses[:, :3, :3] = Rotation.from_quat(values[:, 3:7]).as_matrix()
        poses[:, :3, 3] = values[:, :3]
    ts, tp = truth_arrays(truth)
    return PeerRun(np.asarray(stamps_ns, dtype=float) * 1e-9, poses, ts, tp,
                   scans=counts["registered"], wall_s=wall, notes=counts)
