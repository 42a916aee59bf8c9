"""Without wheels, which source lags or overruns along the direction of travel, scan by scan.

    python -m benchmarks.studies.travel_bias                     # the default windows/variants
    python -m benchmarks.studies.travel_bias --windows airfield:30:20 \\
        --variant defaults --variant "10 steps" pipeline.plane_refinement.iterations=10

Each window (``SCENARIO:START:DURATION``, seconds of the scenario's trial; seed 0, one
resolution) runs `lili` with the wheel topic ignored, once per ``--variant LABEL
[NAME=VALUE ...]`` (``--set``-style overrides over the defaults). On every scan whose fusion
gets a LiDAR measurement inside a degenerate subspace, and while the robot moves (true step
at least ``MIN_STEP_M``), four poses are compared with the truth as steps from the previous
scan's fused pose, projected on the true direction of travel (base_link):

* ``prediction``: the IMU's prediction the registration starts from;
* ``registration``: KISS-ICP's point-to-point result;
* ``measurement``: the pose the fusion gets (the registration refined by point-to-plane
  inside the subspace, :mod:`lili_odom.pipeline.plane_refinement`), with the information
  along the direction of travel it carries [1/m^2];
* ``fused``: the fusion's output.

Each column is the step's error [cm] (negative: short of the true step): mean, standard
deviation, and the mean weighted by the measurement's information (what the fusion's
average of the measurements sees). Also: the ATE after SE(3) alignment, and a figure of the
distance travelled by the estimate minus the true one over time per window and variant.

Writes ``benchmarks/results/<name>.{md,json}`` and ``<name>.png`` (default ``travel_bias``).
"""
from __future__ import annotations

import argparse
import contextlib
import shlex
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, machine_info, parse_set, write_results
from benchmarks._pieces import format_resolution, parse_resolution, piece_bag

#: default windows: starts while driving on open ground (airfield, parking lot), and the
#: whole of Trial 1
WINDOWS = ("airfield:30:20", "parking_lot:20:20", "tunnel_trial1:0:340")

#: true steps shorter than this [m] (standing, creeping) are not compared
MIN_STEP_M = 0.02

COLUMNS = ("prediction", "registration", "measurement", "fused")

#: at most about this many points of each run's distance-gap curve are kept (report, figure)
CURVE_POINTS = 500


@contextlib.contextmanager
def recording(log: list[dict]):
    """Record per processed scan (``log``): the prediction and the registration (LiDAR
    frame), the pose and subspace information the fusion gets (base_link), the fused pose,
    ``T_base_lidar``."""
    from lili_odom.fusion.estimator import FusionEstimator
    from lili_odom.pipeline.odometry import OdometryPipeline
    from lili_odom.pipeline.scan_matcher import ScanMatcher

    register, update, process = (ScanMatcher.register, FusionEstimator.update,
                                 OdometryPipeline.process_scan)
    scan: dict = {}

    def registered(self, source, guess):
        result = register(self, source, guess)
        scan.update(prediction=np.array(guess, float), registration=np.array(result.pose, float))
        return result

    def updated(self, t, T_icp_base, degeneracy=None, **kwargs):
        subspace = kwargs.get("subspace")
        scan.update(measurement=None if T_icp_base is None else np.array(T_icp_base, float),
                    information=(None if subspace is None
                                 else np.array(subspace.information_scaled, float)))
        return update(self, t, T_icp_base, degeneracy, **kwargs)

    def processed(self, s):
        scan.clear()
        out = process(self, s)
        if out is not None:
            log.append({**scan, "stamp": float(out.stamp), "fused": np.array(out.pose, float),
                        "T_base_lidar": np.array(self.T_base_lidar, float)})
        return out

    ScanMatcher.register, FusionEstimator.update = registered, updated
    OdometryPipeline.process_scan = processed
    try:
        yield
    finally:
        ScanMatcher.register, FusionEstimator.update = register, update
        OdometryPipeline.process_scan = process


