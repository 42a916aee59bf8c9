"""What LiDAR+IMU odometry started while driving needs: the speed at the start.

    python -m benchmarks.studies.start_speed              # the four windows of moving_start
    python -m benchmarks.studies.start_speed --windows parking_lot:20

Without wheel odometry the fusion starts at zero velocity with a loose prior (an IMU cannot
tell driving from rest). For each window (a suite scenario cut to start while the robot
drives; 32x512, seed 0, 20 s, the wheel topic ignored) this runs `lili`:

* with the start speed search off (zero start velocity, loose prior), with the defaults
  (the search of :mod:`lili_odom.pipeline.start_speed`), and with the start velocity given:
  the truth's body velocity at the first scan scaled by each ``--scales`` factor, held by the
  estimator's tight velocity prior (``FusionEstimator.initialize(velocity=...)``,
  ``prior_sigma_velocity``); ATE after SE(3) alignment and end-point error [m];
* the point-to-plane cost of the first two sweeps over forward speeds 0-3 m/s (both deskewed
  with the speed, the second placed at the speed's travel and fitted to the first one's planes:
  ``fit_planes`` / ``plane_cost`` of :mod:`lili_odom.pipeline.plane_refinement`, the pipeline's
  voxelisation; the rotation over the sweeps from the gyro's mean rate), its minimum against
  the true speed, and what :func:`lili_odom.pipeline.start_speed.forward_speed` finds with
  its defaults.

Writes ``benchmarks/results/<name>.{md,json}`` (default ``start_speed``).
"""
from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, config_with, machine_info, write_results
from benchmarks._pieces import piece_bag
from lili_odom.pipeline.scan_matcher import ScanMatcher
from lili_odom.pipeline.plane_refinement import PlaneRefinementConfig
from lili_odom.pipeline.start_speed import StartSpeedConfig, forward_speed, speed_cost
from lili_odom.pipeline.start_sweeps import StartSweep

WINDOWS = ("building:30", "parking_lot:20", "airfield:30", "long_tunnel:30")
SPEEDS = np.round(np.arange(0.0, 3.0001, 0.1), 2)


def _run(bag: Path, out: Path, body_velocity: np.ndarray | None = None,
         search: bool = True) -> dict:
    """`lili` without wheels over ``bag``; the start velocity given in base_link when set,
    the start speed search (``pipeline.start_speed``) off unless ``search``. Returns the
    metrics, the counters, the truth and the first two scans."""
    from lili_odom.evaluation.runner import run_bag

    overrides = {"method": "lili", "start_speed.enabled": search}
    config = dataclasses.replace(config_with(overrides, prog="start_speed"),
                                 wheel_topic="/none")
    captured: dict = {"scans": []}

    import lili_odom.pipeline.odometry as odometry

    pipeline_cls = odometry.OdometryPipeline
    original_process = pipeline_cls.process_scan

    def process_scan(self, scan):
        if len(captured["scans"]) < 2:
            captured["scans"].append(scan)
            captured["matcher_config"] = self.config.scan_matcher
            captured["T_base_lidar"] = self.T_base_lidar
            if len(captured["scans"]) == 2:  # the gyro's mean rate over both sweeps, base_link
                first = captured["scans"][0]
                samples = self.estimator.imu.samples(first.stamp + float(first.times.min()),
                                                     scan.stamp + float(scan.times.max()))
                rate = np.mean([s.gyro for s in samples], axis=0) if samples else np.zeros(3)
                captured["rate"] = self.estimator.T_base_imu[:3, :3] @ rate
            if body_velocity is not None and not self.estimator.initialized:
                estimator = self.estimator
                original_init = estimator.initialize

                def initialize(t, pose=None, velocity=None):
                    out = original_init(t, pose=pose)
                    return original_init(t, pose=out.pose,
                                         velocity=out.pose[:3, :3] @ body_velocity)

                estimator.initialize = initialize
        return original_process(self, scan)

    pipeline_cls.process_scan = process_scan
    try:
        run = run_bag(bag, config, out, progress=False)
    finally:
        pipeline_cls.process_scan = original_process
    truth = np.loadtxt(out / "truth.tum", ndmin=2)
    return {"metrics": run.summary["metrics"], "counters": run.summary.get("counters", {}),
            "truth": truth, **captured}


def _body_velocity(truth: np.ndarray, stamp: float) -> np.ndarray:
    """Body-frame velocity [m/s] of the truth (TUM rows) around ``stamp``."""
    from scipy.spatial.transform import Rotation

    i = int(np.clip(np.searchsorted(truth[:, 0], stamp), 1, len(truth) - 1))
    a, b = truth[i - 1], truth[i]
    v = (b[1:4] - a[1:4]) / (b[0] - a[0])
    return Rotation.from_quat(a[4:8]).inv().apply(v)


def speed_costs(scans: list, matcher_config, T_base_lidar: np.ndarray, rate: np.ndarray,
                speeds: np.ndarray = SPEEDS) -> list[float]:
    """:func:`lili_odom.pipeline.start_speed.speed_cost` of the two scans per forward speed
    (base_link, with the angular ``rate`` [rad/s, base_link] of the gyro)."""
    first, second = (_sweep(s) for s in scans)
    matcher = ScanMatcher(matcher_config)
    return [speed_cost(first, second, float(v), rate, matcher, T_base_lidar,
                       PlaneRefinementConfig()) for v in speeds]


