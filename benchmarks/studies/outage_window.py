"""One wheel-outage window scan by scan: the fused speed against the true one, and the
point-to-plane information the refinement measures inside the degenerate subspace.

    python -m benchmarks.studies.outage_window --seed 2 --start 150 [--trial 1] \\
        [--resolution 32x256] [--duration 40] [--outage 20] [--every 1.0] [--config FILE] \\
        [--out FILE]

The piece of the trial (as :mod:`benchmarks.wheel_outage` makes it, wheel odometry dropped
for its last ``--outage`` seconds, one native thread) runs through the default pipeline;
every ``--every`` seconds of the piece one row: the fused speed and the true one [m/s], the
position error along and across the direction of travel [m] (the estimate placed on the truth
at the piece's first scan), and the eigenvalues [1/m^2] of
the refinement's information over the subspace of the scan's detection, as the fusion gets
it (after ``plane_refinement.return_check``, before the directions it holds to
``clear_information`` are cleared; none where no refinement ran), and on scans without wheel
data where the refinement also ran from the prediction (``plane_refinement.predicted_start``)
how far each pose is ahead of the previous fused pose along the true direction of travel [cm]:
the registration refined inside the subspace, and the refinement from the prediction, its
start and its end (does it come back to the registration's?). ``--config`` runs the defaults
with a parameter file over them. Appends a section to
``benchmarks/results/outage_window.md`` (``--out``).
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, SIM_CACHE, git

DEFAULT_OUT = RESULTS / "outage_window.md"


def run_window(trial: int, seed: int, start: float, duration: float, outage: float,
               resolution: str, config: Path | None = None) -> tuple[list[dict], dict]:
    """(one dict per processed scan, the run's metrics) of the window."""
    import lili_odom.pipeline.odometry as odometry
    from lili_odom.bagio.reader import BagReader
    from lili_odom.config import load_config
    from lili_odom.evaluation.faults import FaultInjector, FaultSpec, read_bag, run_stream
    from lili_odom.sim.generator import ensure_trial_bag

    bag = ensure_trial_bag(trial, SIM_CACHE, resolution=resolution, seed=seed, start=start,
                           duration=duration, progress=False)
    cfg = load_config(config)
    cfg.pipeline.method = "lili"
    cfg.pipeline.scan_matcher.max_threads = 1
    cfg.pipeline.lili.registration.max_threads = 1
    cfg.validate()
    measured: list[np.ndarray | None] = []
    clear = odometry.OdometryPipeline._clear_held_directions

    def recording(self, degeneracy, refined):  # the refinement's information, then as usual
        measured.append(np.linalg.eigvalsh(0.5 * (refined.information + refined.information.T)))
        return clear(self, degeneracy, refined)

    both: dict = {}  # this scan's two refinements without wheel data
    from_prediction = odometry.OdometryPipeline._refined_from_prediction
    refine = odometry.refine_in_subspace

    def two_starts(self, planes, refined, measured_pose, guess, degeneracy, *rest):
        calls = []

        def recorded(*args, **kwargs):
            result = refine(*args, **kwargs)
            calls.append((np.array(args[2], float), np.array(result.pose, float)))
            return result

        odometry.refine_in_subspace = recorded
        try:
            return from_prediction(self, planes, refined, measured_pose, guess, degeneracy,
                                   *rest)
        finally:
            odometry.refine_in_subspace = refine
            if calls:  # the refinement from the prediction ran
                both.update(registration=np.array(refined.pose, float), start=calls[0][0],
                            end=calls[0][1], T_lidar_base=np.linalg.inv(self.T_base_lidar))

    rows: list[dict] = []

    def on_output(out, _pipeline) -> None:
        info = measured[-1] if measured else None  # None: no refinement on this scan
        rows.append({"stamp": out.stamp, "pose": np.asarray(out.pose, float),
                     "speed": float(np.linalg.norm(out.twist[:3])), "information": info,
                     "used_wheel": bool(out.details.get("used_wheel")),
                     "two_starts": dict(both) or None})
        both.clear()
        measured.append(None)  # a scan without a refinement shows none

    topics = [cfg.lidar_topic, cfg.imu_topic, cfg.wheel_topic, cfg.ground_truth_topic,
              "/tf_static"]
    spec = FaultSpec(seed=0, wheel_outage=(duration - outage, duration))
    odometry.OdometryPipeline._clear_held_directions = recording
    odometry.OdometryPipeline._refined_from_prediction = two_starts
    try:
        with BagReader(bag, topics=topics) as reader:
            run = run_stream(FaultInjector(spec)(read_bag(reader, None)), cfg,
                             on_output=on_output)
    finally:
        odometry.OdometryPipeline._clear_held_directions = clear
        odometry.OdometryPipeline._refined_from_prediction = from_prediction
    truth = sorted(run.truth, key=lambda x: x[0])
    t_truth = np.array([t for t, _ in truth])
    p_truth = np.array([T[:3, 3] for _, T in truth])
    for r in rows:
        i = int(np.argmin(np.abs(t_truth - r["stamp"])))
        j = min(i + 1, len(t_truth) - 1)
        k = max(j - 2, 0)
        step = p_truth[j] - p_truth[k]
        r["true_speed"] = float(np.linalg.norm(step) / max(t_truth[j] - t_truth[k], 1e-9))
        r["travel"] = step / max(np.linalg.norm(step), 1e-9)
        r["true_pose"] = truth[i][1]
    m = run.metrics(segment_m=100.0)
    return rows, (m.to_dict() if m is not None else {})


def markdown(rows: list[dict], metrics: dict, args: argparse.Namespace, command: str) -> str:
    t0 = rows[0]["stamp"]
    # the estimate's frame placed on the truth's at the first scan (no fit over the piece)
    align = rows[0]["true_pose"] @ np.linalg.inv(rows[0]["pose"])
    lines = [f"## Trial {args.trial}, seed {args.seed}, from {args.start:g} s "
             f"({args.resolution}, wheels out for the last {args.outage:g} s)", "",
             f"`{command}`, commit {git('rev-parse', '--short', 'HEAD') or '?'}. ATE "
             f"{metrics.get('ate_rmse_m', float('nan')):.3f} m, final error "
             f"{metrics.get('final_error_m', float('nan')):.2f} m.", "",
             "| t [s] | wheels | fused / true speed [m/s] | error along / across travel [m] "
             "| subspace information [1/m^2] | ahead [cm]: registration refined; from the "
             "prediction, start -> end |",
             "|---:|---|---|---|---|---|"]
    next_t = 0.0
    previous = None
    for r in rows:
        last, previous = previous, r
        t = r["stamp"] - t0
        if t + 1e-6 < next_t:
            continue
        next_t += args.every
        err = (align @ r["pose"])[:3, 3] - r["true_pose"][:3, 3]
        along = float(err @ r["travel"])
        across = float(np.linalg.norm(err - along * r["travel"]))
        info = "–"
        if r["information"] is not None:
            info = ", ".join(f"{v:.0f}" for v in r["information"])
        lines.append(f"| {t:.1f} | {'yes' if r['used_wheel'] else 'no'} | {r['speed']:.2f} / "
                     f"{r['true_speed']:.2f} | {along:+.2f} / {across:.2f} | {info} | "
                     f"{_ahead(r, last)} |")
    return "\n".join(lines) + "\n"


def _ahead(row: dict, last: dict | None) -> str:
    """The two refinements' poses ahead of the previous scan's fused pose along the true
    direction of travel (in that pose's frame) [cm], or an en dash."""
    two = row["two_starts"]
    if two is None or last is None:
        return "–"
    R, p = last["pose"][:3, :3], last["pose"][:3, 3]
    travel = last["true_pose"][:3, :3].T @ row["travel"]  # in the body frame

    def ahead(T_odom_lidar: np.ndarray) -> float:
        T = T_odom_lidar @ two["T_lidar_base"]
        return 100.0 * float((R.T @ (T[:3, 3] - p)) @ travel)

    return (f"{ahead(two['registration']):+.1f}; {ahead(two['start']):+.1f} -> "
            f"{ahead(two['end']):+.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.studies.outage_window",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--trial", type=int, default=1, choices=(1, 2))
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--start", type=float, default=150.0, help="piece start in the trial [s]")
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--outage", type=float, default=20.0)
    ap.add_argument("--resolution", default="32x256")
    ap.add_argument("--every", type=float, default=1.0, help="seconds between rows")
    ap.add_argument("--config", type=Path, default=None,
                    help="parameter file over the defaults (e.g. benchmarks/configs/...)")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = ap.parse_args(argv)
    if not 0.0 < args.outage <= args.duration or not args.every > 0:
        ap.error("--outage must be in (0, --duration] and --every positive")
    logging.basicConfig(level=logging.ERROR)
    if args.config is not None and not args.config.is_file():
        ap.error(f"--config: no such file: {args.config}")
    rows, metrics = run_window(args.trial, args.seed, args.start, args.duration, args.outage,
                               args.resolution, args.config)
    if not rows:
        print("error: no scan was processed", file=sys.stderr)
        return 1
    command = "python -m benchmarks.studies.outage_window " + " ".join(
        argv if argv is not None else sys.argv[1:])
    text = markdown(rows, metrics, args, command)
    header = "" if args.out.exists() else (
        "# Wheel outage windows scan by scan\n\nGenerated by "
        "`python -m benchmarks.studies.outage_window` (one section per run).\n\n")
    with open(args.out, "a") as f:
        f.write(header + text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