def step_errors(log: list[dict], truth_stamps: np.ndarray, truth_poses: np.ndarray) -> dict:
    """Per column the step errors along the true direction of travel [m] of the scans with a
    subspace measurement, and ``information``: the measurement's information along it."""
    inv = np.linalg.inv
    out: dict[str, list[float]] = {c: [] for c in COLUMNS + ("information",)}

    def truth_at(t: float) -> np.ndarray:
        return truth_poses[int(np.argmin(np.abs(truth_stamps - t)))]

    for last, now in zip(log, log[1:]):
        if now.get("information") is None or now.get("measurement") is None:
            continue
        true_step = (inv(truth_at(last["stamp"])) @ truth_at(now["stamp"]))[:3, 3]
        length = float(np.linalg.norm(true_step))
        if length < MIN_STEP_M:
            continue
        u = true_step / length  # base_link of the previous scan
        to_base = inv(now["T_base_lidar"])
        base = {"prediction": now["prediction"] @ to_base,
                "registration": now["registration"] @ to_base,
                "measurement": now["measurement"], "fused": now["fused"]}
        for c, T in base.items():
            out[c].append(float((inv(last["fused"]) @ T)[:3, 3] @ u) - length)
        R = now["T_base_lidar"][:3, :3]  # translation block of the scaled twists: plain metres
        out["information"].append(float(u @ R @ now["information"][:3, :3] @ R.T @ u))
    return {k: np.array(v) for k, v in out.items()}


def summary(errors: dict) -> dict:
    """Mean, standard deviation and information-weighted mean [cm] per column."""
    info = errors["information"]
    weights = info / info.sum() if len(info) and info.sum() > 0 else None
    rows = {"scans": int(len(info)),
            "median_information": float(np.median(info)) if len(info) else None}
    for c in COLUMNS:
        e = 100.0 * errors[c]
        rows[c] = {"mean_cm": float(e.mean()) if len(e) else None,
                   "std_cm": float(e.std()) if len(e) else None,
                   "weighted_mean_cm": float(weights @ e) if weights is not None else None}
    return rows


def distance_gap(stamps, poses, truth_stamps, truth_poses) -> tuple[list[float], list[float]]:
    """(time since the first scan [s], distance travelled by the estimate minus the truth's
    over the same stamps [m]), rounded to 10 ms and 1 mm."""
    idx = [int(np.argmin(np.abs(truth_stamps - t))) for t in stamps]
    est = np.asarray([T[:3, 3] for T in poses])
    tru = np.asarray([truth_poses[i][:3, 3] for i in idx])

    def travelled(p):
        return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])

    t = np.round(np.asarray(stamps) - stamps[0], 2)
    return t.tolist(), np.round(travelled(est) - travelled(tru), 3).tolist()


