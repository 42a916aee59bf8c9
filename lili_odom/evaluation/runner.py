"""Offline odometry over a bag: the node's pipeline, as fast as possible, with its evaluation.

:func:`run_bag` is what ``lili-odom run`` and the benchmarks call. It reads the bag in header-stamp
order through the replay loop (:class:`~lili_odom.evaluation.replay.Replay`: the same
:class:`~lili_odom.pipeline.feeder.MessageFeeder` as the node; the bag is decoded and its clouds
parsed in a thread ahead of the pipeline, :mod:`lili_odom.bagio.prefetch`) and writes into
``out_dir``:

* ``odometry/``: rosbag2 mcap with ``/lili_odom/odometry``, ``path``, degeneracy markers and JSON
  basis, ``/tf`` and the final local map;
* ``estimate.tum`` and, when the bag has ground truth, ``truth.tum`` (TUM: stamp x y z qx qy qz qw);
* ``scans.csv``: one row per processed scan: stamp [s], degenerate dimension (directions the
  LiDAR does not hold, ``OdometryOutput.degenerate_basis``), position [m],
  per-stage times [s], the online wheel scale, the orientation of the scan-to-map registration
  (base_link in the odometry frame, quaternion ``icp_qx .. icp_qw``; the fused one is in
  ``estimate.tum``), the estimated IMU biases (``accel_bias_*`` [m/s^2], ``gyro_bias_*``
  [rad/s], IMU frame) and the tracked gravity's rotation about the odometry frame's x and y
  (``gravity_tilt_x/y`` [rad], ``fusion.gravity_tracking_gain``), and how the scan's subspace
  came about: ``weak_directions`` (directions of planar motion the weak-direction check added to
  the detector's, ``plane_refinement.weak_information``), ``reused`` (1 when a recent detection
  served the scan), ``screened`` (1 when the planes held every direction and the detector
  was not asked) and ``weakly_held`` (directions of the subspace the LiDAR still holds, with
  its measured weight: ``OdometryOutput.weak_basis``);
* ``metrics.json``: ATE / RPE (via ``evo``, when there is truth), degeneracy statistics,
  counters, mean per-stage timings, throughput;
* ``trajectory.png``: top view of the estimate (degenerate scans marked) and the truth.
"""
from __future__ import annotations

import csv
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lili_odom.config import NodeConfig
from lili_odom.errors import UserError

log = logging.getLogger(__name__)

STAGES = ("predict", "deskew", "icp", "detector", "remap", "fusion", "map", "total")


@dataclass
class OfflineRun:
    """What one offline run produced (poses are base_link in the odometry frame, 4x4)."""

    method: str
    estimates: list[tuple[float, np.ndarray]] = field(default_factory=list)
    truth: list[tuple[float, np.ndarray]] = field(default_factory=list)
    #: per scan: the degenerate dimension (directions the LiDAR does not hold)
    dimensions: list[int] = field(default_factory=list)
    #: per scan: the detection's (k, 6) basis in the sensor body frame, scaled (empty: none)
    bases_scaled: list[np.ndarray] = field(default_factory=list)
    #: per scan: True when the detection was carried over from an earlier scan
    reused: list[bool] = field(default_factory=list)
    timings: dict[str, list[float]] = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    map_path: str = ""  # the saved map (save_map), absolute

    @property
    def stamps(self) -> np.ndarray:
        return np.array([s for s, _ in self.estimates])

    @property
    def poses(self) -> np.ndarray:
        return np.array([T for _, T in self.estimates])

    def truth_in_odometry_frame(self) -> np.ndarray | None:
        """(n, 3) truth positions expressed in the odometry frame, aligned at the first estimate."""
        if not self.truth or not self.estimates:
            return None
        stamps = np.array([s for s, _ in self.truth])
        i = int(np.argmin(np.abs(stamps - self.estimates[0][0])))
        T_align = self.estimates[0][1] @ np.linalg.inv(self.truth[i][1])
        return np.array([(T_align @ T)[:3, 3] for _, T in self.truth])


def _origin(det) -> tuple[int, int, int]:
    """(weak directions added, reused, screened) of a scan's degeneracy result (zeros without
    one)."""
    if det is None:
        return 0, 0, 0
    d = det.details
    return int(d.get("weak", 0)), int(bool(d.get("reused"))), int(bool(d.get("screened")))


def _quaternions(poses: list[np.ndarray | None]) -> np.ndarray:
    """(n, 4) (qx, qy, qz, qw) of 4x4 poses' rotations, in one call; NaN rows for poses that
    are missing or not finite."""
    from scipy.spatial.transform import Rotation

    quats = np.full((len(poses), 4), np.nan)
    good = [i for i, T in enumerate(poses)
            if T is not None and np.shape(T) == (4, 4) and np.isfinite(T).all()]
    if good:
        rotations = np.array([np.asarray(poses[i], dtype=float)[:3, :3] for i in good])
        quats[good] = Rotation.from_matrix(rotations).as_quat()
    return quats


