"""``lili-odom run BAG``: offline odometry over a bag, the node's pipeline as fast as possible.

Writes into ``--out DIR``: ``odometry/`` (rosbag2 mcap: odometry, path, degeneracy markers and
JSON basis, /tf, a final map), ``estimate.tum`` and (when the bag has truth) ``truth.tum``,
``metrics.json`` (ATE/RPE via evo, counters, timings, degeneracy statistics) and
``trajectory.png`` (top view).
"""
from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import numpy as np

from lili_odom.errors import UserError

help = "run the odometry over a rosbag2 bag offline and write outputs, TUM files and metrics"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory or .mcap file")
    parser.add_argument("--method", choices=("lili", "zhang", "hessian", "none"), default=None,
                        help="degeneracy detector (default: the config's, lili)")
    parser.add_argument("--out", required=True, type=Path, help="output directory")
    parser.add_argument("--config", type=Path, help="ROS 2 parameter file (default: built-in)")
    parser.add_argument("--max-scans", type=int, default=0, help="stop after N scans (0 = all)")
    parser.add_argument("--rpe-segment", type=float, default=100.0, help="RPE path segment [m]")
    parser.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    from lili_odom.bagio.reader import BagReader
    from lili_odom.bagio.tum import write_tum
    from lili_odom.bagio.writer import OutputBagWriter
    from lili_odom.config import load_config
    from lili_odom.messages import odometry_pose_from_msg
    from lili_odom.pipeline.feeder import MessageFeeder
    from lili_odom.pipeline.odometry import OdometryPipeline

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        config = load_config(args.config)
        if args.method:
            config.pipeline.method = args.method
        config.validate()
    except (ValueError, OSError) as exc:
        raise UserError(f"configuration: {exc}") from None
    out_dir: Path = args.out
    if (out_dir / "odometry").exists():
        raise UserError(f"{out_dir}: already holds a run (odometry/ exists); choose another --out")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{out_dir}: cannot create the output directory: "
                        f"{exc.strerror or exc}") from None

    pipeline = OdometryPipeline(config.pipeline)
    feeder = MessageFeeder(pipeline, config)
    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic, config.ground_truth_topic,
              "/tf_static"]
    estimates: list[tuple[float, np.ndarray]] = []
    truth: list[tuple[float, np.ndarray]] = []
    dims: list[int] = []
    timings: dict[str, list[float]] = {}
    t_wall = time.perf_counter()
    with BagReader(args.bag, topics=topics, required=[config.lidar_topic]) as reader, \
            OutputBagWriter(out_dir / "odometry", odom_frame=config.odom_frame,
                            base_frame=config.base_frame) as writer:
        progress = _progress(reader.message_count, args.no_progress)
        scans = 0

        def record(out) -> None:
            estimates.append((out.stamp, out.pose))
            dims.append(out.degeneracy.dimension if out.degeneracy is not None else 0)
            for k, v in out.timings.items():
                timings.setdefault(k, []).append(v)
            writer.write_output(out)

        for item in reader:
            progress.advance()
            if item.topic == config.ground_truth_topic:
                try:
                    stamp, T_truth = odometry_pose_from_msg(item.msg)
                except (AttributeError, TypeError, ValueError):
                    continue
                if np.isfinite(stamp) and np.all(np.isfinite(T_truth)):
                    truth.append((stamp, T_truth))
                continue
            done = bool(args.max_scans) and scans >= args.max_scans
            if item.topic == config.lidar_topic:
                if done:  # keep feeding IMU/wheels until the last scan has its data
                    continue
                scans += 1
            for out in feeder.feed(item.topic, item.msg):
                record(out)
            if done and not feeder.pending:
                break
        for out in feeder.flush():
            record(out)
        progress.close()
        if estimates:
            writer.write_map(pipeline.local_map_points(), estimates[-1][0])
    wall = time.perf_counter() - t_wall
    if not estimates:
        raise UserError(f"{args.bag}: no scan could be processed ({dict(pipeline.counters)})")

    write_tum(out_dir / "estimate.tum", estimates)
    result: dict = {
        "bag": str(args.bag),
        "method": config.pipeline.method,
        "scans_processed": len(estimates),
        "wall_time_s": wall,
        "scans_per_second": len(estimates) / wall if wall > 0 else float("nan"),
        "degenerate_fraction": float(np.mean(np.asarray(dims) > 0)),
        "mean_dimension": float(np.mean(dims)),
        "timings_mean_s": {k: float(np.mean(v)) for k, v in timings.items()},
        "counters": dict(pipeline.counters),
    }
    truth_xyz = None
    if truth:
        write_tum(out_dir / "truth.tum", truth)
        from lili_odom.evaluation.metrics import evaluate

        truth.sort(key=lambda x: x[0])
        m = evaluate(np.array([s for s, _ in estimates]), np.array([T for _, T in estimates]),
                     np.array([s for s, _ in truth]), np.array([T for _, T in truth]),
                     segment_m=args.rpe_segment)
        result["metrics"] = m.to_dict()
        truth_xyz = _aligned_truth_xyz(estimates, truth)
    (out_dir / "metrics.json").write_text(json.dumps(result, indent=1) + "\n")
    from lili_odom.evaluation.plots import trajectory_top_view

    est_xyz = np.array([T[:3, 3] for _, T in estimates])
    trajectory_top_view(out_dir / "trajectory.png", truth_xyz, {config.pipeline.method: est_xyz},
                        {config.pipeline.method: np.asarray(dims) > 0},
                        title=f"{Path(args.bag).name}: {config.pipeline.method}")
    _summary(result)
    return 0


def _aligned_truth_xyz(estimates, truth) -> np.ndarray:
    """Truth positions expressed in the odometry frame (aligned at the first estimate)."""
    stamps = np.array([s for s, _ in truth])
    i = int(np.argmin(np.abs(stamps - estimates[0][0])))
    T_align = estimates[0][1] @ np.linalg.inv(truth[i][1])
    return np.array([(T_align @ T)[:3, 3] for _, T in truth])


def _summary(result: dict) -> None:
    m = result.get("metrics")
    line = (f"{result['method']}: {result['scans_processed']} scans, "
            f"{result['scans_per_second']:.1f} scans/s, degenerate {100 * result['degenerate_fraction']:.0f} %")
    if m:
        line += (f", ATE {m['ate_rmse_m']:.3f} m, RPE({m['rpe_segment_m']:.0f} m) {m['rpe_rmse_m']:.3f} m,"
                 f" path {m['path_length_m']:.1f} m")
    print(line)


class _progress:
    """A rich progress bar over messages (or nothing)."""

    def __init__(self, total: int, disabled: bool):
        self._bar = None
        if not disabled:
            from rich.progress import Progress

            self._bar = Progress(transient=False)
            self._task = self._bar.add_task("odometry", total=total or None)
            self._bar.start()

    def advance(self) -> None:
        if self._bar is not None:
            self._bar.advance(self._task)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
