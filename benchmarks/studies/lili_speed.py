#!/usr/bin/env python3
"""LiLi detection speed and detected subspace on odometry-sized inputs.

1. Simulates two 10 s pieces of tunnel trial 1 (64 x 512 beams): ``--degenerate-start`` (95 s,
   featureless stretch, translation along the tunnel is degenerate) and ``--entrance-start``
   (0 s, cluttered entrance, well constrained).
2. Drives ``OdometryPipeline`` (method ``none``) over each piece through the
   replay loop and records, every ``--every``-th scan, exactly what the pipeline hands a
   detector: the local map (its voxel map's points), the detection scan points, the guess and
   the ICP optimum.
3. Runs LiliDetector on every snapshot with each configuration (the map-derived cache is
   invalidated before every detection, as the odometry's map update does) and reports the
   detection time (mean, p95) and the detected subspace next to the paper settings' one.

The noise floor row reruns the paper settings with the ICP optimum moved by a random twist of
``--jitter`` (per component; default 1e-4, the odometry ICP's own convergence criterion): a
difference from the paper settings smaller than that one's is below what the detector can
resolve on these inputs.

Writes ``benchmarks/results/lili_speed.md`` and ``.json``.

Usage: ``python -m benchmarks.studies.lili_speed [--work-dir DIR] [--out DIR] [--every 10]``
"""
from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, ROOT
from lili_odom import geometry
from lili_odom.degeneracy.lili import LiliConfig, LiliDetector
from lili_odom.degeneracy.reference import ReferenceMap
from lili_odom.degeneracy.result import DegeneracyResult
from lili_odom.degeneracy.subspace import largest_principal_angle_deg

# name -> LiliConfig keyword overrides; "paper" is the reference (the shapes benchmark's).
CONFIGS = {
    "paper": {},
    "iterations 30": {"perturbation_iterations": 30},
    "points 300": {"perturbation_points": 300},
    "points 150": {"perturbation_points": 150},
    "one sign": {"both_signs": False},
}


class _Recorder:
    """Stands in for the detector: keeps the inputs of every ``every``-th detection."""

    name = "record"

    def __init__(self, every: int):
        self.every, self.calls, self.snapshots = every, 0, []

    def detect(self, reference, scan, initial_pose, optimized_pose=None):
        self.calls += 1
        if self.calls % self.every == 0:
            self.snapshots.append({
                "map": np.array(reference.points), "scan": np.array(scan),
                "guess": np.array(initial_pose), "pose": np.array(optimized_pose),
                "voxel": float(reference.voxel_size), "mppv": int(reference.max_points_per_voxel),
            })
        return DegeneracyResult("record", optimized_pose, np.zeros((0, 6)), 1.0)


def simulate(out: Path, start: float, duration: float, resolution: str) -> Path:
    if not out.exists():
        subprocess.run([sys.executable, "-c", "import sys; from lili_odom.cli import main; sys.exit(main())",
                        "simulate", "tunnel", "--trial", "1", "--start", str(start), "--duration",
                        str(duration), "--resolution", resolution, "--out", str(out), "--no-progress"],
                       check=True, cwd=ROOT)
    return out


def snapshots(bag: Path, every: int) -> list[dict]:
    from lili_odom.bagio.reader import BagReader
    from lili_odom.config import NodeConfig
    from lili_odom.evaluation.replay import Replay
    from lili_odom.pipeline.odometry import OdometryPipeline

    config = NodeConfig()
    config.pipeline.method = "none"
    config.validate()
    pipeline = OdometryPipeline(config.pipeline)
    recorder = _Recorder(every)
    pipeline._detector = recorder  # sees exactly the detector's inputs
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic, "/tf_static"]
    with BagReader(bag, topics=topics, required=[config.lidar_topic]) as reader:
        Replay(config, pipeline=pipeline).run(reader)
    return recorder.snapshots


def detect_all(snaps: list[dict], config: LiliConfig, jitter: float = 0.0, seed: int = 0):
    detector = LiliDetector(config)
    rng = np.random.default_rng(seed)
    rows = []
    for s in snaps:
        pose = s["pose"]
        if jitter:
            pose = pose @ geometry.exp(rng.normal(0.0, jitter, 6))
        s["reference"].invalidate()
        t0 = time.perf_counter()
        r = detector.detect(s["reference"], s["scan"], s["guess"], optimized_pose=pose)
        rows.append({"time_s": time.perf_counter() - t0, "result": r})
    return rows