def _sweep(scan) -> StartSweep:
    return StartSweep(scan.points, scan.times, np.eye(4), np.eye(4),
                      scan.stamp + float(scan.times.min()), scan.stamp + float(scan.times.max()))


def study(scenario: str, start: float, scales: list[float], tmp: Path) -> dict:
    bag = piece_bag(scenario, start, 20.0, (32, 512), 0, progress=False)
    base = _run(bag, tmp / f"{scenario}_zero", search=False)
    first_stamp = base["scans"][0].stamp
    v_true = _body_velocity(base["truth"], first_stamp)
    rows = [{"start": "zero, loose (search off)", "ate_m": base["metrics"]["ate_rmse_m"],
             "final_m": base["metrics"]["final_error_m"]}]
    found = _run(bag, tmp / f"{scenario}_found")
    label = ("searched, found (default)" if found["counters"].get("start_speed_found")
             else "searched, not found (default)")
    rows.append({"start": label, "ate_m": found["metrics"]["ate_rmse_m"],
                 "final_m": found["metrics"]["final_error_m"]})
    print(f"  {scenario} {label}: ATE {rows[-1]['ate_m']:.3f} m", flush=True)
    for k in scales:
        r = _run(bag, tmp / f"{scenario}_{k:g}", body_velocity=k * v_true)
        rows.append({"start": f"{k:g} x truth", "ate_m": r["metrics"]["ate_rmse_m"],
                     "final_m": r["metrics"]["final_error_m"]})
        print(f"  {scenario} {k:g} x truth: ATE {rows[-1]['ate_m']:.3f} m", flush=True)
    costs = speed_costs(base["scans"], base["matcher_config"], base["T_base_lidar"],
                        base["rate"])
    searched = forward_speed(*(_sweep(s) for s in base["scans"]),
                             ScanMatcher(base["matcher_config"]), base["T_base_lidar"],
                             base["rate"], StartSpeedConfig())
    return {"window": f"{scenario} {start:g}-{start + 20:g} s", "true_speed": float(v_true[0]),
            "runs": rows, "speeds": SPEEDS.tolist(), "costs": costs,
            "cost_argmin": float(SPEEDS[int(np.argmin(costs))]),
            "searched_speed": searched.speed, "searched_rise": searched.rise}


def markdown(report: dict, command: str) -> str:
    lines = ["# The speed at a start while driving, without wheels", "",
             f"`{command}` (`benchmarks/studies/start_speed.py`): `lili` without wheel odometry "
             "over suite windows that start while the robot drives (32x512, seed 0, 20 s). "
             "Start velocity: zero with a loose prior (the start speed search off), the "
             "default (the speed searched from the first two sweeps, `pipeline.start_speed`), "
             "or the truth's body velocity at the first scan times a factor, held by the tight "
             "velocity prior. Speed from the "
             "LiDAR: the forward speed at which the first two sweeps, deskewed with it, fit "
             "each other's planes best (0-3 m/s in 0.1 m/s steps; rotation from the gyro).", "",
             f"Commit `{report['machine']['commit']}`.", "",
             "| window | true speed [m/s] | start velocity | ATE [m] | final [m] |",
             "|---|---:|---|---:|---:|"]
    for w in report["windows"]:
        for r in w["runs"]:
            lines.append(f"| {w['window']} | {w['true_speed']:.2f} | {r['start']} | "
                         f"{r['ate_m']:.3f} | {r['final_m']:.3f} |")
    lines += ["", "| window | true speed [m/s] | cost minimum, 0-3 m/s grid [m/s] | cost at 0 / "
              "minimum / at 3 m/s | `forward_speed` (defaults) [m/s] | its cost rise |",
              "|---|---:|---:|---|---:|---:|"]
    for w in report["windows"]:
        c = w["costs"]
        found = "not found" if w["searched_speed"] is None else f"{w['searched_speed']:.2f}"
        lines.append(f"| {w['window']} | {w['true_speed']:.2f} | {w['cost_argmin']:.1f} | "
                     f"{c[0]:.4f} / {min(c):.4f} / {c[-1]:.4f} | {found} | "
                     f"{w['searched_rise']:.3f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--windows", nargs="+", default=list(WINDOWS), metavar="SCENARIO:START",
                    help="suite windows (scenario and start [s]); default the four of "
                         "benchmarks.moving_start")
    ap.add_argument("--scales", nargs="+", type=float, default=[0.9, 1.0, 1.1],
                    help="factors on the true start velocity (default 0.9 1.0 1.1)")
    ap.add_argument("--out", default=RESULTS)
    ap.add_argument("--name", default="start_speed")
    args = ap.parse_args(argv)
    windows = []
    for text in args.windows:
        name, _, start = text.partition(":")
        try:
            windows.append((name, float(start or 0.0)))
        except ValueError:
            ap.error(f"--windows: {text!r} is not SCENARIO:START")
    report = {"machine": machine_info(), "windows": []}
    with tempfile.TemporaryDirectory() as tmp:
        for name, start in windows:
            print(f"{name} from {start:g} s", flush=True)
            report["windows"].append(study(name, start, args.scales, Path(tmp)))
    command = ("python -m benchmarks.studies.start_speed"
               + (f" --windows {' '.join(args.windows)}" if args.windows != list(WINDOWS) else "")
               + (f" --scales {' '.join(f'{s:g}' for s in args.scales)}"
                  if args.scales != [0.9, 1.0, 1.1] else "")
               + (f" --name {args.name}" if args.name != "start_speed" else ""))
    print(f"wrote {write_results(args.out, args.name, markdown(report, command), report)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