def run(window: str, label: str, overrides: dict[str, str], resolution: tuple[int, int],
        tmp: Path) -> dict:
    """One window with one variant: the summary, its ATE and the distance-gap curve."""
    from lili_odom.bagio.tum import read_tum
    from lili_odom.suite.jobs import BagSpec, Job, execute
    from lili_odom.suite.scenario import load_scenarios

    scenario, start, duration = window.split(":")
    (sc,) = load_scenarios([scenario], measure=False)
    bag = piece_bag(scenario, float(start), float(duration), resolution, 0, progress=False)
    log: list[dict] = []
    out = tmp / f"{scenario}_{len(list(tmp.iterdir()))}"
    job = Job(scenario=scenario, split=sc.split, kind=sc.kind, seed=0, method="lili",
              bag=BagSpec(path=str(bag)), out_dir=str(out), truth_path=str(out / "truth.tum"),
              overrides=(("wheel_topic", "/none"),) + tuple(overrides.items()))
    with recording(log):
        row = execute(job)
    result = {"window": window, "variant": label, "overrides": overrides,
              "ate_m": row.get("ate_m"), "error": row.get("error")}
    if not row.get("error"):  # the suite's job wrote the estimate and the truth
        ts, tp = read_tum(job.truth_path)
        t, gap = distance_gap(*read_tum(out / "estimate_base.tum"), ts, tp)
        result.update(summary(step_errors(log, ts, tp)))
        stride = -(-len(t) // CURVE_POINTS)
        result["curve"] = (t[::stride], gap[::stride])
    return result


def _stats(s: dict | None) -> str:
    """``mean / std / weighted mean`` [cm] of one column, or an en dash."""
    if not s or s.get("mean_cm") is None:
        return "–"
    weighted = "–" if s["weighted_mean_cm"] is None else f"{s['weighted_mean_cm']:+.2f}"
    return f"{s['mean_cm']:+.2f} / {s['std_cm']:.2f} / {weighted}"


def markdown(report: dict, command: str, name: str) -> str:
    lines = ["# Steps along the direction of travel without wheels", "",
             f"`{command}` (`benchmarks/studies/travel_bias.py`): `lili` with the wheel topic "
             f"ignored, seed 0, {report['resolution']}; commit `{report['machine']['commit']}`. "
             "Scans with a LiDAR measurement inside a degenerate subspace while moving: each "
             "pose's step from the previous fused pose along the true direction of travel, "
             "minus the true step [cm]: mean / standard deviation / mean weighted by the "
             "measurement's information along the travel (negative: short).", "",
             "| window | variant | ATE [m] | scans | median information [1/m^2] | "
             + " | ".join(COLUMNS) + " |",
             "|---|---|---:|---:|---:|" + "---|" * len(COLUMNS)]
    for r in report["rows"]:
        if r.get("error"):
            lines.append(f"| {r['window']} | {r['variant']} | failed: {r['error'][:60]} |"
                         + " |" * (2 + len(COLUMNS)))
            continue
        med = r.get("median_information")
        lines.append(f"| {r['window']} | {r['variant']} | {r['ate_m']:.3f} | {r['scans']} | "
                     f"{'–' if med is None else f'{med:.0f}'} | "
                     + " | ".join(_stats(r.get(c)) for c in COLUMNS) + " |")
    lines += ["", f"![distance travelled by the estimate minus the truth's]({name}.png)", ""]
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    windows = list(dict.fromkeys(r["window"] for r in report["rows"]))
    fig, axes = plt.subplots(1, len(windows), figsize=(4.5 * len(windows), 3.6), squeeze=False)
    for ax, w in zip(axes[0], windows):
        for r in report["rows"]:
            if r["window"] == w and r.get("curve"):
                ax.plot(*r["curve"], lw=1.1, label=f"{r['variant']} (ATE {r['ate_m']:.2f} m)")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_title(w, fontsize=9)
        ax.set_xlabel("time since the first scan [s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("distance travelled: estimate - truth [m]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.studies.travel_bias",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--windows", nargs="+", default=list(WINDOWS),
                    metavar="SCENARIO:START:DURATION")
    ap.add_argument("--variant", action="append", nargs="+", metavar="LABEL [NAME=VALUE]",
                    help="a label and --set-style overrides; repeat (default: the defaults)")
    ap.add_argument("--resolution", default="32x512", help="ROWSxCOLS (default 32x512)")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--name", default="travel_bias")
    args = ap.parse_args(argv)
    from lili_odom.suite.scenario import load_scenarios

    try:
        resolution = parse_resolution(args.resolution)
        for w in args.windows:
            parts = w.split(":")
            if len(parts) != 3 or not (float(parts[1]) >= 0 and float(parts[2]) > 0):
                raise ValueError(f"window {w}: expected SCENARIO:START:DURATION, start >= 0 "
                                 "and duration positive [s]")
        load_scenarios([w.split(":")[0] for w in args.windows], measure=False)
    except ValueError as exc:
        ap.error(str(exc))
    variants = [(v[0], parse_set(v[1:], prog="travel_bias")) for v in
                (args.variant or [["defaults"]])]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for w in args.windows:
            for label, overrides in variants:
                print(f"[{w}] {label} ...", flush=True)
                rows.append(run(w, label, overrides, resolution, Path(tmp)))
                print(f"  ATE {rows[-1].get('ate_m')}", flush=True)
    report = {"machine": machine_info(), "resolution": format_resolution(resolution),
              "rows": rows}
    command = "python -m benchmarks.studies.travel_bias " + shlex.join(
        argv if argv is not None else sys.argv[1:])
    args.out.mkdir(parents=True, exist_ok=True)
    plot(report, args.out / f"{args.name}.png")
    text = markdown(report, command.strip(), args.name)
    print(f"wrote {write_results(args.out, args.name, text, report)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