def _vector(v: np.ndarray | None, n: int = 3) -> list[float]:
    """An n-vector as n floats (NaN when missing)."""
    if v is None or np.shape(v) != (n,):
        return [float("nan")] * n
    return [float(x) for x in v]


def run_bag(bag: Path | str, config: NodeConfig, out_dir: Path, *, max_scans: int = 0,
            rpe_segment: float = 100.0, progress: bool = True,
            progress_label: str = "odometry", reader: Any = None,
            save_map: Path | str | None = None, map_voxel: float = 0.2) -> OfflineRun:
    """Run the odometry over ``bag`` and write the outputs listed in the module docstring.

    ``reader``: another message source than the bag (e.g.
    :class:`lili_odom.io.ouster.OusterRecording`): a context manager with ``message_count``
    yielding items with ``topic`` and ``msg``. ``save_map``: also write the accumulated map
    (:class:`lili_odom.io.map_file.MapAccumulator`, ``map_voxel`` [m]) to this ``.pcd`` /
    ``.ply`` file, as the node's ``~/save_map`` does.

    Raises:
        UserError: unreadable bag, missing LiDAR topic, unusable ``out_dir``, no scan processed.
    """
    from lili_odom.bagio.prefetch import prefetched
    from lili_odom.bagio.reader import BagReader
    from lili_odom.bagio.tum import write_tum
    from lili_odom.bagio.writer import OutputBagWriter
    from lili_odom.evaluation.replay import Replay

    out_dir = Path(out_dir)
    if (out_dir / "odometry").exists():
        raise UserError(f"{out_dir}: already holds a run (odometry/ exists); choose another --out")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{out_dir}: cannot create the output directory: "
                        f"{exc.strerror or exc}") from None

    topics = [config.lidar_topic, config.imu_topic, config.wheel_topic, config.ground_truth_topic,
              "/tf_static"]
    run = OfflineRun(method=config.pipeline.method)
    accumulator = None
    if save_map is not None:
        from lili_odom.io.map_file import MAP_SUFFIXES, MapAccumulator

        if Path(save_map).suffix.lower() not in MAP_SUFFIXES:
            raise UserError(f"{save_map}: map files are .pcd or .ply")
        accumulator = MapAccumulator(map_voxel)
    last_accumulated = [-float("inf")]
    rows: list[list[float]] = []
    icp_poses: list[np.ndarray | None] = []  # scans.csv's icp_q*, converted at the end
    replay = Replay(config)
    pipeline = replay.pipeline
    t_wall = time.perf_counter()
    source = reader if reader is not None else BagReader(bag, topics=topics,
                                                          required=[config.lidar_topic])
    with source as reader, \
            OutputBagWriter(out_dir / "odometry", odom_frame=config.odom_frame,
                            base_frame=config.base_frame) as writer:
        for note in missing_inputs(reader, config):
            log.warning(note)
        bar = _Progress(reader.message_count, not progress, progress_label)

        def record(out, _pipeline) -> None:
            dim = len(out.degenerate_basis)
            run.estimates.append((out.stamp, out.pose))
            run.dimensions.append(dim)
            det = out.degeneracy
            run.bases_scaled.append(det.basis_scaled if det is not None else np.zeros((0, 6)))
            run.reused.append(bool(det is not None and det.details.get("reused")))
            for k, v in out.timings.items():
                run.timings.setdefault(k, []).append(v)
            rows.append([out.stamp, dim, *out.pose[:3, 3],
                         *(out.timings.get(k, float("nan")) for k in STAGES),
                         out.details.get("wheel_scale", float("nan")),
                         *_vector(out.details.get("accel_bias")),
                         *_vector(out.details.get("gyro_bias")),
                         *_vector(out.details.get("gravity_tilt"), 2),
                         *_origin(det), len(out.weak_basis)])
            icp_poses.append(out.icp_pose)
            writer.write_output(out)
            if accumulator is not None and out.stamp - last_accumulated[0] >= 1.0:
                accumulator.add(pipeline.local_map_points())
                last_accumulated[0] = out.stamp

        def advancing(items):
            for item in items:
                bar.advance()
                yield item

        def parsed(items):
            """(topic, message) of ``items``, the clouds parsed already (in the reading
            thread, off the pipeline's)."""
            for item in items:
                msg = item.msg
                if item.topic == config.lidar_topic:
                    msg = replay.feeder.parse_ahead(msg)
                yield item.topic, msg

        replay.on_output = record
        # decoded, and the clouds parsed, in a thread ahead of the pipeline
        messages = prefetched(parsed(reader))
        try:
            pipeline.start()  # the background detector process, before the first scan
            replay.run(advancing(messages), max_scans=max_scans)
        finally:
            messages.close()  # stops the reading thread before the bag is closed
            pipeline.close()  # the background detector process
        run.truth = replay.truth
        bar.close()
        if run.estimates:
            writer.write_map(pipeline.local_map_points(), run.estimates[-1][0])
            if accumulator is not None:
                from lili_odom.io.map_file import save_points

                accumulator.add(pipeline.local_map_points())
                try:
                    run.map_path = str(save_points(save_map, accumulator.points()))
                except OSError as exc:
                    raise UserError(f"{save_map}: cannot write the map: "
                                    f"{exc.strerror or exc}") from None
    wall = time.perf_counter() - t_wall
    if not run.estimates:
        raise UserError(f"{bag}: no scan could be processed ({dict(pipeline.counters)})")

    write_tum(out_dir / "estimate.tum", run.estimates)
    with open(out_dir / "scans.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["stamp", "dimension", "x", "y", "z", *(f"{k}_s" for k in STAGES),
                    "wheel_scale", "icp_qx", "icp_qy", "icp_qz", "icp_qw",
                    *(f"accel_bias_{a}" for a in "xyz"), *(f"gyro_bias_{a}" for a in "xyz"),
                    "gravity_tilt_x", "gravity_tilt_y", "weak_directions", "reused", "screened",
                    "weakly_held"])
        quaternion_at = 6 + len(STAGES)  # after stamp, dimension, x, y, z, stages, scale
        w.writerows(row[:quaternion_at] + [float(q) for q in quat] + row[quaternion_at:]
                    for row, quat in zip(rows, _quaternions(icp_poses)))
    dims = np.asarray(run.dimensions)
    summary: dict = {
        "bag": str(bag),
        "method": run.method,
        "scans_processed": len(run.estimates),
        "wall_time_s": wall,
        "scans_per_second": len(run.estimates) / wall if wall > 0 else float("nan"),
        "degenerate_fraction": float(np.mean(dims > 0)),
        "mean_dimension": float(np.mean(dims)),
        "timings_mean_s": {k: float(np.mean(v)) for k, v in run.timings.items()},
        "counters": dict(pipeline.counters),
    }
    if run.truth:
        from lili_odom.evaluation.metrics import evaluate

        run.truth.sort(key=lambda x: x[0])
        write_tum(out_dir / "truth.tum", run.truth)
        from evo import EvoException

        try:
            m = evaluate(run.stamps, run.poses, np.array([s for s, _ in run.truth]),
                         np.array([T for _, T in run.truth]), segment_m=rpe_segment)
            summary["metrics"] = m.to_dict()
        except EvoException as exc:
            # too few or degenerate poses to align (e.g. a short run standing still)
            summary["metrics"] = None
            summary["metrics_error"] = " ".join(str(exc).split())
            log.warning("no ATE/RPE for this run: %s", summary["metrics_error"])
    run.summary = summary
    (out_dir / "metrics.json").write_text(json.dumps(summary, indent=1) + "\n")

    from lili_odom.evaluation.plots import trajectory_top_view

    trajectory_top_view(out_dir / "trajectory.png", run.truth_in_odometry_frame(),
                        {run.method: run.poses[:, :3, 3]}, {run.method: dims > 0},
                        title=f"{Path(bag).name}: {run.method}")
    return run


