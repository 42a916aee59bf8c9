"""Does the fused IMU state agree with the fused poses and with the simulator's truth?

    python -m benchmarks.studies.imu_consistency                      # Trial 1, 64x512, first 200 s
    python -m benchmarks.studies.imu_consistency --set fusion.lidar.factor=prior
    python -m benchmarks.studies.imu_consistency --trial 2 --duration 240 --set fusion.lidar.factor=hybrid \
        --set remap_iterations=10 --name imu_consistency_t2_hybrid

Runs the odometry (``lili`` unless ``--method``) over simulated Trial 1 and samples, every
``--every`` seconds: the fused velocity state of base_link in base_link axes [m/s], the
velocity implied by the fused poses (their displacement over the last second, same axes), and
the estimated accelerometer bias against the simulator's true bias (os_imu axes [m/s^2]; the
simulator regenerates its IMU noise from the seed, so the truth is exact), and the online
wheel distance scale (``fusion.wheel_scale``) against the simulator's (from the bag's sidecar). In a consistent
estimate the two velocities agree to within noise and the bias converges towards the truth;
a persistent difference means the IMU factor is being overruled, (docs/design/fusion.md,
known modelling gaps).
Writes ``benchmarks/results/imu_consistency.{md,json}`` (``--name`` changes the file name).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from benchmarks._common import RESULTS, SET_HELP, SIM_CACHE, apply_set, parse_set
from lili_odom.bagio.reader import BagReader
from lili_odom.config import NodeConfig
from lili_odom.evaluation.replay import Replay
from lili_odom.sim.generator import SimRequest, Simulation, ensure_trial_bag
from lili_odom.sim.imu import simulate_imu


def true_accel_bias(resolution: tuple[int, int], seed: int, trial: int = 1
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(times from the trial start [s], true accelerometer bias (N, 3) in os_imu [m/s^2])."""
    sim = Simulation(SimRequest(world="tunnel", trial=trial, seed=seed, resolution=resolution))
    imu = simulate_imu(sim.trajectory, sim.sensors.extrinsics.base_to_imu, sim.sensors.imu, seed)
    return imu.t, imu.accel_bias


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=200.0, help="seconds of the trial (default 200)")
    ap.add_argument("--every", type=float, default=20.0, help="sampling period [s] (default 20)")
    ap.add_argument("--resolution", default="64x512")
    ap.add_argument("--trial", type=int, default=1, choices=[1, 2])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--method", default="lili", choices=["none", "zhang", "hessian", "lili"])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help=SET_HELP)
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--name", default="imu_consistency")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)

    rows, cols = (int(v) for v in args.resolution.lower().split("x"))
    bag = ensure_trial_bag(args.trial, SIM_CACHE, resolution=(rows, cols), seed=args.seed,
                           progress=not args.no_progress)
    cfg = NodeConfig()
    overrides = {"method": args.method}
    overrides.update(parse_set(args.set, "imu_consistency"))
    apply_set(cfg, overrides, "imu_consistency")

    samples: list[tuple[float, np.ndarray, np.ndarray]] = []  # (stamp, pose, fused velocity)
    biases: list[np.ndarray] = []
    scales: list[float] = []
    topics = [cfg.lidar_topic, cfg.imu_topic, cfg.wheel_topic, "/tf_static"]
    t_bag0 = None
    bar = tqdm(total=args.duration, unit="s", disable=args.no_progress, desc="odometry")

    def on_output(out, pipe) -> None:
        fused = pipe.estimator.last_output
        if fused is None:
            return
        samples.append((out.stamp, out.pose, fused.velocity.copy()))
        biases.append(fused.accel_bias.copy())
        scales.append(float(out.details.get("wheel_scale", float("nan"))))
        bar.update(max(0.0, out.stamp - t_bag0 - bar.n))

    def first_seconds(items):
        nonlocal t_bag0
        for item in items:
            t_bag0 = item.stamp if t_bag0 is None else t_bag0
            if item.stamp - t_bag0 > args.duration:
                return
            yield item

    with BagReader(bag, topics=topics, required=[cfg.lidar_topic]) as reader:
        Replay(cfg, on_output=on_output).run(first_seconds(reader), flush=False)
    bar.close()
    if len(samples) < 20:
        print("imu_consistency: fewer than 20 fused scans; nothing to report", file=sys.stderr)
        return 1

    t_true, b_true = true_accel_bias((rows, cols), args.seed, args.trial)
    try:
        true_scale = float(json.loads(Path(str(bag) + ".json").read_text())["wheel_scale"])
    except (OSError, KeyError, ValueError):
        true_scale = float("nan")
    stamps = np.array([s for s, _, _ in samples])
    trial_t0 = t_bag0  # the full trial's bag starts at trial time 0
    table = []
    for target in np.arange(args.every, stamps[-1] - stamps[0] + 1e-9, args.every):
        k = int(np.searchsorted(stamps - stamps[0], target))
        k = min(k, len(samples) - 1)
        j = int(np.searchsorted(stamps, stamps[k] - 1.0))
        t_k, T_k, v_k = samples[k]
        t_j, T_j, _ = samples[j]
        R = T_k[:3, :3]
        v_state = R.T @ v_k
        v_poses = R.T @ (T_k[:3, 3] - T_j[:3, 3]) / max(t_k - t_j, 1e-6)
        i = int(np.argmin(np.abs(t_true - (t_k - trial_t0))))
        table.append({"t": float(t_k - stamps[0]), "v_state": v_state.tolist(),
                      "v_poses": v_poses.tolist(), "accel_bias": biases[k].tolist(),
                      "accel_bias_true": b_true[i].tolist(), "wheel_scale": scales[k]})

    args.out.mkdir(parents=True, exist_ok=True)
    command = "python -m benchmarks.studies.imu_consistency" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:]))
    lines = [
        "# Fused IMU state against the fused poses and the simulator's truth", "",
        f"`{command}`: simulated Trial {args.trial} ({args.resolution}, seed {args.seed}), method "
        f"`{args.method}`, first {args.duration:.0f} s. Velocities of base_link in base_link "
        "axes (x forward, y left) [m/s]: the fused state, and the fused poses' displacement over "
        "the last second. Accelerometer bias in os_imu axes [m/s^2]: estimated and true. Wheel "
        f"distance scale: estimated (the simulator's: {true_scale:.4f}).", "",
        "| t [s] | v state x / y | v from poses x / y | y difference | accel bias x / y | true bias x / y | wheel scale |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in table:
        vs, vp, b, bt = r["v_state"], r["v_poses"], r["accel_bias"], r["accel_bias_true"]
        lines.append(f"| {r['t']:.0f} | {vs[0]:+.3f} / {vs[1]:+.3f} | {vp[0]:+.3f} / {vp[1]:+.3f} "
                     f"| {vs[1] - vp[1]:+.3f} | {b[0]:+.3f} / {b[1]:+.3f} | {bt[0]:+.3f} / {bt[1]:+.3f} "
                     f"| {r['wheel_scale']:.4f} |")
    dy = np.array([r["v_state"][1] - r["v_poses"][1] for r in table])
    eb = np.array([np.subtract(r["accel_bias"], r["accel_bias_true"])[:2] for r in table])
    lines += ["", f"Lateral velocity difference (state - poses): mean {dy.mean():+.3f}, "
              f"RMS {np.sqrt((dy ** 2).mean()):.3f} m/s. Accelerometer bias error x / y: RMS "
              f"{np.sqrt((eb[:, 0] ** 2).mean()):.3f} / {np.sqrt((eb[:, 1] ** 2).mean()):.3f} m/s^2."]
    (args.out / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    (args.out / f"{args.name}.json").write_text(json.dumps(
        {"command": command, "rows": table, "lateral_velocity_difference_mean": float(dy.mean()),
         "lateral_velocity_difference_rms": float(np.sqrt((dy ** 2).mean()))}, indent=1))
    print(f"wrote {args.out / (args.name + '.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
