"""The odometry on the real OS1-128 recording of the Ouster SDK's tests, against its poses.

Runs ``lili-odom run`` on ``../shared/data/ouster/OS-1-128_v2.3.0_1024x10_lb_n3.pcap`` (3
frames, about 0.25 m apart; ``LILI_ODOM_SHARED`` names another shared folder) with the default
configuration and with ``pipeline.scan_matcher.deskew: false``, and compares every estimated
pose (``base_link`` = ``os_sensor``) with the SDK's reference poses (KITTI file, sensor frame,
frame 0 = identity): translation error per frame [m], each frame's step length [m] and the
detected dimension. Needs the Ouster SDK.

Writes ``benchmarks/results/ouster_recording.json`` and ``.md``.

    python -m benchmarks.ouster_recording
"""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SHARED = Path(os.environ.get("LILI_ODOM_SHARED", ROOT.parent / "shared"))
DATA = SHARED / "data" / "ouster"
PCAP = DATA / "OS-1-128_v2.3.0_1024x10_lb_n3.pcap"
META = DATA / "OS-1-128_v2.3.0_1024x10.json"
POSES = DATA / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt"
VARIANTS = {"default": "", "no_deskew": "    pipeline:\n      scan_matcher:\n        deskew: false\n"}


def reference() -> np.ndarray:
    rows = np.loadtxt(POSES).reshape(-1, 3, 4)
    return rows[:, :, 3]


def run_variant(name: str, extra: str, tmp: Path) -> dict:
    cfg = tmp / f"{name}.yaml"
    cfg.write_text("lili_odom:\n  ros__parameters:\n" + (extra or "    {}\n"))
    out = tmp / name
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "lili_odom.cli", "run", str(PCAP), "--metadata",
                           str(META), "--out", str(out), "--no-progress", "--config", str(cfg)],
                          capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        return {"variant": name, "error": proc.stderr.strip()[-400:]}
    est = np.loadtxt(out / "estimate.tum", ndmin=2)[:, 1:4]
    ref = reference()[: len(est)]
    with open(out / "scans.csv") as f:
        dims = [int(r["dimension"]) for r in csv.DictReader(f)]
    est_steps = np.linalg.norm(np.diff(est, axis=0), axis=1)
    ref_steps = np.linalg.norm(np.diff(ref, axis=0), axis=1)
    return {"variant": name, "frames": len(est),
            "error_m": np.round(np.linalg.norm(est - ref, axis=1), 4).tolist(),
            "step_m": np.round(est_steps, 4).tolist(),
            "reference_step_m": np.round(ref_steps, 4).tolist(), "dimensions": dims}


def main() -> int:
    if not PCAP.is_file():
        print(f"no recording at {PCAP}", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        rows = [run_variant(n, e, Path(tmp)) for n, e in VARIANTS.items()]
    doc = {"recording": PCAP.name, "rows": rows}
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "ouster_recording.json").write_text(json.dumps(doc, indent=1) + "\n")
    lines = ["# Odometry on the real OS1-128 recording", "",
             f"`python -m benchmarks.ouster_recording`: `{PCAP.name}` (3 frames), estimated "
             "positions against the Ouster SDK's reference poses.", "",
             "| variant | error per frame [m] | step [m] | reference step [m] | dimension |",
             "|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['variant']} | error: {r['error'][:80]} | | | |")
        else:
            lines.append(f"| {r['variant']} | {r['error_m']} | {r['step_m']} | "
                         f"{r['reference_step_m']} | {r['dimensions']} |")
    (RESULTS / "ouster_recording.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
