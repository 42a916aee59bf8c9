"""How the odometry's height drifts against the truth, per settings variant: the frame a start
at rest gives the local map, and what happens to it after a turn.

    python -m benchmarks.studies.height_drift                     # warehouse, seed 21
    python -m benchmarks.studies.height_drift --scenario warehouse --seed 21 \\
        --variant defaults --variant "gain 0.05" pipeline.fusion.gravity_tracking_gain=0.05

At rest the accelerometer cannot tell its bias from a tilt: the start's gravity alignment
takes a bias ``b`` along the direction of travel as a pitch of about ``b / g``, and the local
map is built in that frame, so the odometry climbs or descends against the truth by that
slope. A rigid tilt costs nothing after the SE(3) alignment of the ATE; what costs is a frame
that changes during the run (a turn makes the bias observable and the IMU levels the track
while the map stays tilted), and the registration's jump when the older, differently tilted
map comes back into view.

Runs `lili` on the scenario (its own sensor and error profile, with wheels) once per
``--variant LABEL [NAME=VALUE ...]`` (``--set``-style overrides over the defaults) with the
suite's job, and reports per variant: the ATE after SE(3) alignment; the height error (the
estimate's height minus the truth's, both from their first pose, base_link, unaligned [m])
every ``--every`` seconds; its largest change within any 3 s [m] and when; the accelerometer
bias the fusion estimated at the start and at the end (``scans.csv``, IMU frame [m/s^2]);
and the simulated IMU's true turn-on bias. Writes ``benchmarks/results/<name>.{md,json}``
and ``<name>.png`` (height error over time; default name ``height_drift``).
"""
from __future__ import annotations

import argparse
import csv
import shlex
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks._common import RESULTS, machine_info, parse_set, write_results

#: window of the largest height change [s]
JUMP_WINDOW_S = 3.0


def true_accel_bias(seed: int) -> list[float]:
    """The simulated IMU's turn-on accelerometer bias [m/s^2] (IMU frame) for ``seed``
    (:func:`lili_odom.sim.imu.turn_on_biases` with the simulator's default IMU)."""
    from lili_odom.sim.imu import turn_on_biases
    from lili_odom.sim.sensors import ImuConfig

    return [float(v) for v in turn_on_biases(ImuConfig(), seed)[1]]


