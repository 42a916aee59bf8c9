"""How far the fused pose strays from the registration on a rough floor, per IMU model.

    python -m benchmarks.studies.imu_lever_arm                 # ramp_drift, 0-18 s, 32x512
    python -m benchmarks.studies.imu_lever_arm --scenario mine --duration 20

Runs ``none`` (no detector, so every registration is fully trusted) over a window of a suite
scenario (simulated with the suite's scenario code, see :mod:`benchmarks._pieces`) once per
setting and compares, scan by scan, against the simulator's truth of ``base_link``:

* the raw registration (``OdometryOutput.icp_pose``) and the fused pose, each aligned to the
  truth in SE(3), as RMS errors along the truth's forward, lateral and up axes [m];
* where the fused pose is farther from the truth than the registrations it was given, the
  IMU's preintegrated motion pulled it away from them.

Settings: ``euler`` (the defaults: the lever arm's angular-acceleration term removed,
:func:`lili_odom.fusion.imu.euler_correction`), ``gtsam_only`` (GTSAM's own lever-arm
correction, centripetal term only) and ``no_imu`` (the fallback motion model instead of the
IMU). Writes ``benchmarks/results/imu_lever_arm.{md,json}``.
"""
from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from benchmarks._common import RESULTS, config_with, machine_info, write_results
from benchmarks._pieces import (add_window_arguments, format_resolution, window_bag,
                                window_command)

#: Settings compared (overrides below ``pipeline.``).
SETTINGS = {
    "euler": {},
    "gtsam_only": {"fusion.imu.compensate_angular_acceleration": False},
    "no_imu": {"fusion.use_imu": False},
}


def run_setting(job: tuple) -> dict:
    """Run ``none`` over the bag with one setting; (stamp, fused, registration) base poses and
    the truth."""
    bag, overrides = job
    from lili_odom.bagio.reader import BagReader
    from lili_odom.evaluation.replay import Replay

    config = config_with({"method": "none", **overrides}, prog="imu_lever_arm")
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic,
              config.ground_truth_topic, "/tf_static"]
    outs: list[tuple[float, np.ndarray, np.ndarray]] = []

    def record(out, _pipeline) -> None:
        if out.icp_pose is not None:
            outs.append((out.stamp, out.pose, out.icp_pose))

    with BagReader(bag, topics=topics, required=[config.lidar_topic]) as reader:
        replay = Replay(config, on_output=record).run(reader)
    return {"outs": outs, "truth": replay.truth}


def body_rms(stamps: np.ndarray, poses: np.ndarray, truth: list) -> list[float]:
    """RMS position error [m] along the truth's forward, lateral and up axes after an SE(3)
    alignment of ``poses`` (n, 4, 4) at ``stamps`` to the truth (as for the ATE)."""
    from lili_odom.evaluation.metrics import body_frame_errors

    err = body_frame_errors(stamps, poses, np.array([s for s, _ in truth]),
                            np.array([T for _, T in truth]))
    return np.sqrt((err ** 2).mean(axis=0)).tolist()


def summarise(result: dict) -> dict:
    stamps = np.array([s for s, _, _ in result["outs"]])
    fused = np.array([P for _, P, _ in result["outs"]])
    icp = np.array([P for _, _, P in result["outs"]])
    return {"scans": len(stamps),
            "fused_rms_m": body_rms(stamps, fused, result["truth"]),
            "registration_rms_m": body_rms(stamps, icp, result["truth"])}


def markdown(report: dict, command: str) -> str:
    p = report["piece"]
    lines = [
        "# IMU lever arm: fused pose against its registrations on a rough floor", "",
        f"`{command}`: `none` over `{p['scenario']}` (seed {p['seed']}) from {p['start_s']:g} s "
        f"for {p['duration_s']:g} s at {p['resolution']}, once per IMU model. RMS position error "
        "[m] along the true forward / lateral / up axes after an SE(3) alignment to the truth, "
        "for the fused pose and for the raw registration it was given "
        "(`benchmarks/studies/imu_lever_arm.py`).", "",
        f"Commit `{report['machine']['commit']}`.", "",
        "| setting | scans | fused fwd | fused lat | fused up | registration fwd | "
        "registration lat | registration up |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, row in report["settings"].items():
        f, r = row["fused_rms_m"], row["registration_rms_m"]
        lines.append(f"| `{name}` | {row['scans']} | " + " | ".join(f"{v:.3f}" for v in f)
                     + " | " + " | ".join(f"{v:.3f}" for v in r) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_window_arguments(ap, "ramp_drift", 18.0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=RESULTS)
    args = ap.parse_args(argv)
    _, res, bag = window_bag(ap, args)
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        results = list(pool.map(run_setting, [(bag, o) for o in SETTINGS.values()]))
    report = {"piece": {"scenario": args.scenario, "start_s": args.start,
                        "duration_s": args.duration, "seed": args.seed,
                        "resolution": format_resolution(res)},
              "machine": machine_info(),
              "settings": {n: summarise(r) for n, r in zip(SETTINGS, results)}}
    command = window_command("benchmarks.studies.imu_lever_arm", args, "ramp_drift", 18.0)
    print(f"wrote {write_results(args.out, 'imu_lever_arm', markdown(report, command), report)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
