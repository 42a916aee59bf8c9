"""How far the fused motion along a degenerate axis strays from the wheels, per LiDAR factor setup.

    python -m benchmarks.studies.along_axis_jitter                       # Trial 1 seed 2, 140-175 s
    python -m benchmarks.studies.along_axis_jitter --seed 0 --start 100 --duration 40

Inside a detected degenerate subspace the wheels (scale-calibrated) are the only sensor meant
to decide the motion along it. This runs ``lili`` on a window of a simulated trial once per
setting (``--set NAME=key:value,...``, keys below ``pipeline.``) and compares, scan by scan, the
fused pose increment along the robot's forward axis (as published, in the body frame of the
previous output) with the wheel increment over the same interval divided by the wheel scale in
use, and both with the truth:

* ``std(fused - wheel)`` per scan [cm] on scans flagged degenerate: how much the other
  factors move the position along the axis against the wheels;
* the same summed over ``--window-m`` of travel (worst and RMS) [m]: whether that motion
  averages out or builds up;
* ``fused - truth`` and ``wheel - truth`` summed over the window: the along-axis error each
  would give (the wheel part is the calibration's).

The window starts mid-run, so the wheel scale calibration has not seen the entrance: compare
settings against each other, not against full-run figures. Writes
``benchmarks/results/along_axis_jitter.{md,json}``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, config_with


#: The settings compared by default (overrides below ``pipeline.``).
DEFAULT_SETTINGS = {
    "defaults": {},
    "no_anchor": {"fusion.lidar.anchor_sigma": 0.0},
    "marginalized_wheels": {"fusion.wheel_restriction": "same", "fusion.lidar.anchor_sigma": 0.0},
    "marginalized_wheels_anchor": {"fusion.wheel_restriction": "same"},
    "projected_wheels": {"fusion.wheel_restriction": "project", "fusion.lidar.anchor_sigma": 0.0},
    "between_factor": {"fusion.lidar.factor": "between"},
}


def _parse_setting(text: str) -> tuple[str, dict[str, str]]:
    name, _, body = text.partition("=")
    pairs = [p for p in body.split(",") if p.strip()]
    return name.strip(), {k.strip(): v.strip() for k, v in (p.split(":", 1) for p in pairs)}


def run_window(job: tuple) -> dict:
    """Run one setting over the window; returns per-scan along-axis increments."""
    bag, start, duration, overrides = job
    from lili_odom.bagio.reader import BagReader
    from lili_odom.evaluation.replay import Replay

    config = config_with(overrides, prog="along_axis_jitter")
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic,
              config.ground_truth_topic, "/tf_static"]
    outs: list[tuple[float, np.ndarray, int, float]] = []
    wheel: list[tuple[float, float]] = []

    def record(out, _pipeline) -> None:
        dim = out.degeneracy.dimension if out.degeneracy is not None else 0
        outs.append((out.stamp, out.pose, dim, float(out.details.get("wheel_scale", 1.0))))

    def window(items):
        t0 = None
        for item in items:
            t0 = item.stamp if t0 is None else t0
            if item.stamp - t0 < start:
                continue
            if item.stamp - t0 > start + duration:
                return
            if item.topic == config.wheel_topic:
                wheel.append((item.stamp, float(item.msg.twist.twist.linear.x)))
            yield item

    with BagReader(bag, topics=topics, required=[config.lidar_topic]) as reader:
        replay = Replay(config, on_output=record).run(window(reader))
    return along_increments(outs, replay.truth, np.asarray(wheel))


def along_increments(outs, truth, wheel: np.ndarray) -> dict:
    """Per scan pair: forward increments [m] of the fused output, the truth and the wheels."""
    ts = np.array([s for s, _ in truth])
    poses = [T for _, T in truth]

    def truth_at(t: float) -> np.ndarray:
        k = int(np.clip(np.searchsorted(ts, t), 1, len(ts) - 1))
        return poses[k] if abs(ts[k] - t) < abs(ts[k - 1] - t) else poses[k - 1]

    rows = []
    for (sa, Pa, _, _), (sb, Pb, dim, scale) in zip(outs, outs[1:]):
        m = (wheel[:, 0] > sa) & (wheel[:, 0] <= sb)
        if not m.any():
            continue
        Ta, Tb = truth_at(sa), truth_at(sb)
        fused = float((Pa[:3, :3].T @ (Pb[:3, 3] - Pa[:3, 3]))[0])
        true = float((Ta[:3, :3].T @ (Tb[:3, 3] - Ta[:3, 3]))[0])
        wheels = float(wheel[m, 1].mean() * (sb - sa) / scale)
        rows.append((sb, true, fused, wheels, dim))
    return {"rows": rows}


def summarise(rows: list, window_m: float, skip: int) -> dict:
    R = np.asarray(rows, dtype=float)[skip:]
    deg = R[R[:, 4] > 0]
    per_scan = deg[:, 2] - deg[:, 3]
    travel = np.cumsum(deg[:, 1])
    edges = np.searchsorted(travel, np.arange(0.0, travel[-1], window_m))
    sums = [(deg[a:b, 2] - deg[a:b, 3]).sum() for a, b in zip(edges[:-1], edges[1:])]
    return {
        "degenerate_scans": int(len(deg)), "scans": int(len(R)),
        "travel_m": float(travel[-1]),
        "per_scan_std_cm": float(100 * per_scan.std()),
        "window_rms_m": float(math.sqrt(np.mean(np.square(sums)))) if sums else float("nan"),
        "window_worst_m": float(np.max(np.abs(sums))) if sums else float("nan"),
        "fused_minus_truth_m": float((deg[:, 2] - deg[:, 1]).sum()),
        "wheel_minus_truth_m": float((deg[:, 3] - deg[:, 1]).sum()),
    }


def render(data: dict) -> str:
    a = data["args"]
    L = ["# Along-axis motion against the wheels",
         "",
         f"`python -m benchmarks.studies.along_axis_jitter --trial {a['trial']} --seed {a['seed']} "
         f"--resolution {a['resolution']} --start {a['start']:g} --duration {a['duration']:g}`: "
         "`lili` on that window, once per setting; per degenerate scan, the fused forward "
         "increment minus the calibrated wheel increment (see the script's docstring). The "
         f"first {a['skip']} scans (start-up) are left out.",
         "",
         f"| setting | overrides | degenerate scans | per scan std [cm] | per {a['window_m']:g} m RMS "
         f"[m] | per {a['window_m']:g} m worst [m] | fused - truth [m] | wheel - truth [m] |",
         "|---|---|---|---|---|---|---|---|"]
    for name, r in data["settings"].items():
        s = r["summary"]
        ov = ", ".join(f"{k}={v}" for k, v in r["overrides"].items()) or "(defaults)"
        L.append(f"| {name} | {ov} | {s['degenerate_scans']}/{s['scans']} | "
                 f"{s['per_scan_std_cm']:.2f} | {s['window_rms_m']:.3f} | "
                 f"{s['window_worst_m']:.3f} | {s['fused_minus_truth_m']:+.3f} | "
                 f"{s['wheel_minus_truth_m']:+.3f} |")
    return "\n".join(L) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trial", type=int, default=1)
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--resolution", default="64x512")
    ap.add_argument("--start", type=float, default=140.0, help="window start in the trial [s]")
    ap.add_argument("--duration", type=float, default=35.0, help="window length [s]")
    ap.add_argument("--window-m", type=float, default=5.0, help="travel per summed window [m]")
    ap.add_argument("--skip", type=int, default=50, help="start-up scans left out")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=key:value,...",
                    help="a setting to compare (repeatable); default: the built-in list")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS / "along_axis_jitter")
    args = ap.parse_args(argv)

    from lili_odom.sim.generator import ensure_trial_bag

    settings = dict(_parse_setting(s) for s in args.set) if args.set else DEFAULT_SETTINGS
    bag = ensure_trial_bag(args.trial, resolution=args.resolution, seed=args.seed)
    jobs = [(bag, args.start, args.duration, ov) for ov in settings.values()]
    print(f"{len(jobs)} settings on {bag.name}, {args.start:g}-{args.start + args.duration:g} s",
          flush=True)
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(run_window, jobs))
    data = {"args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                     if k not in ("set", "out")},
            "bag": bag.name, "settings": {}}
    for (name, ov), res in zip(settings.items(), results):
        s = summarise(res["rows"], args.window_m, args.skip)
        data["settings"][name] = {"overrides": ov, "summary": s}
        print(f"{name:22s} per scan {s['per_scan_std_cm']:.2f} cm, per {args.window_m:g} m RMS "
              f"{s['window_rms_m']:.3f} m", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(data, indent=1, default=str) + "\n")
    args.out.with_suffix(".md").write_text(render(data))
    print(f"wrote {args.out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