def missing_inputs(reader: Any, config: NodeConfig) -> list[str]:
    """One line per IMU or wheel topic of ``config`` that ``reader`` (a bag) does not have,
    naming the bag's topics of that message type (none for readers without a topic list)."""
    types = getattr(reader, "topic_types", None)
    missing = getattr(reader, "missing_topics", None)
    if not isinstance(types, dict) or not isinstance(missing, list):
        return []
    effect = {"imu_topic": ("sensor_msgs/msg/Imu", "the prediction falls back to the motion "
                            "model"),
              "wheel_topic": ("nav_msgs/msg/Odometry", "degenerate directions rest on the "
                              "IMU alone")}
    notes = []
    for name, (msgtype, consequence) in effect.items():
        topic = getattr(config, name)
        if topic not in missing:
            continue
        others = sorted(t for t, m in types.items()
                        if m == msgtype and t != config.ground_truth_topic)
        hint = (f"; {msgtype} topics in the bag: {', '.join(others)} (set {name})" if others
                else "")
        notes.append(f"{topic} ({name}) is not in the bag: {consequence}{hint}")
    return notes


def summary_line(summary: dict) -> str:
    """One line: method, scans, throughput, degenerate share and (with truth) ATE/RPE."""
    m = summary.get("metrics")
    line = (f"{summary['method']}: {summary['scans_processed']} scans, "
            f"{summary['scans_per_second']:.1f} scans/s, "
            f"degenerate {100 * summary['degenerate_fraction']:.0f} %")
    if m:
        line += (f", ATE {m['ate_rmse_m']:.3f} m, RPE({m['rpe_segment_m']:.0f} m) "
                 f"{m['rpe_rmse_m']:.3f} m, path {m['path_length_m']:.1f} m")
    return line


class _Progress:
    """A rich progress bar over messages (or nothing)."""

    def __init__(self, total: int, disabled: bool, label: str):
        self._bar = None
        if not disabled:
            from rich.progress import Progress

            self._bar = Progress(transient=False)
            self._task = self._bar.add_task(label, total=total or None)
            self._bar.start()

    def advance(self) -> None:
        if self._bar is not None:
            self._bar.advance(self._task)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
