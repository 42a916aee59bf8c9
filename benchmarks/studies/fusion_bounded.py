"""Per-update time and memory of the fusion estimator over a long run.

A Husky-like robot drives a circle (1 m/s, 0.2 rad/s) for N scans at 10 Hz with a 100 Hz IMU
(noisy), noisy wheel increments and noisy LiDAR poses, degenerate along base_link x half of
the time. Prints time per update and resident memory at intervals; both must stay flat.

    python -m benchmarks.studies.fusion_bounded [--updates 3000] [--reset-every 100]
"""
from __future__ import annotations

import argparse
import math
import resource
import time
from types import SimpleNamespace

import numpy as np

from lili_odom.fusion import FusionConfig, FusionEstimator
from lili_odom.geometry import exp

G = 9.80665


def truth(t: float, v: float, w: float) -> np.ndarray:
    yaw = w * t
    T = np.eye(4)
    T[:3, :3] = [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
    T[:3, 3] = [v * math.sin(yaw) / w, v * (1 - math.cos(yaw)) / w, 0.0]
    return T


def rss_mb() -> float:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--updates", type=int, default=3000)
    ap.add_argument("--reset-every", type=int, default=100)
    ap.add_argument("--report-every", type=int, default=500)
    args = ap.parse_args()

    v, w = 1.0, 0.2
    rng = np.random.default_rng(0)
    cfg = FusionConfig(T_base_lidar=np.eye(4), T_base_imu=np.eye(4), reset_every=args.reset_every)
    est = FusionEstimator(cfg)
    f_body = np.array([0.0, v * w, G])  # centripetal + gravity reaction, level robot
    gyro = np.array([0.0, 0.0, w])
    imu_t = -1.0

    def feed_until(t_end: float) -> None:
        nonlocal imu_t
        while imu_t <= t_end + 1e-9:
            moving = imu_t >= 0.0
            est.add_imu(imu_t,
                        (f_body if moving else np.array([0, 0, G])) + rng.normal(0, 0.02, 3),
                        (gyro if moving else np.zeros(3)) + rng.normal(0, 0.002, 3))
            imu_t = round(imu_t + 0.01, 6)

    feed_until(0.0)
    est.initialize(0.0, velocity=np.array([v, 0.0, 0.0]))
    deg = SimpleNamespace(basis_scaled=np.array([[1.0, 0, 0, 0, 0, 0]]), characteristic_length=10.0)
    times, errors, sizes = [], [], []
    t_start = time.perf_counter()
    for i in range(1, args.updates + 1):
        t = 0.1 * i
        feed_until(t + 0.02)
        T_true = truth(t, v, w)
        T_icp = T_true @ exp(np.concatenate([rng.normal(0, 0.01, 3), rng.normal(0, 0.001, 3)]))
        wheel = np.linalg.inv(truth(t - 0.1, v, w)) @ T_true @ exp(
            np.concatenate([rng.normal(0, 0.005, 3), rng.normal(0, 0.002, 3)]))
        degenerate = (i // 200) % 2 == 1
        if degenerate:  # the LiDAR slides along x: its x is garbage
            T_icp = T_icp @ exp(np.array([rng.normal(0, 0.5), 0, 0, 0, 0, 0]))
        t0 = time.perf_counter()
        out = est.update(t, T_icp, deg if degenerate else None, wheel_delta=wheel)
        times.append(time.perf_counter() - t0)
        sizes.append(est.graph_size)
        errors.append(float(np.linalg.norm(out.pose[:3, 3] - T_true[:3, 3])))
        if i % args.report_every == 0:
            chunk = np.array(times[-args.report_every:]) * 1e3
            print(f"updates {i:5d}: {np.mean(chunk):.2f} ms mean, {np.percentile(chunk, 99):.2f} ms "
                  f"p99, rss {rss_mb():.1f} MB, max factors {max(sizes[-args.report_every:])}, imu buffer "
                  f"{len(est.imu)}, position error {errors[-1]:.3f} m, "
                  f"sigma_x {math.sqrt(out.covariance[0, 0]):.3f} m")
    print(f"total {time.perf_counter() - t_start:.1f} s, resets {est.stats.n_resets}, "
          f"solver failures {est.stats.n_solver_failures}, mean position error "
          f"{np.mean(errors):.3f} m")


if __name__ == "__main__":
    main()
