"""Speed of the tunnel simulator: full-resolution (128 x 1024) OS1 scans per second.

Measures
  1. the sensor model alone (trajectory poses per column + Embree ray casting + return model),
  2. the whole bag pipeline (scans + IMU/wheels/truth + CDR serialisation + zstd mcap writing)
     with 1 and 2 ray-casting processes,
at the cluttered entrance and inside the tunnel, and writes ``benchmarks/results/sim_speed.md``.

    python -m benchmarks.sim_speed [--scans 100] [--resolution 128x1024]

Real time is 10 scans/s (the OS1 spins at 10 Hz). The machine's load average is recorded with
the figures because the benchmark machine may be shared.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import RESULTS
from lili_odom.sim.generator import SimRequest, Simulation, default_cache_dir, simulate_bag
from lili_odom.sim.sensors import parse_resolution

PLACES = {"entrance (outside, t = 0-10 s)": 0.0, "inside the tunnel (t = 80-90 s)": 80.0}


def sensor_only(res, start: float, n: int) -> float:
    sim = Simulation(SimRequest(trial=1, resolution=res))
    sim.scan(start)  # build the scene outside the timing
    t0 = time.perf_counter()
    for k in range(n):
        sim.scan(start + 0.1 * k)
    return n / (time.perf_counter() - t0)


def whole_bag(res, start: float, n: int, jobs: int) -> tuple[float, float, int]:
    tmp = Path(tempfile.mkdtemp(prefix="sim_speed_"))
    try:
        t0 = time.perf_counter()
        s = simulate_bag(SimRequest(trial=1, resolution=res, start=start, duration=0.1 * n + 1e-6),
                         tmp / "bag", progress=False, jobs=jobs)
        wall = time.perf_counter() - t0
        size = sum(f.stat().st_size for f in (tmp / "bag").iterdir())
        return s.scans / wall, wall, size // max(s.scans, 1)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=100)
    ap.add_argument("--resolution", default="128x1024")
    ap.add_argument("--out", type=Path, default=RESULTS / "sim_speed.md")
    args = ap.parse_args(argv)
    res = parse_resolution(args.resolution)
    rows = []
    load0 = os.getloadavg()
    for name, start in PLACES.items():
        so = sensor_only(res, start, args.scans)
        b1 = whole_bag(res, start, args.scans, 1)
        b2 = whole_bag(res, start, args.scans, 2)
        rows.append((name, so, b1, b2))
        print(f"{name}: sensor {so:.1f} scans/s, bag jobs=1 {b1[0]:.1f}, jobs=2 {b2[0]:.1f} scans/s, "
              f"{b1[2] / 1e6:.2f} MB/scan", flush=True)
    load1 = os.getloadavg()
    lines = [
        "# Simulator speed",
        "",
        f"`python -m benchmarks.sim_speed --scans {args.scans} --resolution {args.resolution}` "
        f"({res[0]} x {res[1]} OS1 scans, {args.scans} scans per cell; real time = 10 scans/s).",
        "",
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
        f"load average {load0[0]:.1f} before and {load1[0]:.1f} after (a shared machine lowers the figures).",
        "",
        "| where | sensor model only [scans/s] | whole bag, 1 process [scans/s] | whole bag, 2 processes [scans/s] | bag size [MB/scan] |",
        "|---|---|---|---|---|",
    ]
    for name, so, b1, b2 in rows:
        lines.append(f"| {name} | {so:.1f} | {b1[0]:.1f} | {b2[0]:.1f} | {b1[2] / 1e6:.2f} |")
    full = sorted(default_cache_dir().glob("tunnel_trial1_128x1024_seed0_*.json"))
    if full:
        side = json.loads(full[-1].read_text())
        n = side["counts"]["/ouster/points"]
        lines += [
            "",
            f"Full trial 1 (`lili-odom simulate tunnel --trial 1`, 2 processes, cached bag of {side['code_version']}): "
            f"{n} scans ({side['window_s'][1]:.0f} s of data) in {side['wall_time_s']:.0f} s = "
            f"{n / side['wall_time_s']:.1f} scans/s ({side['window_s'][1] / side['wall_time_s']:.2f} x real time).",
        ]
    lines += [
        "",
        "Sensor model = poses of the 1024 columns, Embree ray casting of all beams, the return model.",
        "Whole bag = that plus IMU / wheel / truth messages, CDR serialisation and zstd (level 2)",
        "chunk compression in the rosbag2 MCAP writer, including start-up (mesh build, process spawn).",
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