def leading_angle_deg(a: DegeneracyResult, b: DegeneracyResult) -> float:
    """Smallest angle [deg] between a basis direction of ``a`` and the subspace of ``b``: 0 when
    ``b`` contains at least one of ``a``'s directions (e.g. the slide along the tunnel) whatever
    the other dimensions; 0 when both are empty, 90 when only one is."""
    if a.dimension == 0 or b.dimension == 0:
        return 0.0 if a.dimension == b.dimension else 90.0
    return float(min(largest_principal_angle_deg(row[None], b.basis_scaled) for row in a.basis_scaled))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work-dir", type=Path, default=None,
                        help="where the simulated pieces go (kept and reused; default: a temporary dir)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--every", type=int, default=10, help="snapshot every n-th detection")
    parser.add_argument("--resolution", default="64x512")
    parser.add_argument("--degenerate-start", type=float, default=95.0)
    parser.add_argument("--entrance-start", type=float, default=0.0)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--jitter", type=float, default=1e-4)
    args = parser.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        work = args.work_dir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        pieces = {
            "degenerate": args.degenerate_start,
            "entrance": args.entrance_start,
        }
        snaps = []
        for piece, start in pieces.items():
            bag = simulate(work / f"tunnel1_{start:g}s_{args.resolution}", start, args.duration,
                           args.resolution)
            for i, s in enumerate(snapshots(bag, args.every)):
                s["piece"], s["index"] = piece, i
                s["reference"] = ReferenceMap.from_points(s["map"], s["voxel"], s["mppv"], 1e4)
                snaps.append(s)
    print(f"{len(snaps)} snapshots: map {min(len(s['map']) for s in snaps)}-"
          f"{max(len(s['map']) for s in snaps)} points, scan {min(len(s['scan']) for s in snaps)}-"
          f"{max(len(s['scan']) for s in snaps)} points")

    runs = {name: detect_all(snaps, LiliConfig(**kw)) for name, kw in CONFIGS.items()}
    runs[f"paper, pose jitter {args.jitter:g}"] = detect_all(snaps, LiliConfig(), jitter=args.jitter)
    ref = runs["paper"]
    summary, per_snapshot = [], []
    for name, rows in runs.items():
        t = np.array([r["time_s"] for r in rows]) * 1e3
        entry = {"config": name, "overrides": CONFIGS.get(name, {"pose_jitter": args.jitter}),
                 "mean_ms": float(t.mean()), "p95_ms": float(np.percentile(t, 95))}
        for piece in pieces:
            idx = [i for i, s in enumerate(snaps) if s["piece"] == piece]
            dims = [rows[i]["result"].dimension for i in idx]
            same = [rows[i]["result"].dimension == ref[i]["result"].dimension for i in idx]
            angles = [largest_principal_angle_deg(rows[i]["result"].basis_scaled,
                                                  ref[i]["result"].basis_scaled) for i in idx]
            lead = [leading_angle_deg(ref[i]["result"], rows[i]["result"]) for i in idx]
            entry[piece] = {
                "dimensions": dims,
                "same_dimension": int(sum(same)),
                "snapshots": len(idx),
                "max_angle_same_dim_deg": float(max([a for a, ok in zip(angles, same) if ok] or [0.0])),
                "max_leading_direction_angle_deg": float(max(lead)),
            }
        summary.append(entry)
        for i, (s, r) in enumerate(zip(snaps, rows)):
            per_snapshot.append({"config": name, "piece": s["piece"], "index": s["index"],
                                 "map_points": len(s["map"]), "scan_points": len(s["scan"]),
                                 "time_ms": 1e3 * r["time_s"], "dimension": r["result"].dimension,
                                 "eigenvalues": np.round(r["result"].eigenvalues, 4).tolist(),
                                 "basis_scaled": np.round(r["result"].basis_scaled, 5).tolist()})

    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "lili_speed.json").write_text(json.dumps(
        {"summary": summary, "snapshots": per_snapshot}, indent=1) + "\n")
    md = ["# LiLi detection speed on odometry inputs", "",
          "Generated by `python -m benchmarks.studies.lili_speed`. Inputs: every "
          f"{args.every}th detection of `OdometryPipeline` over {args.duration:g} s of tunnel trial 1 "
          f"({args.resolution}); *degenerate* = from {args.degenerate_start:g} s (featureless), "
          f"*entrance* = from {args.entrance_start:g} s. Time: wall time of one `detect` call "
          "including the map spacing (re-measured each call, as after every odometry map update). "
          "dims: detected dimension per snapshot; same dim: snapshots whose dimension equals the "
          "paper settings'; angle: largest principal angle to the paper settings' subspace "
          "where the dimensions agree; lead: angle of the paper settings' best-matching basis "
          "direction to this subspace (the most robust, freely sliding direction).", "",
          "| config | mean [ms] | p95 [ms] | degenerate dims | same dim | angle [deg] | lead [deg] "
          "| entrance dims | same dim |",
          "|---|---|---|---|---|---|---|---|---|"]
    for e in summary:
        d, en = e["degenerate"], e["entrance"]
        md.append(f"| {e['config']} | {e['mean_ms']:.0f} | {e['p95_ms']:.0f} | "
                  f"{''.join(map(str, d['dimensions']))} | {d['same_dimension']}/{d['snapshots']} | "
                  f"{d['max_angle_same_dim_deg']:.1f} | {d['max_leading_direction_angle_deg']:.1f} | "
                  f"{''.join(map(str, en['dimensions']))} | {en['same_dimension']}/{en['snapshots']} |")
    md += ["", f"Machine: {platform.machine()}, {platform.python_version()}, "
           f"{len(snaps)} snapshots."]
    text = "\n".join(md) + "\n"
    (args.out / "lili_speed.md").write_text(text)
    print(text)
    print(f"wrote {args.out / 'lili_speed.md'}, {args.out / 'lili_speed.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