def height_error(stamps: np.ndarray, poses: np.ndarray, truth_stamps: np.ndarray,
                 truth_poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(time since the first pose [s], estimate height minus truth height [m]), both from
    their own first pose, at the estimate's stamps (truth interpolated)."""
    z_true = np.interp(stamps, truth_stamps, truth_poses[:, 2, 3])
    return stamps - stamps[0], (poses[:, 2, 3] - poses[0, 2, 3]) - (z_true - z_true[0])


def largest_jump(t: np.ndarray, dz: np.ndarray, window: float = JUMP_WINDOW_S
                 ) -> tuple[float, float]:
    """(change [m], time of the window's end [s]) of the largest absolute change of ``dz``
    over any ``window`` seconds."""
    j = np.searchsorted(t, t - window)
    change = dz - dz[j]
    i = int(np.argmax(np.abs(change)))
    return float(change[i]), float(t[i])


def accel_bias(scans_csv: Path) -> tuple[list[float], list[float]]:
    """The fusion's accelerometer bias estimate [m/s^2] at the first scan after 5 s and at the
    last scan (``scans.csv``)."""
    with open(scans_csv) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return [float("nan")] * 3, [float("nan")] * 3
    t0 = float(rows[0]["stamp"])
    first = next((r for r in rows if float(r["stamp"]) - t0 >= 5.0), rows[-1])
    pick = lambda r: [float(r[f"accel_bias_{a}"]) for a in "xyz"]  # noqa: E731
    return pick(first), pick(rows[-1])


def run(scenario: str, seed: int, label: str, overrides: dict[str, str], every: float,
        tmp: Path) -> dict:
    """One variant: its ATE, height-error samples, largest jump and bias estimates."""
    from lili_odom.bagio.tum import read_tum
    from lili_odom.suite.jobs import BagSpec, Job, execute
    from lili_odom.suite.scenario import load_scenarios, scenario_bag

    (sc,) = load_scenarios([scenario], measure=False)
    bag = scenario_bag(sc, seed, progress=False)
    out = tmp / f"run_{len(list(tmp.iterdir()))}"
    job = Job(scenario=scenario, split=sc.split, kind=sc.kind, seed=seed, method="lili",
              bag=BagSpec(path=str(bag)), out_dir=str(out), truth_path=str(out / "truth.tum"),
              overrides=tuple(overrides.items()))
    row = execute(job)
    result = {"variant": label, "overrides": overrides, "ate_m": row.get("ate_m"),
              "error": row.get("error")}
    if row.get("error"):
        return result
    t, dz = height_error(*read_tum(out / "estimate_base.tum"), *read_tum(job.truth_path))
    jump, when = largest_jump(t, dz)
    samples = np.arange(0.0, t[-1] + 1e-9, every)
    start, end = accel_bias(out / "scans.csv")
    result.update(samples_s=samples.tolist(),
                  height_error_m=np.interp(samples, t, dz).tolist(),
                  jump_m=jump, jump_at_s=when, accel_bias_start=start, accel_bias_end=end,
                  curve=(t[::5].tolist(), dz[::5].tolist()))
    return result


def markdown(report: dict, command: str) -> str:
    res = [r for r in report["results"] if not r.get("error")]
    b = report["true_accel_bias"]
    lines = [
        "# Height drift against the truth", "",
        f"`{command}` (`benchmarks/studies/height_drift.py`): `lili` on `{report['scenario']}` "
        f"seed {report['seed']} (its own sensor and error profile, with wheels); commit "
        f"`{report['machine'].get('commit', '?')}`. Height error: the estimate's height minus "
        "the truth's, both from their first pose (base_link, not aligned) [m]. Jump: the "
        f"largest change of that error within {JUMP_WINDOW_S:g} s. The simulated IMU's "
        f"turn-on accelerometer bias: ({b[0]:+.3f}, {b[1]:+.3f}, {b[2]:+.3f}) m/s^2 (IMU "
        "frame); the fusion's estimate 5 s in and at the end.", "",
        "| variant | ATE [m] | jump [m] (at [s]) | bias at 5 s | bias at the end |",
        "|---|---:|---|---|---|"]
    fmt = lambda v: "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"  # noqa: E731
    for r in res:
        lines.append(f"| {r['variant']} | {r['ate_m']:.3f} | {r['jump_m']:+.3f} "
                     f"({r['jump_at_s']:.1f}) | {fmt(r['accel_bias_start'])} | "
                     f"{fmt(r['accel_bias_end'])} |")
    for r in report["results"]:
        if r.get("error"):
            lines.append(f"| {r['variant']} | failed: {r['error']} | | | |")
    if res:
        lines += ["", "Height error [m] every "
                  f"{report['every_s']:g} s:", "",
                  "| t [s] | " + " | ".join(r["variant"] for r in res) + " |",
                  "|---:|" + "---:|" * len(res)]
        for i, s in enumerate(res[0]["samples_s"]):
            cells = [f"{r['height_error_m'][i]:+.3f}" if i < len(r["height_error_m"]) else "–"
                     for r in res]
            lines.append(f"| {s:g} | " + " | ".join(cells) + " |")
    lines += ["", f"![height error over time]({report['name']}.png)", ""]
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    for r in report["results"]:
        if not r.get("error"):
            ax.plot(*r["curve"], label=f"{r['variant']} (ATE {r['ate_m']:.3f} m)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("height error [m]")
    ax.set_title(f"{report['scenario']}, seed {report['seed']}: estimate minus truth height")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.studies.height_drift",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="warehouse")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--variant", nargs="+", action="append", metavar=("LABEL", "NAME=VALUE"),
                    help="a label and --set-style overrides; repeat (default: the defaults)")
    ap.add_argument("--every", type=float, default=10.0, help="height samples every S seconds")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--name", default="height_drift")
    args = ap.parse_args(argv)
    from lili_odom.suite.scenario import load_scenarios

    try:
        load_scenarios([args.scenario], measure=False)
        variants = [(v[0], parse_set(v[1:], prog="height_drift"))
                    for v in (args.variant or [["defaults"]])]
    except (KeyError, ValueError) as e:
        print(f"height_drift: {e}", file=sys.stderr)
        return 2
    report = {"scenario": args.scenario, "seed": args.seed, "every_s": args.every,
              "name": args.name, "true_accel_bias": true_accel_bias(args.seed),
              "machine": machine_info(), "results": []}
    with tempfile.TemporaryDirectory() as tmp:
        for label, overrides in variants:
            print(f"[{args.scenario} seed {args.seed}] {label} ...", flush=True)
            r = run(args.scenario, args.seed, label, overrides, args.every, Path(tmp))
            print(f"  ATE {r.get('ate_m')}", flush=True)
            report["results"].append(r)
    command = "python -m benchmarks.studies.height_drift " + shlex.join(
        sys.argv[1:] if argv is None else argv)
    path = write_results(args.out, args.name, markdown(report, command), report)
    plot(report, Path(args.out) / f"{args.name}.png")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
